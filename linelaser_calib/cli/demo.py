"""``linelaser-calib demo``: calibrate the committed bags and compare with their truth
(:mod:`linelaser_calib.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from linelaser_calib.core.errors import InputError
from linelaser_calib.demo import demo_runs


def run(args: argparse.Namespace) -> int:
    root = Path(args.bags)
    bags = sorted(p.parent for p in root.glob("*/metadata.yaml"))
    if not bags:
        raise InputError(f"no rosbag2 bags found under {root}; run from the repository root")
    rows: list[tuple[str, str, float, float, float]] = []
    for bag in bags:
        demo_runs(bag, args.seed, rows)
    print("Difference of the hand-eye T_flange_sensor to the truth (simulated bags) or to the")
    print("reference (real scans: another tool's published hand-eye, not ground truth):")
    print(f"  {'bag':<24}{'method':<22}{'rotation deg':>14}{'translation mm':>16}{'time s':>9}")
    for name, label, rot_deg, trans_mm, seconds in rows:
        print(f"  {name:<24}{label:<22}{rot_deg:>14.4f}{trans_mm:>16.4f}{seconds:>9.2f}")
    return 0
