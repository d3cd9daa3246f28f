"""The simulated arm: nominal vs true kinematics, joint states, the ur5e_kinematic preset."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import (
    UR_JOINT_NAMES,
    flange_poses_from_joint_states,
    forward_kinematics,
)
from linelaser_calib.io.bags import read_bag, read_joint_states, write_bag
from linelaser_calib.io.errors import BagError
from linelaser_calib.sim import SimulatedData, scenario_from_preset, simulate

SMALL = {"n_poses": 8}


@lru_cache(maxsize=4)
def run(seed: int = 4) -> SimulatedData:
    return simulate(scenario_from_preset("ur5e_kinematic", **SMALL), seed)


def _position_errors_m(data: SimulatedData) -> np.ndarray:
    truth = data.truth
    diff = truth.T_base_flange_true[:, :3, 3] - truth.T_base_flange_recorded[:, :3, 3]
    return np.linalg.norm(diff, axis=1)


def test_reported_poses_are_nominal_kinematics_of_the_joint_states() -> None:
    data = run()
    assert data.joint_states is not None and data.truth.arm is not None
    assert data.joint_states.names == UR_JOINT_NAMES
    assert [p.stamp_ns for p in data.poses] == data.joint_states.stamps_ns.tolist()
    from_joints = flange_poses_from_joint_states(data.truth.arm.nominal, data.joint_states)
    np.testing.assert_allclose(
        np.array([p.T_base_flange for p in from_joints]),
        np.array([p.T_base_flange for p in data.poses]),
        atol=1e-12,
    )


def test_true_pose_is_true_kinematics_within_repeatability() -> None:
    data = run()
    truth = data.truth
    assert truth.arm is not None and truth.joint_positions is not None
    T_true_fk = forward_kinematics(truth.arm.true, truth.joint_positions)
    off = np.linalg.norm(T_true_fk[:, :3, 3] - truth.T_base_flange_true[:, :3, 3], axis=1)
    # Repeatability 0.02 mm per axis (plus 0.001 deg at the flange): well below 0.15 mm.
    assert off.max() < 1.5e-4
    assert off.mean() > 5e-6


def test_kinematic_errors_give_sub_millimetre_absolute_error() -> None:
    errors = np.concatenate([_position_errors_m(run(seed)) for seed in (4, 5)])
    # Lengths off by 0.15 mm and angles by 0.02 deg (1 sigma) over a ~1 m arm.
    assert 1e-4 < errors.mean() < 1.5e-3
    assert errors.max() < 3e-3


def test_joint_states_survive_the_bag(tmp_path: Path) -> None:
    data = run()
    assert data.joint_states is not None
    bag = write_bag(tmp_path / "bag", data.profiles, data.poses, joint_states=data.joint_states)
    states = read_joint_states(bag)
    assert states.names == data.joint_states.names
    np.testing.assert_array_equal(states.stamps_ns, data.joint_states.stamps_ns)
    np.testing.assert_array_equal(states.positions, data.joint_states.positions)
    assert len(read_bag(bag, read_poses=False).poses) == 0


def test_a_bag_without_joint_states_lists_its_topics(tmp_path: Path) -> None:
    data = run()
    bag = write_bag(tmp_path / "bag", data.profiles, data.poses)
    with pytest.raises(BagError, match=r"no sensor_msgs/msg/JointState.*/flange_pose"):
        read_joint_states(bag)


def test_unreachable_cylinder_is_refused() -> None:
    far = scenario_from_preset("ur5e_kinematic", n_poses=4, cylinder_base_m=(2.0, 0.0, 0.0))
    with pytest.raises(InputError, match="reaches only"):
        simulate(far, 0)
