"""The simulator's bag writer: a preset's scans as a rosbag2 MCAP bag, with ``truth.yaml``
(and, for a known point or a seam, ``initial.yaml``) beside it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from linelaser_calib.core.result import CalibrationResult
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
    from linelaser_calib.sim.recording import record
    from linelaser_calib.sim.tf_chain import ur_tf_tree
    from linelaser_calib.sim.weld import bumped_hand_eye

    run = record(scenario_name, overrides, seed)
    rig = run.rig
    tf_dynamic, tf_static = (
        ur_tf_tree(run.poses, rig.base_frame, rig.flange_frame) if tf else ([], [])
    )
    write_bag(
        out,
        run.profiles,
        run.poses,
        profile_topic=rig.profile_topic,
        pose_topic=rig.pose_topic,
        sensor_frame=rig.sensor_frame,
        base_frame=rig.base_frame,
        organised=rig.organised,
        intensities=run.intensities if rig.intensity else None,
        tf=tf_dynamic,
        tf_static=tf_static,
        joint_states=run.joint_states,
        joint_state_topic=rig.joint_state_topic,
    )
    simulation: dict[str, object] = {
        "scenario": scenario_name,
        "seed": seed,
        "overrides": overrides,
        "profiles": len(run.profiles),
        "poses": len(run.poses),
    }
    if command is not None:
        simulation["command"] = command
    simulation.update(run.simulation)
    if run.initial is not None:
        write_result_yaml(
            CalibrationResult(
                T_flange_sensor=bumped_hand_eye(run.T_flange_sensor, np.random.default_rng(seed)),
                target=run.initial,
                method="initial",
                samples_used=[],
                samples_rejected=[],
                rms_residual_m=0.0,
                parent_frame=rig.flange_frame,
                child_frame=rig.sensor_frame,
                base_frame=rig.base_frame,
            ),
            out / "initial.yaml",
        )
    truth = write_truth_yaml(
        out / "truth.yaml",
        run.T_flange_sensor,
        run.truth,
        parent_frame=rig.flange_frame,
        child_frame=rig.sensor_frame,
        base_frame=rig.base_frame,
        extra={
            "simulation": simulation,
            **(
                {}
                if run.arm is None
                else {SECTION: kinematics_section(run.arm.errors, run.arm.nominal)}
            ),
        },
    )
    return out, truth
