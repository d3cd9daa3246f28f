"""The visualisation MCAP file (``calibrate --viz``), read back with the mcap library.

A small simulated bag is calibrated; the file must hold the expected topics, types and
counts, the hand-eye and flange poses as transforms, and profiles in the base frame that
lie on the fitted cylinder within their residual (and on the true one within the robot's
pose error).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import transform_from_translation_quaternion
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder.residuals import (
    cylinder_coordinates,
    sample_points_base,
    sample_surface_residuals,
)
from linelaser_calib.io import write_bag
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.report import VIZ_TOPICS, write_viz_mcap
from linelaser_calib.sim import scenario_from_preset, simulate
from linelaser_calib.sim.simulate import SimulatedData
from msg_adapters import points_from_pointcloud2, stamp_ns_from_msg

#: float32 rounding of base-frame coordinates below 1 m, m.
FLOAT32_M = 1e-7


@pytest.fixture(scope="module")
def data() -> SimulatedData:
    return simulate(scenario_from_preset("paper", n_poses=12, resolution=200), 9)


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory, data: SimulatedData) -> CalibrationResult:
    bag = write_bag(tmp_path_factory.mktemp("bag") / "bag", data.profiles, data.poses)
    return calibrate_bag(bag, PipelineConfig()).result


@pytest.fixture(scope="module")
def messages(
    tmp_path_factory: pytest.TempPathFactory, result: CalibrationResult
) -> dict[str, list[tuple[str, int, Any]]]:
    """Per topic: (schema name, log time, decoded message)."""
    path = write_viz_mcap(tmp_path_factory.mktemp("viz") / "calibration.mcap", result)
    found: dict[str, list[tuple[str, int, Any]]] = defaultdict(list)
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema is not None
            found[channel.topic].append((schema.name, message.log_time, decoded))
    return found


def transform_of(msg: Any) -> np.ndarray:
    t, q = msg.transform.translation, msg.transform.rotation
    return transform_from_translation_quaternion([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])


def test_topics_types_and_counts(
    messages: dict[str, list[tuple[str, int, Any]]], result: CalibrationResult
) -> None:
    m = len(result.sample_fits)
    assert m == len(result.samples_used) == 12
    expected = {
        VIZ_TOPICS["tf_static"]: ("tf2_msgs/msg/TFMessage", 1),
        VIZ_TOPICS["tf"]: ("tf2_msgs/msg/TFMessage", m),
        VIZ_TOPICS["profiles"]: ("sensor_msgs/msg/PointCloud2", m),
        VIZ_TOPICS["cloud"]: ("sensor_msgs/msg/PointCloud2", 1),
        VIZ_TOPICS["markers"]: ("visualization_msgs/msg/MarkerArray", 1),
    }
    assert {topic: (items[0][0], len(items)) for topic, items in messages.items()} == expected


def test_transforms_are_the_hand_eye_and_the_recorded_poses(
    messages: dict[str, list[tuple[str, int, Any]]], result: CalibrationResult
) -> None:
    ((_, _, static),) = messages["/tf_static"]
    (hand_eye,) = static.transforms
    assert (hand_eye.header.frame_id, hand_eye.child_frame_id) == ("tool0", "laser")
    np.testing.assert_allclose(transform_of(hand_eye), result.T_flange_sensor, atol=1e-12)
    fits = sorted(result.sample_fits, key=lambda f: f.stamp_ns)
    for fit, (_, log_ns, msg) in zip(fits, messages["/tf"], strict=True):
        (pose,) = msg.transforms
        assert (pose.header.frame_id, pose.child_frame_id) == ("base_link", "tool0")
        assert stamp_ns_from_msg(pose.header.stamp) == log_ns == fit.stamp_ns
        np.testing.assert_allclose(transform_of(pose), fit.T_base_flange, atol=1e-12)


def test_profiles_lie_on_the_cylinder_within_their_residual(
    messages: dict[str, list[tuple[str, int, Any]]], result: CalibrationResult, data: SimulatedData
) -> None:
    fits = sorted(result.sample_fits, key=lambda f: f.stamp_ns)
    residuals = sample_surface_residuals(fits, result.T_flange_sensor, result.target.cylinder)
    for fit, residual, (_, log_ns, cloud) in zip(
        fits, residuals, messages["/linelaser_calib/profiles"], strict=True
    ):
        assert cloud.header.frame_id == "base_link"
        assert stamp_ns_from_msg(cloud.header.stamp) == log_ns == fit.stamp_ns
        points = points_from_pointcloud2(cloud)
        np.testing.assert_allclose(
            points, sample_points_base(fit, result.T_flange_sensor), atol=FLOAT32_M
        )
        distance = cylinder_coordinates(points, result.target.cylinder).residual_m
        assert np.all(np.abs(distance) <= np.max(np.abs(residual)) + FLOAT32_M)
    ((_, _, combined),) = messages["/linelaser_calib/cloud"]
    every = points_from_pointcloud2(combined)
    assert len(every) == sum(len(f.points) for f in fits)
    # Against the truth: off by the robot's pose error only (1 sigma 0.1 mm, 0.01 deg).
    on_true = cylinder_coordinates(every, data.truth.cylinder).residual_m
    assert float(np.sqrt(np.mean(on_true**2))) < 3e-4


def test_cylinder_marker_covers_the_profiles(
    messages: dict[str, list[tuple[str, int, Any]]], result: CalibrationResult
) -> None:
    ((_, _, array),) = messages["/linelaser_calib/markers"]
    (marker,) = array.markers
    assert marker.type == 3  # visualization_msgs/Marker CYLINDER
    assert marker.header.frame_id == "base_link"
    diameter = 2.0 * result.target.cylinder.radius
    assert marker.scale.x == pytest.approx(diameter) and marker.scale.y == pytest.approx(diameter)
    p, q = marker.pose.position, marker.pose.orientation
    T = transform_from_translation_quaternion([p.x, p.y, p.z], [q.x, q.y, q.z, q.w])
    direction = result.target.cylinder.direction / np.linalg.norm(result.target.cylinder.direction)
    assert abs(float(T[:3, 2] @ direction)) == pytest.approx(1.0, abs=1e-9)
    assert cylinder_coordinates(T[:3, 3], result.target.cylinder).residual_m[0] == pytest.approx(
        -result.target.cylinder.radius, abs=1e-9
    )  # the marker's centre is on the axis
    ((_, _, combined),) = messages["/linelaser_calib/cloud"]
    along = (points_from_pointcloud2(combined) - T[:3, 3]) @ T[:3, 2]
    assert np.all(np.abs(along) <= 0.5 * marker.scale.z)


def test_an_existing_file_is_replaced_and_no_partial_file_is_left(
    tmp_path: Path, result: CalibrationResult
) -> None:
    target = tmp_path / "viz.mcap"
    target.write_bytes(b"old")
    write_viz_mcap(target, result)
    assert target.read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert [p.name for p in tmp_path.iterdir()] == ["viz.mcap"]


def test_every_target_gets_a_visualisation_and_the_help_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Regression of issue 24: --viz works for a known point (and the other targets), and its
    help no longer says it shows a cylinder only."""
    repo = Path(__file__).resolve().parents[1]
    output, viz = tmp_path / "result.yaml", tmp_path / "viz.mcap"
    argv = ["calibrate", str(repo / "bags/weld_seam"), "--target", "known_point"]
    assert main([*argv, "--output", str(output), "--viz", str(viz)]) == 0
    assert f"Wrote {viz}" in capsys.readouterr().out
    point = yaml.safe_load(output.read_text(encoding="utf-8"))["known_point"]["point"]
    with viz.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        markers = [
            decoded
            for _, channel, _, decoded in reader.iter_decoded_messages()
            if channel.topic == VIZ_TOPICS["markers"]
        ]
    ((marker,),) = [array.markers for array in markers]
    assert marker.ns == "known_point" and marker.header.frame_id == "base_link"
    (shown,) = marker.points
    np.testing.assert_allclose([shown.x, shown.y, shown.z], point, atol=1e-12)
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "the fitted target and the transforms as an MCAP file" in help_text
    assert "report (index.html and PNG figures) of any target" in help_text
