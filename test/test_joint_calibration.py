"""Joint kinematic + hand-eye calibration: chain rule, identifiability, recovery, files, export."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import apply_transform
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.robot.joint_calibration import (
    JointProblem,
    JointState,
    KinematicPoseModel,
    KinematicSetup,
    MultiScanProblem,
)
from linelaser_calib.core.robot.kinematics import (
    UR_JOINT_NAMES,
    KinematicCorrections,
    KinematicModel,
    forward_kinematics,
    model_from_preset,
)
from linelaser_calib.core.targets.base import SolveContext, TargetSolution
from linelaser_calib.core.targets.cylinder import TARGET, CylinderConfig
from linelaser_calib.core.targets.cylinder.joint import kinematic_problem
from linelaser_calib.core.targets.cylinder.problem import build_problem, initial_state
from linelaser_calib.core.types import FloatArray
from linelaser_calib.export import UR_SEGMENTS, ur_kinematics_yaml
from linelaser_calib.io.kinematics import model_from_urdf, read_kinematics
from linelaser_calib.sim import SimulatedData, Surface, scenario_from_preset, simulate

#: The arm of every recording here: one draw of the kinematic errors.
ARM_SEED = 5


@lru_cache(maxsize=4)
def recording(seed: int, n_poses: int, base: tuple[float, float, float]) -> SimulatedData:
    scenario = scenario_from_preset(
        "ur5e_kinematic", n_poses=n_poses, kinematic_seed=ARM_SEED, cylinder_base_m=base
    )
    return simulate(scenario, seed)


@lru_cache(maxsize=1)
def joint_solution() -> tuple[TargetSolution, SimulatedData]:
    """The cylinder's default method with the joint calibration on 30 poses."""
    data = recording(1, 30, (0.45, 0.15, 0.0))
    assert data.joint_states is not None and data.truth.arm is not None
    config = CylinderConfig(radius_m=0.02)
    paired = pair_profiles(data.profiles, data.poses, PairingConfig())
    features, _ = TARGET.extract(paired.samples, config, 0, lambda *_: None)
    setup = KinematicSetup(data.truth.arm.nominal, data.joint_states)
    context = SolveContext(n_samples=len(features), kinematics=setup)
    return TARGET.solve_default(features, config, context), data


def held_out_rms_m(
    data: SimulatedData, model: KinematicModel, T_flange_sensor: FloatArray
) -> float:
    """RMS distance (m) of a recording's true cylinder points, mapped with ``model`` and
    ``T_flange_sensor`` from its joint vectors, from the true cylinder surface."""
    truth = data.truth
    assert truth.joint_positions is not None
    T = forward_kinematics(model, truth.joint_positions)
    cylinder = truth.cylinder
    distances = []
    for k, T_bf in enumerate(T):
        x = truth.points_true_sensor[k][truth.surface[k] == Surface.SIDE]
        v = apply_transform(T_bf @ T_flange_sensor, x) - cylinder.point
        radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
        distances.append(np.linalg.norm(radial, axis=1) - cylinder.radius)
    return float(np.sqrt(np.mean(np.concatenate(distances) ** 2)))


def test_kinematic_columns_match_finite_differences() -> None:
    data = recording(2, 6, (0.45, 0.15, 0.0))
    truth = data.truth
    assert truth.arm is not None and truth.joint_positions is not None
    model = truth.arm.nominal
    points = [
        p[s == Surface.SIDE][::20]
        for p, s in zip(truth.points_true_sensor, truth.surface, strict=True)
    ]
    free = np.arange(len(model.parameter_names))
    sigma = np.full(len(free), 1e-3)
    pose_model = KinematicPoseModel(model, truth.joint_positions, free, sigma)
    config = CylinderConfig(radius_m=0.02).refine
    problem = build_problem(points, pose_model.poses(np.zeros(len(free))), config, False)
    state = initial_state(problem, truth.T_flange_sensor, truth.cylinder, 0.02)
    rng = np.random.default_rng(0)
    state = replace(state, omega=rng.normal(0, 1e-4, (6, 3)), tau=rng.normal(0, 1e-4, (6, 3)))
    joint = JointProblem(problem, pose_model)
    delta = rng.normal(0, 1e-4, len(free))
    J = joint.linearise(JointState(state, delta)).J_global[:, :, problem.n_global :]
    h = 1e-7
    for k in range(0, len(free), 3):
        step = np.zeros(len(free))
        step[k] = h
        plus = joint.residuals(JointState(state, delta + step)).points
        minus = joint.residuals(JointState(state, delta - step)).points
        numeric = (plus - minus) / (2 * h)
        scale = np.max(np.abs(numeric)) + 1.0
        assert np.max(np.abs(J[:, :, k] - numeric)) < 1e-4 * scale, model.parameter_names[k]


def test_identifiability_names_what_the_base_and_the_flange_absorb() -> None:
    solution, _ = joint_solution()
    report = solution.identifiability
    assert report is not None and solution.kinematics is not None
    names = set(report.names)
    assert len(names) == 24
    assert set(report.identifiable) | set(report.unidentifiable) == names
    assert len(report.free_combinations) == len(report.unidentifiable)
    # A vertical cylinder does not see the base turned about its vertical first joint axis,
    # and the hand-eye absorbs the last link.
    assert "shoulder_pan_joint.offset" in report.unidentifiable
    assert any(name.startswith("wrist_3_joint.") for name in report.unidentifiable)
    assert set(solution.kinematics.corrections) == set(report.identifiable)
    assert solution.kinematics.kept_nominal == report.unidentifiable
    assert any("kinematic parameters are identifiable" in w for w in solution.warnings)


def test_joint_calibration_maps_a_held_out_recording_closer_to_the_truth() -> None:
    solution, data = joint_solution()
    assert solution.kinematics is not None and data.truth.arm is not None
    nominal = data.truth.arm.nominal
    other = recording(3, 10, (0.35, -0.2, 0.0))
    before = held_out_rms_m(other, nominal, data.truth.T_flange_sensor)
    after = held_out_rms_m(other, solution.kinematics.apply(nominal), solution.T_flange_sensor)
    assert before > 2e-4
    assert after < 0.5 * before


@pytest.fixture(scope="module")
def arm_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small ur5e_kinematic recording (12 poses) with joint states."""
    bag = tmp_path_factory.mktemp("joint") / "arm"
    args = ["simulate", str(bag), "--scenario", "ur5e_kinematic", "--seed", "4", "--poses", "12"]
    assert main(args) == 0
    return bag


def test_kinematics_section_round_trips(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = arm_bag
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(bag), "--kinematics", "ur5e", "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Kinematic corrections of the ur5e model" in printed
    assert "moved by the arm's kinematic error after its last joint's motion" in printed
    raw = yaml.safe_load(out.read_text(encoding="utf-8"))["kinematics"]
    assert raw["model"] == "ur5e" and raw["base_frame"] == "base_link"
    read = read_kinematics(out)
    assert read is not None
    assert read.kept_nominal == tuple(raw["kept_nominal"])
    assert set(read.corrections) | set(read.kept_nominal) == set(
        model_from_preset("ur5e").parameter_names
    )
    for name, value in raw["corrections"].items():
        assert read.corrections[name] == pytest.approx(value, rel=1e-12, abs=1e-15)
    cloud = tmp_path / "cloud.ply"
    args = ["reconstruct", str(bag), "--calibration", str(out), "--output", str(cloud)]
    assert main(args) == 0
    assert cloud.stat().st_size > 0


def test_a_wrong_robot_model_is_refused(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(arm_bag), "--kinematics", "ur10e", "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert "ur10e kinematic model does not explain the robot's error" in err
    assert "Traceback" not in err
    assert not out.exists()


def _urdf_from_ur_kinematics(text: str) -> str:
    """A URDF placing the joints where the exported segments say, as UR's description does."""
    segments = yaml.safe_load(text)["kinematics"]
    links = ["base_link", "base_link_inertia", *(f"link_{i}" for i in range(6))]
    joints = [
        '<joint name="base_fixed" type="fixed"><parent link="base_link"/>'
        f'<child link="base_link_inertia"/><origin xyz="0 0 0" rpy="0 0 {math.pi!r}"/></joint>'
    ]
    parent = "base_link_inertia"
    for i, (name, segment) in enumerate(zip(UR_JOINT_NAMES, UR_SEGMENTS, strict=True)):
        s = segments[segment]
        joints.append(
            f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link_{i}"/><origin xyz="{s["x"]} {s["y"]} {s["z"]}" '
            f'rpy="{s["roll"]} {s["pitch"]} {s["yaw"]}"/><axis xyz="0 0 1"/></joint>'
        )
        parent = f"link_{i}"
    links.append("tool0")
    joints.append(
        f'<joint name="tool0_fixed" type="fixed"><parent link="{parent}"/>'
        '<child link="tool0"/></joint>'
    )
    body = "".join(f'<link name="{n}"/>' for n in links) + "".join(joints)
    return f'<?xml version="1.0"?><robot name="exported">{body}</robot>'


def test_ur_kinematics_export_gives_the_corrected_arm() -> None:
    nominal = model_from_preset("ur5e")
    rng = np.random.default_rng(3)
    names = [
        n for n in nominal.parameter_names if n not in ("wrist_3_joint.a", "wrist_3_joint.alpha")
    ]
    corrections = KinematicCorrections("ur5e", {n: float(rng.normal(0, 3e-4)) for n in names})
    exported = model_from_urdf(_urdf_from_ur_kinematics(ur_kinematics_yaml(corrections)))
    q = rng.uniform(-math.pi, math.pi, (20, 6))
    np.testing.assert_allclose(
        forward_kinematics(exported, q),
        forward_kinematics(corrections.apply(nominal), q),
        atol=1e-12,
    )
    default = yaml.safe_load(ur_kinematics_yaml(KinematicCorrections("ur5e", {})))["kinematics"]
    assert default["shoulder"]["z"] == pytest.approx(0.1625)
    assert default["forearm"]["x"] == pytest.approx(-0.425)
    assert default["wrist_2"]["y"] == pytest.approx(-0.0997)
    assert default["wrist_3"]["y"] == pytest.approx(0.0996)


def test_ur_kinematics_export_refuses_what_it_cannot_hold(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "no_kinematics.yaml"
    result.write_text(
        yaml.safe_dump(
            {
                "hand_eye": {
                    "parent_frame": "tool0",
                    "child_frame": "laser",
                    "translation": [0.0, 0.0, 0.1],
                    "rotation_xyzw": [0.0, 0.0, 0.0, 1.0],
                },
                "cylinder": {
                    "frame": "base_link",
                    "point": [0.4, 0.1, 0.0],
                    "direction": [0.0, 0.0, 1.0],
                    "radius": 0.02,
                },
                "quality": {"method": "default", "rms_residual_m": 1e-5},
            }
        ),
        encoding="utf-8",
    )
    assert main(["export", str(result), "--format", "ur-kinematics"]) == 1
    assert "--kinematics" in capsys.readouterr().err
    with pytest.raises(Exception, match=r"wrist_3_joint\.a"):
        ur_kinematics_yaml(KinematicCorrections("ur5e", {"wrist_3_joint.a": 1e-4}))


def test_several_placements_share_the_hand_eye_and_keep_their_cylinders() -> None:
    setup_scans = [recording(2, 6, (0.45, 0.15, 0.0)), recording(6, 6, (0.35, -0.2, 0.0))]
    config = CylinderConfig(radius_m=0.02).refine
    problems, states, qs = [], [], []
    for data in setup_scans:
        truth = data.truth
        assert truth.arm is not None and data.joint_states is not None
        assert truth.joint_positions is not None
        setup = KinematicSetup(truth.arm.nominal, data.joint_states)
        points = [
            p[s == Surface.SIDE][:: 10 + len(problems)]
            for p, s in zip(truth.points_true_sensor, truth.surface, strict=True)
        ]
        problem, state = kinematic_problem(
            points, truth.joint_positions, setup, truth.T_flange_sensor, truth.cylinder, config
        )
        problems.append(problem)
        states.append(state)
        qs.append(truth.joint_positions)
    multi = MultiScanProblem(tuple(problems))
    both = multi.linearise(tuple(states))
    G0 = problems[0].n_global
    assert multi.n_global == G0 + problems[1].n_global - 6
    first, second = (p.linearise(s) for p, s in zip(problems, states, strict=True))
    K0, K1 = first.J_global.shape[1], second.J_global.shape[1]
    np.testing.assert_allclose(both.J_global[:6, :K0, :G0], first.J_global)
    np.testing.assert_allclose(both.J_global[:6, :, G0:], 0.0)
    np.testing.assert_allclose(both.J_global[6:, :K1, :6], second.J_global[:, :, :6])
    np.testing.assert_allclose(both.J_global[6:, :K1, G0:], second.J_global[:, :, 6:])
    np.testing.assert_allclose(both.J_global[6:, :, 6:G0], 0.0)
    np.testing.assert_allclose(both.residuals.points[6:, :K1], second.residuals.points)
    step = np.arange(multi.n_global) * 1e-6
    moved = multi.retract(tuple(states), step, np.zeros((12, 6)))
    np.testing.assert_allclose(moved[0].t_fs, moved[1].t_fs)
    assert not np.allclose(moved[0].point, moved[1].point)
    nominal = model_from_preset("ur5e")
    again = multi.with_flange_poses(forward_kinematics(nominal, np.vstack(qs)))
    np.testing.assert_allclose(again.scans[1].t_bf, problems[1].t_bf)


def test_self_check_of_a_joint_calibration_maps_held_out_profiles_through_its_kinematics(
    tmp_path: Path,
) -> None:
    """The committed kinematic-error bag: with the corrections the held-out profiles lie on the
    cylinder (~20 um) and no systematic robot error is claimed; with nominal kinematics the
    same recording is flagged and its held-out profiles lie several times farther off."""
    from linelaser_calib.io.results import read_result_yaml, read_truth_yaml
    from linelaser_calib.summary import hand_eye_seen, truth_error

    bag = Path(__file__).resolve().parent.parent / "bags" / "ur5e_kinematic"
    truth = read_truth_yaml(bag / "truth.yaml")
    checks = {}
    for name, extra in (("joint", []), ("nominal", ["--nominal-kinematics"])):
        out = tmp_path / f"{name}.yaml"
        argv = ["calibrate", str(bag), "--kinematics", "ur5e", *extra, "--output", str(out)]
        assert main(argv) == 0
        checks[name] = yaml.safe_load(out.read_text())["quality"]
        result = read_result_yaml(out)
        if name == "joint":
            # Against the hand-eye the corrected kinematics see (the arm's error after the
            # last joint's motion cannot be told from the hand-eye), the joint calibration is
            # within its 1 sigma's reach; against the physical hand-eye it is not.
            seen = truth_error(result.T_flange_sensor, hand_eye_seen(truth, result.kinematics))
            physical = truth_error(result.T_flange_sensor, truth.T_flange_sensor)
            assert result.uncertainty_rotation_rad is not None
            assert result.uncertainty_translation_m is not None
            sigma = np.concatenate(
                [result.uncertainty_rotation_rad, result.uncertainty_translation_m]
            )
            z = np.abs(np.concatenate([seen.rotation_axes_rad, seen.translation_axes_m])) / sigma
            assert seen.translation_m < 0.1e-3 and float(z.max()) < 3.0
            assert physical.translation_m > 2 * seen.translation_m
    assert checks["joint"]["accuracy_in_use_m"] < 60e-6
    assert not checks["joint"]["self_check"]["systematic_robot_error"]
    assert checks["nominal"]["accuracy_in_use_m"] > 2 * checks["joint"]["accuracy_in_use_m"]
    assert checks["nominal"]["self_check"]["systematic_robot_error"]
    # The joint calibration estimates the arm's error common to the workspace: its 1 sigma
    # needs no prior on the arm's accuracy; the nominal kinematics' 1 sigma states one.
    assert checks["joint"]["self_check"]["arm_accuracy_m"] == 0.0
    assert checks["nominal"]["self_check"]["arm_accuracy_m"] > 0.0
