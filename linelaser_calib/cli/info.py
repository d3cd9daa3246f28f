"""``linelaser-calib info``: what a bag holds (:func:`~linelaser_calib.io.bags.bag_info`)."""

from __future__ import annotations

import argparse

from linelaser_calib.io.bags import bag_info, format_bag_info


def run(args: argparse.Namespace) -> int:
    print(format_bag_info(bag_info(args.bag)))
    return 0
