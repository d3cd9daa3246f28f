"""msg_adapters: PointCloud2, PoseStamped, TransformStamped and markers in both message worlds.

Layouts are built by a plain per-point ``struct.pack_into`` reference, independent of the
vectorised numpy code under test.
"""

from __future__ import annotations

import dataclasses
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import (
    matrix_from_quaternion_xyzw,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FlangePose
from msg_adapters import (
    MessageError,
    cloud_from_pointcloud2,
    cylinder_marker,
    flange_pose_from_pose_stamped,
    marker_array,
    pointcloud2_from_points,
    points_from_pointcloud2,
    points_marker,
    pose_stamped_from_flange_pose,
    profile_from_pointcloud2,
    rclpy_types,
    rosbags_types,
    stamp_ns_from_msg,
    stamped_transform_from_msg,
    stamped_transforms_from_msgs,
    time_msg_from_ns,
    transform_stamped_from_matrix,
)
from msg_adapters.message_types import uint8_field

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
WORLDS = {"rclpy": rclpy_types(), "rosbags": rosbags_types(TYPESTORE)}
DATATYPES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}
STRUCT_CODES = {
    "i1": "b",
    "u1": "B",
    "i2": "h",
    "u2": "H",
    "i4": "i",
    "u4": "I",
    "f4": "f",
    "f8": "d",
}


@pytest.fixture(params=sorted(WORLDS))
def types(request: pytest.FixtureRequest) -> Any:
    return WORLDS[request.param]


def scan_line(rng: np.random.Generator, n: int) -> np.ndarray:
    """A line-laser profile (n, 3) in m: an arc in the x-z plane with NaN and +-Inf returns."""
    angle = rng.uniform(-1.0, 1.0, n)
    points = np.column_stack([0.03 * np.sin(angle), np.zeros(n), 0.2 - 0.03 * np.cos(angle)])
    points[rng.choice(n, 3, replace=False)] = np.nan
    points[rng.integers(n), 2] = np.inf
    points[rng.integers(n), 0] = -np.inf
    return points


def reference_cloud(
    types: Any,
    layout: list[tuple[str, str, int]],
    values: dict[str, np.ndarray],
    *,
    height: int,
    width: int,
    point_step: int,
    bigendian: bool,
) -> Any:
    """PointCloud2 whose bytes are packed point by point with ``struct`` (the reference)."""
    order = ">" if bigendian else "<"
    data = bytearray(height * width * point_step)
    for i in range(height * width):
        for name, kind, offset in layout:
            code = order + STRUCT_CODES[kind]
            struct.pack_into(code, data, i * point_step + offset, values[name][i])
    field_cls = types("sensor_msgs/msg/PointField")
    cloud_cls = types("sensor_msgs/msg/PointCloud2")
    return cloud_cls(
        header=types("std_msgs/msg/Header")(stamp=time_msg_from_ns(5, types), frame_id="laser"),
        height=height,
        width=width,
        fields=[
            field_cls(name=name, offset=offset, datatype=DATATYPES[kind], count=1)
            for name, kind, offset in layout
        ],
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=width * point_step,
        data=uint8_field(cloud_cls, np.frombuffer(bytes(data), dtype=np.uint8)),
        is_dense=False,
    )


def random_layout(
    rng: np.random.Generator, coordinate_kind: str
) -> tuple[list[tuple[str, str, int]], int]:
    """Fields x, y, z, intensity, ring, t in shuffled order with random gaps; point_step."""
    kinds = {
        "x": coordinate_kind,
        "y": coordinate_kind,
        "z": coordinate_kind,
        "intensity": "u2",
        "ring": "u1",
        "t": "f8",
    }
    names = list(kinds)
    rng.shuffle(names)
    layout, offset = [], int(rng.integers(0, 4))
    for name in names:
        layout.append((name, kinds[name], offset))
        offset += np.dtype(kinds[name]).itemsize + int(rng.integers(0, 5))
    return layout, offset + int(rng.integers(0, 9))


@pytest.mark.parametrize("seed", range(6))
def test_adversarial_layouts_decode_like_the_reference(types: Any, seed: int) -> None:
    rng = np.random.default_rng(seed)
    kind = "f4" if seed % 2 == 0 else "f8"
    height, width = (1, 40) if seed < 3 else (3, 13)
    truth = scan_line(rng, height * width).astype(np.dtype(kind)).astype(np.float64)
    values = {
        "x": truth[:, 0],
        "y": truth[:, 1],
        "z": truth[:, 2],
        "intensity": rng.integers(0, 65535, height * width),
        "ring": rng.integers(0, 255, height * width),
        "t": rng.normal(size=height * width),
    }
    layout, point_step = random_layout(rng, kind)
    msg = reference_cloud(
        types,
        layout,
        values,
        height=height,
        width=width,
        point_step=point_step,
        bigendian=bool(seed % 3 == 1),
    )

    valid = np.all(np.isfinite(truth), axis=1)
    cloud = cloud_from_pointcloud2(msg, extra_fields=("intensity", "ring"))
    np.testing.assert_array_equal(cloud.points, truth[valid])
    np.testing.assert_array_equal(cloud.extras["intensity"], values["intensity"][valid])
    np.testing.assert_array_equal(cloud.extras["ring"], values["ring"][valid])
    full = points_from_pointcloud2(msg, keep_invalid=True)
    np.testing.assert_array_equal(full, truth)  # row-major, NaN and +-Inf as sent


@pytest.mark.parametrize("organised", [True, False])
@pytest.mark.parametrize(
    ("dtype", "bigendian", "padding"), [(np.float32, False, 0), (np.float64, True, 5)]
)
def test_built_clouds_round_trip_identically_in_both_worlds(
    organised: bool, dtype: type, bigendian: bool, padding: int
) -> None:
    rng = np.random.default_rng(11)
    points = scan_line(rng, 64)
    intensity = rng.uniform(0.0, 1000.0, 64)
    valid = np.all(np.isfinite(points), axis=1)
    messages = {
        world: pointcloud2_from_points(
            points,
            1_700_000_000_123_456_789,
            "laser",
            types=resolver,
            intensity=intensity,
            organised=organised,
            padding_bytes=padding,
            dtype=dtype,
            is_bigendian=bigendian,
        )
        for world, resolver in WORLDS.items()
    }
    decoded = {
        w: cloud_from_pointcloud2(m, extra_fields=("intensity",)) for w, m in messages.items()
    }
    expected = points.astype(dtype).astype(np.float64)[valid]
    for world, cloud in decoded.items():
        np.testing.assert_array_equal(cloud.points, expected, err_msg=world)
        np.testing.assert_array_equal(
            cloud.extras["intensity"], intensity.astype(np.float32)[valid], err_msg=world
        )
    rclpy_msg, rosbags_msg = messages["rclpy"], messages["rosbags"]
    assert bytes(rclpy_msg.data) == rosbags_msg.data.tobytes()
    assert (
        rclpy_msg.point_step == rosbags_msg.point_step == 3 * np.dtype(dtype).itemsize + 4 + padding
    )
    assert rclpy_msg.width == rosbags_msg.width == (64 if organised else int(valid.sum()))
    assert rclpy_msg.is_dense == rosbags_msg.is_dense == (not organised)
    assert stamp_ns_from_msg(rclpy_msg.header.stamp) == 1_700_000_000_123_456_789


def test_messages_cross_serialise_between_worlds() -> None:
    rng = np.random.default_rng(3)
    points = scan_line(rng, 50)
    expected = points_from_pointcloud2(
        pointcloud2_from_points(points, 9, "laser", types=WORLDS["rosbags"])
    )
    from sensor_msgs.msg import PointCloud2

    rclpy_msg = pointcloud2_from_points(points, 9, "laser", types=WORLDS["rclpy"])
    as_rosbags = TYPESTORE.deserialize_cdr(
        serialize_message(rclpy_msg), "sensor_msgs/msg/PointCloud2"
    )
    np.testing.assert_array_equal(points_from_pointcloud2(as_rosbags), expected)

    rosbags_msg = pointcloud2_from_points(points, 9, "laser", types=WORLDS["rosbags"])
    raw = TYPESTORE.serialize_cdr(rosbags_msg, "sensor_msgs/msg/PointCloud2")
    as_rclpy = deserialize_message(bytes(raw), PointCloud2)
    np.testing.assert_array_equal(points_from_pointcloud2(as_rclpy), expected)


def serialised_round_trip(msg: Any) -> Any:
    """The message after CDR serialisation and back, in its own world."""
    if dataclasses.is_dataclass(msg):
        raw = TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2")
        return TYPESTORE.deserialize_cdr(raw, "sensor_msgs/msg/PointCloud2")
    return deserialize_message(serialize_message(msg), type(msg))


#: Point layouts that drivers send: (fields (name, kind, offset), point_step).
DRIVER_LAYOUTS = {
    "float64 xyz + uint16 intensity, 26-byte point": (
        [("x", "f8", 0), ("y", "f8", 8), ("z", "f8", 16), ("intensity", "u2", 24)],
        26,
    ),
    "float32 xyz at odd offsets, 15-byte point": (
        [("intensity", "u1", 0), ("x", "f4", 1), ("y", "f4", 5), ("z", "f4", 9)],
        15,
    ),
}


@pytest.mark.parametrize("layout_name", sorted(DRIVER_LAYOUTS))
@pytest.mark.parametrize("sentinel", [-0.999999, 0.0])
def test_sentinel_depths_are_no_return_in_any_layout(
    types: Any, layout_name: str, sentinel: float
) -> None:
    layout, point_step = DRIVER_LAYOUTS[layout_name]
    kind = dict((name, k) for name, k, _ in layout)["x"]
    rng = np.random.default_rng(7)
    truth = scan_line(rng, 40)
    no_return = np.zeros(40, dtype=bool)
    no_return[[3, 17, 18, 39]] = True
    truth[no_return] = [0.0, 0.0, sentinel]  # how drivers mark a missing return
    truth[5] = [0.01, 0.0, sentinel]  # a sentinel depth with a valid-looking x
    no_return[5] = True
    truth = truth.astype(np.dtype(kind)).astype(np.float64)
    values = {"x": truth[:, 0], "y": truth[:, 1], "z": truth[:, 2]}
    values["intensity"] = rng.integers(0, 200, 40)
    msg = serialised_round_trip(
        reference_cloud(
            types, layout, values, height=1, width=40, point_step=point_step, bigendian=False
        )
    )
    finite = np.all(np.isfinite(truth), axis=1)

    plain = points_from_pointcloud2(msg)
    np.testing.assert_array_equal(plain, truth[finite])  # without the sentinel: kept
    cloud = cloud_from_pointcloud2(msg, extra_fields=("intensity",), invalid_values_m=[sentinel])
    np.testing.assert_array_equal(cloud.points, truth[finite & ~no_return])
    np.testing.assert_array_equal(
        cloud.extras["intensity"], values["intensity"][finite & ~no_return]
    )
    narrow = cloud_from_pointcloud2(msg, invalid_values_m=[sentinel], keep_float32=True).points
    assert narrow.dtype == (np.float32 if np.dtype(kind).itemsize == 4 else np.float64)
    np.testing.assert_array_equal(narrow, cloud.points)  # float32 as sent, the same test
    full = points_from_pointcloud2(msg, keep_invalid=True, invalid_values_m=[sentinel])
    assert np.all(np.isnan(full[no_return]))
    np.testing.assert_array_equal(full[~no_return], truth[~no_return])
    profile = profile_from_pointcloud2(msg, invalid_values_m=[1.5, sentinel])
    assert profile.points.shape == (int(np.sum(finite & ~no_return)), 3)


def test_organised_clouds_keep_invalid_rows_and_dense_ones_drop_them(types: Any) -> None:
    points = scan_line(np.random.default_rng(4), 30)
    valid = np.all(np.isfinite(points), axis=1)
    organised = pointcloud2_from_points(points, 1, "laser", types=types)
    dense = pointcloud2_from_points(points, 1, "laser", types=types, organised=False)
    assert (organised.height, organised.width, organised.is_dense) == (1, 30, False)
    assert (dense.height, dense.width, dense.is_dense) == (1, int(valid.sum()), True)
    kept = points_from_pointcloud2(organised, keep_invalid=True)
    np.testing.assert_array_equal(kept, points.astype(np.float32).astype(np.float64))
    assert points_from_pointcloud2(dense, keep_invalid=True).shape == (int(valid.sum()), 3)
    profile = profile_from_pointcloud2(organised)
    assert (profile.stamp_ns, profile.frame_id, profile.points.shape) == (
        1,
        "laser",
        (valid.sum(), 3),
    )


def test_empty_cloud_gives_no_points(types: Any) -> None:
    msg = pointcloud2_from_points(np.zeros((0, 3)), 1, "laser", types=types)
    assert points_from_pointcloud2(msg).shape == (0, 3)


def good_layout_cloud(types: Any, **changes: Any) -> Any:
    """A valid 4-point float32 cloud; ``changes`` overwrite message attributes afterwards."""
    msg = pointcloud2_from_points(np.ones((4, 3)), 1, "laser", types=types, intensity=np.ones(4))
    for name, value in changes.items():
        setattr(msg, name, value)
    return msg


def point_field(types: Any, name: str, offset: int, datatype: int, count: int = 1) -> Any:
    return types("sensor_msgs/msg/PointField")(
        name=name, offset=offset, datatype=datatype, count=count
    )


@pytest.mark.parametrize(
    ("case", "expected_text"),
    [
        ("no_x", "no field(s) ['x']"),
        ("int_z", "expected FLOAT32 or FLOAT64"),
        ("point_step_small", "point_step 12 B is smaller than field 'intensity' needs"),
        ("row_step", "row_step 15 B is inconsistent with width 4 x point_step 16 B"),
        ("data_short", "data holds 63 B but height 1 x row_step 64 B"),
        ("duplicate", "field 'y' appears twice"),
        ("bad_datatype", "unknown datatype 9"),
        ("count_zero", "count 0"),
        ("missing_extra", "no field(s) ['ring']"),
    ],
)
def test_malformed_layouts_raise_message_error_naming_the_problem(
    types: Any, case: str, expected_text: str
) -> None:
    msg = good_layout_cloud(types)
    x, y, z, intensity = list(msg.fields)
    extra: tuple[str, ...] = ()
    if case == "no_x":
        msg.fields = [y, z, intensity]
    elif case == "int_z":
        msg.fields = [x, y, point_field(types, "z", 8, 5), intensity]
    elif case == "point_step_small":
        msg.point_step, msg.row_step = 12, 48
        msg.data = uint8_field(type(msg), np.zeros(48, np.uint8))
    elif case == "row_step":
        msg.row_step = 15
    elif case == "data_short":
        msg.data = uint8_field(type(msg), np.zeros(63, np.uint8))
    elif case == "duplicate":
        msg.fields = [x, y, z, point_field(types, "y", 12, 7)]
    elif case == "bad_datatype":
        msg.fields = [x, y, z, point_field(types, "intensity", 12, 9)]
    elif case == "count_zero":
        msg.fields = [point_field(types, "x", 0, 7, 0), y, z, intensity]
    elif case == "missing_extra":
        extra = ("ring",)
    with pytest.raises(MessageError) as caught:
        cloud_from_pointcloud2(msg, extra_fields=extra)
    assert expected_text in str(caught.value)
    assert isinstance(caught.value, ValueError)
    assert isinstance(caught.value, CalibrationError)


def test_building_a_cloud_rejects_bad_shapes_and_dtypes(types: Any) -> None:
    with pytest.raises(MessageError, match="shape"):
        pointcloud2_from_points(np.zeros((4, 2)), 1, "laser", types=types)
    with pytest.raises(MessageError, match="float32 or float64"):
        pointcloud2_from_points(np.zeros((4, 3)), 1, "laser", types=types, dtype=np.float16)
    with pytest.raises(MessageError, match="intensity has 3 values for 4 points"):
        pointcloud2_from_points(np.zeros((4, 3)), 1, "laser", types=types, intensity=np.ones(3))


def test_stamps_round_trip_and_out_of_range_is_rejected(types: Any) -> None:
    rng = np.random.default_rng(5)
    for stamp_ns in [0, 1, 999_999_999, *rng.integers(0, 2**31 * 10**9, 20).tolist()]:
        msg = time_msg_from_ns(stamp_ns, types)
        assert 0 <= msg.nanosec < 10**9
        assert stamp_ns_from_msg(msg) == stamp_ns
    for bad in (-1, 2**31 * 10**9):
        with pytest.raises(MessageError, match="outside ROS 2 time"):
            time_msg_from_ns(bad, types)


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))


def test_pose_stamped_round_trips_flange_poses(types: Any) -> None:
    rng = np.random.default_rng(6)
    for i in range(20):
        pose = FlangePose(10**9 * i + 7, random_transform(rng), "base_link")
        back = flange_pose_from_pose_stamped(pose_stamped_from_flange_pose(pose, types=types))
        assert (back.stamp_ns, back.frame_id) == (pose.stamp_ns, "base_link")
        np.testing.assert_allclose(back.T_base_flange, pose.T_base_flange, atol=1e-12)


def pose_msg_with_quaternion(types: Any, q_xyzw: list[float]) -> Any:
    msg = pose_stamped_from_flange_pose(FlangePose(3, np.eye(4)), types=types)
    for name, value in zip("xyzw", q_xyzw, strict=True):
        setattr(msg.pose.orientation, name, value)
    return msg


def test_slightly_non_unit_quaternion_is_normalised(types: Any) -> None:
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q_scaled = q / np.linalg.norm(q) * (1.0 + 5e-4)
    pose = flange_pose_from_pose_stamped(pose_msg_with_quaternion(types, q_scaled.tolist()))
    np.testing.assert_allclose(
        pose.T_base_flange[:3, :3], matrix_from_quaternion_xyzw(q / np.linalg.norm(q))
    )
    R = pose.T_base_flange[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)


@pytest.mark.parametrize(
    ("q_xyzw", "expected_text"),
    [
        ([0.0, 0.0, 0.0, 0.0], "zero quaternion"),
        ([float("nan"), 0.0, 0.0, 1.0], "NaN or Inf"),
        ([0.0, 0.0, 0.0, 2.0], "not unit"),
    ],
)
def test_invalid_quaternions_are_rejected_with_the_stamp(
    types: Any, q_xyzw: list[float], expected_text: str
) -> None:
    with pytest.raises(MessageError) as caught:
        flange_pose_from_pose_stamped(pose_msg_with_quaternion(types, q_xyzw))
    assert expected_text in str(caught.value)
    assert "stamp 3 ns" in str(caught.value)


def test_nan_position_is_rejected(types: Any) -> None:
    msg = pose_stamped_from_flange_pose(FlangePose(3, np.eye(4)), types=types)
    msg.pose.position.y = float("nan")
    with pytest.raises(MessageError, match="position contains NaN"):
        flange_pose_from_pose_stamped(msg)


def test_transform_stamped_carries_the_transform(types: Any) -> None:
    T = random_transform(np.random.default_rng(8))
    msg = transform_stamped_from_matrix(T, 42, "tool0", "laser", types=types)
    assert (msg.header.frame_id, msg.child_frame_id, stamp_ns_from_msg(msg.header.stamp)) == (
        "tool0",
        "laser",
        42,
    )
    t = msg.transform.translation
    q = msg.transform.rotation
    np.testing.assert_allclose([t.x, t.y, t.z], T[:3, 3], atol=1e-15)
    np.testing.assert_allclose(
        matrix_from_quaternion_xyzw([q.x, q.y, q.z, q.w]), T[:3, :3], atol=1e-12
    )
    with pytest.raises(MessageError, match="not a proper rotation"):
        transform_stamped_from_matrix(np.diag([1.0, 2.0, 1.0, 1.0]), 0, "a", "b", types=types)


def test_tf_transforms_read_back_with_frames_and_stamp(types: Any) -> None:
    T = random_transform(np.random.default_rng(9))
    msg = transform_stamped_from_matrix(T, 1_700_000_000_000_000_042, "tool0", "laser", types=types)
    read = stamped_transform_from_msg(msg)
    assert (read.stamp_ns, read.parent, read.child) == (1_700_000_000_000_000_042, "tool0", "laser")
    np.testing.assert_allclose(read.T_parent_child, T, atol=1e-12)
    good = transform_stamped_from_matrix(T, 7, "base_link", "tool0", types=types)
    msg.transform.rotation.w = 0.0
    msg.transform.rotation.x = msg.transform.rotation.y = msg.transform.rotation.z = 0.0
    with pytest.raises(MessageError, match="TransformStamped tool0 -> laser at stamp"):
        stamped_transform_from_msg(msg)
    first, bad, last = stamped_transforms_from_msgs([good, msg, good])
    assert isinstance(bad, str) and "zero quaternion" in bad
    for item in (first, last):
        assert not isinstance(item, str)
        assert (item.stamp_ns, item.parent, item.child) == (7, "base_link", "tool0")
        np.testing.assert_allclose(item.T_parent_child, T, atol=1e-12)


def test_cylinder_marker_axis_is_the_local_z(types: Any) -> None:
    rng = np.random.default_rng(9)
    direction = rng.normal(size=3)
    cylinder = Cylinder(rng.normal(size=3), direction / np.linalg.norm(direction), 0.025)
    centre = (
        cylinder.point + 0.3 * cylinder.direction + 0.01 * np.cross(cylinder.direction, [1, 0, 0])
    )
    marker = cylinder_marker(cylinder, 0.2, "base_link", types=types, centre=centre)
    q = marker.pose.orientation
    R = matrix_from_quaternion_xyzw([q.x, q.y, q.z, q.w])
    np.testing.assert_allclose(R[:, 2], cylinder.direction, atol=1e-12)
    p = marker.pose.position
    np.testing.assert_allclose(
        [p.x, p.y, p.z], cylinder.point + 0.3 * cylinder.direction, atol=1e-12
    )
    assert (marker.scale.x, marker.scale.y, marker.scale.z) == (0.05, 0.05, 0.2)
    assert marker.type == 3  # CYLINDER
    with pytest.raises(MessageError, match="radius > 0"):
        cylinder_marker(
            Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.0), 0.1, "b", types=types
        )


def test_points_markers_and_marker_array_serialise(types: Any) -> None:
    points = scan_line(np.random.default_rng(10), 20)
    valid = np.all(np.isfinite(points), axis=1)
    dots = points_marker(points, "laser", types=types, marker_id=1)
    spheres = points_marker(points, "laser", types=types, spheres=True, marker_id=2)
    assert (dots.type, spheres.type) == (8, 7)  # POINTS, SPHERE_LIST
    np.testing.assert_array_equal([[p.x, p.y, p.z] for p in dots.points], points[valid])
    cylinder = Cylinder(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.02)
    array = marker_array(
        [cylinder_marker(cylinder, 0.1, "base_link", types=types), dots, spheres], types=types
    )
    back: Any
    if types is WORLDS["rosbags"]:
        raw = TYPESTORE.serialize_cdr(array, "visualization_msgs/msg/MarkerArray")
        back = TYPESTORE.deserialize_cdr(raw, "visualization_msgs/msg/MarkerArray")
    else:
        from visualization_msgs.msg import MarkerArray

        back = deserialize_message(serialize_message(array), MarkerArray)
    assert [m.id for m in back.markers] == [0, 1, 2]
    assert len(back.markers[1].points) == int(valid.sum())


def test_msg_adapters_import_without_rclpy() -> None:
    # A module set to None in sys.modules raises ImportError when imported.
    code = (
        "import sys\n"
        "for name in ('rclpy', 'sensor_msgs', 'geometry_msgs', 'std_msgs'):\n"
        "    sys.modules[name] = None\n"
        "import msg_adapters\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).parents[1])
