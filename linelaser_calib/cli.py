"""``linelaser-calib``: a thin command-line wrapper around the library.

Subcommands: ``simulate`` (write a synthetic bag and its truth), ``convert`` (another tool's
recordings into a bag), ``info`` (what a bag holds), ``calibrate`` (the offline
calibration), ``plan`` (the next flange poses to scan from), ``reconstruct`` (apply a
calibration: a recording's profiles in the base frame), ``export`` (a result as a URDF joint,
a static TF command or a launch file) and ``demo`` (calibrate the committed bags and show the
error against their truth). Exit code 0 means success; a user error prints one
paragraph on stderr and exits with 1; a usage error exits with 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from linelaser_calib.core.errors import CalibrationError, InputError, PairingError
from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.planning import (
    Plan,
    PlanConstraints,
    SigmaPoint,
    plan_for_target,
    plannable,
    predicted_curve,
)
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.joint_calibration import JointCalibrationConfig
from linelaser_calib.core.robot.kinematics import KinematicModel
from linelaser_calib.core.selfcheck import DEFAULT_ARM_ACCURACY_M
from linelaser_calib.core.targets import DEFAULT_TARGET, get_target, target_names
from linelaser_calib.core.targets.base import ResultSection, configure
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import Sample
from linelaser_calib.io.bags import bag_info, format_bag_info, write_bag
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.initial import FORMS, read_initial_hand_eye
from linelaser_calib.io.kinematics import (
    SECTION,
    kinematics_section,
    load_model,
    read_kinematics,
)
from linelaser_calib.io.results import (
    read_reference_yaml,
    read_result_yaml,
    result_to_dict,
    truth_beside,
    write_plan_yaml,
    write_result_yaml,
    write_truth_yaml,
)
from linelaser_calib.offline import OfflineRun, advise_placements, bag_samples, calibrate_bag
from linelaser_calib.summary import format_summary, hand_eye_seen

PROG = "linelaser-calib"


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def _seed(text: str) -> int:
    """A seed of the random stages: an integer from 0 to 2**32 - 1 (numpy's generators take
    no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to 2**32 - 1, got {text}")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (np.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
    return value


def _min_samples(text: str) -> int:
    """Parse a sample count >= 3."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 3, got {text!r}") from None
    if value < 3:
        raise argparse.ArgumentTypeError(f"expected an integer >= 3, got {value}")
    return value


def _offset(text: str) -> float | str:
    """Parse a clock offset in s, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds or 'auto', got {text!r}") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected finite seconds, got {text!r}")
    return value


def _centre_side(text: str) -> str:
    """Parse ``+y`` or ``-y``."""
    if text not in ("+y", "-y"):
        raise argparse.ArgumentTypeError(f"expected +y or -y, got {text!r}")
    return text


def _xyz(text: str) -> tuple[float, float, float]:
    """Parse ``x,y,z`` (m)."""
    try:
        x, y, z = (float(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,z in metres, got {text!r}") from None
    if not all(np.isfinite([x, y, z])):
        raise argparse.ArgumentTypeError(f"expected finite x,y,z in metres, got {text!r}")
    return x, y, z


# --- simulate -------------------------------------------------------------------------------


def simulate_to_bag(
    out: Path, scenario_name: str, seed: int, overrides: dict[str, object], *, tf: bool = False
) -> tuple[Path, Path]:
    """Simulate a scenario, write its bag directory and ``truth.yaml`` beside the .mcap.

    Weld-seam scenarios (known-point target) also get ``initial.yaml``: an old hand-eye, the
    truth bumped by 1-2 deg and 1-3 mm, with the taught point, as ``--initial`` input; so do
    straight-seam scenarios (line target), with the true line.
    With ``tf`` the flange poses are also written as a robot_state_publisher-style
    ``/tf`` chain base frame -> flange frame, with its fixed links on ``/tf_static``
    (:func:`~linelaser_calib.sim.tf_chain.ur_tf_tree`).
    Returns the bag directory and the truth file.
    """
    from linelaser_calib.core.targets.cylinder import CylinderSection
    from linelaser_calib.core.targets.known_point import KnownPoint
    from linelaser_calib.core.targets.line import Line, LineSection
    from linelaser_calib.core.targets.sphere import SphereSection
    from linelaser_calib.sim.line import LINE_PRESETS, line_scenario_from_preset, simulate_line
    from linelaser_calib.sim.scenario import scenario_from_preset
    from linelaser_calib.sim.simulate import simulate
    from linelaser_calib.sim.sphere import (
        SPHERE_PRESETS,
        simulate_sphere,
        sphere_scenario_from_preset,
    )
    from linelaser_calib.sim.tf_chain import ur_tf_tree
    from linelaser_calib.sim.weld import (
        WELD_PRESETS,
        bumped_hand_eye,
        simulate_weld,
        weld_scenario_from_preset,
    )

    weld = scenario_name in WELD_PRESETS
    arm, joint_states = None, None  # only the cylinder scenes simulate an arm's joints
    initial_target: ResultSection | None = None
    if weld:
        weld_data = simulate_weld(weld_scenario_from_preset(scenario_name, **overrides), seed)
        scenario, profiles, poses = weld_data.scenario, weld_data.profiles, weld_data.poses
        intensities, T_true = weld_data.intensities, weld_data.truth.T_flange_sensor
        target: ResultSection = KnownPoint(weld_data.truth.weld_point_m, estimated=False)
        initial_target = KnownPoint(np.asarray(weld_data.truth.taught_point_m), estimated=False)
    elif scenario_name in SPHERE_PRESETS:
        # --radius is the target's radius: the sphere's here.
        own = {"radius_m" if k == "cylinder_radius_m" else k: v for k, v in overrides.items()}
        ball = simulate_sphere(sphere_scenario_from_preset(scenario_name, **own), seed)
        scenario, profiles, poses = ball.scenario, ball.profiles, ball.poses
        intensities, T_true = ball.intensities, ball.truth.T_flange_sensor
        target = SphereSection(
            ball.truth.centre_m,
            ball.truth.radius_m,
            ball.truth.centre_side,
            radius_estimated=False,
            side_estimated=False,
        )
    elif scenario_name in LINE_PRESETS:
        line_data = simulate_line(line_scenario_from_preset(scenario_name, **overrides), seed)
        scenario, profiles, poses = line_data.scenario, line_data.profiles, line_data.poses
        intensities, T_true = line_data.intensities, line_data.truth.T_flange_sensor
        target = LineSection(Line(line_data.truth.line_point, line_data.truth.line_direction))
        initial_target = target
    else:
        data = simulate(scenario_from_preset(scenario_name, **overrides), seed)
        scenario, profiles, poses = data.scenario, data.profiles, data.poses
        intensities, T_true = data.intensities, data.truth.T_flange_sensor
        target = CylinderSection(data.truth.cylinder)
        arm, joint_states = data.truth.arm, data.joint_states
    tf_dynamic, tf_static = (
        ur_tf_tree(poses, scenario.base_frame, scenario.flange_frame) if tf else ([], [])
    )
    write_bag(
        out,
        profiles,
        poses,
        profile_topic=scenario.profile_topic,
        pose_topic=scenario.pose_topic,
        sensor_frame=scenario.sensor_frame,
        base_frame=scenario.base_frame,
        organised=scenario.organised,
        intensities=intensities if scenario.intensity else None,
        tf=tf_dynamic,
        tf_static=tf_static,
        joint_states=joint_states,
        joint_state_topic=scenario.joint_state_topic,
    )
    simulation: dict[str, object] = {
        "scenario": scenario_name,
        "seed": seed,
        "overrides": overrides,
        "profiles": len(profiles),
        "poses": len(poses),
        "command": simulate_command(out, scenario_name, seed, overrides, tf=tf),
    }
    if weld:
        simulation["taught_point"] = weld_data.truth.taught_point_m
    if initial_target is not None:
        write_result_yaml(
            CalibrationResult(
                T_flange_sensor=bumped_hand_eye(T_true, np.random.default_rng(seed)),
                target=initial_target,
                method="initial",
                samples_used=[],
                samples_rejected=[],
                rms_residual_m=0.0,
                parent_frame=scenario.flange_frame,
                child_frame=scenario.sensor_frame,
                base_frame=scenario.base_frame,
            ),
            out / "initial.yaml",
        )
    truth = write_truth_yaml(
        out / "truth.yaml",
        T_true,
        target,
        parent_frame=scenario.flange_frame,
        child_frame=scenario.sensor_frame,
        base_frame=scenario.base_frame,
        extra={
            "simulation": simulation,
            **({} if arm is None else {SECTION: kinematics_section(arm.errors, arm.nominal)}),
        },
    )
    return out, truth


#: Command-line options of ``simulate`` that override scenario fields: (flag, field, type).
SIMULATE_OPTIONS: tuple[tuple[str, str, Callable[[str], object]], ...] = (
    ("--poses", "n_poses", int),
    ("--radius", "cylinder_radius_m", float),  # the sphere's radius with a sphere preset
    ("--points", "resolution", int),
    ("--sensor-sigma", "sigma_depth_m", float),
    ("--robot-sigma-t", "robot_sigma_translation_m", float),
    ("--robot-sigma-r", "robot_sigma_rotation_rad", float),
    ("--spikes", "spike_fraction", float),
    ("--arm-seed", "kinematic_seed", int),  # the same arm's kinematic errors in other runs
    ("--cylinder-base", "cylinder_base_m", _xyz),  # another placement of the cylinder, m
    ("--axis", "axis_direction", _xyz),
    ("--profile-topic", "profile_topic", str),
    ("--pose-topic", "pose_topic", str),
    ("--sensor-frame", "sensor_frame", str),
    ("--flange-frame", "flange_frame", str),
    ("--base-frame", "base_frame", str),
)


def simulate_command(
    out: Path, scenario_name: str, seed: int, overrides: dict[str, object], *, tf: bool = False
) -> str:
    """The ``linelaser-calib simulate`` command line that regenerates a bag."""
    flags = {field: flag for flag, field, _ in SIMULATE_OPTIONS}
    words = [PROG, "simulate", str(out), "--scenario", scenario_name, "--seed", str(seed)]
    for field, value in overrides.items():
        if field == "organised":
            words.append("--organised" if value else "--dense")
        elif isinstance(value, tuple):
            words += [flags[field], ",".join(f"{v:g}" for v in value)]
        else:
            words += [flags[field], str(value)]
    if tf:
        words.append("--tf")
    return " ".join(words)


def _cmd_simulate(args: argparse.Namespace) -> int:
    overrides: dict[str, object] = {
        field: getattr(args, field)
        for _, field, _ in SIMULATE_OPTIONS
        if getattr(args, field) is not None
    }
    if args.organised is not None:
        overrides["organised"] = args.organised
    bag, truth = simulate_to_bag(Path(args.out), args.scenario, args.seed, overrides, tf=args.tf)
    print(f"wrote {bag} and {truth}")
    print(format_bag_info(bag_info(bag)))
    return 0


# --- info -----------------------------------------------------------------------------------


def _cmd_info(args: argparse.Namespace) -> int:
    print(format_bag_info(bag_info(args.bag)))
    return 0


# --- convert --------------------------------------------------------------------------------


def _cmd_convert(args: argparse.Namespace) -> int:
    from linelaser_calib.io.robcalibrator import convert_robcalibrator

    command = f"{PROG} convert {args.format} {args.folder} --output {args.output}"
    bag = convert_robcalibrator(args.folder, args.output, command)
    print(f"wrote {bag} (with reference.yaml, LICENSE and README.md)")
    print(format_bag_info(bag_info(bag)))
    return 0


# --- calibrate ------------------------------------------------------------------------------


#: The calibrate flag behind each shared target setting (for refusals).
SETTING_FLAGS = {
    "radius_m": "--radius",
    "point_m": "--point x,y,z",
    "centre_side": "--centre-side",
    "sensor_sigma_m": "--sensor-sigma",
    "robot_sigma_t_m": "--robot-sigma-t",
    "robot_sigma_r_rad": "--robot-sigma-r",
    "min_samples": "--min-samples",
    "scale": "--scale",
    "initial": "--initial FILE.yaml",
}


def _initial_hand_eye(text: str) -> np.ndarray:
    """The hand-eye (4, 4) of ``--initial``; its warnings go to stderr."""
    try:
        initial, warnings = read_initial_hand_eye(text)
    except CalibrationError as exc:
        raise type(exc)(f"cannot use the initial hand-eye (--initial): {exc}") from exc
    for warning in warnings:
        print(f"{PROG}: warning: --initial: {warning}", file=sys.stderr)
    return initial


def _pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    """The pipeline configuration of ``calibrate``; a flag that does not act is refused."""
    initial = None if args.initial is None else _initial_hand_eye(args.initial)
    given = {
        "radius_m": args.radius,
        "point_m": None if args.point is None else np.array(args.point),
        "centre_side": args.centre_side,
        "sensor_sigma_m": args.sensor_sigma,
        "robot_sigma_t_m": args.robot_sigma_t,
        "robot_sigma_r_rad": args.robot_sigma_r,
        "min_samples": args.min_samples,
        "scale": args.scale,
        "initial": initial,
    }
    target = get_target(args.target)
    settings = {name: value for name, value in given.items() if value is not None}
    return PipelineConfig(
        method=Method(args.method),
        target=target.name,
        target_config=configure(target, args.method, settings, SETTING_FLAGS),
        seed=args.seed,
        pairing=PairingConfig(
            sync_tolerance_s=args.sync_tolerance,
            clock_offset_s=0.0 if args.clock_offset in (None, "auto") else float(args.clock_offset),
            max_linear_speed_m_s=args.max_speed,
            max_angular_speed_rad_s=args.max_angular_speed,
        ),
        initial_T_flange_sensor=initial,
        workers=available_workers(),
        arm_accuracy_m=_arm_accuracy(args),
    )


def _arm_accuracy(args: argparse.Namespace) -> float:
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


class _StderrProgress:
    """Progress on stderr, one line per stage, for long bags."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.started = time.monotonic()
        self.last_stage = ""

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self.last_stage or done == total:
            elapsed = time.monotonic() - self.started
            print(f"  [{elapsed:6.2f} s] {stage}: {done}/{total}", file=sys.stderr)
            self.last_stage = stage


def _check_output(path: str, what: str, *, directory: bool = False) -> Path:
    """Fail before calibrating when an output cannot be written where the user asked.

    The directory that is to hold the output must exist (a typo should not create a tree of
    directories); a file output must not be an existing directory.
    """
    target = Path(path)
    parent = target.absolute().parent
    if not parent.is_dir():
        problem = "is not a directory" if parent.exists() else "does not exist"
        raise InputError(
            f"cannot write the {what} {target}: its directory {parent} {problem}; "
            "create the directory first or fix the path"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(
            f"cannot write the {what} {target}: its directory {parent} is not writable; "
            "choose another path"
        )
    if target.is_dir() != directory and target.exists():
        kind = "an existing directory" if target.is_dir() else "an existing file"
        raise InputError(f"cannot write the {what} {target}: it is {kind}; choose another path")
    return target


def _check_outputs(args: argparse.Namespace) -> None:
    """Validate every output of ``calibrate`` before the (possibly long) calibration."""
    if args.output is not None:
        _check_output(args.output, "result file (--output)")
    if args.viz is not None:
        if Path(args.viz).suffix != ".mcap":
            raise InputError(
                f"--viz writes an MCAP file; give a name ending in .mcap, not {args.viz}"
            )
        _check_output(args.viz, "visualisation file (--viz)")
    if args.report is not None:
        from linelaser_calib.report import require_matplotlib

        _check_output(args.report, "report directory (--report)", directory=True)
        require_matplotlib()


def _cmd_calibrate(args: argparse.Namespace) -> int:
    _check_outputs(args)
    config = _pipeline_config(args)
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    source, model = _pose_source(args)
    if args.nominal_kinematics and model is None:
        raise InputError(
            "--nominal-kinematics keeps the robot model of --kinematics nominal; give "
            "--kinematics MODEL or leave --nominal-kinematics out"
        )
    try:
        run = calibrate_bag(
            args.bag,
            config,
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
            flange_frame=args.flange_frame,
            estimate_offset=args.clock_offset == "auto",
            progress=_StderrProgress(progress),
            pose_source=source,
            base_frame=args.base_frame,
            invalid_values_m=tuple(args.invalid_value),
            joint_state_topic=args.joint_state_topic,
            model=model,
            kinematic_calibration=(
                None if model is None or args.nominal_kinematics else JointCalibrationConfig()
            ),
            placements=args.placements,
        )
    except PairingError as exc:
        raise PairingError(
            f"{exc} (Options of calibrate: --clock-offset SECONDS, --sync-tolerance SECONDS.)"
        ) from exc
    truth, note = truth_beside(args.bag)
    if note:
        print(note, file=sys.stderr)
    written = []
    if args.output is not None:
        written.append(write_result_yaml(run.result, args.output))
    if args.viz is not None or args.report is not None:
        from linelaser_calib.report import write_report, write_viz_mcap

        if args.viz is not None:
            written.append(write_viz_mcap(args.viz, run.result))
        if args.report is not None:
            written.append(
                write_report(args.report, run.result, inputs=_input_rows(run), truth=truth)
            )
    if args.json:
        print(json.dumps(result_to_dict(run.result), indent=2))
    else:
        print(_input_line(run))
        if args.placements:
            print(
                f"  calibrated together with {len(args.placements)} more recordings "
                f"({', '.join(args.placements)}): one hand-eye and one set of kinematic "
                "corrections; the target, residuals and self-check below are the first "
                "recording's"
            )
        print(format_summary(run.result, truth))
        for path in written:
            print(f"Wrote {path}")
    return 0


def _pose_source(args: argparse.Namespace) -> tuple[PoseSource, KinematicModel | None]:
    """The pose source and robot model of ``--pose-source`` and ``--kinematics``.

    Without ``--pose-source``, ``--kinematics`` selects the joint states, else the
    PoseStamped topic is the source.
    """
    if args.pose_source is None:
        args.pose_source = (
            PoseSource.POSE.value if args.kinematics is None else PoseSource.JOINT_STATES.value
        )
    source = PoseSource(args.pose_source)
    if source is PoseSource.JOINT_STATES and args.kinematics is None:
        raise InputError(
            "--pose-source joint_states computes the flange poses from the joint states "
            "through the robot's kinematic model: pass --kinematics ur5e, ur10e or a URDF file"
        )
    if source is not PoseSource.JOINT_STATES and args.kinematics is not None:
        raise InputError(
            f"--kinematics {args.kinematics} selects the robot model of the joint_states pose "
            f"source and does not apply to --pose-source {source.value}; add --pose-source "
            "joint_states or leave --kinematics out"
        )
    if args.kinematics is None:
        return source, None
    return source, load_model(
        args.kinematics, base_frame=args.base_frame, flange_frame=args.flange_frame
    )


def _add_pairing_arguments(parser: argparse.ArgumentParser, clock_offset_help: str) -> None:
    parser.add_argument(
        "--sync-tolerance",
        type=_positive_float,
        default=PairingConfig.sync_tolerance_s,
        help="largest profile-to-pose stamp gap, s",
    )
    parser.add_argument("--clock-offset", type=_offset, default=None, help=clock_offset_help)
    for flag, parse, default, text in CALIBRATE_NUMBERS:
        if flag in PAIRING_FLAGS:
            parser.add_argument(flag, type=parse, default=default, help=text)


# --- reconstruct ----------------------------------------------------------------------------


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    from linelaser_calib.io.ply import write_ply
    from linelaser_calib.reconstruct import reconstruct_bag
    from linelaser_calib.report import write_cloud_mcap

    suffix = Path(args.output).suffix
    if suffix not in (".ply", ".mcap"):
        raise InputError(
            f"--output {args.output}: give a .ply file (point-cloud tools) or an .mcap file "
            "(PointCloud2 for Foxglove and RViz)"
        )
    _check_output(args.output, "point cloud (--output)")
    try:
        calibration = read_result_yaml(args.calibration)
        corrections = read_kinematics(args.calibration)
    except ResultFileError as exc:
        raise ResultFileError(
            f"cannot use the calibration (--calibration): {exc}; give a result YAML written "
            "by linelaser-calib calibrate"
        ) from exc
    source, model = _pose_source(args)
    if args.clock_offset == "auto":
        raise InputError(
            "reconstruct takes the clock offset from the calibration (quality.clock_offset_s) "
            "or as --clock-offset SECONDS; 'auto' applies to calibrate only"
        )
    offset = calibration.clock_offset_s if args.clock_offset is None else args.clock_offset
    pairing = PairingConfig(
        sync_tolerance_s=args.sync_tolerance,
        clock_offset_s=float(offset),
        max_linear_speed_m_s=args.max_speed,
        max_angular_speed_rad_s=args.max_angular_speed,
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
    if done.rejected:
        reasons = sorted({r.reason.split(" (")[0] for r in done.rejected})
        print(f"  {len(done.rejected)} profiles not paired: {'; '.join(reasons[:3])}")
    print(f"Wrote {written}")
    return 0


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


# --- plan -----------------------------------------------------------------------------------


def _numbers(text: str) -> list[float]:
    """Parse comma-separated finite numbers."""
    try:
        values = [float(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers a,b,..., got {text!r}") from None
    if not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def _span(text: str) -> tuple[float, float]:
    """Parse ``lo,hi`` (m)."""
    values = _numbers(text)
    if len(values) != 2 or not values[0] < values[1]:
        raise argparse.ArgumentTypeError(f"expected LO,HI in metres with LO < HI, got {text!r}")
    return values[0], values[1]


#: The target settings ``plan`` takes (those that shape the information of a pose).
PLAN_TARGET_OPTIONS = (
    "--radius",
    "--centre-side",
    "--sensor-sigma",
    "--robot-sigma-t",
    "--robot-sigma-r",
)


def _plan_constraints(args: argparse.Namespace) -> PlanConstraints:
    return PlanConstraints(
        z_min_m=args.range[0],
        z_max_m=args.range[1],
        fan_half_angle_rad=float(np.deg2rad(args.fan_deg)),
        reach_centre_m=args.reach_centre,
        reach_half_extent_m=args.reach,
        table_height_m=None if args.no_table else args.table_height,
    )


def _cmd_plan(args: argparse.Namespace) -> int:
    if args.output is not None:
        _check_output(args.output, "plan file (--output)")
    if args.figure is not None:
        from linelaser_calib.report import require_matplotlib

        _check_output(args.figure, "figure (--figure)")
        require_matplotlib()
    target = get_target(args.target)
    section = None
    achieved: list[SigmaPoint] = []
    planner = plannable(target)
    placed = {"--cylinder": args.cylinder, "--sphere": args.sphere}
    given_numbers = {flag: value for flag, value in placed.items() if value is not None}
    for flag in given_numbers:
        if flag != planner.numbers_flag:
            raise InputError(
                f"{flag} does not apply to the {target.title} target and would be ignored; "
                f"give its placement with {planner.numbers_flag} ({planner.numbers_help})"
            )
    numbers = given_numbers.get(planner.numbers_flag)
    if args.from_result is not None:
        if args.initial is not None or numbers is not None:
            raise InputError(
                "--from gives the hand-eye and the target's placement; omit --initial and "
                f"{planner.numbers_flag}"
            )
        result = read_result_yaml(args.from_result)
        if result.target.key != target.name:
            raise InputError(
                f"{args.from_result} holds a {result.target.key} result, not a {target.name} "
                f"one; choose --target {result.target.key}"
            )
        T_flange_sensor, section = result.T_flange_sensor, result.target
        sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
        if sigma_t is not None and sigma_r is not None:
            achieved = [(len(result.samples_used), sigma_t, sigma_r)]
    elif args.initial is not None:
        T_flange_sensor = _initial_hand_eye(args.initial)
    else:
        raise InputError(
            "plan needs the current hand-eye: give --from RESULT.yaml (a calibration of this "
            "set-up), or --initial (a file or 'x y z qx qy qz qw', e.g. from CAD, within ~5 mm "
            "and ~5 deg) with "
            "--cylinder or a bag of 3 or more exploratory scans; the planner does not yet "
            "estimate the hand-eye from exploratory scans alone"
        )
    if section is None and numbers is None and args.bag is None:
        raise InputError(
            f"plan needs the target's placement: give --from RESULT.yaml, "
            f"{planner.numbers_flag} {planner.numbers_help}, or a bag of 3 or more exploratory "
            "scans"
        )
    given = {
        "radius_m": args.radius,
        "centre_side": args.centre_side,
        "sensor_sigma_m": args.sensor_sigma,
        "robot_sigma_t_m": args.robot_sigma_t,
        "robot_sigma_r_rad": args.robot_sigma_r,
    }
    settings = {name: value for name, value in given.items() if value is not None}
    config = configure(target, "default", settings, SETTING_FLAGS)
    samples = (
        []
        if args.bag is None
        else bag_samples(
            args.bag,
            PairingConfig(),
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
        )
    )
    goal = None
    if args.goal_mm is not None or args.goal_deg is not None:
        goal = (
            np.inf if args.goal_mm is None else args.goal_mm * 1e-3,
            np.inf if args.goal_deg is None else float(np.deg2rad(args.goal_deg)),
        )
    advice = (
        None
        if args.kinematics is None
        else _placement_advice(args, samples, T_flange_sensor, section, numbers)
    )
    started = time.monotonic()
    plan = plan_for_target(
        target,
        config,
        T_flange_sensor,
        args.n,
        samples=samples,
        section=section,
        numbers=numbers,
        extent=args.axial_range,
        constraints=_plan_constraints(args),
        goal=goal,
        seed=args.seed,
    )
    elapsed = time.monotonic() - started
    print(format_plan(plan, elapsed))
    if advice:
        print("Placements: " + advice)
    if args.output is not None:
        print(f"Wrote {write_plan_yaml(plan, args.output)}")
    if args.figure is not None:
        from linelaser_calib.report.figures import DPI, sigma_curve_figure

        sigma_curve_figure(predicted_curve(plan), achieved).savefig(args.figure, dpi=DPI)
        print(f"Wrote {args.figure}")
    return 0


def _placement_advice(
    args: argparse.Namespace,
    samples: list[Sample],
    T_flange_sensor: np.ndarray,
    section: ResultSection | None,
    numbers: list[float] | None,
) -> str:
    """``plan --kinematics``: whether another placement of the cylinder would determine more
    of the robot's kinematics, from the bag's scans and joint states."""
    from linelaser_calib.core.targets.cylinder import CylinderSection
    from linelaser_calib.io.bags import read_joint_states

    if args.bag is None or args.target != "cylinder":
        raise InputError(
            "plan --kinematics judges the placements of a cylinder from the scans so far: give "
            "the bag (with /joint_states) and --target cylinder"
        )
    if isinstance(section, CylinderSection):
        cylinder = section.cylinder
    elif numbers is not None and args.radius is not None:
        direction = np.array(numbers[3:6]) / np.linalg.norm(numbers[3:6])
        cylinder = Cylinder(np.array(numbers[:3]), direction, args.radius)
    else:
        raise InputError(
            "plan --kinematics needs the cylinder's placement: give --from RESULT.yaml (e.g. "
            "of calibrate --kinematics) or --cylinder with --radius"
        )
    model = load_model(args.kinematics)
    if args.from_result is not None:
        corrections = read_kinematics(args.from_result)
        if corrections is not None:
            model = corrections.apply(model)
    states = read_joint_states(args.bag)
    return advise_placements(samples, states, model, T_flange_sensor, cylinder)


def format_plan(plan: Plan, elapsed_s: float) -> str:
    """The plan as a table: pose, flange position (mm), predicted 1 sigma after it."""
    lines = [
        f"{len(plan.poses)} poses chosen from {plan.candidates} feasible candidates in "
        f"{elapsed_s:.2f} s (D-optimal on the hand-eye's information)."
    ]
    if plan.sigma_translation_m is not None and plan.sigma_rotation_rad is not None:
        lines.append(
            "Predicted 1 sigma from the scans taken: "
            f"{np.array2string(plan.sigma_translation_m * 1e3, precision=4)} mm, "
            f"{np.array2string(np.rad2deg(plan.sigma_rotation_rad), precision=4)} deg"
        )
    lines.append(
        f"{'pose':>4}  {'flange position x, y, z (mm)':>30}  "
        f"{'1 sigma translation (mm)':>26}  {'1 sigma rotation (deg)':>26}"
    )
    for k, pose in enumerate(plan.poses, 1):
        p = pose.T_base_flange[:3, 3] * 1e3
        t = pose.sigma_translation_m * 1e3
        r = np.rad2deg(pose.sigma_rotation_rad)
        lines.append(
            f"{k:>4}  {p[0]:9.1f} {p[1]:9.1f} {p[2]:9.1f}   "
            f"{t[0]:8.4f} {t[1]:8.4f} {t[2]:8.4f}  {r[0]:8.4f} {r[1]:8.4f} {r[2]:8.4f}"
        )
    if plan.goal_reached:
        lines.append("The goal is reached: the predicted 1 sigma is within it.")
    return "\n".join(lines)


# --- export ---------------------------------------------------------------------------------


def _cmd_export(args: argparse.Namespace) -> int:
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
    result = read_result_yaml(args.result)
    print(export_text(result, form))
    note = scale_note(result)
    if note:
        print(note, file=sys.stderr)
    return 0


# --- demo -----------------------------------------------------------------------------------


def _preset_motion(name: object) -> str | None:
    """The motion (``step``, ``continuous``) of a simulator preset; None for another name."""
    from linelaser_calib.sim.line import LINE_PRESETS
    from linelaser_calib.sim.scenario import PRESETS
    from linelaser_calib.sim.sphere import SPHERE_PRESETS
    from linelaser_calib.sim.weld import WELD_PRESETS

    rigs = {
        **PRESETS,
        **{k: v.rig for k, v in WELD_PRESETS.items()},
        **{k: v.rig for k, v in LINE_PRESETS.items()},
        **{k: v.rig for k, v in SPHERE_PRESETS.items()},
    }
    rig = rigs.get(name) if isinstance(name, str) else None
    return None if rig is None else rig.motion


def _demo_runs(bag: Path, seed: int, rows: list[tuple[str, str, float, float, float]]) -> None:
    """Calibrate one committed bag with both methods, print the summaries, add table rows.

    A simulated bag is compared with its ``truth.yaml`` (and, with ``initial.yaml``,
    corrects that hand-eye; a continuous scan is calibrated as one, at any flange speed with
    the clock offset estimated); a converted real recording with its ``reference.yaml``
    (another tool's hand-eye, calibrated with the settings recorded there). A bag with
    neither is skipped with a note.
    """
    settings: dict[str, object] = {}
    initial = None
    continuous = False
    truth, note = truth_beside(bag)
    if truth is None and not (bag / "reference.yaml").is_file():
        print(note or f"{bag} has no truth.yaml or reference.yaml; skipped", file=sys.stderr)
        return
    if truth is not None:
        target = get_target(truth.target.key)
        compare, against = truth.T_flange_sensor, "truth"
        label = target.title
        if (bag / "initial.yaml").is_file():
            initial = read_result_yaml(bag / "initial.yaml")
            settings = {**initial.target.given_settings(), "initial": initial.T_flange_sensor}
            label += ", from initial.yaml"
            rot, trans = transform_error(initial.T_flange_sensor, truth.T_flange_sensor)
            rows.append((bag.name, "initial", np.degrees(rot), trans * 1e3, 0.0))
        continuous = _preset_motion(truth.raw.get("simulation", {}).get("scenario")) == "continuous"
        if continuous:
            label += ", continuous, clock offset estimated"
    else:
        compare, reference = read_reference_yaml(bag / "reference.yaml")
        target = get_target(str(reference["target"]))
        settings = dict(reference.get("settings") or {})
        against = "reference"
        label = f"{target.title}, real scans; reference.yaml is not ground truth"
    pairing = (
        PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
        if continuous
        else PairingConfig()
    )
    for method in (Method.PAPER, Method.DEFAULT):
        config = PipelineConfig(
            method=method,
            target=target.name,
            target_config=configure(target, method.value, settings, SETTING_FLAGS),
            seed=seed,
            pairing=pairing,
            initial_T_flange_sensor=None if initial is None else initial.T_flange_sensor,
            workers=available_workers(),
        )
        started = time.perf_counter()
        run = calibrate_bag(bag, config, estimate_offset=continuous)
        seconds = time.perf_counter() - started
        print(f"=== {bag.name} ({label}), method {method.value} ({seconds:.2f} s) ===")
        print(format_summary(run.result, truth))
        seen = compare if truth is None else hand_eye_seen(truth, run.result.kinematics)
        rot, trans = transform_error(run.result.T_flange_sensor, seen)
        if truth is None:
            print(
                f"Difference to the reference hand-eye: rotation {np.degrees(rot):.4f} deg, "
                f"translation {trans * 1e3:.4f} mm (not ground truth)"
            )
        print()
        rows.append(
            (bag.name, f"{method.value} vs {against}", np.degrees(rot), trans * 1e3, seconds)
        )


def _cmd_demo(args: argparse.Namespace) -> int:
    root = Path(args.bags)
    bags = sorted(p.parent for p in root.glob("*/metadata.yaml"))
    if not bags:
        raise InputError(f"no rosbag2 bags found under {root}; run from the repository root")
    rows: list[tuple[str, str, float, float, float]] = []
    for bag in bags:
        _demo_runs(bag, args.seed, rows)
    print("Difference of the hand-eye T_flange_sensor to the truth (simulated bags) or to the")
    print("reference (real scans: another tool's published hand-eye, not ground truth):")
    print(f"  {'bag':<24}{'method':<22}{'rotation deg':>14}{'translation mm':>16}{'time s':>9}")
    for name, label, rot_deg, trans_mm, seconds in rows:
        print(f"  {name:<24}{label:<22}{rot_deg:>14.4f}{trans_mm:>16.4f}{seconds:>9.2f}")
    return 0


# --- parser ---------------------------------------------------------------------------------

#: Numeric options of ``calibrate`` for the pairing gate: (flag, parser, default, help).
CALIBRATE_NUMBERS: tuple[tuple[str, Callable[[str], float], float, str], ...] = (
    (
        "--max-speed",
        _non_negative_float,
        PairingConfig.max_linear_speed_m_s,
        "reject profiles taken while the flange moved faster, m/s; 0 accepts any "
        "(continuous scanning with a good clock)",
    ),
    (
        "--max-angular-speed",
        _non_negative_float,
        PairingConfig.max_angular_speed_rad_s,
        "reject profiles taken while the flange turned faster, rad/s; 0 accepts any",
    ),
)

#: Options of ``calibrate`` that set the chosen target's settings (default: the target's own;
#: one the target or method does not use is refused): (flag, parser, help).
TARGET_OPTIONS: tuple[tuple[str, Callable[[str], object], str], ...] = (
    ("--radius", _positive_float, "cylinder or sphere radius, m (default: estimate)"),
    (
        "--point",
        _xyz,
        "known_point target: the taught point x,y,z in m, base frame (default: estimate)",
    ),
    (
        "--centre-side",
        _centre_side,
        "sphere target: the side of the laser plane the sphere centre lies on, +y or -y "
        "(sensor frame; default: resolved from the data)",
    ),
    (
        "--sensor-sigma",
        _positive_float,
        "profiler noise, 1 sigma, m (default method; re-estimated from the residuals; "
        "cylinder default 5 um)",
    ),
    (
        "--robot-sigma-t",
        _positive_float,
        "robot pose error per pose, 1 sigma per axis, m (default method; cylinder default "
        "0.1 mm, known_point 0.05 mm)",
    ),
    (
        "--robot-sigma-r",
        _positive_float,
        "robot orientation error per pose, 1 sigma per axis, rad (default method; cylinder "
        "default 0.01 deg, known_point 0.005 deg)",
    ),
    (
        "--min-samples",
        _min_samples,
        "fewest samples with a usable feature (ellipse, corner, ...); default the target's",
    ),
)


#: Flags of :data:`CALIBRATE_NUMBERS` that set the pairing gate (shared with reconstruct).
PAIRING_FLAGS = ("--max-speed", "--max-angular-speed")


def _sentinel(text: str) -> float:
    """Parse a sentinel depth, m (finite)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a depth in metres, got {text!r}") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(
            f"NaN and +-Inf are always no return; give a finite depth, got {text!r}"
        )
    return value


def _add_pose_source_arguments(cal: argparse.ArgumentParser) -> None:
    """Where the flange poses come from, the frames, and the profiler's no-return value."""
    cal.add_argument(
        "--pose-source",
        choices=[s.value for s in PoseSource],
        default=None,
        help="flange poses from a PoseStamped topic (pose, the default without --kinematics), "
        "from the /tf + /tf_static chain --base-frame -> --flange-frame (tf), or from "
        "sensor_msgs/JointState through the robot model (joint_states, the default with "
        "--kinematics)",
    )
    cal.add_argument(
        "--base-frame", default="base_link", help="robot base frame (start of the TF chain)"
    )
    cal.add_argument(
        "--flange-frame", default="tool0", help="frame id of the flange (end of the TF chain)"
    )
    cal.add_argument(
        "--kinematics",
        metavar="MODEL",
        help="robot model of the joint_states pose source: ur5e, ur10e or a URDF file "
        "(chain --base-frame to --flange-frame); calibrate estimates its identifiable "
        "corrections with the hand-eye",
    )
    cal.add_argument(
        "--joint-state-topic",
        help="JointState topic (default /joint_states, else the only JointState topic)",
    )
    cal.add_argument(
        "--invalid-value",
        type=_sentinel,
        action="append",
        default=[],
        metavar="M",
        help="a depth z, m, that the profiler sends for no return besides NaN/Inf, e.g. "
        "-0.999999 (Keyence's -999.999 mm) or 0; repeat for several",
    )


def _add_initial_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--initial",
        metavar="FILE|NUMBERS",
        help=f"initial hand-eye T_flange_sensor (e.g. from CAD or an earlier result): {FORMS}",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``linelaser-calib``."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Hand-eye calibration of a line-laser profile sensor from scans of a target.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="write a synthetic rosbag2 MCAP bag and truth.yaml")
    sim.add_argument("out", help="bag directory to create (must not exist)")
    sim.add_argument(
        "--scenario",
        default="paper",
        help=(
            "preset: paper, ur_scancontrol, continuous, ur5e_kinematic, ur5e_cell, "
            "cluttered_camera, weld_seam, weld_seam_general, sphere, line, line_features"
        ),
    )
    sim.add_argument("--seed", type=_seed, default=0)
    for flag, field, kind in SIMULATE_OPTIONS:
        sim.add_argument(flag, dest=field, type=kind, default=None, help=f"scenario {field}")
    layout = sim.add_mutually_exclusive_group()
    layout.add_argument(
        "--organised",
        dest="organised",
        action="store_true",
        default=None,
        help="organised profiles with NaN for invalid rays",
    )
    layout.add_argument(
        "--dense",
        dest="organised",
        action="store_false",
        help="dense profiles, invalid rays dropped",
    )
    sim.add_argument(
        "--tf",
        action="store_true",
        help="also write the flange poses as a /tf chain (UR-like links) with /tf_static",
    )
    sim.set_defaults(func=_cmd_simulate)

    convert = sub.add_parser(
        "convert", help="convert another tool's recordings into a rosbag2 bag (SI units)"
    )
    convert.add_argument(
        "format",
        choices=["robcalibrator"],
        help="robcalibrator: a RobCalibrator scan folder (p1.yml..., RobPoses.rob, "
        "calibration.sec, LICENSE)",
    )
    convert.add_argument("folder", help="the folder to convert")
    convert.add_argument("--output", required=True, help="bag directory to create (must not exist)")
    convert.set_defaults(func=_cmd_convert)

    info = sub.add_parser("info", help="print what a bag holds")
    info.add_argument("bag")
    info.set_defaults(func=_cmd_info)

    cal = sub.add_parser("calibrate", help="calibrate the hand-eye from a bag")
    cal.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    cal.add_argument(
        "placements",
        nargs="*",
        metavar="BAG",
        help="with --kinematics: recordings of other placements of the target by the same arm "
        "and sensor, calibrated together with the first (one hand-eye, one set of kinematic "
        "corrections)",
    )
    cal.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    cal.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    cal.add_argument("--method", choices=[m.value for m in Method], default=Method.DEFAULT.value)
    cal.add_argument(
        "--target",
        choices=target_names(),
        default=DEFAULT_TARGET,
        help=f"what was scanned (default {DEFAULT_TARGET}): cylinder, a cylinder of known or "
        "estimated radius; known_point, one fixed point such as a weld-seam corner; each "
        "registered target is a choice",
    )
    cal.add_argument("--output", help="result YAML to write (its directory must exist)")
    cal.add_argument(
        "--report",
        metavar="DIR",
        help="write an HTML report (index.html and PNG figures) into DIR (needs matplotlib)",
    )
    cal.add_argument(
        "--viz",
        metavar="OUT.mcap",
        help="write the calibrated profiles, cylinder and transforms as an MCAP file (Foxglove)",
    )
    _add_initial_argument(cal)
    cal.add_argument("--seed", type=_seed, default=0, help="seed of RANSAC and PSO")
    _add_pairing_arguments(
        cal,
        "added to profile stamps to reach the pose clock, s (default 0); 'auto' estimates "
        "it (continuous scanning with latency)",
    )
    for flag, parse, default, text in CALIBRATE_NUMBERS:
        if flag not in PAIRING_FLAGS:
            cal.add_argument(flag, type=parse, default=default, help=text)
    for flag, parse_setting, text in TARGET_OPTIONS:
        cal.add_argument(flag, type=parse_setting, default=None, help=text)
    cal.add_argument(
        "--scale",
        metavar="auto|fixed|free",
        help="cylinder target, default method: the sensor's along-line (x) scale, estimated "
        "with the hand-eye (free) or held at 1 (fixed); default auto: free when --radius is "
        "given",
    )
    _add_pose_source_arguments(cal)
    cal.add_argument(
        "--arm-accuracy",
        type=_non_negative_float,
        metavar="M",
        help="prior 1 sigma per axis, m, of the robot's error common to the whole scanned "
        "workspace (its absolute accuracy there), which no subset of the poses can see: part "
        "of the hand-eye's 1 sigma when the robot's error looks systematic (default 0.0001; "
        "not with --kinematics, whose joint calibration estimates that error)",
    )
    cal.add_argument(
        "--nominal-kinematics",
        action="store_true",
        help="with --kinematics: keep the robot model nominal (no kinematic corrections)",
    )
    cal.add_argument("--json", action="store_true", help="print the result as JSON")
    cal.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="print progress on stderr (default: when stderr is a terminal)",
    )
    cal.set_defaults(func=_cmd_calibrate)

    plan = sub.add_parser("plan", help="plan the next flange poses that most reduce the 1 sigma")
    plan.add_argument(
        "bag", nargs="?", help="rosbag2 directory, .mcap file or session of the scans so far"
    )
    plan.add_argument("--target", choices=target_names(), default=DEFAULT_TARGET)
    plan.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    plan.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    plan.add_argument(
        "--from",
        dest="from_result",
        metavar="RESULT.yaml",
        help="a result of this set-up: the hand-eye and the target's placement",
    )
    _add_initial_argument(plan)
    plan.add_argument(
        "--cylinder",
        type=_numbers,
        help="px,py,pz,dx,dy,dz: a point on the cylinder axis and its direction (base frame, m)",
    )
    plan.add_argument(
        "--sphere", type=_numbers, help="cx,cy,cz: the centre of the sphere (base frame, m)"
    )
    plan.add_argument(
        "--axial-range",
        type=_span,
        help="LO,HI: the span of the shaft to scan, m along the axis (upwards) from its point "
        "nearest the base origin (default: the span the scans cover)",
    )
    plan.add_argument(
        "--kinematics",
        metavar="MODEL",
        help="ur5e, ur10e or a URDF: also say whether another placement of the cylinder would "
        "determine more of the robot's kinematics (from the bag's scans and /joint_states)",
    )
    plan.add_argument("--n", type=int, default=10, help="poses to plan (default 10)")
    plan.add_argument("--goal-mm", type=_positive_float, help="stop at this 1 sigma, mm")
    plan.add_argument("--goal-deg", type=_positive_float, help="stop at this 1 sigma, deg")
    plan.add_argument(
        "--range",
        type=_span,
        default=(PlanConstraints.z_min_m, PlanConstraints.z_max_m),
        help="measuring range of the profiler, m (default 0.07,0.15)",
    )
    plan.add_argument(
        "--fan-deg",
        type=_positive_float,
        default=float(np.rad2deg(PlanConstraints.fan_half_angle_rad)),
        help="half opening of the laser fan, deg (default 25)",
    )
    plan.add_argument(
        "--reach-centre",
        type=_xyz,
        help="centre of the flange's reach box, x,y,z in m (default: the first scan's flange)",
    )
    plan.add_argument(
        "--reach",
        type=_positive_float,
        default=PlanConstraints.reach_half_extent_m,
        help="half side of the reach box, m (default 0.25)",
    )
    plan.add_argument(
        "--table-height",
        type=float,
        default=PlanConstraints.table_height_m,
        help="base z of the table; sensor and flange stay above it, m (default 0)",
    )
    plan.add_argument("--no-table", action="store_true", help="no table below the target")
    for flag, parse_setting, text in TARGET_OPTIONS:
        if flag in PLAN_TARGET_OPTIONS:
            plan.add_argument(flag, type=parse_setting, default=None, help=text)
    plan.add_argument("--seed", type=_seed, default=0, help="seed of the candidate poses")
    plan.add_argument("--output", help="plan YAML to write (its directory must exist)")
    plan.add_argument(
        "--figure",
        metavar="FILE.png",
        help="plot the predicted 1 sigma against the number of poses, with the one --from's "
        "result achieved (needs matplotlib)",
    )
    plan.set_defaults(func=_cmd_plan)
    rec = sub.add_parser(
        "reconstruct", help="map every profile of a bag into the base frame with a calibration"
    )
    rec.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    rec.add_argument(
        "--calibration", required=True, metavar="RESULT.yaml", help="result of calibrate"
    )
    rec.add_argument(
        "--output",
        required=True,
        metavar="OUT.ply|OUT.mcap",
        help="PLY (x y z float, m, base frame) or MCAP (PointCloud2 in the base frame)",
    )
    rec.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    rec.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    _add_pairing_arguments(
        rec,
        "added to profile stamps to reach the pose clock, s (default: the calibration's)",
    )
    _add_pose_source_arguments(rec)
    rec.set_defaults(func=_cmd_reconstruct)

    export = sub.add_parser(
        "export", help="print a result as a URDF joint, a static TF command or a launch file"
    )
    export.add_argument("result", help="result YAML written by calibrate")
    export.add_argument(
        "--format",
        choices=["urdf", "static-tf", "launch", "ur-kinematics"],
        required=True,
        help="urdf: a fixed <joint>; static-tf: the static_transform_publisher command line; "
        "launch: a Python launch file publishing it; ur-kinematics: the corrected robot "
        "kinematics (result of calibrate --kinematics ur5e|ur10e) as UR's description YAML",
    )
    export.set_defaults(func=_cmd_export)

    demo = sub.add_parser("demo", help="calibrate the committed bags and compare with truth")
    demo.add_argument("bags", nargs="?", default="bags")
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except CalibrationError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"{PROG}: error: {exc.strerror or exc} ({exc.filename or ''})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
