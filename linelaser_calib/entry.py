"""The console scripts (``linelaser-calib`` and the two nodes): one BLAS thread per process,
then the command or the node.

Every BLAS call of a calibration is small (a few dozen rows), so a second OpenBLAS thread
only costs: its start when numpy loads, and its waiting beside the forked child that takes
half of the self-check's solves (:mod:`linelaser_calib.core.forked`, which forks only a
process without other threads). The limit is set here,
in the command line's own process before numpy loads, and only where the user has not set
``OPENBLAS_NUM_THREADS``; importing :mod:`linelaser_calib.cli` (tests, other programs) does
not set it.

The nodes (``ros2 run linelaser_calib collector`` / ``calibration_service``) never fork, but
they share the machine with the middleware's and the executor's threads: a second OpenBLAS
thread waiting for a core there made one live ``/calibrate`` on a 3,638-sample session take
71 s where the same solve took 2.9 s with the core free (two busy processes beside it on two
cores). With one BLAS thread the same session solves in the time the command line takes.
"""

from __future__ import annotations

import os
import signal
import sys


def _one_blas_thread() -> None:
    """One OpenBLAS thread in this process unless the user chose otherwise; before numpy
    loads."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main() -> int:
    """Console-script entry point: :func:`linelaser_calib.cli.main` with one BLAS thread.

    Ctrl-C while the libraries load (the first half-second) ends the run as Ctrl-C later
    does: one line, exit 130, no traceback; once the command has ended, its exit code
    stands."""
    _one_blas_thread()
    try:
        from linelaser_calib.cli import main as cli_main

        code = cli_main()
    except KeyboardInterrupt:
        print("linelaser-calib: interrupted", file=sys.stderr)
        return 130
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


def collector() -> int:
    """``ros2 run linelaser_calib collector``: the node with one BLAS thread."""
    _one_blas_thread()
    from linelaser_calib.nodes.collector import main as node_main

    return node_main()


def calibration_service() -> int:
    """``ros2 run linelaser_calib calibration_service``: the node with one BLAS thread."""
    _one_blas_thread()
    from linelaser_calib.nodes.calibration_service import main as node_main

    return node_main()
