"""``linelaser-calib``: the command line, a thin layer over the library.

Subcommands: ``simulate`` (write a synthetic bag and its truth), ``convert`` (another tool's
recordings into a bag), ``info`` (what a bag holds), ``calibrate`` (the offline
calibration), ``plan`` (the next flange poses to scan from), ``reconstruct`` (apply a
calibration: a recording's profiles in the base frame), ``export`` (a result as a URDF joint,
a static TF command or a launch file) and ``demo`` (calibrate the committed bags and show the
error against their truth). Exit code 0 means success; a user error prints one
paragraph on stderr and exits with 1; a usage error prints one line and a pointer to the
verb's ``--help`` and exits with 2; a reader of stdout that leaves early (``| head``) ends
the output quietly with 0 (docs/reference.md, "Exit status").

:mod:`~linelaser_calib.cli.parser` holds the parser and :func:`main`; each verb has its own
module calling a library function.
"""

from __future__ import annotations

from linelaser_calib.cli.parser import build_parser, main

__all__ = ["build_parser", "main"]
