"""The ``linelaser-calib`` console script: one BLAS thread per process, then the command line.

Every BLAS call of a calibration is small (a few dozen rows), so a second OpenBLAS thread
only costs: its start when numpy loads, and its waiting beside the forked child that takes
half of the self-check's solves (:mod:`linelaser_calib.core.forked`, which forks only a
process without other threads). The limit is set here,
in the command line's own process before numpy loads, and only where the user has not set
``OPENBLAS_NUM_THREADS``; importing :mod:`linelaser_calib.cli` (tests, other programs) does
not set it.
"""

from __future__ import annotations

import os


def main() -> int:
    """Console-script entry point: :func:`linelaser_calib.cli.main` with one BLAS thread."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from linelaser_calib.cli import main as cli_main

    return cli_main()
