"""The parser of ``linelaser-calib`` and its entry point; each verb runs in its own module."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import NoReturn

from linelaser_calib.cli import calibrate, convert, demo, export, info, plan, reconstruct, simulate
from linelaser_calib.cli.arguments import (
    centre_side,
    min_samples,
    non_negative_float,
    non_negative_int,
    numbers,
    offset,
    positive_float,
    seed,
    sentinel,
    span,
    xyz,
)
from linelaser_calib.cli.common import INTERRUPTS, PROG
from linelaser_calib.cli.simulate import SCENARIO_PRESETS, SIMULATE_OPTIONS
from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method
from linelaser_calib.core.planning import PlanConstraints
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.targets import (
    DEFAULT_TARGET,
    all_targets,
    plannable_target_names,
    target_names,
)
from linelaser_calib.core.thinning import DEFAULT_PER_NEIGHBOURHOOD
from linelaser_calib.io.initial import FORMS
from linelaser_calib.settings import Front, render

#: Numeric options of ``calibrate`` for the pairing gate: (flag, parser, default, help).
CALIBRATE_NUMBERS: tuple[tuple[str, Callable[[str], float], float, str], ...] = (
    (
        "--max-speed",
        non_negative_float,
        PairingConfig.max_linear_speed_m_s,
        "reject profiles taken while the flange moved faster, m/s; 0 accepts any "
        "(continuous scanning with a good clock) (default %(default)s)",
    ),
    (
        "--max-angular-speed",
        non_negative_float,
        PairingConfig.max_angular_speed_rad_s,
        "reject profiles taken while the flange turned faster, rad/s; 0 accepts any "
        "(default %(default)s)",
    ),
)


#: Options of ``calibrate`` that set the chosen target's settings (default: the target's own;
#: one the target or method does not use is refused): (flag, parser, help).
TARGET_OPTIONS: tuple[tuple[str, Callable[[str], object], str], ...] = (
    ("--radius", positive_float, "cylinder or sphere radius, m (default: estimate)"),
    (
        "--point",
        xyz,
        "known_point target: the taught point x,y,z in m, base frame (default: estimate)",
    ),
    (
        "--centre-side",
        centre_side,
        "sphere target: the side of the laser plane the sphere centre lies on, +y or -y "
        "(sensor frame; default: resolved from the data)",
    ),
    (
        "--sensor-sigma",
        positive_float,
        "profiler noise, 1 sigma, m (default method; re-estimated from the residuals; "
        "cylinder default 5 um)",
    ),
    (
        "--robot-sigma-t",
        positive_float,
        "robot pose error per pose, 1 sigma per axis, m (default method; cylinder default "
        "0.1 mm, known_point 0.05 mm)",
    ),
    (
        "--robot-sigma-r",
        positive_float,
        "robot orientation error per pose, 1 sigma per axis, rad (default method; cylinder "
        "default 0.01 deg, known_point 0.005 deg)",
    ),
    (
        "--min-samples",
        min_samples,
        "fewest samples with a usable feature (ellipse, corner, ...), unitless (default: the "
        "target's)",
    ),
)


_SYNC_HELP = "largest profile-to-pose stamp gap, s (default %(default)s)"

#: Flags of :data:`CALIBRATE_NUMBERS` that set the pairing gate (shared with reconstruct).
PAIRING_FLAGS = ("--max-speed", "--max-angular-speed")


#: The target settings ``plan`` takes (those that shape the information of a pose).
PLAN_TARGET_OPTIONS = (
    "--radius",
    "--centre-side",
    "--sensor-sigma",
    "--robot-sigma-t",
    "--robot-sigma-r",
)


def _add_pairing_arguments(
    parser: argparse.ArgumentParser, clock_offset_help: str, *, from_result: bool = False
) -> None:
    """The pairing flags; with ``from_result`` an absent flag (None) takes the calibration's
    value (``quality.pairing``)."""
    numbers = (
        ("--sync-tolerance", positive_float, PairingConfig.sync_tolerance_s, _SYNC_HELP),
        *(entry for entry in CALIBRATE_NUMBERS if entry[0] in PAIRING_FLAGS),
    )
    for flag, parse, default, text in numbers:
        if from_result:
            text = text.replace("%(default)s", f"the calibration's, else {default}")
        parser.add_argument(flag, type=parse, default=None if from_result else default, help=text)
    parser.add_argument("--clock-offset", type=offset, default=None, help=clock_offset_help)


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
        "--base-frame",
        default="base_link",
        help="robot base frame (start of the TF chain; default %(default)s)",
    )
    cal.add_argument(
        "--flange-frame",
        default="tool0",
        help="frame id of the flange (end of the TF chain; default %(default)s)",
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
        help="JointState topic (default: /joint_states, else the only JointState topic)",
    )
    cal.add_argument(
        "--invalid-value",
        type=sentinel,
        action="append",
        default=[],
        metavar="M",
        help="a depth z, m, that the profiler sends for no return besides NaN/Inf, e.g. "
        "-0.999999 (Keyence's -999.999 mm) or 0; repeat for several (default: none)",
    )


def _add_initial_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--initial",
        metavar="FILE|NUMBERS",
        help=f"initial hand-eye T_flange_sensor (e.g. from CAD or an earlier result): {FORMS}",
    )


#: Exit code of a usage error (argparse's; docs/reference.md, "Exit status").
USAGE_ERROR = 2


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage error is one line and a pointer to the help, not the
    whole usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(USAGE_ERROR, f"{self.prog}: error: {message}\nsee '{self.prog} --help'\n")


def package_version() -> str:
    """The installed package's version (setup.py takes it from package.xml)."""
    try:
        return version("linelaser_calib")
    except PackageNotFoundError:
        return "unknown (the package is not installed)"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``linelaser-calib``."""
    parser = _Parser(
        prog=PROG,
        description="Hand-eye calibration of a line-laser profile sensor from scans of a target.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    sim_p = sub.add_parser("simulate", help="write a synthetic rosbag2 MCAP bag and truth.yaml")
    sim_p.add_argument("out", help="bag directory to create (must not exist)")
    sim_p.add_argument(
        "--scenario",
        default="paper",
        help=f"preset: {', '.join(SCENARIO_PRESETS)} (default %(default)s)",
    )
    sim_p.add_argument(
        "--seed", type=seed, default=0, help="seed of the simulation, unitless (default 0)"
    )
    for flag, field, kind, text in SIMULATE_OPTIONS:
        sim_p.add_argument(
            flag,
            dest=field,
            metavar=flag.removeprefix("--").upper().replace("-", "_"),
            type=kind,
            default=None,
            help=f"{text} (default: the preset's)",
        )
    layout = sim_p.add_mutually_exclusive_group()
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
    sim_p.add_argument(
        "--tf",
        action="store_true",
        help="also write the flange poses as a /tf chain (UR-like links) with /tf_static",
    )
    sim_p.set_defaults(func=simulate.run)

    convert_p = sub.add_parser(
        "convert", help="convert another tool's recordings into a rosbag2 bag (SI units)"
    )
    convert_p.add_argument(
        "format",
        choices=["robcalibrator"],
        help="robcalibrator: a RobCalibrator scan folder (p1.yml..., RobPoses.rob, "
        "calibration.sec, LICENSE)",
    )
    convert_p.add_argument("folder", help="the folder to convert")
    convert_p.add_argument(
        "--output", required=True, help="bag directory to create (must not exist)"
    )
    convert_p.set_defaults(func=convert.run)

    info_p = sub.add_parser("info", help="print what a bag holds")
    info_p.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    info_p.set_defaults(func=info.run)

    cal_p = sub.add_parser("calibrate", help="calibrate the hand-eye from a bag")
    cal_p.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    cal_p.add_argument(
        "placements",
        nargs="*",
        default=[],
        metavar="BAG",
        help="with --kinematics: recordings of other placements of the target by the same arm "
        "and sensor, calibrated together with the first (one hand-eye, one set of kinematic "
        "corrections)",
    )
    cal_p.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    cal_p.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    cal_p.add_argument(
        "--method",
        choices=[m.value for m in Method],
        default=Method.DEFAULT.value,
        help="default (the default): maximum likelihood on every inlier point with the robot's "
        "pose error modelled; paper: the target's source paper's method",
    )
    cal_p.add_argument(
        "--target",
        choices=target_names(),
        default=DEFAULT_TARGET,
        help=f"what was scanned (default {DEFAULT_TARGET}): "
        + "; ".join(f"{t.name}, {t.summary}" for t in all_targets()),
    )
    cal_p.add_argument("--output", help="result YAML to write (its directory must exist)")
    cal_p.add_argument(
        "--report",
        metavar="DIR",
        help="write an HTML report (index.html and PNG figures) of any target into DIR (needs "
        "matplotlib); a run that fails writes none of its outputs",
    )
    cal_p.add_argument(
        "--viz",
        metavar="OUT.mcap",
        help="write the calibrated profiles, the fitted target and the transforms as an MCAP "
        "file (Foxglove)",
    )
    _add_initial_argument(cal_p)
    cal_p.add_argument(
        "--seed", type=seed, default=0, help="seed of RANSAC and PSO, unitless (default 0)"
    )
    _add_pairing_arguments(
        cal_p,
        "added to profile stamps to reach the pose clock, s (default 0); 'auto' estimates "
        "it (continuous scanning with latency)",
    )
    for flag, parse, default, text in CALIBRATE_NUMBERS:
        if flag not in PAIRING_FLAGS:
            cal_p.add_argument(flag, type=parse, default=default, help=text)
    for flag, parse_setting, text in TARGET_OPTIONS:
        cal_p.add_argument(flag, type=parse_setting, default=None, help=text)
    cal_p.add_argument(
        "--scale",
        metavar="auto|fixed|free",
        help="cylinder, sphere and line targets, default method: the profiler's along-line (x) "
        "scale (the line's and, radius given, the cylinder's depth (z) scale too), unitless, "
        "estimated with the hand-eye (free) or held at 1 (fixed); default auto: for the "
        "cylinder and the line free where clearly off 1, for the sphere free where clearly "
        "off 1 and holding it would move the hand-eye beyond its 1 sigma",
    )
    _add_pose_source_arguments(cal_p)
    cal_p.add_argument(
        "--arm-accuracy",
        type=non_negative_float,
        metavar="M",
        help="prior 1 sigma per axis, m, of the robot's error common to the whole scanned "
        "workspace (its absolute accuracy there), which no subset of the poses can see: part "
        "of the hand-eye's 1 sigma when the robot's error looks systematic (default 0.0001; "
        "not with --kinematics, whose joint calibration estimates that error)",
    )
    cal_p.add_argument(
        "--per-neighbourhood",
        type=non_negative_int,
        default=DEFAULT_PER_NEIGHBOURHOOD,
        metavar="N",
        help="most profiles kept from one neighbourhood of flange poses (50 mm x 8 deg), "
        "evenly spaced in time, where a long recording holds more from nearly the same pose; "
        "unitless, 0 keeps every profile (default %(default)s)",
    )
    cal_p.add_argument(
        "--nominal-kinematics",
        action="store_true",
        help="with --kinematics: keep the robot model nominal (no kinematic corrections)",
    )
    cal_p.add_argument("--json", action="store_true", help="print the result as JSON")
    cal_p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="print progress on stderr (default: when stderr is a terminal)",
    )
    cal_p.set_defaults(func=calibrate.run)

    plan_p = sub.add_parser("plan", help="plan the next flange poses that most reduce the 1 sigma")
    plan_p.add_argument(
        "bag", nargs="?", help="rosbag2 directory, .mcap file or session of the scans so far"
    )
    plan_p.add_argument(
        "--target",
        choices=plannable_target_names(),
        default=DEFAULT_TARGET,
        help="what is scanned; the targets whose poses can be planned (default %(default)s)",
    )
    plan_p.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    plan_p.add_argument(
        "--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)"
    )
    plan_p.add_argument(
        "--from",
        dest="from_result",
        metavar="RESULT.yaml",
        help="a result of this set-up: the hand-eye and the target's placement",
    )
    _add_initial_argument(plan_p)
    plan_p.add_argument(
        "--cylinder",
        type=numbers,
        help="px,py,pz,dx,dy,dz: a point on the cylinder axis and its direction (base frame, "
        "m; default: from --from or the bag)",
    )
    plan_p.add_argument(
        "--sphere",
        type=numbers,
        help="cx,cy,cz: the centre of the sphere (base frame, m; default: from --from or the bag)",
    )
    plan_p.add_argument(
        "--axial-range",
        type=span,
        help="LO,HI: the span of the shaft to scan, m along the axis (upwards) from its point "
        "nearest the base origin (default: the span the scans cover)",
    )
    plan_p.add_argument(
        "--kinematics",
        metavar="MODEL",
        help="ur5e, ur10e or a URDF: also say whether another placement of the cylinder would "
        "determine more of the robot's kinematics (from the bag's scans and /joint_states)",
    )
    plan_p.add_argument(
        "--n", type=int, default=10, help="poses to plan, unitless (default %(default)s)"
    )
    plan_p.add_argument(
        "--goal-translation",
        type=positive_float,
        help="stop when the predicted translation 1 sigma is within this on every axis, m "
        "(default: none)",
    )
    plan_p.add_argument(
        "--goal-rotation",
        type=positive_float,
        help="stop when the predicted rotation 1 sigma is within this on every axis, rad "
        "(default: none)",
    )
    plan_p.add_argument(
        "--range",
        type=span,
        default=(PlanConstraints.z_min_m, PlanConstraints.z_max_m),
        help="measuring range of the profiler, LO,HI in m (default "
        f"{PlanConstraints.z_min_m},{PlanConstraints.z_max_m})",
    )
    plan_p.add_argument(
        "--fan-half-angle",
        type=positive_float,
        default=PlanConstraints.fan_half_angle_rad,
        help="half opening of the laser fan, rad (default %(default).4f, 25 deg)",
    )
    plan_p.add_argument(
        "--reach-centre",
        type=xyz,
        help="centre of the flange's reach box, x,y,z in m (default: the first scan's flange)",
    )
    plan_p.add_argument(
        "--reach",
        type=positive_float,
        default=PlanConstraints.reach_half_extent_m,
        help="half side of the reach box, m (default %(default)s)",
    )
    plan_p.add_argument(
        "--table-height",
        type=float,
        default=PlanConstraints.table_height_m,
        help="base z of the table; sensor and flange stay above it, m (default %(default)s)",
    )
    plan_p.add_argument("--no-table", action="store_true", help="no table below the target")
    for flag, parse_setting, text in TARGET_OPTIONS:
        if flag in PLAN_TARGET_OPTIONS:
            plan_p.add_argument(flag, type=parse_setting, default=None, help=text)
    plan_p.add_argument(
        "--seed", type=seed, default=0, help="seed of the candidate poses, unitless (default 0)"
    )
    plan_p.add_argument("--output", help="plan YAML to write (its directory must exist)")
    plan_p.add_argument(
        "--figure",
        metavar="FILE.png",
        help="plot the predicted 1 sigma against the number of poses, with the one --from's "
        "result achieved (needs matplotlib)",
    )
    plan_p.set_defaults(func=plan.run)
    rec_p = sub.add_parser(
        "reconstruct", help="map every profile of a bag into the base frame with a calibration"
    )
    rec_p.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    rec_p.add_argument(
        "--calibration", required=True, metavar="RESULT.yaml", help="result of calibrate"
    )
    rec_p.add_argument(
        "--output",
        required=True,
        metavar="OUT.ply|OUT.mcap",
        help="PLY (x y z float, m, base frame) or MCAP (PointCloud2 in the base frame)",
    )
    rec_p.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    rec_p.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    _add_pairing_arguments(
        rec_p,
        "added to profile stamps to reach the pose clock, s (default: the calibration's)",
        from_result=True,
    )
    _add_pose_source_arguments(rec_p)
    rec_p.set_defaults(func=reconstruct.run)

    export_p = sub.add_parser(
        "export", help="print a result as a URDF joint, a static TF command or a launch file"
    )
    export_p.add_argument("result", help="result YAML written by calibrate")
    export_p.add_argument(
        "--format",
        choices=["urdf", "static-tf", "launch", "ur-kinematics"],
        required=True,
        help="urdf: a fixed <joint>; static-tf: the static_transform_publisher command line; "
        "launch: a Python launch file publishing it; ur-kinematics: the corrected robot "
        "kinematics (result of calibrate --kinematics ur5e|ur10e) as UR's description YAML",
    )
    export_p.set_defaults(func=export.run)

    demo_p = sub.add_parser("demo", help="calibrate the committed bags and compare with truth")
    demo_p.add_argument(
        "bags", nargs="?", default="bags", help="folder of bags with truth (default bags)"
    )
    demo_p.add_argument(
        "--seed", type=seed, default=0, help="seed of RANSAC and PSO, unitless (default 0)"
    )
    demo_p.set_defaults(func=demo.run)
    return parser


def _quiet_broken_pipe() -> int:
    """The reader of stdout went away (``... | head``): stop quietly, as ``cat`` does.

    Python would report the failed flush of stdout at exit; pointing stdout at /dev/null
    prevents that. Exit 0: what was read was the result, and the rest was not wanted.
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args = build_parser().parse_args(argv)
    in_main_thread = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGINT) if in_main_thread else None
    INTERRUPTS.caught = 0
    try:
        code = int(args.func(args))
        sys.stdout.flush()
        if INTERRUPTS.caught:
            print(
                f"{PROG}: interrupted after the outputs were written; they are complete",
                file=sys.stderr,
            )
        return code
    except BrokenPipeError:
        return _quiet_broken_pipe()
    except CalibrationError as exc:
        print(f"{PROG}: error: {render(str(exc), Front.CLI)}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"{PROG}: error: {exc.strerror or exc} ({exc.filename or ''})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    finally:
        if in_main_thread:
            signal.signal(signal.SIGINT, handler)
