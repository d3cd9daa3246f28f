"""``reconstruct`` and ``--pose-source joint_states``: points against the true cylinder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from _urdf import ur_urdf
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.io.ply import read_ply, write_ply
from linelaser_calib.io.results import read_result_yaml, read_truth_yaml
from msg_adapters import points_from_pointcloud2

#: Points above this height are on the cylinder (the table is z = 0), m.
ABOVE_TABLE_M = 0.002


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small ur5e_kinematic recording (8 poses)."""
    path = tmp_path_factory.mktemp("reconstruct") / "arm"
    args = ["simulate", str(path), "--scenario", "ur5e_kinematic", "--seed", "3", "--poses", "8"]
    assert main(args) == 0
    return path


@pytest.fixture(scope="module")
def calibrated(bag: Path) -> Path:
    """The default method's result on ``bag`` (its hand-eye is off by the robot's error)."""
    out = bag.parent / "calibrated.yaml"
    assert main(["calibrate", str(bag), "--output", str(out)]) == 0
    return out


def true_calibration(
    bag: Path, calibrated: Path, path: Path, *, kinematics: bool, child: str = "laser"
) -> Path:
    """A result file holding the true hand-eye and, if asked, the true kinematic corrections."""
    truth = read_truth_yaml(bag / "truth.yaml").raw
    data = yaml.safe_load(calibrated.read_text(encoding="utf-8"))
    for key in ("translation", "rotation_xyzw", "matrix"):
        data["hand_eye"][key] = truth["hand_eye"][key]
    data["hand_eye"]["child_frame"] = child
    if kinematics:
        data["kinematics"] = truth["kinematics"]
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def surface_distances_m(bag: Path, points: np.ndarray) -> np.ndarray:
    section = read_truth_yaml(bag / "truth.yaml").target
    assert isinstance(section, CylinderSection)
    cylinder = section.cylinder
    above = points[points[:, 2] > ABOVE_TABLE_M]
    v = above - cylinder.point
    radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
    return np.asarray(np.abs(np.linalg.norm(radial, axis=1) - cylinder.radius))


def ply_points(path: Path) -> np.ndarray:
    vertex = read_ply(path)
    return np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1)


def reconstruct(bag: Path, calibration: Path, out: Path) -> Path:
    args = ["reconstruct", str(bag), "--calibration", str(calibration), "--output", str(out)]
    assert main(args) == 0
    return out


def test_true_kinematics_put_the_points_on_the_true_cylinder(
    bag: Path, calibrated: Path, tmp_path: Path
) -> None:
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=True)
    out = reconstruct(bag, calibration, tmp_path / "cloud.ply")
    vertex = read_ply(out)
    assert set(vertex) == {"x", "y", "z", "intensity"}
    assert np.all((vertex["intensity"] >= 0.0) & (vertex["intensity"] <= 1.5))
    assert np.ptp(vertex["intensity"]) > 0.1
    distance = surface_distances_m(bag, ply_points(out))
    # Sensor noise 8 um and repeatability 0.02 mm; spikes (0.5 %) are left in the cloud.
    assert len(distance) > 500
    assert np.median(distance) < 3e-5
    assert np.percentile(distance, 90) < 8e-5


def test_a_calibrated_along_line_scale_is_applied_to_the_points(
    bag: Path, calibrated: Path, tmp_path: Path
) -> None:
    # The simulated profiler has no scale error: a calibration claiming the profiles read 1 %
    # long must shrink them along the line and move the points off the true cylinder.
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=True)
    data = yaml.safe_load(calibration.read_text(encoding="utf-8"))
    plain = ply_points(reconstruct(bag, calibration, tmp_path / "plain.ply"))
    data["cylinder"]["along_line_scale"] = 1.01
    calibration.write_text(yaml.safe_dump(data), encoding="utf-8")
    scaled = ply_points(reconstruct(bag, calibration, tmp_path / "scaled.ply"))
    # Each point moves along the line by 1 - 1 / 1.01 of its distance from the sensor's z axis.
    assert np.max(np.linalg.norm(scaled - plain, axis=1)) > 1e-4
    assert np.percentile(surface_distances_m(bag, scaled), 90) > 1.5 * np.percentile(
        surface_distances_m(bag, plain), 90
    )


def test_nominal_kinematics_leave_the_robot_error_in_the_points(
    bag: Path, calibrated: Path, tmp_path: Path
) -> None:
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=False)
    out = reconstruct(bag, calibration, tmp_path / "cloud.ply")
    distance = surface_distances_m(bag, ply_points(out))
    assert np.median(distance) > 8e-5


def test_mcap_output_holds_pointclouds_in_the_base_frame(
    bag: Path, calibrated: Path, tmp_path: Path
) -> None:
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=True)
    ply = reconstruct(bag, calibration, tmp_path / "cloud.ply")
    mcap = reconstruct(bag, calibration, tmp_path / "cloud.mcap")
    store = get_typestore(Stores.ROS2_JAZZY)
    per_topic: dict[str, list[np.ndarray]] = {}
    with mcap.open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            msg = store.deserialize_cdr(message.data, schema.name)
            assert msg.header.frame_id == "base_link"
            assert [f.name for f in msg.fields][:4] == ["x", "y", "z", "intensity"]
            per_topic.setdefault(channel.topic, []).append(points_from_pointcloud2(msg))
    (cloud,) = per_topic["/linelaser_calib/cloud"]
    assert len(per_topic["/linelaser_calib/profiles"]) == 8
    np.testing.assert_allclose(cloud, ply_points(ply), atol=1e-6)


def test_joint_states_pose_source_calibrates_like_the_pose_topic(
    bag: Path, calibrated: Path, tmp_path: Path
) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ur_urdf("ur5e"), encoding="utf-8")
    out = tmp_path / "joint_states.yaml"
    args = ["calibrate", str(bag), "--pose-source", "joint_states", "--kinematics", str(urdf)]
    assert main([*args, "--nominal-kinematics", "--output", str(out)]) == 0
    from_joints = read_result_yaml(out)
    rot, trans = transform_error(
        read_result_yaml(calibrated).T_flange_sensor, from_joints.T_flange_sensor
    )
    assert rot < 1e-6 and trans < 1e-7
    truth = read_truth_yaml(bag / "truth.yaml")
    rot, trans = transform_error(from_joints.T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot) < 0.3 and trans < 2e-3


def _fails(args: list[str], capsys: pytest.CaptureFixture[str], *phrases: str) -> None:
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for phrase in phrases:
        assert phrase in err, err


def test_missing_calibration_file(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["reconstruct", str(bag), "--calibration", str(tmp_path / "none.yaml")]
    _fails([*args, "--output", str(tmp_path / "c.ply")], capsys, "none.yaml does not exist")
    assert not (tmp_path / "c.ply").exists()


def test_frame_mismatch_names_both_frames(
    bag: Path, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = true_calibration(
        bag, calibrated, tmp_path / "other.yaml", kinematics=False, child="cam"
    )
    args = ["reconstruct", str(bag), "--calibration", str(calibration)]
    _fails([*args, "--output", str(tmp_path / "c.ply")], capsys, "'cam'", "'laser'")


def test_unknown_output_format(
    bag: Path, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=False)
    args = ["reconstruct", str(bag), "--calibration", str(calibration)]
    _fails([*args, "--output", str(tmp_path / "c.xyz")], capsys, ".ply", ".mcap")


def test_joint_states_need_a_model_and_a_model_needs_joint_states(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _fails(["calibrate", str(bag), "--pose-source", "joint_states"], capsys, "--kinematics")
    args = ["calibrate", str(bag), "--pose-source", "pose", "--kinematics", "ur5e"]
    _fails(args, capsys, "--pose-source joint_states")
    _fails(["calibrate", str(bag), "--nominal-kinematics"], capsys, "--kinematics MODEL")
    args = ["calibrate", str(bag), "--pose-source", "joint_states", "--kinematics", "ur5e"]
    _fails([*args, "--pose-topic", "/flange_pose"], capsys, "drop --pose-topic")


def test_no_joint_states_in_the_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "plain"
    assert (
        main(["simulate", str(bag), "--scenario", "paper", "--poses", "6", "--points", "60"]) == 0
    )
    args = ["calibrate", str(bag), "--pose-source", "joint_states", "--kinematics", "ur5e"]
    _fails(args, capsys, "no sensor_msgs/msg/JointState", "/flange_pose")


def test_joint_names_of_another_robot_are_listed(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    names = tuple(f"joint_{i + 1}" for i in range(6))
    urdf = tmp_path / "abb.urdf"
    urdf.write_text(ur_urdf("ur5e", joint_names=names), encoding="utf-8")
    args = ["calibrate", str(bag), "--pose-source", "joint_states", "--kinematics", str(urdf)]
    _fails(args, capsys, "joint_1", "shoulder_pan_joint")


def test_ascii_ply_reads_like_binary(tmp_path: Path) -> None:
    points = np.array([[0.1, -0.2, 0.3], [1.5, 2.5, -3.5]])
    binary = write_ply(tmp_path / "b.ply", points, frame_id="base_link", intensity=np.ones(2))
    ascii_path = tmp_path / "a.ply"
    ascii_path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
        "property double z\nend_header\n0.1 -0.2 0.3\n1.5 2.5 -3.5\n",
        encoding="ascii",
    )
    np.testing.assert_allclose(ply_points(binary), points, rtol=1e-7)
    np.testing.assert_allclose(ply_points(ascii_path), points, rtol=1e-12)
    assert "frame base_link, unit m" in binary.read_bytes()[:200].decode("ascii", "replace")


def test_corrections_for_another_model_are_refused(
    bag: Path, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = true_calibration(bag, calibrated, tmp_path / "true.yaml", kinematics=True)
    args = ["reconstruct", str(bag), "--calibration", str(calibration), "--output"]
    args += [str(tmp_path / "c.ply"), "--pose-source", "joint_states", "--kinematics", "ur10e"]
    _fails(args, capsys, "'ur5e'", "'ur10e'")
