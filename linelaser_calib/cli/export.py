"""``linelaser-calib export``: a result as a URDF joint, a static TF command, a launch file
or UR's kinematics YAML (:mod:`linelaser_calib.export`)."""

from __future__ import annotations

import argparse
import sys

from linelaser_calib.cli.common import read_calibration
from linelaser_calib.core.errors import InputError
from linelaser_calib.io.kinematics import read_kinematics


def run(args: argparse.Namespace) -> int:
    from linelaser_calib.export import ExportFormat, export_text, scale_note, ur_kinematics_yaml

    form = ExportFormat(args.format)
    if form is ExportFormat.UR_KINEMATICS:
        corrections = read_kinematics(args.result)
        if corrections is None:
            raise InputError(
                f"{args.result} holds no kinematics section: calibrate with --kinematics "
                "MODEL (and joint states in the recording) to estimate the robot's corrections"
            )
        print(ur_kinematics_yaml(corrections))
        return 0
    result = read_calibration(args.result, "result")
    print(export_text(result, form))
    note = scale_note(result)
    if note:
        print(note, file=sys.stderr)
    return 0
