"""``linelaser-calib convert``: another tool's recordings into a bag
(:func:`~linelaser_calib.io.robcalibrator.convert_robcalibrator`)."""

from __future__ import annotations

import argparse

from linelaser_calib.cli.common import PROG
from linelaser_calib.io.bags import bag_info, format_bag_info


def run(args: argparse.Namespace) -> int:
    from linelaser_calib.io.robcalibrator import convert_robcalibrator

    command = f"{PROG} convert {args.format} {args.folder} --output {args.output}"
    bag = convert_robcalibrator(args.folder, args.output, command)
    print(f"wrote {bag} (with reference.yaml, LICENSE and README.md)")
    print(format_bag_info(bag_info(bag)))
    return 0
