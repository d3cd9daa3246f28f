"""``linelaser-calib reconstruct``: a recording's profiles in the base frame with a
calibration (:func:`~linelaser_calib.reconstruct.reconstruct_bag`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from linelaser_calib.cli.common import (
    INTERRUPTS,
    calibration_pairing,
    check_output,
    pose_source,
    read_calibration,
    why_not_paired,
)
from linelaser_calib.core.errors import InputError, PairingError
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.kinematics import read_kinematics


def run(args: argparse.Namespace) -> int:
    from linelaser_calib.io.ply import write_ply
    from linelaser_calib.reconstruct import reconstruct_bag
    from linelaser_calib.report import write_cloud_mcap

    suffix = Path(args.output).suffix
    if suffix not in (".ply", ".mcap"):
        raise InputError(
            f"--output {args.output}: give a .ply file (point-cloud tools) or an .mcap file "
            "(PointCloud2 for Foxglove and RViz)"
        )
    check_output(args.output, "point cloud (--output)")
    try:
        calibration = read_calibration(args.calibration, "--calibration")
        corrections = read_kinematics(args.calibration)
    except ResultFileError as exc:
        raise ResultFileError(
            f"cannot use the calibration (--calibration): {exc}; give a result YAML written "
            "by linelaser-calib calibrate"
        ) from exc
    source, model = pose_source(args)
    if args.clock_offset == "auto":
        raise InputError(
            "reconstruct takes the clock offset from the calibration (quality.pairing) "
            "or as --clock-offset SECONDS; 'auto' applies to calibrate only"
        )
    pairing, paired_how = calibration_pairing(
        calibration,
        {
            "sync_tolerance_s": args.sync_tolerance,
            "clock_offset_s": args.clock_offset,
            "max_linear_speed_m_s": args.max_speed,
            "max_angular_speed_rad_s": args.max_angular_speed,
        },
    )
    try:
        done = reconstruct_bag(
            args.bag,
            calibration,
            pairing,
            kinematics=corrections,
            pose_source=source,
            model=model,
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
            joint_state_topic=args.joint_state_topic,
            base_frame=args.base_frame,
            flange_frame=args.flange_frame,
            invalid_values_m=tuple(args.invalid_value),
        )
    except PairingError as exc:
        raise PairingError(
            f"{exc} (Options of reconstruct: --clock-offset SECONDS, --sync-tolerance SECONDS.)"
        ) from exc
    INTERRUPTS.hold()
    if suffix == ".ply":
        written = write_ply(
            args.output, done.points, frame_id=done.base_frame, intensity=done.intensity
        )
    else:
        written = write_cloud_mcap(args.output, done.clouds, done.base_frame, done.intensities)
    corrected = " (kinematic corrections applied)" if corrections else ""
    print(
        f"{done.bag.path}: {len(done.clouds)} of {len(done.bag.profiles)} profiles mapped into "
        f"{done.base_frame} with {done.poses.description}{corrected}; {len(done.points)} points"
    )
    print(f"  {paired_how}")
    if done.rejected:
        print(f"  {len(done.rejected)} profiles not mapped: {why_not_paired(done.rejected)}")
    print(f"Wrote {written}")
    return 0
