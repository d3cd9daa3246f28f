"""``linelaser-calib simulate``: a synthetic bag and its truth
(:func:`~linelaser_calib.sim.bag_writer.simulate_to_bag`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from linelaser_calib.cli.arguments import named_numbers, xyz
from linelaser_calib.cli.common import PROG
from linelaser_calib.io.bags import bag_info, format_bag_info

#: The simulator's presets, named in ``--scenario``'s help without loading the simulator (a
#: test holds this list equal to :func:`linelaser_calib.sim.recording.preset_names`).
SCENARIO_PRESETS = (
    "cluttered_camera",
    "continuous",
    "cylinder_gocator",
    "cylinder_keyence",
    "cylinder_scancontrol",
    "line",
    "line_features",
    "line_ridge",
    "paper",
    "sphere",
    "sphere_sszn",
    "ur5e_cell",
    "ur5e_kinematic",
    "ur_scancontrol",
    "weld_seam",
    "weld_seam_general",
)

#: Command-line options of ``simulate`` that override scenario fields (each defaults to the
#: preset's value): (flag, field, type, help).
SIMULATE_OPTIONS: tuple[tuple[str, str, Callable[[str], object], str], ...] = (
    ("--poses", "n_poses", int, "number of flange poses, unitless"),
    (
        "--radius",
        "cylinder_radius_m",
        float,
        "radius of the target, m (the cylinder's, or the sphere's with a sphere preset)",
    ),
    ("--points", "resolution", int, "points per profile, unitless"),
    ("--sensor-sigma", "sigma_depth_m", float, "profiler depth noise, 1 sigma, m"),
    (
        "--robot-sigma-t",
        "robot_sigma_translation_m",
        float,
        "robot pose error, 1 sigma per axis, m",
    ),
    (
        "--robot-sigma-r",
        "robot_sigma_rotation_rad",
        float,
        "robot orientation error, 1 sigma per axis, rad",
    ),
    ("--spikes", "spike_fraction", float, "fraction of points that are spikes, unitless"),
    (
        "--arm-seed",
        "kinematic_seed",
        int,
        "seed of the arm's kinematic errors (the same arm in other runs), unitless",
    ),
    (
        "--cylinder-base",
        "cylinder_base_m",
        xyz,
        "another placement of the cylinder: its base point x,y,z, m, base frame",
    ),
    ("--axis", "axis_direction", xyz, "direction of the cylinder axis x,y,z, unitless"),
    (
        "--profiler-errors",
        "sensor",
        named_numbers,
        "terms of the profiler's error model to change, NAME=VALUE,... (SI; the simulator's "
        "profiler-model fields, e.g. gap_rate=0,x_scale_error=0 leaves out the gaps and the "
        "x scale error of a real profiler's preset)",
    ),
    ("--profile-topic", "profile_topic", str, "PointCloud2 topic to write"),
    ("--pose-topic", "pose_topic", str, "PoseStamped flange-pose topic to write"),
    ("--sensor-frame", "sensor_frame", str, "frame id of the profiles"),
    ("--flange-frame", "flange_frame", str, "frame id of the flange"),
    ("--base-frame", "base_frame", str, "frame id of the robot base"),
)


def simulate_command(
    out: Path, scenario_name: str, seed: int, overrides: dict[str, object], *, tf: bool = False
) -> str:
    """The ``linelaser-calib simulate`` command line that regenerates a bag."""
    flags = {field: flag for flag, field, _, _ in SIMULATE_OPTIONS}
    words = [PROG, "simulate", str(out), "--scenario", scenario_name, "--seed", str(seed)]
    for field, value in overrides.items():
        if field == "organised":
            words.append("--organised" if value else "--dense")
        elif isinstance(value, tuple):
            words += [flags[field], ",".join(f"{v:g}" for v in value)]
        elif isinstance(value, dict):
            words += [flags[field], ",".join(f"{k}={v!r}" for k, v in value.items())]
        else:
            words += [flags[field], str(value)]
    if tf:
        words.append("--tf")
    return " ".join(words)


def run(args: argparse.Namespace) -> int:
    overrides: dict[str, object] = {
        field: getattr(args, field)
        for _, field, _, _ in SIMULATE_OPTIONS
        if getattr(args, field) is not None
    }
    if args.organised is not None:
        overrides["organised"] = args.organised
    from linelaser_calib.sim.bag_writer import simulate_to_bag  # the simulator loads slowly

    out = Path(args.out)
    command = simulate_command(out, args.scenario, args.seed, overrides, tf=args.tf)
    bag, truth = simulate_to_bag(
        out, args.scenario, args.seed, overrides, tf=args.tf, command=command
    )
    print(f"wrote {bag} and {truth}")
    print(format_bag_info(bag_info(bag)))
    return 0
