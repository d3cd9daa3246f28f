"""``linelaser-calib calibrate``: the offline calibration of a bag
(:func:`~linelaser_calib.offline.calibrate_bag`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from linelaser_calib.cli.common import (
    INTERRUPTS,
    StagedOutputs,
    StderrProgress,
    check_output,
    initial_hand_eye,
    pose_source,
)
from linelaser_calib.core.errors import (
    DegenerateError,
    InputError,
    ModelMismatch,
    PairingError,
    SolverError,
)
from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.robot.joint_calibration import JointCalibrationConfig
from linelaser_calib.core.selfcheck import DEFAULT_ARM_ACCURACY_M
from linelaser_calib.io.results import Truth, result_to_dict, truth_beside, write_result_yaml
from linelaser_calib.offline import OfflineRun, Recording, calibrate_bag
from linelaser_calib.settings import Front, given_from_arguments, pipeline_config, render_warnings
from linelaser_calib.summary import format_summary, refusal_text


def calibrate_config(args: argparse.Namespace) -> PipelineConfig:
    """The pipeline configuration of ``calibrate``; a flag that does not act is refused."""
    initial = None if args.initial is None else initial_hand_eye(args.initial)
    return pipeline_config(
        args.target,
        Method(args.method),
        given_from_arguments(args, initial),
        Front.CLI,
        seed=args.seed,
        pairing=PairingConfig(
            sync_tolerance_s=args.sync_tolerance,
            clock_offset_s=0.0 if args.clock_offset in (None, "auto") else float(args.clock_offset),
            max_linear_speed_m_s=args.max_speed,
            max_angular_speed_rad_s=args.max_angular_speed,
        ),
        workers=available_workers(),
        arm_accuracy_m=arm_accuracy(args),
        per_neighbourhood=args.per_neighbourhood,
    )


def arm_accuracy(args: argparse.Namespace) -> float:
    """``arm_accuracy_m``: ``--arm-accuracy``, or the default; refused with ``--kinematics``
    unless ``--nominal-kinematics`` (the joint calibration estimates the error it stands for)."""
    if args.arm_accuracy is None:
        return DEFAULT_ARM_ACCURACY_M
    if args.kinematics is not None and not args.nominal_kinematics:
        raise InputError(
            "--arm-accuracy does not act with --kinematics and would be ignored: the joint "
            "calibration estimates the robot's systematic error itself; omit it"
        )
    return float(args.arm_accuracy)


def _check_outputs(args: argparse.Namespace) -> None:
    """Validate every output of ``calibrate`` before the (possibly long) calibration."""
    if args.output is not None:
        check_output(args.output, "result file (--output)")
    if args.viz is not None:
        if Path(args.viz).suffix != ".mcap":
            raise InputError(
                f"--viz writes an MCAP file; give a name ending in .mcap, not {args.viz}"
            )
        check_output(args.viz, "visualisation file (--viz)")
    if args.report is not None:
        from linelaser_calib.report import require_matplotlib

        check_output(args.report, "report directory (--report)", directory=True)
        require_matplotlib()


def run(args: argparse.Namespace) -> int:
    _check_outputs(args)
    config = calibrate_config(args)
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    source, model = pose_source(args)
    if args.nominal_kinematics and model is None:
        raise InputError(
            "--nominal-kinematics keeps the robot model of --kinematics nominal; give "
            "--kinematics MODEL or leave --nominal-kinematics out"
        )
    try:
        recording = Recording(
            args.bag,
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
            pose_source=source,
            base_frame=args.base_frame,
            flange_frame=args.flange_frame,
            joint_state_topic=args.joint_state_topic,
            model=model,
            invalid_values_m=tuple(args.invalid_value),
        )
        run = calibrate_bag(
            recording,
            config,
            estimate_offset=args.clock_offset == "auto",
            progress=StderrProgress(progress),
            kinematic_calibration=(
                None if model is None or args.nominal_kinematics else JointCalibrationConfig()
            ),
            placements=args.placements,
        )
    except PairingError as exc:
        raise PairingError(
            refusal_text(
                f"{exc} (Options of calibrate: --clock-offset SECONDS, --sync-tolerance SECONDS.)"
            )
        ) from exc
    except (DegenerateError, ModelMismatch, SolverError) as exc:
        exc.args = (refusal_text(str(exc)),)
        raise
    render_warnings(run.result, Front.CLI)
    truth, note = truth_beside(args.bag)
    if note:
        print(note, file=sys.stderr)
    INTERRUPTS.hold()
    written = _write_outputs(args, run, truth)
    if args.json:
        print(json.dumps(result_to_dict(run.result), indent=2))
    else:
        inputs = [_input_line(run)]
        if args.placements:
            inputs.append(
                f"  calibrated together with {len(args.placements)} more recordings "
                f"({', '.join(args.placements)}): one hand-eye and one set of kinematic "
                "corrections; the target, residuals and self-check below are the first "
                "recording's"
            )
        print(format_summary(run.result, truth, inputs))
        for path in written:
            print(f"Wrote {path}")
    return 0


def _write_outputs(args: argparse.Namespace, run: OfflineRun, truth: Truth | None) -> list[Path]:
    """Write the result, the visualisation and the report, all or none: the visualisation and
    the report are staged, the result written (atomically), then both moved into place; a
    failure on the way removes what was staged and leaves any earlier file as it was."""
    written: list[Path] = []
    index = None
    staged = StagedOutputs()
    try:
        if args.viz is not None or args.report is not None:
            from linelaser_calib.report import write_report, write_viz_mcap

            if args.viz is not None:
                write_viz_mcap(staged.stage(args.viz), run.result)
            if args.report is not None:
                index = write_report(
                    staged.stage(args.report), run.result, inputs=_input_rows(run), truth=truth
                ).name
        if args.output is not None:
            written.append(write_result_yaml(run.result, args.output))
        staged.commit()
    except BaseException:
        staged.discard()
        raise
    if args.viz is not None:
        written.append(Path(args.viz))
    if index is not None:
        written.append(Path(args.report) / index)
    return written


def _input_rows(run: OfflineRun) -> list[tuple[str, str]]:
    """What was calibrated, as (label, text) rows."""
    bag = run.bag
    return [
        ("bag", str(bag.path)),
        ("profiles", f"{len(bag.profiles)} on {bag.profile_topic} (frame {bag.sensor_frame})"),
        ("flange poses", run.poses.description),
    ]


def _input_line(run: OfflineRun) -> str:
    bag = run.bag
    return (
        f"{bag.path}: {len(bag.profiles)} profiles on {bag.profile_topic}, {run.poses.description}"
    )
