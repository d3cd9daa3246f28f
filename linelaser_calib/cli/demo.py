"""``linelaser-calib demo``: calibrate the committed bags and compare with their truth
(:func:`linelaser_calib.demo.run_demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    # Imported here: the demo loads the simulator's preset registry, which other verbs skip.
    from linelaser_calib.demo import format_demo_table, run_demo

    print(format_demo_table(run_demo(Path(args.bags), args.seed)))
    return 0
