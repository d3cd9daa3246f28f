"""linelaser_calib.io.bags: rosbag2 MCAP round trips, topic detection, damaged bags, sessions."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from linelaser_calib.core.geometry import transform_from_rotvec_translation
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import (
    BagError,
    SessionBagWriter,
    bag_info,
    format_bag_info,
    read_bag,
    write_bag,
)
from linelaser_calib.io.bags import SESSION_FILE, SESSION_MARKER
from msg_adapters import (
    pointcloud2_from_points,
    points_from_pointcloud2,
    pose_stamped_from_flange_pose,
    rosbags_types,
    stamp_ns_from_msg,
)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
TYPES = rosbags_types(TYPESTORE)
CLOUD = "sensor_msgs/msg/PointCloud2"
POSE = "geometry_msgs/msg/PoseStamped"
T0 = 1_700_000_000_000_000_000


def make_profiles(rng: np.random.Generator, n: int) -> list[Profile]:
    """Arcs of a 25 mm cylinder in the sensor x-z plane, 100 points, some NaN/Inf returns."""
    profiles = []
    for i in range(n):
        angle = np.linspace(-1.2, 1.2, 100)
        points = np.column_stack(
            [0.025 * np.sin(angle), np.zeros(100), 0.15 - 0.025 * np.cos(angle)]
        ) + rng.normal(scale=2e-5, size=(100, 3))
        points[rng.choice(100, int(rng.integers(0, 15)), replace=False)] = np.nan
        points[rng.integers(100), 2] = np.inf
        profiles.append(Profile(T0 + i * 50_000_000 + int(rng.integers(0, 1000)), points))
    return profiles


def make_poses(rng: np.random.Generator, n: int) -> list[FlangePose]:
    return [
        FlangePose(
            T0 - 20_000_000 + i * 10_000_000,
            transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3)),
        )
        for i in range(n)
    ]


def expected_points(profile: Profile) -> np.ndarray:
    """What a reader must return: float32-rounded points, invalid rows dropped."""
    points = profile.points.astype(np.float32).astype(np.float64)
    return points[np.all(np.isfinite(points), axis=1)]


@pytest.fixture(scope="module")
def recording() -> tuple[list[Profile], list[FlangePose]]:
    rng = np.random.default_rng(20)
    return make_profiles(rng, 12), make_poses(rng, 70)


def write_raw_bag(path: Path, messages: list[tuple[str, str, int, Any]]) -> None:
    """Write arbitrary (topic, msgtype, log time, rosbags message) records with rosbags."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections: dict[tuple[str, str], Any] = {}
        for topic, msgtype, log_ns, msg in messages:
            if (topic, msgtype) not in connections:
                connections[topic, msgtype] = writer.add_connection(
                    topic, msgtype, typestore=TYPESTORE
                )
            writer.write(connections[topic, msgtype], log_ns, TYPESTORE.serialize_cdr(msg, msgtype))


def cloud(stamp_ns: int, n: int = 20) -> Any:
    return pointcloud2_from_points(np.ones((n, 3)), stamp_ns, "laser", types=TYPES)


def profile_msg(profile: Profile) -> Any:
    return pointcloud2_from_points(profile.points, profile.stamp_ns, "laser", types=TYPES)


def pose(stamp_ns: int) -> Any:
    return pose_stamped_from_flange_pose(FlangePose(stamp_ns, np.eye(4)), types=TYPES)


@pytest.mark.parametrize(
    ("organised", "padding", "with_intensity"), [(True, 0, False), (False, 3, True)]
)
def test_round_trip_profiles_and_poses(
    tmp_path: Path,
    recording: tuple[list[Profile], list[FlangePose]],
    organised: bool,
    padding: int,
    with_intensity: bool,
) -> None:
    profiles, poses = recording
    intensities = (
        [np.arange(len(p.points), dtype=float) for p in profiles] if with_intensity else None
    )
    path = write_bag(
        tmp_path / "bag",
        profiles,
        poses,
        organised=organised,
        intensities=intensities,
        padding_bytes=padding,
    )
    assert sorted(p.name for p in path.iterdir()) == ["bag.mcap", "metadata.yaml"]
    assert [p.name for p in tmp_path.iterdir()] == ["bag"]  # no staging directory left

    contents = read_bag(path)
    assert (contents.profile_topic, contents.pose_topic) == ("/profile", "/flange_pose")
    assert (contents.sensor_frame, contents.base_frame) == ("laser", "base_link")
    assert [p.stamp_ns for p in contents.profiles] == [p.stamp_ns for p in profiles]
    for got, sent in zip(contents.profiles, profiles, strict=True):
        np.testing.assert_array_equal(got.points, expected_points(sent))
    assert [p.stamp_ns for p in contents.poses] == [p.stamp_ns for p in poses]
    for got_pose, sent_pose in zip(contents.poses, poses, strict=True):
        np.testing.assert_allclose(got_pose.T_base_flange, sent_pose.T_base_flange, atol=1e-14)
    assert [(t.topic, t.msgtype, t.msgcount) for t in contents.topics] == [
        ("/flange_pose", POSE, 70),
        ("/profile", CLOUD, 12),
    ]
    assert contents.start_ns == poses[0].stamp_ns
    assert contents.end_ns == poses[-1].stamp_ns
    assert contents.skipped == []


def test_mcap_library_decodes_the_bag_in_time_order(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    profiles, poses = recording
    path = write_bag(tmp_path / "bag", profiles, poses, profile_topic="/scan", pose_topic="/tcp")
    with (path / "bag.mcap").open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = list(reader.iter_decoded_messages(log_time_order=False))
    log_times = [message.log_time for _, _, message, _ in decoded]
    assert log_times == sorted(log_times)
    counts: dict[tuple[str, str], int] = {}
    clouds = []
    for schema, channel, message, msg in decoded:
        assert schema is not None
        counts[channel.topic, schema.name] = counts.get((channel.topic, schema.name), 0) + 1
        assert message.log_time == stamp_ns_from_msg(msg.header.stamp)
        if schema.name == CLOUD:
            clouds.append(points_from_pointcloud2(msg))
    assert counts == {("/scan", CLOUD): 12, ("/tcp", POSE): 70}
    for got, sent in zip(clouds, profiles, strict=True):
        np.testing.assert_array_equal(got, expected_points(sent))


def test_reading_the_mcap_file_directly_works(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    profiles, poses = recording
    path = write_bag(tmp_path / "bag", profiles, poses)
    assert len(read_bag(path / "bag.mcap").profiles) == len(profiles)


def test_existing_path_is_never_overwritten(tmp_path: Path) -> None:
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "keep.txt").write_text("mine")
    with pytest.raises(BagError, match=r"exists already.*choose a new output path"):
        write_bag(tmp_path / "bag", [], [])
    assert [p.name for p in (tmp_path / "bag").iterdir()] == ["keep.txt"]


def test_failed_write_leaves_nothing_behind(tmp_path: Path) -> None:
    bad = [Profile(-5, np.zeros((3, 3)))]  # a negative stamp cannot be a ROS time
    with pytest.raises(ValueError, match="outside ROS 2 time"):
        write_bag(tmp_path / "bag", bad, [])
    assert list(tmp_path.iterdir()) == []


def test_two_cloud_topics_are_ambiguous_until_one_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_raw_bag(
        path,
        [
            ("/flange_pose", POSE, 1, pose(1)),
            ("/left/profile", CLOUD, 2, cloud(2)),
            ("/right/profile", CLOUD, 3, cloud(3, 7)),
        ],
    )
    with pytest.raises(BagError) as caught:
        read_bag(path)
    text = str(caught.value)
    assert "several sensor_msgs/msg/PointCloud2 topics" in text
    assert "/left/profile" in text and "/right/profile" in text and "--profile-topic" in text
    contents = read_bag(path, profile_topic="/right/profile")
    assert [len(p.points) for p in contents.profiles] == [7]
    info = bag_info(path)
    assert info.contents is None and "several" in str(info.problem)
    assert "/right/profile" in format_bag_info(info)


def test_named_topics_must_exist_and_have_the_right_type(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    path = write_bag(tmp_path / "bag", *recording)
    with pytest.raises(BagError, match=r"has type geometry_msgs/msg/PoseStamped, expected sensor"):
        read_bag(path, profile_topic="/flange_pose")
    with pytest.raises(BagError, match=r"no topic '/nope'.*/flange_pose.*/profile"):
        read_bag(path, pose_topic="/nope")


def test_bag_without_poses_says_so(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_raw_bag(path, [("/profile", CLOUD, 1, cloud(1))])
    with pytest.raises(BagError, match="holds no geometry_msgs/msg/PoseStamped messages"):
        read_bag(path)


@pytest.mark.parametrize(
    "case", ["missing", "empty_dir", "dir_of_bags", "no_metadata", "yaml_file", "empty_bag"]
)
def test_unusable_paths_raise_bag_error(tmp_path: Path, case: str) -> None:
    path = tmp_path / "thing"
    expected = {
        "missing": "does not exist",
        "empty_dir": "not a rosbag2 bag",
        "dir_of_bags": r"contains the bags \['a'\]: pass one of them",
        "no_metadata": r"holds \['thing.mcap'\].*ros2 bag reindex",
        "yaml_file": "not a rosbag2 bag",
        "empty_bag": "is empty",
    }[case]
    if case == "empty_dir":
        path.mkdir()
    elif case == "dir_of_bags":
        write_bag(path / "a", [], [])
    elif case == "no_metadata":
        write_bag(path, [], [])
        (path / "metadata.yaml").unlink()
    elif case == "yaml_file":
        path = tmp_path / "result.yaml"
        path.write_text("a: 1\n")
    elif case == "empty_bag":
        write_bag(path, [], [])
    with pytest.raises(BagError, match=expected):
        read_bag(path)


def test_truncated_mcap_files_raise_bag_error(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    path = write_bag(tmp_path / "bag", *recording)
    mcap = path / "bag.mcap"
    data = mcap.read_bytes()
    rng = np.random.default_rng(21)
    for cut in [0, 5, len(data) - 1, *rng.integers(8, len(data) - 1, 6).tolist()]:
        mcap.write_bytes(data[:cut])
        with pytest.raises(BagError, match="truncated or corrupt"):
            read_bag(path)


def test_corrupt_bytes_never_escape_as_tracebacks(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    profiles, poses = recording
    path = write_bag(tmp_path / "bag", profiles, poses)
    mcap = path / "bag.mcap"
    data = mcap.read_bytes()
    rng = np.random.default_rng(22)
    outcomes = set()
    for _ in range(25):
        damaged = bytearray(data)
        for position in rng.integers(0, len(data), 4):
            damaged[position] = int(rng.integers(0, 256))
        mcap.write_bytes(bytes(damaged))
        try:
            contents = read_bag(path)
        except BagError:
            outcomes.add("error")
        else:
            outcomes.add("read")
            assert len(contents.profiles) + len(contents.skipped) <= len(profiles) + len(poses)
    assert "error" in outcomes


def test_corrupt_metadata_raises_bag_error(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    path = write_bag(tmp_path / "bag", *recording)
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(BagError, match="cannot read bag"):
        read_bag(path)


@pytest.mark.parametrize(
    ("compression", "index_types"),
    [
        (CompressionType.NONE, IndexType.ALL),
        (CompressionType.LZ4, IndexType.ALL),
        (CompressionType.ZSTD, IndexType.ALL),
        (CompressionType.ZSTD, IndexType.NONE),
    ],
)
def test_reading_through_the_mcap_indexes_equals_the_rosbags_reading(
    tmp_path: Path,
    recording: tuple[list[Profile], list[FlangePose]],
    compression: CompressionType,
    index_types: IndexType,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An MCAP file of many small chunks, as the mcap library writes it (rosbag2 uses the
    same library's C++ twin), with a malformed profile and pose: read through its indexes
    (where it has them) and message by message by rosbags, the same contents."""
    from linelaser_calib.io.bags import read as read_module
    from linelaser_calib.io.bags.indexed import indexed_topics

    profiles, poses = recording
    broken_cloud = cloud(poses[3].stamp_ns + 1)
    broken_cloud.row_step = 5
    zero_quaternion = pose(poses[5].stamp_ns + 1)
    zero_quaternion.pose.orientation.w = 0.0
    messages = [
        *(("/profile", CLOUD, p.stamp_ns, profile_msg(p)) for p in profiles),
        *(("/flange_pose", POSE, p.stamp_ns, pose(p.stamp_ns)) for p in poses),
        ("/profile", CLOUD, poses[3].stamp_ns + 1, broken_cloud),
        ("/flange_pose", POSE, poses[5].stamp_ns + 1, zero_quaternion),
    ]
    path = tmp_path / "bag.mcap"
    with path.open("wb") as stream:
        writer = McapWriter(
            stream, chunk_size=2048, compression=compression, index_types=index_types
        )
        writer.start(profile="ros2", library="test")
        channels = {}
        for topic, msgtype in (("/profile", CLOUD), ("/flange_pose", POSE)):
            text = TYPESTORE.generate_msgdef(msgtype)[0].encode()
            schema = writer.register_schema(msgtype, "ros2msg", text)
            channels[topic] = writer.register_channel(topic, "cdr", schema)
        for topic, msgtype, log_ns, msg in sorted(messages, key=lambda m: m[2]):
            data = bytes(TYPESTORE.serialize_cdr(msg, msgtype))
            writer.add_message(channels[topic], log_ns, data, log_ns)
        writer.finish()
    with Reader(path) as reader:
        used = indexed_topics(path, reader.connections) is not None
    assert used == (index_types is IndexType.ALL)
    fast = read_bag(path)
    monkeypatch.setattr(read_module, "indexed_topics", lambda part, connections: None)
    plain = read_bag(path)
    assert [p.stamp_ns for p in fast.profiles] == [p.stamp_ns for p in plain.profiles]
    for a, b in zip(fast.profiles, plain.profiles, strict=True):
        np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(fast.poses.stamps_ns, plain.poses.stamps_ns)
    np.testing.assert_array_equal(fast.poses.translation, plain.poses.translation)
    np.testing.assert_array_equal(fast.poses.rotation_xyzw, plain.poses.rotation_xyzw)
    assert fast.skipped == plain.skipped and len(fast.skipped) == 2
    assert len(fast.profiles) == len(profiles) and len(fast.poses) == len(poses)


def test_malformed_messages_are_skipped_not_fatal(tmp_path: Path) -> None:
    broken_cloud = cloud(2_000)
    broken_cloud.row_step = 5
    zero_quaternion = pose(3_000)
    zero_quaternion.pose.orientation.w = 0.0
    path = tmp_path / "bag"
    write_raw_bag(
        path,
        [
            ("/flange_pose", POSE, 1_000, pose(1_000)),
            ("/profile", CLOUD, 1_500, cloud(1_500)),
            ("/profile", CLOUD, 2_000, broken_cloud),
            ("/flange_pose", POSE, 3_000, zero_quaternion),
            ("/flange_pose", POSE, 4_000, pose(4_000)),
        ],
    )
    contents = read_bag(path)
    assert [p.stamp_ns for p in contents.profiles] == [1_500]
    assert [p.stamp_ns for p in contents.poses] == [1_000, 4_000]
    assert [(s.topic, s.stamp_ns) for s in contents.skipped] == [
        ("/profile", 2_000),
        ("/flange_pose", 3_000),
    ]
    assert "row_step 5 B is inconsistent" in contents.skipped[0].reason
    assert "zero quaternion" in contents.skipped[1].reason


def test_no_readable_profile_at_all_is_an_error(tmp_path: Path) -> None:
    broken = cloud(2)
    broken.row_step = 5
    path = tmp_path / "bag"
    write_raw_bag(path, [("/flange_pose", POSE, 1, pose(1)), ("/profile", CLOUD, 2, broken)])
    with pytest.raises(BagError, match=r"no readable profile on /profile \(1 skipped"):
        read_bag(path)


def test_progress_reports_every_profile_and_ends_at_the_total(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    """Each profile counts on its own, the flange poses a batch at a time."""
    profiles, poses = recording
    path = write_bag(tmp_path / "bag", profiles, poses)
    calls: list[tuple[int, int]] = []
    read_bag(path, progress=lambda done, total: calls.append((done, total)))
    done = [d for d, _ in calls]
    assert {t for _, t in calls} == {len(profiles) + len(poses)}
    assert done == sorted(set(done)) and done[-1] == len(profiles) + len(poses)
    assert len(calls) >= len(profiles)


def test_bag_info_reports_counts_and_points_per_profile(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    profiles, poses = recording
    path = write_bag(tmp_path / "bag", profiles, poses)
    info = bag_info(path)
    sizes = [len(expected_points(p)) for p in profiles]
    assert info.points_per_profile == (min(sizes), float(np.median(sizes)), max(sizes))
    assert info.contents is not None and len(info.contents.poses) == len(poses)
    assert (info.start_ns, info.end_ns) == (poses[0].stamp_ns, poses[-1].stamp_ns)
    text = format_bag_info(info)
    duration_s = (poses[-1].stamp_ns - poses[0].stamp_ns) / 1e9
    assert f"duration {duration_s:.3f} s" in text
    assert "profiles: 12 on /profile (frame laser)" in text
    assert f"min {min(sizes)}" in text and f"max {max(sizes)}" in text
    assert "flange poses: 70 on /flange_pose (frame base_link)" in text


def test_session_samples_are_readable_once_flushed_while_the_writer_is_open(
    tmp_path: Path, recording: tuple[list[Profile], list[FlangePose]]
) -> None:
    profiles, poses = recording
    session = SessionBagWriter(tmp_path / "session")
    for i, profile in enumerate(profiles[:5]):
        pose_at_profile = FlangePose(profile.stamp_ns + 123, poses[i].T_base_flange, "world")
        assert session.append(profile, pose_at_profile) == i
        session.flush()
        assert session.durable == i + 1
        contents = read_bag(tmp_path / "session")  # durable before close
        assert len(contents.profiles) == len(contents.poses) == i + 1
    assert [p.stamp_ns for p in contents.poses] == [p.stamp_ns for p in contents.profiles]
    assert contents.base_frame == "world"
    for got, sent in zip(contents.profiles, profiles[:5], strict=True):
        np.testing.assert_array_equal(got.points, expected_points(sent))
    session.close()
    # Closed: a plain MCAP file with its summary, which rosbags (and ros2 bag) read too.
    assert len(read_bag(tmp_path / "session" / SESSION_FILE).profiles) == 5
    reader = Reader(tmp_path / "session" / SESSION_FILE)
    reader.open()
    assert sorted((c.topic, c.msgcount) for c in reader.connections) == [
        ("/flange_pose", 5),
        ("/profile", 5),
    ]
    reader.close()
    with pytest.raises(BagError, match="is closed"):
        session.append(profiles[5], poses[5])
    with pytest.raises(BagError, match="exists already"):
        SessionBagWriter(tmp_path / "session")


def test_session_survives_sigkill_keeping_every_flushed_sample(tmp_path: Path) -> None:
    # The child appends samples and flushes after each third, printing how many are on disk,
    # until it is killed (SIGKILL: no clean-up at all, maybe in the middle of a write).
    code = f"""
import numpy as np
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import SessionBagWriter
session = SessionBagWriter({str(tmp_path / "session")!r}, organised=False)
points = np.random.default_rng(0).normal(size=(2048, 3))
for i in range(10**6):
    session.append(Profile(10**9 + i, points), FlangePose(10**9 + i, np.eye(4)))
    if i % 3 == 2:
        session.flush()
        print(session.durable, flush=True)
"""
    child = subprocess.Popen(
        [sys.executable, "-c", code],
        cwd=Path(__file__).parents[1],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    durable = 0
    while durable < 300:
        durable = int(child.stdout.readline())
    os.kill(child.pid, signal.SIGKILL)
    child.wait(10.0)
    contents = read_bag(tmp_path / "session")
    stamps = [p.stamp_ns for p in contents.profiles]
    assert len(stamps) >= durable  # every flushed sample, perhaps a few more
    assert stamps == [10**9 + i for i in range(len(stamps))]
    assert len(contents.poses) in (len(stamps), len(stamps) + 1) and contents.skipped == []


def test_session_with_a_torn_last_record_keeps_every_complete_sample(tmp_path: Path) -> None:
    session = SessionBagWriter(tmp_path / "session")
    for i in range(4):
        session.append(Profile(10**9 + i, np.ones((10, 3))), FlangePose(10**9 + i, np.eye(4)))
    session.flush()
    file = tmp_path / "session" / SESSION_FILE
    data = file.read_bytes()
    file.write_bytes(data[:-7])  # the last profile's record cut short, as a crash leaves it
    contents = read_bag(tmp_path / "session")
    assert [p.stamp_ns for p in contents.profiles] == [10**9, 10**9 + 1, 10**9 + 2]
    assert len(contents.poses) == 4


def test_empty_session_says_so(tmp_path: Path) -> None:
    SessionBagWriter(tmp_path / "session").close()
    with pytest.raises(BagError, match="holds no samples yet"):
        read_bag(tmp_path / "session")


def test_session_of_one_bag_per_sample_from_earlier_versions_still_reads(tmp_path: Path) -> None:
    session = tmp_path / "session"
    session.mkdir()
    (session / SESSION_MARKER).write_text("linelaser_calib sample session\n", encoding="utf-8")
    for i in range(3):
        stamp = 10**9 + i
        write_bag(
            session / f"sample_{i:06d}",
            [Profile(stamp, np.ones((10, 3)))],
            [FlangePose(stamp, np.eye(4))],
        )
    contents = read_bag(session)
    assert [p.stamp_ns for p in contents.profiles] == [10**9, 10**9 + 1, 10**9 + 2]
    assert [p.stamp_ns for p in contents.poses] == [10**9, 10**9 + 1, 10**9 + 2]


def test_fast_pointcloud2_decoding_equals_rosbags() -> None:
    """The hand-written PointCloud2 reader against rosbags' deserialiser, over layouts
    (organised or dense, padding, intensity, float64, big-endian data, empty frame ids);
    bytes cut short are left to the generic decoder, never a crash."""
    from linelaser_calib.io.bags.cdr import pointcloud2_from_cdr

    rng = np.random.default_rng(23)
    for k in range(60):
        n = int(rng.integers(0, 30))
        points = rng.normal(size=(n, 3))
        points[rng.random(n) < 0.2] = np.nan
        msg = pointcloud2_from_points(
            points,
            int(rng.integers(0, 2**60)),
            "f" * int(rng.integers(0, 9)),
            types=TYPES,
            intensity=rng.normal(size=n) if k % 2 else None,
            organised=bool(k % 3),
            padding_bytes=int(rng.integers(0, 5)),
            dtype=np.float64 if k % 5 == 0 else np.float32,
            is_bigendian=k % 7 == 0,
        )
        raw = np.frombuffer(bytes(TYPESTORE.serialize_cdr(msg, CLOUD)), dtype=np.uint8)
        fast = pointcloud2_from_cdr(raw)
        assert fast is not None
        assert stamp_ns_from_msg(fast.header.stamp) == stamp_ns_from_msg(msg.header.stamp)
        assert fast.header.frame_id == msg.header.frame_id
        for name in ("height", "width", "is_bigendian", "point_step", "row_step", "is_dense"):
            assert getattr(fast, name) == getattr(msg, name)
        assert [(f.name, f.offset, f.datatype, f.count) for f in fast.fields] == [
            (f.name, f.offset, f.datatype, f.count) for f in msg.fields
        ]
        np.testing.assert_array_equal(fast.data, msg.data)
        assert all(pointcloud2_from_cdr(raw[:cut]) is None for cut in range(0, len(raw), 5))


def test_fast_pose_decoding_equals_the_message_adapter() -> None:
    """The batch PoseStamped parser against rosbags + flange_pose_from_pose_stamped."""
    from rosbags.typesys import Stores, get_typestore

    from linelaser_calib.io.bags import SkippedMessage
    from linelaser_calib.io.bags.cdr import flange_poses
    from linelaser_calib.io.bags.records import RawMessages
    from msg_adapters import flange_pose_from_pose_stamped

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    rng = np.random.default_rng(17)
    frames = ["base_link", "b", "world_ünïcode", "x" * 13, "robot/base", ""]
    raws: list[bytes] = []
    for k in range(120):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        if k % 17 == 3:
            q = np.zeros(4)  # zero quaternion: rejected by both
        if k % 19 == 5:
            q = q * 1.0004  # slightly non-unit: normalised by both
        position = rng.normal(size=3)
        if k % 23 == 7:
            position[1] = np.nan
        msg = types["geometry_msgs/msg/PoseStamped"](
            header=types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](
                    sec=int(rng.integers(0, 2**31 - 1)), nanosec=int(rng.integers(0, 10**9))
                ),
                frame_id=frames[k % len(frames)],
            ),
            pose=types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](*position),
                orientation=types["geometry_msgs/msg/Quaternion"](*q),
            ),
        )
        raw = bytes(store.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped"))
        if k % 29 == 11:
            raw = raw[:-5]  # truncated
        if k % 31 == 13:
            raw = raw + b"\0" * 8  # trailing bytes: left to the generic decoder
        raws.append(raw)
    track, lost = flange_poses("/pose", RawMessages.of(raws, range(len(raws))))
    expected_poses = []
    for raw in raws:
        try:
            expected_poses.append(
                flange_pose_from_pose_stamped(
                    store.deserialize_cdr(raw, "geometry_msgs/msg/PoseStamped")
                )
            )
        except Exception:  # MessageError, or undecodable bytes
            continue
    skipped = len(lost)
    assert len(track) + skipped == len(raws)
    assert all(isinstance(s, SkippedMessage) for s in lost)
    assert track.frame_id == expected_poses[0].frame_id
    assert track.stamps_ns.tolist() == [p.stamp_ns for p in expected_poses]
    np.testing.assert_allclose(
        track.transforms(), [p.T_base_flange for p in expected_poses], atol=1e-12
    )
    assert skipped >= 10


def test_sqlite3_bags_read_like_mcap_bags(tmp_path: Path) -> None:
    """rosbag2's other storage (SQLite3, the default before Iron) gives the same contents."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    bags = Path(__file__).resolve().parent.parent / "bags"
    source, target = bags / "ur_scancontrol", tmp_path / "sqlite_bag"
    store = get_typestore(Stores.ROS2_JAZZY)
    with (
        Reader(source) as reader,
        Writer(target, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer,
    ):
        connections = {
            c.id: writer.add_connection(c.topic, c.msgtype, typestore=store)
            for c in reader.connections
        }
        for connection, stamp, raw in reader.messages():
            writer.write(connections[connection.id], stamp, raw)
    mcap, sqlite = read_bag(source), read_bag(target)
    assert len(sqlite.profiles) == len(mcap.profiles) and len(sqlite.poses) == len(mcap.poses)
    for a, b in zip(mcap.profiles, sqlite.profiles, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.points, b.points)
