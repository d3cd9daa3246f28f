"""The ``ur5e_cell`` recording (what a real UR5e cell publishes) through every pose source,
and the collector's live ``joint_states`` input (in process; over DDS in test_ros_e2e.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from _urdf import ur_urdf
from rclpy.context import Context
from rclpy.parameter import Parameter
from ros_helpers import init_context, new_domain_id, reliable_qos

from linelaser_calib.cli import main
from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import invert_transform, rotvec_from_matrix
from linelaser_calib.core.robot.kinematics import UR_JOINT_NAMES, JointStates, forward_kinematics
from linelaser_calib.core.types import FlangePose
from linelaser_calib.io.bags import read_bag, write_bag
from linelaser_calib.io.pose_sources import read_tf
from linelaser_calib.io.results import read_result_yaml
from linelaser_calib.nodes import collector
from linelaser_calib.nodes.joint_state_input import JointStatePoseInput, live_kinematic_model
from linelaser_calib.sim import scenario_from_preset, simulate
from linelaser_calib.sim.bag_writer import simulate_to_bag
from msg_adapters import joint_state_msg, pose_stamped_from_flange_pose, rclpy_types

SEED = 4
#: Host latency of the profile stamps in the ur5e_cell preset, ns.
LATENCY_NS = 15_000_000


@pytest.fixture(scope="module")
def cell_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """ur5e_cell with the /tf chain and /tf_static beside /joint_states and the pose topic."""
    out = tmp_path_factory.mktemp("cell") / "bag"
    simulate_to_bag(out, "ur5e_cell", SEED, {}, tf=True)
    return out


def test_ur5e_cell_profiles_are_stamped_late_and_taken_at_standstill() -> None:
    data = simulate(scenario_from_preset("ur5e_cell"), SEED)
    truth, states = data.truth, data.joint_states
    assert states is not None and len(data.profiles) == 16
    assert np.all(truth.stamps_ns - truth.acquisition_stamps_ns == LATENCY_NS)
    assert [p.stamp_ns for p in data.profiles] == truth.stamps_ns.tolist()
    # The joints do not move from 20 ms before the acquisition to 20 ms after the stamp.
    for acquired, stamped in zip(truth.acquisition_stamps_ns, truth.stamps_ns, strict=True):
        around = (states.stamps_ns >= acquired - 20_000_000) & (
            states.stamps_ns <= stamped + 20_000_000
        )
        assert around.sum() >= 5
        assert np.ptp(states.positions[around], axis=0).max() < 1e-12


def test_ur5e_cell_recording_carries_what_a_real_cell_publishes(cell_bag: Path) -> None:
    topics = {t.topic: (t.msgtype, t.msgcount) for t in read_bag(cell_bag).topics}
    poses = topics["/flange_pose"][1]
    assert topics["/joint_states"] == ("sensor_msgs/msg/JointState", poses)
    assert topics["/flange_pose"][0] == "geometry_msgs/msg/PoseStamped"
    assert topics["/profile"] == ("sensor_msgs/msg/PointCloud2", 16)
    assert topics["/tf"][0] == topics["/tf_static"][0] == "tf2_msgs/msg/TFMessage"
    tf = read_tf(cell_bag)
    assert tf.static_count > 0 and tf.dynamic_count > 0
    assert {"base_link", "base_link_inertia", "shoulder_link", "wrist_3_link", "tool0"} <= set(
        tf.tree.frames
    )


def test_each_pose_source_gives_the_same_hand_eye_within_a_tenth_of_its_sigma(
    cell_bag: Path, tmp_path: Path
) -> None:
    """The pose topic, the /tf chain and forward kinematics of /joint_states (nominal: the
    kinematic corrections, estimated by default from joint states, would change the flange
    poses themselves), with default pairing options: the profiles are stamped 15 ms late but
    taken at standstill."""
    results = {}
    joint_states = ["--kinematics", "ur5e", "--nominal-kinematics"]
    for source, extra in (("pose", []), ("tf", []), ("joint_states", joint_states)):
        out = tmp_path / f"{source}.yaml"
        argv = ["calibrate", str(cell_bag), "--pose-source", source, "--output", str(out)]
        assert main([*argv, *extra]) == 0
        results[source] = read_result_yaml(out)
    pose = results["pose"]
    sigma_t, sigma_r = pose.uncertainty_translation_m, pose.uncertainty_rotation_rad
    assert sigma_t is not None and sigma_r is not None
    assert len(pose.samples_used) == 16
    for source in ("tf", "joint_states"):
        other = results[source]
        assert len(other.samples_used) == 16
        delta = invert_transform(pose.T_flange_sensor) @ other.T_flange_sensor
        assert np.all(np.abs(delta[:3, 3]) < 0.1 * sigma_t), source
        assert np.all(np.abs(rotvec_from_matrix(delta[:3, :3])) < 0.1 * sigma_r), source


def test_joint_states_ending_before_the_last_profile_drop_it_and_say_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording stopped by hand: /joint_states ends 5 ms before the last profile. The
    kinematic calibration leaves that profile out, names it, and calibrates from the rest
    (translation within 3 sigma of the truth) instead of refusing the recording."""
    data = simulate(scenario_from_preset("ur5e_cell"), SEED)
    states = data.joint_states
    assert states is not None
    keep = states.stamps_ns <= data.profiles[-1].stamp_ns - 5_000_000
    short = JointStates(states.names, states.stamps_ns[keep], states.positions[keep])
    bag = write_bag(tmp_path / "bag", data.profiles, data.poses, joint_states=short)
    out = tmp_path / "result.yaml"
    argv = ["calibrate", str(bag), "--kinematics", "ur5e"]
    assert main([*argv, "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    last = len(data.profiles) - 1
    result = read_result_yaml(out)
    assert [r.index for r in result.samples_rejected] == [last]
    assert "after the joint-state stream" in result.samples_rejected[0].reason
    assert len(result.samples_used) == last
    assert any(
        f"outside the joint-state stream and were left out (#{last})" in w for w in result.warnings
    )
    assert f"after the joint-state stream (at pairing; #{last})" in printed
    sigma_t = result.uncertainty_translation_m
    assert sigma_t is not None
    error = result.T_flange_sensor[:3, 3] - data.truth.T_flange_sensor[:3, 3]
    assert np.all(np.abs(error) < 3.0 * sigma_t + 1e-4)


# -- the collector's live input -------------------------------------------------------------


@pytest.fixture
def context() -> Iterator[Context]:
    context = init_context(new_domain_id())
    try:
        yield context
    finally:
        context.try_shutdown()


def test_live_model_takes_a_preset_a_urdf_file_or_urdf_text(tmp_path: Path) -> None:
    urdf = tmp_path / "ur5e.urdf"
    urdf.write_text(ur_urdf(), encoding="utf-8")
    q = np.array([[0.3, -1.2, 1.4, -0.8, 1.1, 0.4]])
    preset = live_kinematic_model("ur5e", "base_link", "tool0")
    for spec in (str(urdf), ur_urdf()):
        model = live_kinematic_model(spec, "base_link", "tool0")
        assert model.joint_names == UR_JOINT_NAMES
        np.testing.assert_allclose(
            forward_kinematics(model, q), forward_kinematics(preset, q), atol=1e-12
        )
    with pytest.raises(CalibrationError, match="needs the robot's kinematic model"):
        live_kinematic_model(" ", "base_link", "tool0")
    with pytest.raises(CalibrationError, match=r"kinematics parameter: .*neither a preset"):
        live_kinematic_model("ur3", "base_link", "tool0")
    with pytest.raises(CalibrationError, match=r"kinematics parameter: the URDF text: .*no link"):
        live_kinematic_model(ur_urdf(), "base_link", "flange")


@pytest.mark.ros
def test_joint_states_give_the_pose_topic_and_missing_joints_are_named(
    context: Context,
) -> None:
    data = simulate(scenario_from_preset("ur5e_cell", n_poses=2), SEED)
    states = data.joint_states
    assert states is not None
    node = rclpy.create_node("joint_state_input_test", context=context)
    poses: list[FlangePose] = []
    problems: list[str] = []
    try:
        model = live_kinematic_model("ur5e", "base_link", "tool0")
        live = JointStatePoseInput(node, model, reliable_qos(10), poses.append, problems.append)
        assert live.subscription.topic_name == "/joint_states"
        types = rclpy_types()
        picks = [0, len(states.stamps_ns) // 2, len(states.stamps_ns) - 1]
        # Joints in another order, with a gripper joint the model does not use.
        order = [5, 2, 0, 4, 1, 3]
        names = [*(states.names[k] for k in order), "gripper_joint"]
        for k in picks:
            q = [*states.positions[k, order], 0.02]
            live._on_joint_state(joint_state_msg(int(states.stamps_ns[k]), names, q, types=types))
        msg: Any = joint_state_msg(1, states.names[:5], states.positions[0, :5], types=types)
        live._on_joint_state(msg)
    finally:
        node.destroy_node()
    assert [p.stamp_ns for p in poses] == [int(states.stamps_ns[k]) for k in picks]
    for pose, k in zip(poses, picks, strict=True):
        expected = data.poses[k]
        assert pose.frame_id == "base_link" and expected.stamp_ns == pose.stamp_ns
        np.testing.assert_allclose(pose.T_base_flange, expected.T_base_flange, atol=1e-9)
    (problem,) = problems
    assert "['wrist_3_joint']" in problem and str(list(states.names[:5])) in problem
    assert str(list(UR_JOINT_NAMES)) in problem


@pytest.mark.ros
@pytest.mark.parametrize(
    ("kinematics", "message"),
    [("", "pose_source joint_states needs the robot's kinematic model"), ("ur3", "neither")],
)
def test_collector_refuses_joint_states_without_a_usable_model(
    context: Context, tmp_path: Path, kinematics: str, message: str
) -> None:
    with pytest.raises(CalibrationError, match=message):
        collector.CollectorNode(
            context=context,
            parameter_overrides=[
                Parameter("pose_source", value="joint_states"),
                Parameter("kinematics", value=kinematics),
                Parameter("session_dir", value=str(tmp_path)),
            ],
        )
    assert not list(tmp_path.iterdir())  # refused before a session was opened


@pytest.mark.ros
def test_collector_with_joint_states_takes_robot_description_and_ignores_pose_stamped(
    context: Context, tmp_path: Path
) -> None:
    data = simulate(scenario_from_preset("ur5e_cell", n_poses=2), SEED)
    states = data.joint_states
    assert states is not None
    node = collector.CollectorNode(
        context=context,
        parameter_overrides=[
            Parameter("pose_source", value="joint_states"),
            Parameter("kinematics", value=ur_urdf()),
            Parameter("session_dir", value=str(tmp_path)),
        ],
        cli_args=["--ros-args", "-r", "joint_states:=/ur/joint_states"],
    )
    try:
        live = node._pose_input
        assert isinstance(live, JointStatePoseInput)
        assert live.subscription.topic_name == "/ur/joint_states"
        assert live.model.name == "ur5e_urdf"
        types = rclpy_types()
        node._on_pose(pose_stamped_from_flange_pose(data.poses[0], types=types), {})
        assert node._collector.poses_received == 0  # PoseStamped is not the source
        live._on_joint_state(
            joint_state_msg(
                int(states.stamps_ns[0]), states.names, states.positions[0], types=types
            )
        )
        assert node._collector.poses_received == 1
    finally:
        node.destroy_node()
