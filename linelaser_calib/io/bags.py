"""rosbag2 (MCAP) recordings of profiles and flange poses: write, read, summarise, append.

A recording holds ``sensor_msgs/msg/PointCloud2`` profiles in the sensor frame and
``geometry_msgs/msg/PoseStamped`` flange poses in the base frame. Bags are written with
rosbags as rosbag2 version 9 MCAP directories (``metadata.yaml`` + ``<name>.mcap``), with each
message logged at its header stamp. Reading uses rosbags' rosbag2 ``Reader`` (MCAP or
SQLite 3 storage) and decodes with the Jazzy typestore: the definitions of PointCloud2 and
PoseStamped (and of Header, Time, PointField, Pose) are the same in every ROS 2
distribution, so this decodes bags recorded with any of them, without parsing each bag's
stored definitions (which costs ~15 ms per bag, too much for a session of many small bags).

Durability. rosbags buffers messages in memory (MCAP chunks of about 1 MiB) and writes the
chunk index, the summary and ``metadata.yaml`` only on close; its reader needs all of them.
So a rosbag2 bag is readable only once closed. :func:`write_bag` therefore writes into a
hidden temporary directory and renames it into place when complete: a crash leaves no
half-written bag under the requested name. :class:`SessionBagWriter`, for live collection,
appends the samples (each a profile and its flange pose) to one MCAP file of unchunked
records, flushed and fsynced on request, which this module reads record by record up to a
torn tail; a crash loses only what was not flushed yet. :func:`read_bag` reads a session
directory like a single bag (also a session of one bag per sample, written by earlier
versions).

Topics are auto-detected by type when exactly one topic of each type holds messages.
Every user-caused failure (missing, empty, truncated or corrupt bag, missing or ambiguous
topics, wrong types) raises :class:`~linelaser_calib.io.errors.BagError` saying what to do;
a single malformed message is skipped and reported in :attr:`BagContents.skipped`.
"""

from __future__ import annotations

import datetime
import functools
import os
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from io import BufferedWriter, BytesIO
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel as McapChannel
from mcap.records import Message as McapMessage
from mcap.records import Schema as McapSchema
from mcap.well_known import MessageEncoding, SchemaEncoding
from numpy.typing import NDArray
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import QUATERNION_NORM_TOLERANCE, matrices_from_quaternions_xyzw
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.tf import StampedTransform
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io.errors import BagError
from msg_adapters import (
    MessageError,
    cloud_from_pointcloud2,
    flange_pose_from_pose_stamped,
    joint_state_from_msg,
    joint_state_msg,
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    profile_from_pointcloud2,
    rosbags_types,
    stamp_ns_from_msg,
    transform_stamped_from_matrix,
)
from msg_adapters.message_types import NS_PER_S

PROFILE_TYPE = "sensor_msgs/msg/PointCloud2"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
#: The joint-state topic of a session (and the default one read from any bag).
JOINT_STATE_TOPIC = "/joint_states"
#: File in a session directory that marks it as one (see :class:`SessionBagWriter`).
SESSION_MARKER = "linelaser_calib_session.txt"
#: The MCAP file of a session's samples (see :class:`SessionBagWriter`).
SESSION_FILE = "session.mcap"
SAMPLE_PREFIX = "sample_"

#: The first bytes of every MCAP file.
MCAP_MAGIC = b"\x89MCAP0\r\n"

#: Called as ``progress(done, total)`` while messages are decoded.
Progress = Callable[[int, int], None]


class TopicSummary(NamedTuple):
    """One topic of a bag: name, message type and message count."""

    topic: str
    msgtype: str
    msgcount: int


class SkippedMessage(NamedTuple):
    """A message that could not be used: topic, stamp (header, else log time) ns, reason."""

    topic: str
    stamp_ns: int
    reason: str


@dataclass(frozen=True)
class BagContents:
    """Profiles and flange poses read from a bag, sorted by stamp.

    Attributes
    ----------
    path : Path
        The bag (or session) directory or MCAP file read.
    profiles : list of Profile
        Points (N, 3) in m with invalid (NaN/Inf) points dropped.
    poses : list of FlangePose
    profile_topic, pose_topic : str
        Topics the profiles and poses came from.
    sensor_frame, base_frame : str
        Header frame ids of the first profile and the first pose.
    topics : list of TopicSummary
        Every topic of the bag, sorted by name.
    start_ns, end_ns : int
        Log times of the first and last message of the bag, ns.
    skipped : list of SkippedMessage
        Messages on the two topics that were malformed or undecodable.
    """

    path: Path
    profiles: list[Profile]
    poses: list[FlangePose]
    profile_topic: str
    pose_topic: str
    sensor_frame: str
    base_frame: str
    topics: list[TopicSummary]
    start_ns: int
    end_ns: int
    skipped: list[SkippedMessage]


class PointCount(NamedTuple):
    """Valid points per profile: minimum, median and maximum over the profiles."""

    min: int
    median: float
    max: int


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds, for ``linelaser-calib info``.

    Attributes
    ----------
    path : Path
    topics : list of TopicSummary
    start_ns, end_ns : int or None
        Log times of the first and last message, ns; None for an empty bag.
    contents : BagContents or None
        The decoded profiles and poses; None when they could not be read (see ``problem``).
    problem : str or None
        Why the profiles and poses could not be read (e.g. ambiguous topics).
    points_per_profile : PointCount or None
        Valid points per profile; None without profiles.
    """

    path: Path
    topics: list[TopicSummary]
    start_ns: int | None
    end_ns: int | None
    contents: BagContents | None
    problem: str | None
    points_per_profile: PointCount | None


@functools.cache
def jazzy_typestore() -> Typestore:
    """The ROS 2 Jazzy typestore that serialises every message written."""
    return get_typestore(Stores.ROS2_JAZZY)


@functools.cache
def _store_from_definitions(definitions: tuple[tuple[str, str], ...]) -> Typestore:
    """A typestore of just the given (type, ``.msg`` definition) pairs and their fields."""
    store = get_typestore(Stores.EMPTY)
    for msgtype, text in definitions:
        store.register(get_types_from_msg(text, msgtype))
    return store


def reading_store(connections: Sequence[Connection | SessionConnection]) -> Typestore:
    """The typestore that decodes the messages of ``connections``.

    Built from the message definitions the recording carries (rosbag2 >= 8, MCAP) when each
    connection has one in ``.msg`` form: ~30 ms, against ~0.25 s for every type of Jazzy
    (:func:`jazzy_typestore`, the fallback), which would be most of a calibration's start-up.
    """
    definitions = set()
    for connection in connections:
        msgdef = getattr(connection, "msgdef", None)  # session files carry no definitions
        if msgdef is None or msgdef.format != MessageDefinitionFormat.MSG or not msgdef.data:
            return jazzy_typestore()
        definitions.add((connection.msgtype, msgdef.data))
    try:
        return _store_from_definitions(tuple(sorted(definitions)))
    except TypesysError:  # a definition rosbags cannot parse, or two that disagree
        return jazzy_typestore()


def _fsync_tree(directory: Path) -> None:
    """Flush every file in ``directory`` and the directory entry itself to disk."""
    for path in directory.iterdir():
        if path.is_file():
            with path.open("rb") as stream:
                os.fsync(stream.fileno())
    fsync_directory(directory)


def fsync_directory(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class _ProfilePoseWriter:
    """A rosbags MCAP writer with one profile and one pose connection."""

    def __init__(self, writer: Writer, profile_topic: str, pose_topic: str) -> None:
        store = jazzy_typestore()
        self._writer = writer
        self._types = rosbags_types(store)
        self._profiles = writer.add_connection(profile_topic, PROFILE_TYPE, typestore=store)
        self._poses = writer.add_connection(pose_topic, POSE_TYPE, typestore=store)
        self._joint_states: dict[str, Any] = {}
        self._tf: dict[str, Any] = {}

    def write_transforms(
        self, topic: str, stamp_ns: int, transforms: Sequence[StampedTransform]
    ) -> None:
        """One ``tf2_msgs/msg/TFMessage`` holding ``transforms`` on ``topic``."""
        store = jazzy_typestore()
        if topic not in self._tf:
            self._tf[topic] = self._writer.add_connection(topic, TF_TYPE, typestore=store)
        msg = self._types(TF_TYPE)(
            transforms=[
                transform_stamped_from_matrix(
                    t.T_parent_child, t.stamp_ns, t.parent, t.child, types=self._types
                )
                for t in transforms
            ]
        )
        self._writer.write(self._tf[topic], stamp_ns, store.serialize_cdr(msg, TF_TYPE))

    def write_profile(
        self,
        stamp_ns: int,
        points: NDArray[np.float64],
        frame_id: str,
        *,
        intensity: NDArray[np.float64] | None,
        organised: bool,
        padding_bytes: int,
    ) -> None:
        msg = pointcloud2_from_points(
            points,
            stamp_ns,
            frame_id,
            types=self._types,
            intensity=intensity,
            organised=organised,
            padding_bytes=padding_bytes,
        )
        self._writer.write(
            self._profiles, stamp_ns, jazzy_typestore().serialize_cdr(msg, PROFILE_TYPE)
        )

    def write_pose(self, pose: FlangePose) -> None:
        msg = pose_stamped_from_flange_pose(pose, types=self._types)
        self._writer.write(
            self._poses, pose.stamp_ns, jazzy_typestore().serialize_cdr(msg, POSE_TYPE)
        )

    def write_joint_state(
        self, topic: str, stamp_ns: int, names: Sequence[str], positions: NDArray[np.float64]
    ) -> None:
        store = jazzy_typestore()
        if topic not in self._joint_states:
            self._joint_states[topic] = self._writer.add_connection(
                topic, JOINT_STATE_TYPE, typestore=store
            )
        msg = joint_state_msg(stamp_ns, names, positions, types=self._types)
        self._writer.write(
            self._joint_states[topic], stamp_ns, store.serialize_cdr(msg, JOINT_STATE_TYPE)
        )


@contextmanager
def _new_bag(path: Path, profile_topic: str, pose_topic: str) -> Iterator[_ProfilePoseWriter]:
    """Write a bag at ``path`` that appears there only once complete and on disk.

    The bag is written as ``<tmp>/<name>`` in a hidden temporary directory next to ``path``
    (so the MCAP file keeps the name ``<name>.mcap``), flushed, then renamed to ``path``.
    On any error the temporary directory is removed and nothing appears at ``path``.
    """
    if path.exists():
        raise BagError(
            f"{path} exists already and bags are never overwritten; "
            "choose a new output path or delete the old bag"
        )
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(
            tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
        )
    except OSError as err:
        raise BagError(f"cannot create bag {path}: {err}") from err
    try:
        with Writer(staging / path.name, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            yield _ProfilePoseWriter(writer, profile_topic, pose_topic)
        _fsync_tree(staging / path.name)
        (staging / path.name).rename(path)
        fsync_directory(path.parent)
    except OSError as err:
        raise BagError(f"cannot write bag {path}: {err}") from err
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_bag(
    path: str | Path,
    profiles: Sequence[Profile],
    poses: Sequence[FlangePose],
    *,
    profile_topic: str = "/profile",
    pose_topic: str = "/flange_pose",
    sensor_frame: str = "laser",
    base_frame: str = "base_link",
    organised: bool = True,
    intensities: Sequence[NDArray[np.float64] | None] | None = None,
    padding_bytes: int = 0,
    joint_states: JointStates | None = None,
    joint_state_topic: str = "/joint_states",
    tf: Sequence[StampedTransform] = (),
    tf_static: Sequence[StampedTransform] = (),
) -> Path:
    """Write profiles and flange poses to a new rosbag2 MCAP bag, in stamp order.

    Parameters
    ----------
    path : str or Path
        Bag directory to create; it must not exist.
    profiles : sequence of Profile
        Points (N, 3) in m, NaN/Inf rows are invalid returns.
    poses : sequence of FlangePose
    profile_topic, pose_topic : str
    sensor_frame, base_frame : str
        Header frame ids of every profile and every pose (the records' own ``frame_id`` is
        not used).
    organised : bool
        Organised clouds (height 1, invalid rows kept) or dense ones (invalid rows dropped).
    intensities : sequence of (ndarray (N,) or None), optional
        Per-profile intensity field (float32 in the message).
    padding_bytes : int
        Unused bytes per point, as some drivers send.
    tf, tf_static : sequence of StampedTransform
        Transforms for ``/tf`` (one ``TFMessage`` per stamp, as robot_state_publisher
        sends) and ``/tf_static`` (one message, logged with the first message of the bag).
    joint_states : JointStates, optional
        Joint states to write as ``sensor_msgs/msg/JointState`` on ``joint_state_topic``.
    joint_state_topic : str

    Returns
    -------
    Path
        The bag directory.

    Raises
    ------
    BagError
        If ``path`` exists or cannot be written.
    InputError
        If ``intensities`` does not match ``profiles``.
    """
    path = Path(path)
    if intensities is None:
        intensities = [None] * len(profiles)
    if len(intensities) != len(profiles):
        raise InputError(f"{len(intensities)} intensity arrays given for {len(profiles)} profiles")
    tf_by_stamp: dict[int, list[StampedTransform]] = {}
    for transform in tf:
        tf_by_stamp.setdefault(transform.stamp_ns, []).append(transform)
    joints = [] if joint_states is None else list(enumerate(joint_states.stamps_ns))
    events = sorted(
        [(pose.stamp_ns, 0, i) for i, pose in enumerate(poses)]
        + [(profile.stamp_ns, 1, i) for i, profile in enumerate(profiles)]
        + [(stamp, 2, 0) for stamp in tf_by_stamp]
        + [(int(stamp), 3, i) for i, stamp in joints]
    )
    with _new_bag(path, profile_topic, pose_topic) as bag:
        if tf_static and events:
            bag.write_transforms(TF_STATIC_TOPIC, events[0][0], tf_static)
        for stamp, kind, i in events:
            if kind == 2:
                bag.write_transforms(TF_TOPIC, stamp, tf_by_stamp[stamp])
            elif kind == 3 and joint_states is not None:
                bag.write_joint_state(
                    joint_state_topic, stamp, joint_states.names, joint_states.positions[i]
                )
            elif kind == 0:
                pose = poses[i]
                bag.write_pose(FlangePose(pose.stamp_ns, pose.T_base_flange, base_frame))
            else:
                intensity = intensities[i]
                bag.write_profile(
                    profiles[i].stamp_ns,
                    profiles[i].points,
                    sensor_frame,
                    intensity=None if intensity is None else np.asarray(intensity),
                    organised=organised,
                    padding_bytes=padding_bytes,
                )
    return path


class SessionBagWriter:
    """Persist samples as they arrive during live collection, in one MCAP file per session.

    The session is a directory holding a marker file and ``session.mcap``: a ``ros2`` profile
    MCAP file (``ros2msg`` schemas, CDR messages, as rosbag2 writes them) with a flange pose
    and a profile per sample, both stamped with the profile stamp. Records are written
    unchunked, so every :meth:`flush` ends on a record boundary: :meth:`append` only buffers,
    and :meth:`flush` writes, flushes and fsyncs what was appended, after which those samples
    survive a crash (the collector flushes at a bounded interval). A crash leaves the file
    without its summary and footer, and perhaps a torn last record; :func:`read_bag` reads
    every complete sample of such a file. :meth:`close` writes the summary and footer, after
    which any MCAP reader opens the file. :func:`read_bag` and :func:`bag_info` read the
    session directory (or its ``session.mcap``) as one bag.

    Parameters
    ----------
    path : str or Path
        Session directory to create; it must not exist.
    profile_topic, pose_topic : str
    organised : bool
        Organised (invalid rows kept) or dense profile clouds.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        profile_topic: str = "/profile",
        pose_topic: str = "/flange_pose",
        organised: bool = True,
    ) -> None:
        self.path = Path(path)
        self.organised = organised
        self.count = 0
        self.durable = 0
        self._joints: int | None = None
        if self.path.exists():
            raise BagError(
                f"{self.path} exists already and sessions are never overwritten; "
                "choose a new session path or delete the old one"
            )
        try:
            self.path.mkdir(parents=True)
            (self.path / SESSION_MARKER).write_text(
                f"linelaser_calib sample session: the samples are in {SESSION_FILE}\n",
                encoding="utf-8",
            )
            from mcap.writer import Writer as McapWriter  # zstandard: only sessions need it

            self._stream: BufferedWriter | None = (self.path / SESSION_FILE).open("wb")
            self._writer = McapWriter(self._stream, use_chunking=False)
            self._writer.start(profile="ros2", library="linelaser_calib")
            store = jazzy_typestore()
            channels = {}
            for topic, msgtype in ((pose_topic, POSE_TYPE), (profile_topic, PROFILE_TYPE)):
                text, _ = store.generate_msgdef(msgtype, ros_version=2)
                schema = self._writer.register_schema(msgtype, SchemaEncoding.ROS2, text.encode())
                channels[msgtype] = self._writer.register_channel(
                    topic, MessageEncoding.CDR, schema
                )
            self._pose_channel, self._profile_channel = channels[POSE_TYPE], channels[PROFILE_TYPE]
            self._types = rosbags_types(store)
            self.flush()
            fsync_directory(self.path)
        except OSError as err:
            raise BagError(f"cannot create session {self.path}: {err}") from err

    def append(
        self,
        profile: Profile,
        pose_at_profile: FlangePose,
        joints_at_profile: tuple[Sequence[str], NDArray[np.float64]] | None = None,
    ) -> int:
        """Buffer one sample; it is on disk after the next :meth:`flush`.

        Parameters
        ----------
        profile : Profile
            Points (N, 3) in m in frame ``profile.frame_id``.
        pose_at_profile : FlangePose
            Flange pose at the profile stamp, in frame ``pose_at_profile.frame_id``. It is
            written with the profile stamp, so both messages carry identical stamps.
        joints_at_profile : (names, positions (n,)), optional
            The joint vector the flange pose was computed from (rad or m), written as a
            ``sensor_msgs/msg/JointState`` on ``/joint_states`` with the profile stamp too,
            so that the session can be calibrated with the robot's kinematics.

        Returns
        -------
        int
            The sample's number in the session (0-based).
        """
        if self._stream is None:
            raise BagError(f"session {self.path} is closed; start a new session to record more")
        stamp = profile.stamp_ns
        pose = pose_stamped_from_flange_pose(
            FlangePose(stamp, pose_at_profile.T_base_flange, pose_at_profile.frame_id),
            types=self._types,
        )
        cloud = pointcloud2_from_points(
            profile.points, stamp, profile.frame_id, types=self._types, organised=self.organised
        )
        store = jazzy_typestore()
        messages = [
            (self._pose_channel, store.serialize_cdr(pose, POSE_TYPE)),
            (self._profile_channel, store.serialize_cdr(cloud, PROFILE_TYPE)),
        ]
        try:
            if joints_at_profile is not None:
                names, positions = joints_at_profile
                msg = joint_state_msg(stamp, names, positions, types=self._types)
                messages.append((self._joint_channel(), store.serialize_cdr(msg, JOINT_STATE_TYPE)))
            for channel, data in messages:
                self._writer.add_message(channel, stamp, data.tobytes(), stamp, self.count)
        except OSError as err:
            raise BagError(f"cannot write to session {self.path}: {err}") from err
        self.count += 1
        return self.count - 1

    def _joint_channel(self) -> int:
        """The ``/joint_states`` channel, registered with the first joint vector."""
        if self._joints is None:
            text, _ = jazzy_typestore().generate_msgdef(JOINT_STATE_TYPE, ros_version=2)
            schema = self._writer.register_schema(
                JOINT_STATE_TYPE, SchemaEncoding.ROS2, text.encode()
            )
            self._joints = self._writer.register_channel(
                JOINT_STATE_TOPIC, MessageEncoding.CDR, schema
            )
        return self._joints

    def flush(self) -> None:
        """Write every appended sample to disk (flush and fsync); they then survive a crash."""
        if self._stream is None:
            return
        try:
            self._stream.flush()
            os.fsync(self._stream.fileno())
        except OSError as err:
            raise BagError(f"cannot write to session {self.path}: {err}") from err
        self.durable = self.count

    def close(self) -> None:
        """Write the MCAP summary and footer and close the file; appending then fails."""
        if self._stream is None:
            return
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]  # mcap has no annotation here
            self.flush()
            self._stream.close()
        except OSError as err:
            raise BagError(f"cannot close session {self.path}: {err}") from err
        finally:
            self._stream = None

    def __enter__(self) -> SessionBagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


class SessionConnection(NamedTuple):
    """One channel of a session file, shaped like the rosbags connections read_bag uses."""

    topic: str
    msgtype: str
    msgcount: int


class SessionReader:
    """Reads a session file, complete or not (see :class:`SessionBagWriter`).

    It walks the records from the start and stops at the first incomplete one (the torn
    tail of a session whose writer crashed), so it needs neither the summary nor the footer.
    It offers the parts of rosbags' ``Reader`` that :func:`read_bag` uses.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.connections: list[SessionConnection] = []
        self.start_time = 0
        self.end_time = 0
        self._messages: list[tuple[int, int, bytes]] = []  # (channel, log ns, data)
        self._by_key: dict[int, SessionConnection] = {}

    def open(self) -> None:
        data = self.path.read_bytes()
        if data[: len(MCAP_MAGIC)] != MCAP_MAGIC:
            raise BagError(f"{self.path} is not an MCAP file (wrong magic bytes)")
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        position = len(MCAP_MAGIC)
        while position + 9 <= len(data):
            opcode = data[position]
            (length,) = struct.unpack_from("<Q", data, position + 1)
            body = position + 9
            if body + length > len(data):
                break  # the torn tail of a crashed writer
            stream = ReadDataStream(BytesIO(data[body : body + length]))
            if opcode == Opcode.SCHEMA:
                schema = McapSchema.read(stream)
                schemas[schema.id] = schema.name
            elif opcode == Opcode.CHANNEL:
                channel = McapChannel.read(stream)
                channels[channel.id] = (channel.topic, schemas.get(channel.schema_id, ""))
            elif opcode == Opcode.MESSAGE:
                message = McapMessage.read(stream, length)
                self._messages.append((message.channel_id, message.log_time, message.data))
            position = body + length
        self._by_key = {
            key: SessionConnection(topic, msgtype, sum(m[0] == key for m in self._messages))
            for key, (topic, msgtype) in channels.items()
        }
        self.connections = list(self._by_key.values())
        stamps = [log_ns for _, log_ns, _ in self._messages]
        self.start_time, self.end_time = min(stamps, default=0), max(stamps, default=-1) + 1

    def messages(
        self, connections: Sequence[SessionConnection]
    ) -> Iterator[tuple[SessionConnection, int, bytes]]:
        wanted = set(connections)
        for key, log_ns, data in self._messages:
            conn = self._by_key.get(key)
            if conn in wanted:
                yield conn, log_ns, data

    def close(self) -> None:
        self._messages = []


def bag_parts(path: Path) -> list[Path]:
    """The bag directories or files to read for ``path`` (one, or a session's samples)."""
    if not path.exists():
        raise BagError(f"bag {path} does not exist; check the path")
    if path.is_file():
        if path.suffix not in {".mcap", ".db3"}:
            raise BagError(
                f"{path} is not a rosbag2 bag; pass the bag directory (holding "
                "metadata.yaml) or its .mcap file"
            )
        return [path]
    if (path / "metadata.yaml").is_file():
        return [path]
    if (path / SESSION_FILE).is_file():
        return [path / SESSION_FILE]
    if (path / SESSION_MARKER).is_file():  # a session written one bag per sample
        samples = sorted(
            p for p in path.glob(f"{SAMPLE_PREFIX}*") if (p / "metadata.yaml").is_file()
        )
        if not samples:
            raise BagError(f"session {path} holds no samples yet; record some first")
        return samples
    inner = sorted(p.name for p in path.iterdir() if (p / "metadata.yaml").is_file())
    storage = sorted(p.name for p in path.iterdir() if p.suffix in {".mcap", ".db3"})
    if inner:
        hint = f"; it contains the bags {inner}: pass one of them"
    elif storage:
        hint = (
            f"; it holds {storage} (the recorder was probably killed before closing the bag): "
            "pass the storage file itself, or recreate metadata.yaml with `ros2 bag reindex`"
        )
    else:
        hint = ""
    raise BagError(f"{path} is not a rosbag2 bag (it has no metadata.yaml){hint}")


def is_session_file(path: Path) -> bool:
    """True for the MCAP file of a :class:`SessionBagWriter` session."""
    return path.name == SESSION_FILE and (path.parent / SESSION_MARKER).is_file()


@contextmanager
def open_part(part: Path, bag: Path) -> Iterator[Reader | SessionReader]:
    """Open one bag (rosbags) or session file; any failure to parse it becomes a
    :class:`BagError`."""
    try:
        reader = SessionReader(part) if is_session_file(part) else Reader(part)
        reader.open()
    # A damaged file makes the parsers raise almost anything (seen: UnicodeDecodeError,
    # KeyError, MemoryError, rosbags' own errors); all mean the same to the user.
    except Exception as err:
        raise BagError(_unreadable(bag, part, err)) from err
    try:
        yield reader
    finally:
        reader.close()


def _unreadable(bag: Path, part: Path, err: Exception) -> str:
    where = str(bag) if part == bag else f"{bag} (sample {part.name})"
    return (
        f"cannot read bag {where}: {type(err).__name__}: {err}. The file is truncated or "
        "corrupt (e.g. the recorder was killed before closing it): re-record it, or salvage "
        "a copy of a truncated MCAP file with the mcap CLI (`mcap recover`)"
    )


class BagSummary(NamedTuple):
    """The topics of a bag (or session) and the log times of its first and last message, ns."""

    topics: list[TopicSummary]
    start_ns: int | None
    end_ns: int | None


def summarise(bag: Path, parts: Sequence[Path]) -> BagSummary:
    counts: dict[tuple[str, str], int] = {}
    starts: list[int] = []
    ends: list[int] = []
    for part in parts:
        with open_part(part, bag) as reader:
            for conn in reader.connections:
                key = (conn.topic, conn.msgtype)
                counts[key] = counts.get(key, 0) + conn.msgcount
            if any(conn.msgcount for conn in reader.connections):
                starts.append(reader.start_time)
                ends.append(reader.end_time - 1)
    topics = [TopicSummary(t, m, n) for (t, m), n in sorted(counts.items())]
    return BagSummary(topics, min(starts, default=None), max(ends, default=None))


def _listing(topics: Sequence[TopicSummary]) -> str:
    return ", ".join(f"{t.topic} ({t.msgtype}, {t.msgcount} msgs)" for t in topics) or "none"


def _choose_topic(
    bag: Path, topics: Sequence[TopicSummary], msgtype: str, wanted: str | None, what: str
) -> str:
    """The topic of type ``msgtype`` to read: ``wanted`` if given, else the only one."""
    option = f"{what}_topic (--{what}-topic)"
    if wanted is not None:
        found = [t for t in topics if t.topic == wanted]
        if not found:
            raise BagError(
                f"bag {bag} has no topic {wanted!r}; its topics are: {_listing(topics)}. "
                f"Pass an existing {msgtype} topic as {option}"
            )
        if all(t.msgtype != msgtype for t in found):
            raise BagError(
                f"topic {wanted!r} in bag {bag} has type {found[0].msgtype}, expected "
                f"{msgtype}; pass a {msgtype} topic as {option}"
            )
        if sum(t.msgcount for t in found if t.msgtype == msgtype) == 0:
            raise BagError(f"topic {wanted!r} in bag {bag} holds no messages")
        return wanted
    candidates = [t for t in topics if t.msgtype == msgtype and t.msgcount > 0]
    if len(candidates) == 1:
        return candidates[0].topic
    if not candidates:
        raise BagError(
            f"bag {bag} holds no {msgtype} messages (the {what}s); its topics are: "
            f"{_listing(topics)}"
        )
    raise BagError(
        f"bag {bag} has several {msgtype} topics: {_listing(candidates)}; choose one with {option}"
    )


def raw_messages(
    reader: Reader | SessionReader, connections: Sequence[Any], bag: Path, part: Path
) -> Iterator[tuple[Any, int, Any]]:
    """``reader.messages(connections)``, with a damaged chunk turned into :class:`BagError`."""
    iterator = iter(reader.messages(connections))
    while True:
        try:
            item = next(iterator)
        except StopIteration:
            return
        except Exception as err:  # a damaged chunk: see open_part
            raise BagError(_unreadable(bag, part, err)) from err
        yield item


def decode_message(store: Typestore, topic: str, msgtype: str, log_ns: int, raw: Any) -> Any:
    """Deserialise one message; undecodable bytes become a :class:`SkippedMessage`."""
    try:
        return store.deserialize_cdr(raw, msgtype)
    # Corrupt message bytes make the deserialiser raise various errors; skip the message.
    except Exception as err:
        return SkippedMessage(topic, log_ns, f"cannot decode the message: {err}")


def _profile(topic: str, msg: Any, invalid_values_m: Sequence[float]) -> Profile | SkippedMessage:
    """Profile of a decoded PointCloud2; a malformed one becomes a :class:`SkippedMessage`."""
    try:
        return profile_from_pointcloud2(msg, invalid_values_m=invalid_values_m)
    except MessageError as err:
        return SkippedMessage(topic, stamp_ns_from_msg(msg.header.stamp), str(err))


class _PoseRecords(NamedTuple):
    """PoseStamped fields parsed in a batch; rows with ``parsed`` False are not filled."""

    parsed: NDArray[np.bool_]  # (K,)
    stamps_ns: NDArray[np.int64]  # (K,)
    frame_ids: list[str]
    values: NDArray[np.float64]  # (K, 7): position x, y, z (m), orientation x, y, z, w


def _parse_pose_stamped(raws: Sequence[bytes]) -> _PoseRecords:
    """Parse serialised PoseStamped messages in one vectorised pass (a bag holds thousands).

    Little-endian CDR (what ROS 2 middlewares write on little-endian hosts: x86, ARM) of a
    PoseStamped is fixed but for the frame id: after the 4-byte encapsulation header
    (0, 1, options), int32 sec and uint32 nanosec, uint32 length of frame_id counting its
    NUL, the bytes, zero padding to 8 (relative to the payload), then 7 float64. Messages
    of one size share one array view. A message that does not have exactly this layout
    (big-endian, trailing bytes, a bad length or frame id) is left unparsed for the generic
    decoder.
    """
    count = len(raws)
    parsed = np.zeros(count, dtype=np.bool_)
    stamps = np.zeros(count, dtype=np.int64)
    values = np.full((count, 7), np.nan)
    frame_ids = [""] * count
    sizes = np.fromiter((len(r) for r in raws), dtype=np.int64, count=count)
    for size in np.unique(sizes):
        rows = np.flatnonzero(sizes == size)
        if size < 4 + 12 + 1 + 56:
            continue
        joined = b"".join(raws[int(i)] for i in rows)
        block = np.frombuffer(joined, dtype=np.uint8).reshape(len(rows), int(size))
        length = block[:, 12:16].copy().view("<u4")[:, 0].astype(np.int64)
        data_start = 4 + (12 + length + 7) // 8 * 8
        layout = (block[:, 0] == 0) & (block[:, 1] == 1) & (length >= 1)
        layout &= data_start + 56 == size
        for n in np.unique(length[layout]):
            sub = np.flatnonzero(layout & (length == n))
            # Frame ids as single n-byte items: np.unique(axis=0) is ~30x slower.
            ids = np.ascontiguousarray(block[sub, 16 : 16 + n]).view(np.dtype((np.void, n)))
            unique_ids, inverse = np.unique(ids[:, 0], return_inverse=True)
            frames = unique_ids.view(np.uint8).reshape(len(unique_ids), n)
            names: list[str | None] = []
            for frame in frames:
                try:
                    names.append(bytes(frame[:-1]).decode() if frame[-1] == 0 else None)
                except UnicodeDecodeError:
                    names.append(None)
            inverse = inverse.ravel()
            keep = np.array([name is not None for name in names])[inverse]
            sub, inverse = sub[keep], inverse[keep]
            start = int(4 + (12 + n + 7) // 8 * 8)
            sec = block[sub, 4:8].copy().view("<i4")[:, 0].astype(np.int64)
            nanosec = block[sub, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
            parsed[rows[sub]] = True
            stamps[rows[sub]] = sec * NS_PER_S + nanosec
            values[rows[sub]] = block[sub, start : start + 56].copy().view("<f8")
            for row, name_index in zip(rows[sub], inverse, strict=True):
                frame_ids[row] = str(names[name_index])
    return _PoseRecords(parsed, stamps, frame_ids, values)


def flange_poses(
    topic: str, raws: Sequence[bytes], log_ns: Sequence[int]
) -> list[FlangePose | SkippedMessage]:
    """Flange poses of serialised PoseStamped messages, parsed and converted in one batch.

    A bag holds thousands of poses (125-500 Hz): the batch costs ~2 µs per pose instead of
    ~30 µs for decoding and converting each message. A message that the batch cannot parse
    (:func:`_parse_pose_stamped`), or whose position or quaternion fails the checks of
    :func:`~msg_adapters.flange_pose_from_pose_stamped` (non-finite, zero or non-unit
    quaternion), is decoded by rosbags and converted by that function, which says why it
    is unusable.

    Returns
    -------
    list of FlangePose or SkippedMessage
        One per message, in order.
    """
    records = _parse_pose_stamped(raws)
    position, q_xyzw = records.values[:, :3], records.values[:, 3:]
    norm = np.linalg.norm(q_xyzw, axis=1)
    with np.errstate(invalid="ignore"):
        good = records.parsed & np.all(np.isfinite(records.values), axis=1) & (norm >= 1e-12)
        good &= np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE
    T = np.zeros((len(raws), 4, 4))
    T[:, 3, 3] = 1.0
    if good.any():
        T[good, :3, :3] = matrices_from_quaternions_xyzw(q_xyzw[good])
    T[:, :3, 3] = position
    out: list[FlangePose | SkippedMessage] = []
    for k in range(len(raws)):
        if good[k]:
            out.append(FlangePose(int(records.stamps_ns[k]), T[k], records.frame_ids[k]))
            continue
        msg = decode_message(jazzy_typestore(), topic, POSE_TYPE, log_ns[k], raws[k])
        if isinstance(msg, SkippedMessage):
            out.append(msg)
            continue
        try:
            out.append(flange_pose_from_pose_stamped(msg))
        except MessageError as err:
            out.append(SkippedMessage(topic, stamp_ns_from_msg(msg.header.stamp), str(err)))
    return out


def read_bag(
    path: str | Path,
    *,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
    progress: Progress | None = None,
    read_poses: bool = True,
    invalid_values_m: Sequence[float] = (),
) -> BagContents:
    """Read the profiles and flange poses of a bag (or a :class:`SessionBagWriter` session).

    Parameters
    ----------
    path : str or Path
        rosbag2 directory, its ``.mcap`` file, or a session directory.
    profile_topic, pose_topic : str, optional
        Topics to read. By default the only PointCloud2 topic and the only PoseStamped topic
        holding messages.
    progress : callable(done, total), optional
        Called after each message of the two topics.
    read_poses : bool
        False: read the profiles only (the flange poses come from another source, e.g.
        ``/tf`` or joint states); ``poses`` is then empty and ``pose_topic`` and
        ``base_frame`` are ''.
    invalid_values_m : sequence of float
        Depths z, m, that mark a point as no return besides NaN and +-Inf (driver
        sentinels such as -0.999999 for Keyence's -999.999 mm, or 0).

    Returns
    -------
    BagContents
        Profiles (invalid points dropped) and poses sorted by stamp; malformed messages are
        listed in ``skipped`` instead of aborting the read.

    Raises
    ------
    BagError
        Missing path, not a bag, empty, truncated or corrupt bag, missing, ambiguous or
        wrongly typed topics, or no readable profile or pose at all.
    """
    bag = Path(path)
    parts = bag_parts(bag)
    summary = summarise(bag, parts)
    if summary.start_ns is None or summary.end_ns is None:
        if any(is_session_file(part) for part in parts):
            raise BagError(f"session {bag} holds no samples yet; record some first")
        raise BagError(
            f"bag {bag} is empty (topics: {_listing(summary.topics)}); record the profile "
            "and flange pose topics"
        )
    chosen_profile = _choose_topic(bag, summary.topics, PROFILE_TYPE, profile_topic, "profile")
    chosen_pose = (
        _choose_topic(bag, summary.topics, POSE_TYPE, pose_topic, "pose") if read_poses else ""
    )
    wanted = {(chosen_profile, PROFILE_TYPE), (chosen_pose, POSE_TYPE)}
    total = sum(t.msgcount for t in summary.topics if (t.topic, t.msgtype) in wanted)

    decoded: list[Profile | SkippedMessage | None] = []  # None: a pose, converted below
    pose_raws: list[bytes] = []
    pose_log_ns: list[int] = []
    done = 0
    for part in parts:
        with open_part(part, bag) as reader:
            connections = [c for c in reader.connections if (c.topic, c.msgtype) in wanted]
            store = reading_store(connections)
            for conn, log_ns, raw in raw_messages(reader, connections, bag, part):
                if conn.msgtype == PROFILE_TYPE:
                    msg = decode_message(store, conn.topic, conn.msgtype, log_ns, raw)
                    decoded.append(
                        msg
                        if isinstance(msg, SkippedMessage)
                        else _profile(conn.topic, msg, invalid_values_m)
                    )
                else:
                    decoded.append(None)
                    pose_raws.append(bytes(raw))
                    pose_log_ns.append(log_ns)
                done += 1
                if progress is not None:
                    progress(done, total)
    converted = iter(flange_poses(chosen_pose, pose_raws, pose_log_ns))
    profiles: list[Profile] = []
    poses: list[FlangePose] = []
    skipped: list[SkippedMessage] = []
    for item in decoded:
        entry = next(converted) if item is None else item
        if isinstance(entry, Profile):
            profiles.append(entry)
        elif isinstance(entry, FlangePose):
            poses.append(entry)
        else:
            skipped.append(entry)

    for items, topic, what in ((profiles, chosen_profile, "profile"), (poses, chosen_pose, "pose")):
        if not items and topic:
            first = next((s.reason for s in skipped if s.topic == topic), "none")
            raise BagError(
                f"bag {bag}: no readable {what} on {topic} "
                f"({sum(s.topic == topic for s in skipped)} skipped; first reason: {first})"
            )
    profiles.sort(key=lambda p: p.stamp_ns)
    poses.sort(key=lambda p: p.stamp_ns)
    return BagContents(
        path=bag,
        profiles=profiles,
        poses=poses,
        profile_topic=chosen_profile,
        pose_topic=chosen_pose,
        sensor_frame=profiles[0].frame_id,
        base_frame=poses[0].frame_id if poses else "",
        topics=summary.topics,
        start_ns=summary.start_ns,
        end_ns=summary.end_ns,
        skipped=skipped,
    )


def read_profile_intensities(path: str | Path, topic: str) -> dict[int, NDArray[np.float64]]:
    """Per profile stamp (ns), the ``intensity`` of its valid points, in the order of
    :func:`read_bag`'s points; empty when the profiles have no intensity field.

    Raises
    ------
    BagError
        If the bag cannot be read.
    """
    bag = Path(path)
    found: dict[int, NDArray[np.float64]] = {}
    for msg in _decoded_messages(bag, bag_parts(bag), topic, PROFILE_TYPE):
        if not any(field.name == "intensity" for field in msg.fields):
            return {}
        try:
            cloud = cloud_from_pointcloud2(msg, extra_fields=("intensity",))
        except MessageError:
            continue
        found[stamp_ns_from_msg(msg.header.stamp)] = cloud.extras["intensity"]
    return found


def _decoded_messages(bag: Path, parts: Sequence[Path], topic: str, msgtype: str) -> Iterator[Any]:
    """The decoded messages of one topic and type, part by part; undecodable ones left out."""
    for part in parts:
        with open_part(part, bag) as reader:
            connections = [
                c for c in reader.connections if (c.topic, c.msgtype) == (topic, msgtype)
            ]
            store = reading_store(connections)
            for _, log_ns, raw in raw_messages(reader, connections, bag, part):
                msg = decode_message(store, topic, msgtype, log_ns, raw)
                if not isinstance(msg, SkippedMessage):
                    yield msg


def read_joint_states(path: str | Path, *, topic: str | None = None) -> JointStates:
    """Read the ``sensor_msgs/msg/JointState`` stream of a bag, sorted by stamp.

    Parameters
    ----------
    path : str or Path
        rosbag2 directory, its ``.mcap`` file, or a session directory.
    topic : str, optional
        Default: ``/joint_states`` if it holds JointState messages, else the only
        JointState topic.

    Returns
    -------
    JointStates
        Positions (K, n) in the joint order of the first message; messages that name other
        joints or are malformed are left out.

    Raises
    ------
    BagError
        No JointState topic (the bag's topics are listed), several without a choice, or
        none readable.
    """
    bag = Path(path)
    parts = bag_parts(bag)
    topics = summarise(bag, parts).topics
    found = [t for t in topics if t.msgtype == JOINT_STATE_TYPE and t.msgcount > 0]
    if topic is None:
        default = [t for t in found if t.topic == JOINT_STATE_TOPIC]
        chosen = default or found
        if not chosen:
            raise BagError(
                f"bag {bag} holds no {JOINT_STATE_TYPE} messages, which the joint_states "
                f"pose source needs; its topics are: {_listing(topics)}. Record /joint_states "
                "with the profiles, or use another pose source"
            )
        if len(chosen) > 1:
            raise BagError(
                f"bag {bag} has several {JOINT_STATE_TYPE} topics: {_listing(chosen)}; "
                "choose one with --joint-state-topic"
            )
        topic = chosen[0].topic
    elif not any(t.topic == topic for t in found):
        raise BagError(
            f"bag {bag} has no {JOINT_STATE_TYPE} messages on {topic!r}; its topics are: "
            f"{_listing(topics)}"
        )
    records = []
    for msg in _decoded_messages(bag, parts, topic, JOINT_STATE_TYPE):
        try:
            records.append(joint_state_from_msg(msg))
        except MessageError:
            continue
    if not records:
        raise BagError(f"bag {bag}: no readable {JOINT_STATE_TYPE} message on {topic}")
    records.sort(key=lambda r: r.stamp_ns)
    names = records[0].names
    kept = [r for r in records if r.names == names]
    return JointStates(
        names,
        np.array([r.stamp_ns for r in kept], dtype=np.int64),
        np.array([r.positions for r in kept]),
    )


def bag_info(
    path: str | Path, *, profile_topic: str | None = None, pose_topic: str | None = None
) -> BagInfo:
    """Summarise a bag: topics, time span, profiles, poses and points per profile.

    A bag whose topics cannot be chosen (ambiguous, missing) still gets its topic list, with
    the reason in ``problem``.

    Raises
    ------
    BagError
        If the bag does not exist or cannot be opened at all.
    """
    bag = Path(path)
    summary = summarise(bag, bag_parts(bag))
    try:
        contents: BagContents | None = read_bag(
            bag, profile_topic=profile_topic, pose_topic=pose_topic
        )
        problem = None
    except BagError as err:
        contents, problem = None, str(err)
    counts = None
    if contents is not None:
        sizes = [len(p.points) for p in contents.profiles]
        counts = PointCount(min(sizes), float(np.median(sizes)), max(sizes))
    return BagInfo(bag, summary.topics, summary.start_ns, summary.end_ns, contents, problem, counts)


def _utc(stamp_ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(stamp_ns / 1e9, tz=datetime.timezone.utc)
    return moment.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


def format_bag_info(info: BagInfo) -> str:
    """Human-readable text of :func:`bag_info`'s result (times in UTC and s, labelled)."""
    lines = [f"bag: {info.path}"]
    if info.start_ns is None or info.end_ns is None:
        lines.append("time: empty bag (no messages)")
    else:
        duration_s = (info.end_ns - info.start_ns) / 1e9
        lines.append(
            f"time: {_utc(info.start_ns)} to {_utc(info.end_ns)} UTC, duration {duration_s:.3f} s"
        )
    lines.append("topics:")
    width = max((len(t.topic) for t in info.topics), default=0)
    lines += [f"  {t.topic:<{width}}  {t.msgtype}  {t.msgcount} msgs" for t in info.topics]
    contents = info.contents
    if contents is None:
        lines.append(f"profiles and poses: not readable: {info.problem}")
        return "\n".join(lines)
    lines.append(
        f"profiles: {len(contents.profiles)} on {contents.profile_topic} "
        f"(frame {contents.sensor_frame})"
    )
    if info.points_per_profile is not None:
        n = info.points_per_profile
        lines.append(f"valid points per profile: min {n.min}, median {n.median:g}, max {n.max}")
    lines.append(
        f"flange poses: {len(contents.poses)} on {contents.pose_topic} "
        f"(frame {contents.base_frame})"
    )
    if contents.skipped:
        first = contents.skipped[0]
        lines.append(
            f"skipped messages: {len(contents.skipped)} (first: {first.topic} at "
            f"{first.stamp_ns} ns: {first.reason})"
        )
    return "\n".join(lines)
