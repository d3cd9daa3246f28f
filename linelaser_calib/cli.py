"""``linelaser-calib``: a thin command-line wrapper around the library.

Subcommands: ``simulate`` (write a synthetic bag and its truth), ``info`` (what a bag holds),
``calibrate`` (the offline calibration) and ``demo`` (calibrate the committed bags and show
the error against their truth). Exit code 0 means success; a user error prints one
paragraph on stderr and exits with 1; a usage error exits with 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from linelaser_calib.core.errors import CalibrationError, InputError, PairingError
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig, Target
from linelaser_calib.core.refine import RefineConfig
from linelaser_calib.core.types import CalibrationResult, KnownPoint
from linelaser_calib.io.bags import bag_info, format_bag_info, write_bag
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.results import (
    read_result_yaml,
    read_truth_yaml,
    result_to_dict,
    write_result_yaml,
    write_truth_yaml,
)
from linelaser_calib.offline import OfflineRun, calibrate_bag
from linelaser_calib.summary import format_summary

PROG = "linelaser-calib"


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (np.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
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
    out: Path, scenario_name: str, seed: int, overrides: dict[str, object]
) -> tuple[Path, Path]:
    """Simulate a scenario, write its bag directory and ``truth.yaml`` beside the .mcap.

    Weld-seam scenarios (known-point target) also get ``initial.yaml``: an old hand-eye, the
    truth bumped by 1-2 deg and 1-3 mm, with the taught point, as ``--initial`` input.
    Returns the bag directory and the truth file.
    """
    from linelaser_calib.sim.scenario import scenario_from_preset
    from linelaser_calib.sim.simulate import simulate
    from linelaser_calib.sim.weld import (
        WELD_PRESETS,
        bumped_hand_eye,
        simulate_weld,
        weld_scenario_from_preset,
    )

    weld = scenario_name in WELD_PRESETS
    if weld:
        weld_data = simulate_weld(weld_scenario_from_preset(scenario_name, **overrides), seed)
        scenario, profiles, poses = weld_data.scenario, weld_data.profiles, weld_data.poses
        intensities, T_true = weld_data.intensities, weld_data.truth.T_flange_sensor
        cylinder, known_point = None, weld_data.truth.weld_point_m
    else:
        data = simulate(scenario_from_preset(scenario_name, **overrides), seed)
        scenario, profiles, poses = data.scenario, data.profiles, data.poses
        intensities, T_true = data.intensities, data.truth.T_flange_sensor
        cylinder, known_point = data.truth.cylinder, None
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
    )
    simulation: dict[str, object] = {
        "scenario": scenario_name,
        "seed": seed,
        "overrides": overrides,
        "profiles": len(profiles),
        "poses": len(poses),
        "command": simulate_command(out, scenario_name, seed, overrides),
    }
    if weld:
        taught = weld_data.truth.taught_point_m
        simulation["taught_point"] = taught
        write_result_yaml(
            CalibrationResult(
                T_flange_sensor=bumped_hand_eye(T_true, np.random.default_rng(seed)),
                cylinder=None,
                method="initial",
                samples_used=[],
                samples_rejected=[],
                rms_residual_m=0.0,
                known_point=KnownPoint(np.asarray(taught), estimated=False),
                parent_frame=scenario.flange_frame,
                child_frame=scenario.sensor_frame,
                base_frame=scenario.base_frame,
            ),
            out / "initial.yaml",
        )
    truth = write_truth_yaml(
        out / "truth.yaml",
        T_true,
        cylinder,
        known_point=known_point,
        parent_frame=scenario.flange_frame,
        child_frame=scenario.sensor_frame,
        base_frame=scenario.base_frame,
        extra={"simulation": simulation},
    )
    return out, truth


#: Command-line options of ``simulate`` that override scenario fields: (flag, field, type).
SIMULATE_OPTIONS: tuple[tuple[str, str, type], ...] = (
    ("--poses", "n_poses", int),
    ("--radius", "cylinder_radius_m", float),
    ("--points", "resolution", int),
    ("--sensor-sigma", "sigma_depth_m", float),
    ("--robot-sigma-t", "robot_sigma_translation_m", float),
    ("--robot-sigma-r", "robot_sigma_rotation_rad", float),
    ("--spikes", "spike_fraction", float),
    ("--profile-topic", "profile_topic", str),
    ("--pose-topic", "pose_topic", str),
    ("--sensor-frame", "sensor_frame", str),
    ("--flange-frame", "flange_frame", str),
    ("--base-frame", "base_frame", str),
)


def simulate_command(out: Path, scenario_name: str, seed: int, overrides: dict[str, object]) -> str:
    """The ``linelaser-calib simulate`` command line that regenerates a bag."""
    flags = {field: flag for flag, field, _ in SIMULATE_OPTIONS}
    words = [PROG, "simulate", str(out), "--scenario", scenario_name, "--seed", str(seed)]
    for field, value in overrides.items():
        if field == "organised":
            words.append("--organised" if value else "--dense")
        else:
            words += [flags[field], str(value)]
    return " ".join(words)


def _cmd_simulate(args: argparse.Namespace) -> int:
    overrides: dict[str, object] = {
        field: getattr(args, field)
        for _, field, _ in SIMULATE_OPTIONS
        if getattr(args, field) is not None
    }
    if args.organised is not None:
        overrides["organised"] = args.organised
    bag, truth = simulate_to_bag(Path(args.out), args.scenario, args.seed, overrides)
    print(f"wrote {bag} and {truth}")
    print(format_bag_info(bag_info(bag)))
    return 0


# --- info -----------------------------------------------------------------------------------


def _cmd_info(args: argparse.Namespace) -> int:
    print(format_bag_info(bag_info(args.bag)))
    return 0


# --- calibrate ------------------------------------------------------------------------------


def _pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    initial = None
    if args.initial is not None:
        try:
            initial = read_result_yaml(args.initial).T_flange_sensor
        except ResultFileError as exc:
            raise ResultFileError(
                f"cannot use the initial hand-eye (--initial): {exc}; give a result YAML "
                "written by linelaser-calib (its hand_eye section)"
            ) from exc
    if (
        args.target == Target.KNOWN_POINT.value
        and args.method == Method.PAPER.value
        and (args.point is None or initial is None)
    ):
        raise InputError(
            "--method paper with --target known_point corrects an old hand-eye against the "
            "taught point: it needs --point x,y,z (the taught point, m, base frame) and "
            "--initial FILE.yaml (the old hand-eye)"
        )
    return PipelineConfig(
        method=Method(args.method),
        target=Target(args.target),
        known_point=None if args.point is None else np.array(args.point),
        radius_m=args.radius,
        seed=args.seed,
        pairing=PairingConfig(
            sync_tolerance_s=args.sync_tolerance,
            clock_offset_s=0.0 if args.clock_offset == "auto" else float(args.clock_offset),
            max_linear_speed_m_s=args.max_speed,
            max_angular_speed_rad_s=args.max_angular_speed,
        ),
        refine=RefineConfig(
            sensor_sigma_m=args.sensor_sigma,
            robot_sigma_t_m=args.robot_sigma_t,
            robot_sigma_r_rad=args.robot_sigma_r,
        ),
        initial_T_flange_sensor=initial,
    )


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
    try:
        run = calibrate_bag(
            args.bag,
            config,
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
            flange_frame=args.flange_frame,
            estimate_offset=args.clock_offset == "auto",
            progress=_StderrProgress(progress),
        )
    except PairingError as exc:
        raise PairingError(
            f"{exc} (Options of calibrate: --clock-offset SECONDS, --sync-tolerance SECONDS.)"
        ) from exc
    truth_path = Path(args.bag) / "truth.yaml"
    truth = read_truth_yaml(truth_path) if truth_path.is_file() else None
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
        print(format_summary(run.result, truth))
        for path in written:
            print(f"Wrote {path}")
    return 0


def _input_rows(run: OfflineRun) -> list[tuple[str, str]]:
    """What was calibrated, as (label, text) rows."""
    bag = run.bag
    return [
        ("bag", str(bag.path)),
        ("profiles", f"{len(bag.profiles)} on {bag.profile_topic} (frame {bag.sensor_frame})"),
        ("flange poses", f"{len(bag.poses)} on {bag.pose_topic} (frame {bag.base_frame})"),
    ]


def _input_line(run: OfflineRun) -> str:
    bag = run.bag
    return (
        f"{bag.path}: {len(bag.profiles)} profiles on {bag.profile_topic}, "
        f"{len(bag.poses)} poses on {bag.pose_topic}"
    )


# --- demo -----------------------------------------------------------------------------------


def _cmd_demo(args: argparse.Namespace) -> int:
    root = Path(args.bags)
    bags = sorted(p.parent for p in root.glob("*/metadata.yaml"))
    if not bags:
        raise InputError(f"no rosbag2 bags found under {root}; run from the repository root")
    rows = []
    for bag in bags:
        truth = read_truth_yaml(bag / "truth.yaml")
        for method in (Method.PAPER, Method.DEFAULT):
            config = PipelineConfig(method=method, seed=args.seed)
            target = "cylinder"
            if truth.known_point is not None:
                initial = read_result_yaml(bag / "initial.yaml")
                taught = None if initial.known_point is None else initial.known_point.point
                config = replace(
                    config,
                    target=Target.KNOWN_POINT,
                    known_point=taught,
                    initial_T_flange_sensor=initial.T_flange_sensor,
                )
                target = "known point, from initial.yaml"
                if method is Method.PAPER:
                    rot, trans = transform_error(initial.T_flange_sensor, truth.T_flange_sensor)
                    rows.append((bag.name, "initial", np.degrees(rot), trans * 1e3, 0.0))
            started = time.perf_counter()
            run = calibrate_bag(bag, config)
            seconds = time.perf_counter() - started
            print(f"=== {bag.name} ({target}), method {method.value} ({seconds:.2f} s) ===")
            print(format_summary(run.result, truth))
            print()
            rot, trans = transform_error(run.result.T_flange_sensor, truth.T_flange_sensor)
            rows.append((bag.name, method.value, np.degrees(rot), trans * 1e3, seconds))
    print("Error against truth (hand-eye T_flange_sensor):")
    print(f"  {'bag':<28}{'method':<9}{'rotation deg':>14}{'translation mm':>16}{'time s':>9}")
    for name, label, rot_deg, trans_mm, seconds in rows:
        print(f"  {name:<28}{label:<9}{rot_deg:>14.4f}{trans_mm:>16.4f}{seconds:>9.2f}")
    return 0


# --- parser ---------------------------------------------------------------------------------

#: Numeric options of ``calibrate`` for the pairing gate and the default method's priors:
#: (flag, parser, default, help).
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
    (
        "--sensor-sigma",
        _positive_float,
        RefineConfig.sensor_sigma_m,
        "profiler noise, 1 sigma, m (default method; re-estimated from the residuals)",
    ),
    (
        "--robot-sigma-t",
        _positive_float,
        RefineConfig.robot_sigma_t_m,
        "robot pose error per pose, 1 sigma per axis, m (default: UR-class 0.1 mm)",
    ),
    (
        "--robot-sigma-r",
        _positive_float,
        RefineConfig.robot_sigma_r_rad,
        "robot orientation error per pose, 1 sigma per axis, rad (default 0.01 deg)",
    ),
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``linelaser-calib``."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Hand-eye calibration of a line-laser profile sensor from cylinder scans.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="write a synthetic rosbag2 MCAP bag and truth.yaml")
    sim.add_argument("out", help="bag directory to create (must not exist)")
    sim.add_argument(
        "--scenario",
        default="paper",
        help="preset: paper, ur_scancontrol, continuous, cluttered_camera, weld_seam, "
        "weld_seam_general",
    )
    sim.add_argument("--seed", type=int, default=0)
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
    sim.set_defaults(func=_cmd_simulate)

    info = sub.add_parser("info", help="print what a bag holds")
    info.add_argument("bag")
    info.set_defaults(func=_cmd_info)

    cal = sub.add_parser("calibrate", help="calibrate the hand-eye from a bag")
    cal.add_argument("bag", help="rosbag2 directory, .mcap file or collector session directory")
    cal.add_argument("--profile-topic", help="PointCloud2 topic (auto-detected by type)")
    cal.add_argument("--pose-topic", help="PoseStamped flange-pose topic (auto-detected by type)")
    cal.add_argument(
        "--radius", type=_positive_float, help="cylinder radius, m (default: estimate)"
    )
    cal.add_argument("--method", choices=[m.value for m in Method], default=Method.DEFAULT.value)
    cal.add_argument(
        "--target",
        choices=[t.value for t in Target],
        default=Target.CYLINDER.value,
        help="cylinder (default), or known_point: one fixed point such as a weld-seam corner",
    )
    cal.add_argument(
        "--point",
        type=_xyz,
        help="known_point target: the taught point x,y,z in m, base frame (default: estimate)",
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
    cal.add_argument("--initial", help="result YAML holding an initial hand-eye (e.g. from CAD)")
    cal.add_argument("--seed", type=int, default=0, help="seed of RANSAC and PSO")
    cal.add_argument(
        "--sync-tolerance",
        type=_positive_float,
        default=PairingConfig.sync_tolerance_s,
        help="largest profile-to-pose stamp gap, s",
    )
    cal.add_argument(
        "--clock-offset",
        type=_offset,
        default=0.0,
        help="added to profile stamps to reach the pose clock, s; 'auto' estimates it "
        "(continuous scanning with latency)",
    )
    for flag, parse, default, text in CALIBRATE_NUMBERS:
        cal.add_argument(flag, type=parse, default=default, help=text)
    cal.add_argument("--flange-frame", default="tool0", help="frame id of the flange")
    cal.add_argument("--json", action="store_true", help="print the result as JSON")
    cal.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="print progress on stderr (default: when stderr is a terminal)",
    )
    cal.set_defaults(func=_cmd_calibrate)

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
