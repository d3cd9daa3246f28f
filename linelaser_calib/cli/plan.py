"""``linelaser-calib plan``: the next flange poses to scan from
(:func:`~linelaser_calib.core.planning.plan_for_target`)."""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from linelaser_calib.cli.common import (
    calibration_pairing,
    check_output,
    initial_hand_eye,
    read_calibration,
    why_not_paired,
)
from linelaser_calib.core.errors import InputError
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.planning import (
    Plan,
    PlanConstraints,
    SigmaPoint,
    plan_for_target,
    plannable,
    predicted_curve,
)
from linelaser_calib.core.targets import all_targets, get_target
from linelaser_calib.core.targets.base import ResultSection, Target, placement_adviser
from linelaser_calib.core.types import Rejection, Sample
from linelaser_calib.io.kinematics import load_model, read_kinematics
from linelaser_calib.io.plan_file import write_plan_yaml
from linelaser_calib.offline import bag_samples
from linelaser_calib.settings import Front, given_from_arguments, spelling, target_config


def _plan_constraints(args: argparse.Namespace) -> PlanConstraints:
    return PlanConstraints(
        z_min_m=args.range[0],
        z_max_m=args.range[1],
        fan_half_angle_rad=args.fan_half_angle,
        reach_centre_m=args.reach_centre,
        reach_half_extent_m=args.reach,
        table_height_m=None if args.no_table else args.table_height,
    )


def run(args: argparse.Namespace) -> int:
    if args.output is not None:
        check_output(args.output, "plan file (--output)")
    if args.figure is not None:
        from linelaser_calib.report import require_matplotlib

        check_output(args.figure, "figure (--figure)")
        require_matplotlib()
    target = get_target(args.target)
    section = None
    achieved: list[SigmaPoint] = []
    planner = plannable(target)
    numbers_flag = spelling(planner.numbers_setting, Front.CLI)
    placed = {"--cylinder": args.cylinder, "--sphere": args.sphere}
    given_numbers = {flag: value for flag, value in placed.items() if value is not None}
    for flag in given_numbers:
        if flag != numbers_flag:
            raise InputError(
                f"{flag} does not apply to the {target.title} target and would be ignored; "
                f"give its placement with {numbers_flag} ({planner.numbers_help})"
            )
    numbers = given_numbers.get(numbers_flag)
    result = None
    if args.from_result is not None:
        if args.initial is not None or numbers is not None:
            raise InputError(
                "--from gives the hand-eye and the target's placement; omit --initial and "
                f"{numbers_flag}"
            )
        result = read_calibration(args.from_result, "--from")
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
        T_flange_sensor = initial_hand_eye(args.initial)
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
            f"{numbers_flag} {planner.numbers_help}, or a bag of 3 or more exploratory "
            "scans"
        )
    config = target_config(target.name, "default", given_from_arguments(args), Front.CLI)
    samples: list[Sample] = []
    if args.bag is not None:
        pairing, paired_how = (
            (PairingConfig(), "paired with the default pairing")
            if result is None
            else calibration_pairing(result, {})
        )
        unpaired: list[Rejection] = []
        samples = bag_samples(
            args.bag,
            pairing,
            profile_topic=args.profile_topic,
            pose_topic=args.pose_topic,
            rejected=unpaired,
        )
        print(
            f"{args.bag}: {len(samples)} of {len(samples) + len(unpaired)} profiles {paired_how}"
            + ("" if not unpaired else "; not paired: " + why_not_paired(unpaired))
        )
    goal = None
    if args.goal_translation is not None or args.goal_rotation is not None:
        goal = (
            np.inf if args.goal_translation is None else args.goal_translation,
            np.inf if args.goal_rotation is None else args.goal_rotation,
        )
    advice = (
        None
        if args.kinematics is None
        else _placement_advice(args, target, samples, T_flange_sensor, section, numbers)
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
    target: Target[Any],
    samples: list[Sample],
    T_flange_sensor: np.ndarray,
    section: ResultSection | None,
    numbers: list[float] | None,
) -> str:
    """``plan --kinematics``: whether another placement of the target would determine more
    of the robot's kinematics, from the bag's scans and joint states (the target's
    :class:`~linelaser_calib.core.targets.base.PlacementAdviser`)."""
    from linelaser_calib.io.bags import read_joint_states

    adviser = placement_adviser(target)
    if args.bag is None or adviser is None:
        able = [t.name for t in all_targets() if placement_adviser(t) is not None]
        raise InputError(
            "plan --kinematics judges the placements of a target from the scans so far: give "
            "the bag (with /joint_states) and a target it judges: "
            + ", ".join(f"--target {name}" for name in able)
        )
    placement = None
    if section is not None:
        placement = adviser.placement_of(section)
    elif numbers is not None:
        placement = adviser.placement_from_numbers(numbers, args.radius)
    if placement is None:
        raise InputError(
            f"plan --kinematics needs the {target.title}'s placement: give --from RESULT.yaml "
            "(e.g. of calibrate --kinematics) or "
            f"{spelling(plannable(target).numbers_setting, Front.CLI)} with --radius"
        )
    model = load_model(args.kinematics)
    if args.from_result is not None:
        corrections = read_kinematics(args.from_result)
        if corrections is not None:
            model = corrections.apply(model)
    states = read_joint_states(args.bag)
    return adviser.advise([(samples, states, placement)], model, T_flange_sensor)


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
