"""The simulator's bag writer: a preset's scans as a rosbag2 MCAP bag, with ``truth.yaml``
(and, for a known point or a seam, ``initial.yaml``) beside it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.base import ResultSection
from linelaser_calib.io.bags import write_bag
from linelaser_calib.io.kinematics import SECTION, kinematics_section
from linelaser_calib.io.results import write_result_yaml, write_truth_yaml


def simulate_to_bag(
    out: Path,
    scenario_name: str,
    seed: int,
    overrides: dict[str, object],
    *,
    tf: bool = False,
    command: str | None = None,
) -> tuple[Path, Path]:
    """Simulate a scenario, write its bag directory and ``truth.yaml`` beside the .mcap.

    Weld-seam scenarios (known-point target) also get ``initial.yaml``: an old hand-eye, the
    truth bumped by 1-2 deg and 1-3 mm, with the taught point, as ``--initial`` input; so do
    straight-seam scenarios (line target), with the true line.
    With ``tf`` the flange poses are also written as a robot_state_publisher-style
    ``/tf`` chain base frame -> flange frame, with its fixed links on ``/tf_static``
    (:func:`~linelaser_calib.sim.tf_chain.ur_tf_tree`).
    ``command``, when given, is the command line that regenerates the bag, kept in the
    truth file.
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
    }
    if command is not None:
        simulation["command"] = command
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
