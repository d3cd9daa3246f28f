"""``linelaser-calib simulate``: a synthetic bag and its truth
(:func:`~linelaser_calib.sim.bag_writer.simulate_to_bag`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from linelaser_calib.cli.arguments import xyz
from linelaser_calib.cli.common import PROG
from linelaser_calib.io.bags import bag_info, format_bag_info

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
    ("--cylinder-base", "cylinder_base_m", xyz),  # another placement of the cylinder, m
    ("--axis", "axis_direction", xyz),
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


def run(args: argparse.Namespace) -> int:
    overrides: dict[str, object] = {
        field: getattr(args, field)
        for _, field, _ in SIMULATE_OPTIONS
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
