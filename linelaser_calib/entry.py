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
import signal
import sys


def main() -> int:
    """Console-script entry point: :func:`linelaser_calib.cli.main` with one BLAS thread.

    Ctrl-C while the libraries load (the first half-second) ends the run as Ctrl-C later
    does: one line, exit 130, no traceback; once the command has ended, its exit code
    stands."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        from linelaser_calib.cli import main as cli_main

        code = cli_main()
    except KeyboardInterrupt:
        print("linelaser-calib: interrupted", file=sys.stderr)
        return 130
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code
