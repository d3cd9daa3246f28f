"""calibration_service's kinematics parameter: the joint calibration of the collector's session."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.context import Context
from rclpy.parameter import Parameter
from ros_helpers import wait_for
from std_msgs.msg import String
from std_srvs.srv import Trigger
from test_joint_calibration import ARM_SEED
from test_nodes_unit import ServiceUnderTest, ros_context  # noqa: F401 - a fixture

from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.robot.kinematics import forward_kinematics
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import SessionBagWriter, read_result_yaml
from linelaser_calib.nodes.common import SESSION_TOPIC, latched_qos
from linelaser_calib.sim import SimulatedData, scenario_from_preset, simulate


@pytest.fixture(scope="module")
def arm_scan() -> SimulatedData:
    """16 poses of the kinematic-error arm (ARM_SEED)."""
    return simulate(scenario_from_preset("ur5e_kinematic", n_poses=16, kinematic_seed=ARM_SEED), 21)


def write_session(
    path: Path, data: SimulatedData, joints: bool
) -> list[tuple[Profile, FlangePose]]:
    """A collector session of the scan: flange poses from the nominal model's forward
    kinematics of the joint vectors, stored with each sample when ``joints``."""
    truth = data.truth
    assert truth.arm is not None and truth.joint_positions is not None
    model = truth.arm.nominal
    T = forward_kinematics(model, truth.joint_positions)
    samples = []
    with SessionBagWriter(path, organised=False) as writer:
        for profile, T_bf, q in zip(data.profiles, T, truth.joint_positions, strict=True):
            pose = FlangePose(profile.stamp_ns, T_bf, "base_link")
            writer.append(profile, pose, (model.joint_names, q) if joints else None)
            samples.append((profile, pose))
    return samples


@pytest.fixture
def service(
    ros_context: tuple[Context, int],  # noqa: F811 - the fixture imported above
    tmp_path: Path,
) -> Iterator[ServiceUnderTest]:
    context, domain = ros_context
    under_test = ServiceUnderTest(context, domain, tmp_path / "hand_eye.yaml")
    under_test.node.set_parameters([Parameter("kinematics", value="ur5e")])
    try:
        yield under_test
    finally:
        under_test.close()


def calibrate_session(
    service: ServiceUnderTest, data: SimulatedData, session: Path, joints: bool
) -> Trigger.Response:
    """Write the session, publish it as the collector does (its path, then its samples) and
    call calibrate."""
    samples = write_session(session, data, joints)
    publisher = service.probe.node.create_publisher(String, SESSION_TOPIC, latched_qos(1))
    publisher.publish(String(data=str(session)))
    wait_for(lambda: service.node._store.session == str(session), 20.0, "the session")
    service.send(samples)
    return service.probe.call("calibrate")


@pytest.mark.ros
def test_kinematics_parameter_runs_the_joint_calibration_of_the_session(
    service: ServiceUnderTest, arm_scan: SimulatedData, tmp_path: Path
) -> None:
    answer = calibrate_session(service, arm_scan, tmp_path / "session", joints=True)
    assert answer.success, answer.message
    assert "kinematic corrections of the ur5e model: 16 estimated, 8 kept nominal" in (
        answer.message
    )
    output = Path(service.node.get_parameter("output_path").value)
    section = yaml.safe_load(output.read_text(encoding="utf-8"))["kinematics"]
    assert section["model"] == "ur5e" and len(section["corrections"]) == 16
    written = read_result_yaml(output)
    # The hand-eye absorbs the flange-side kinematic errors (about 0.3 mm here), no more.
    rotation, translation = transform_error(written.T_flange_sensor, arm_scan.truth.T_flange_sensor)
    assert np.degrees(rotation) < 0.1 and translation < 1e-3
    published = service.probe.hand_eye()
    assert max(transform_error(published, written.T_flange_sensor)) < 1e-6
    # ~/plan then also says whether another placement of the cylinder determines more.
    planned = service.probe.call("/calibration_service/plan")
    assert planned.success, planned.message
    assert "placements: 1 placement of the cylinder determines 16 of 24" in planned.message


@pytest.mark.ros
def test_kinematics_parameter_refuses_a_session_without_joint_states(
    service: ServiceUnderTest, arm_scan: SimulatedData, tmp_path: Path
) -> None:
    answer = calibrate_session(service, arm_scan, tmp_path / "session", joints=False)
    assert not answer.success
    assert "holds no joint states" in answer.message
    assert "pose_source joint_states" in answer.message
    assert not Path(service.node.get_parameter("output_path").value).exists()
