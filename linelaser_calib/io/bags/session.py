"""The collector's session: samples appended to one MCAP file, read back up to a torn tail."""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator, Sequence
from io import BufferedWriter, BytesIO
from pathlib import Path
from types import TracebackType

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel as McapChannel
from mcap.records import Message as McapMessage
from mcap.records import Schema as McapSchema
from mcap.well_known import MessageEncoding, SchemaEncoding
from numpy.typing import NDArray

from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io.bags.cdr import jazzy_typestore
from linelaser_calib.io.bags.records import (
    JOINT_STATE_TOPIC,
    JOINT_STATE_TYPE,
    POSE_TYPE,
    PROFILE_TYPE,
    SessionConnection,
)
from linelaser_calib.io.bags.write import fsync_directory
from linelaser_calib.io.errors import BagError
from msg_adapters import (
    joint_state_msg,
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    rosbags_types,
)

#: File in a session directory that marks it as one (see :class:`SessionBagWriter`).
SESSION_MARKER = "linelaser_calib_session.txt"


#: The MCAP file of a session's samples (see :class:`SessionBagWriter`).
SESSION_FILE = "session.mcap"


SAMPLE_PREFIX = "sample_"


#: The first bytes of every MCAP file.
MCAP_MAGIC = b"\x89MCAP0\r\n"


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


def is_session_file(path: Path) -> bool:
    """True for the MCAP file of a :class:`SessionBagWriter` session."""
    return path.name == SESSION_FILE and (path.parent / SESSION_MARKER).is_file()
