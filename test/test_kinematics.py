"""Robot kinematics: UR presets, URDF chains, forward kinematics, Jacobian, inverse kinematics."""

from __future__ import annotations

import numpy as np
import pytest
from _urdf import ur_urdf

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import (
    UR_JOINT_NAMES,
    JointStates,
    KinematicCorrections,
    effective_hand_eye,
    flange_poses_from_joint_states,
    forward_kinematics,
    inverse_kinematics,
    model_from_preset,
    parameter_jacobian,
    pose_twist,
)
from linelaser_calib.io.kinematics import load_model, model_from_urdf


def test_ur5e_zero_pose_is_the_published_one() -> None:
    # UR5e at q = 0, DH base frame "base": tool0 at (-817.2, -232.9, 62.8) mm, z along -y;
    # base_link is "base" turned 180 deg about z.
    T = forward_kinematics(model_from_preset("ur5e"), np.zeros(6))[0]
    np.testing.assert_allclose(T[:3, 3], [0.8172, 0.2329, 0.0628], atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)


def test_ur10e_reach_at_zero() -> None:
    T = forward_kinematics(model_from_preset("ur10e"), np.zeros(6))[0]
    np.testing.assert_allclose(T[:3, 3], [0.6127 + 0.57155, 0.17415 + 0.11655, 0.1807 - 0.11985])


@pytest.mark.parametrize("preset", ["ur5e", "ur10e"])
def test_parameter_jacobian_matches_finite_differences(preset: str) -> None:
    model = model_from_preset(preset)
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (5, 6))
    J = parameter_jacobian(model, q)
    T0 = forward_kinematics(model, q)
    p0 = model.parameters
    eps = 1e-6
    for k in range(len(p0)):
        step = np.zeros_like(p0)
        step[k] = eps
        up = forward_kinematics(model.with_parameters(p0 + step), q)
        down = forward_kinematics(model.with_parameters(p0 - step), q)
        numeric = (pose_twist(up, T0) - pose_twist(down, T0)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, k], numeric, atol=1e-7)


def test_inverse_kinematics_recovers_reachable_poses() -> None:
    model = model_from_preset("ur5e")
    rng = np.random.default_rng(5)
    q = rng.uniform(-2.5, 2.5, (6, 6))
    T = forward_kinematics(model, q)
    solved = inverse_kinematics(model, T, q + rng.normal(0.0, 0.2, q.shape))
    assert solved.converged.all()
    np.testing.assert_allclose(forward_kinematics(model, solved.q), T, atol=1e-9)


def test_unreachable_pose_is_not_converged() -> None:
    model = model_from_preset("ur5e")
    T = np.eye(4)
    T[0, 3] = 2.0  # beyond the 0.85 m reach
    assert not inverse_kinematics(model, T[None], np.zeros((1, 6))).converged[0]


def test_urdf_of_the_dh_arm_gives_the_same_flange_poses() -> None:
    dh = model_from_preset("ur5e")
    urdf = model_from_urdf(ur_urdf("ur5e"))
    assert urdf.joint_names == UR_JOINT_NAMES
    q = np.random.default_rng(7).uniform(-np.pi, np.pi, (20, 6))
    np.testing.assert_allclose(forward_kinematics(urdf, q), forward_kinematics(dh, q), atol=1e-12)
    # 8 joints (6 moving, 2 fixed) with 6 origin parameters each, plus 6 joint offsets.
    assert len(urdf.parameter_names) == 8 * 6 + 6
    assert "elbow_joint.offset" in urdf.parameter_names


def test_urdf_file_and_its_errors(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "arm.urdf"
    path.write_text(ur_urdf("ur10e"), encoding="utf-8")
    model = load_model(str(path))
    q = np.full((1, 6), 0.3)
    np.testing.assert_allclose(
        forward_kinematics(model, q), forward_kinematics(model_from_preset("ur10e"), q), atol=1e-12
    )
    with pytest.raises(InputError, match=r"no link .flange.*tool0"):
        load_model(str(path), flange_frame="flange")
    with pytest.raises(InputError, match=r"missing.urdf: no such file"):
        load_model(str(tmp_path / "missing.urdf"))
    with pytest.raises(InputError, match="neither a preset"):
        load_model("ur3")
    with pytest.raises(InputError, match="not valid XML"):
        model_from_urdf("<robot>")
    broken = ur_urdf().replace('<parent link="link_2"/>', '<parent link="nowhere"/>')
    with pytest.raises(InputError, match="stops at link 'nowhere'"):
        model_from_urdf(broken)


def test_joint_states_in_any_order_give_flange_poses() -> None:
    model = model_from_preset("ur5e")
    q = np.random.default_rng(1).uniform(-1.0, 1.0, (4, 6))
    order = [2, 0, 5, 1, 4, 3]
    names = (*(UR_JOINT_NAMES[i] for i in order), "gripper_joint")
    positions = np.hstack([q[:, order], np.zeros((4, 1))])
    states = JointStates(names, np.arange(4, dtype=np.int64) * 10, positions)
    poses = flange_poses_from_joint_states(model, states)
    assert [p.stamp_ns for p in poses] == [0, 10, 20, 30]
    np.testing.assert_allclose(
        np.array([p.T_base_flange for p in poses]), forward_kinematics(model, q), atol=1e-12
    )
    assert {p.frame_id for p in poses} == {"base_link"}


def test_joint_names_that_do_not_match_list_both() -> None:
    states = JointStates(("joint_1", "joint_2"), np.zeros(1, dtype=np.int64), np.zeros((1, 2)))
    with pytest.raises(InputError, match=r"joint_1.*shoulder_pan_joint"):
        flange_poses_from_joint_states(model_from_preset("ur5e"), states)


def test_corrections_change_only_the_named_parameters() -> None:
    model = model_from_preset("ur5e")
    fixed = KinematicCorrections("ur5e", {"elbow_joint.a": 1e-3, "wrist_1_joint.offset": 0.01})
    corrected = fixed.apply(model)
    delta = corrected.parameters - model.parameters
    names = model.parameter_names
    assert delta[names.index("elbow_joint.a")] == pytest.approx(1e-3)
    assert delta[names.index("wrist_1_joint.offset")] == pytest.approx(0.01)
    assert np.count_nonzero(delta) == 2
    with pytest.raises(InputError, match="does not have"):
        KinematicCorrections("ur5e", {"elbow_joint.x": 0.1}).apply(model)


@pytest.mark.parametrize("source", ["dh", "urdf"])
def test_last_link_error_is_one_hand_eye_change(source: str) -> None:
    """An error after the last joint's motion is a constant transform in the flange frame:
    nominal flange poses with the effective hand-eye put the sensor where the true arm and
    the true hand-eye do; an error before it is not."""
    nominal = model_from_preset("ur5e") if source == "dh" else model_from_urdf(ur_urdf("ur5e"))
    rng = np.random.default_rng(3)
    last = max(i for i, e in enumerate(nominal.elements) if e.joint >= 0)
    delta = rng.normal(0.0, 1e-3, len(nominal.elements))
    tail = np.arange(len(delta)) >= last
    X = np.eye(4)
    X[:3, 3] = (0.012, -0.085, 0.095)
    q = rng.uniform(-2.0, 2.0, (8, 6))
    true = nominal.with_parameters(nominal.parameters + delta * tail)
    seen = effective_hand_eye(nominal, true, X)
    assert np.abs(seen[:3, 3] - X[:3, 3]).max() > 1e-4
    np.testing.assert_allclose(
        forward_kinematics(nominal, q) @ seen, forward_kinematics(true, q) @ X, atol=1e-12
    )
    wrong = nominal.with_parameters(nominal.parameters + delta * ~tail)
    moved = forward_kinematics(nominal, q) @ effective_hand_eye(nominal, wrong, X)
    assert np.abs(moved - forward_kinematics(wrong, q) @ X).max() > 1e-4
