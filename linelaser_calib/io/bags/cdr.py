"""CDR (de)serialisation: the typestores, and hand-written decoders of the two messages a
recording holds thousands of: PoseStamped (a batch at a time) and PointCloud2."""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from linelaser_calib.core.geometry import QUATERNION_NORM_TOLERANCE
from linelaser_calib.core.pose_track import PoseTrack
from linelaser_calib.io.bags.records import (
    POSE_TYPE,
    RawMessages,
    SessionConnection,
    SkippedMessage,
)
from msg_adapters import MessageError, flange_pose_from_pose_stamped, stamp_ns_from_msg
from msg_adapters.message_types import NS_PER_S


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


def decode_message(store: Typestore, topic: str, msgtype: str, log_ns: int, raw: Any) -> Any:
    """Deserialise one message; undecodable bytes become a :class:`SkippedMessage`."""
    try:
        return store.deserialize_cdr(raw, msgtype)
    # Corrupt message bytes make the deserialiser raise various errors; skip the message.
    except Exception as err:
        return SkippedMessage(topic, log_ns, f"cannot decode the message: {err}")


class Stamp(NamedTuple):
    """``builtin_interfaces/msg/Time``."""

    sec: int
    nanosec: int


class Header(NamedTuple):
    """``std_msgs/msg/Header``."""

    stamp: Stamp
    frame_id: str


@dataclass(frozen=True, slots=True)
class PointField:
    """``sensor_msgs/msg/PointField`` (a dataclass: a tuple's ``count`` is a method)."""

    name: str
    offset: int
    datatype: int
    count: int


class PointCloud2(NamedTuple):
    """``sensor_msgs/msg/PointCloud2`` as :func:`pointcloud2_from_cdr` reads it: ``data`` a
    view of the serialised bytes, not a copy."""

    header: Header
    height: int
    width: int
    fields: list[PointField]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: NDArray[np.uint8]
    is_dense: bool


_U32 = struct.Struct("<I")
_TWO_U32 = struct.Struct("<II")


def pointcloud2_from_cdr(raw: NDArray[np.uint8]) -> PointCloud2 | None:
    """A serialised PointCloud2 read field by field (~10 µs, against ~80 µs for rosbags'
    generic deserialiser; a recording holds thousands), or None where the bytes are not
    exactly the little-endian CDR of one (big-endian, cut short, trailing bytes, a string
    that is not UTF-8): the generic decoder then reads them, or says why it cannot.

    Little-endian CDR: the 4-byte encapsulation header (0, 1, options), then each field at
    its own alignment counted from the end of that header; strings and sequences are a
    uint32 count and the items (a string's bytes end in a NUL).
    """
    if len(raw) < 8 or raw[0] != 0 or raw[1] != 1:
        return None
    body = memoryview(raw)[4:]
    try:
        pos = 0

        def text() -> str:
            nonlocal pos
            pos = (pos + 3) & ~3
            (length,) = _U32.unpack_from(body, pos)
            end = pos + 4 + length
            if length < 1 or end > len(body) or body[end - 1] != 0:
                raise ValueError("bad string")
            value = bytes(body[pos + 4 : end - 1]).decode()
            pos = end
            return value

        def two() -> tuple[int, int]:
            nonlocal pos
            pos = (pos + 3) & ~3
            values: tuple[int, int] = _TWO_U32.unpack_from(body, pos)
            pos += 8
            return values

        sec, nanosec = struct.unpack_from("<iI", body, 0)
        pos = 8
        frame_id = text()
        height, width = two()
        (n_fields,) = _U32.unpack_from(body, pos)
        pos += 4
        fields = []
        for _ in range(n_fields):
            name = text()
            offset, datatype = two()  # datatype: a uint8, then padding to count's alignment
            (count,) = _U32.unpack_from(body, pos)
            fields.append(PointField(name, offset, datatype & 0xFF, count))
            pos += 4
        is_bigendian = body[pos]
        pos += 1
        point_step, row_step = two()
        (size,) = _U32.unpack_from(body, pos)
        start = pos + 4
        pos = start + size
        is_dense = body[pos]
        if not 0 <= len(body) - pos - 1 < 4 or any(body[pos + 1 :]):  # at most padding after
            return None
    except (struct.error, ValueError, IndexError, UnicodeDecodeError):
        return None
    return PointCloud2(
        Header(Stamp(sec, nanosec), frame_id),
        height,
        width,
        fields,
        bool(is_bigendian),
        point_step,
        row_step,
        raw[4 + start : 4 + start + size],
        bool(is_dense),
    )


class _PoseRecords(NamedTuple):
    """PoseStamped fields parsed in a batch; rows with ``parsed`` False are not filled."""

    parsed: NDArray[np.bool_]  # (K,)
    stamps_ns: NDArray[np.int64]  # (K,)
    frame_of: NDArray[np.int64]  # (K,): each row's frame id, an index into frame_ids
    frame_ids: list[str]
    values: NDArray[np.float64]  # (K, 7): position x, y, z (m), orientation x, y, z, w


def _parse_pose_stamped(batch: RawMessages) -> _PoseRecords:
    """Parse serialised PoseStamped messages in one vectorised pass (a bag holds thousands).

    Little-endian CDR (what ROS 2 middlewares write on little-endian hosts: x86, ARM) of a
    PoseStamped is fixed but for the frame id: after the 4-byte encapsulation header
    (0, 1, options), int32 sec and uint32 nanosec, uint32 length of frame_id counting its
    NUL, the bytes, zero padding to 8 (relative to the payload), then 7 float64. Messages
    of one size are copied out of the batch's buffer as the rows of one array. A message
    that does not have exactly this layout (big-endian, trailing bytes, a bad length or
    frame id) is left unparsed for the generic decoder.
    """
    count = len(batch)
    parsed = np.zeros(count, dtype=np.bool_)
    stamps = np.zeros(count, dtype=np.int64)
    values = np.full((count, 7), np.nan)
    frame_of = np.zeros(count, dtype=np.int64)
    frame_ids = [""]
    sizes = batch.sizes
    for size in np.unique(sizes):
        rows = np.flatnonzero(sizes == size)
        if size < 4 + 12 + 1 + 56:
            continue
        block = sliding_window_view(batch.buffer, int(size))[batch.starts[rows]]
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
            frame_of[rows[sub]] = len(frame_ids) + inverse
            frame_ids.extend(str(name) for name in names)
    return _PoseRecords(parsed, stamps, frame_of, frame_ids, values)


def flange_poses(topic: str, batch: RawMessages) -> tuple[PoseTrack, list[SkippedMessage]]:
    """Flange poses of serialised PoseStamped messages, parsed and converted in one batch.

    A bag holds thousands of poses (125-500 Hz): the batch costs ~2 µs per pose instead of
    ~30 µs for decoding and converting each message. A message that the batch cannot parse
    (:func:`_parse_pose_stamped`), or whose position or quaternion fails the checks of
    :func:`~msg_adapters.flange_pose_from_pose_stamped` (non-finite, zero or non-unit
    quaternion), is decoded by rosbags and converted by that function, which says why it
    is unusable.

    Returns
    -------
    poses : PoseTrack
        The usable poses, in message order, in the frame of the first (quaternions
        normalised).
    skipped : list of SkippedMessage
    """
    records = _parse_pose_stamped(batch)
    position, q_xyzw = records.values[:, :3], records.values[:, 3:]
    norm = np.linalg.norm(q_xyzw, axis=1)
    with np.errstate(invalid="ignore"):
        good = records.parsed & np.all(np.isfinite(records.values), axis=1) & (norm >= 1e-12)
        good &= np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE
    skipped: list[SkippedMessage] = []
    frame_of, frame_ids = records.frame_of, records.frame_ids
    for k in np.flatnonzero(~good).tolist():
        raw = batch.raw(k).tobytes()
        msg = decode_message(jazzy_typestore(), topic, POSE_TYPE, int(batch.log_ns[k]), raw)
        if isinstance(msg, SkippedMessage):
            skipped.append(msg)
            continue
        try:
            pose = flange_pose_from_pose_stamped(msg)
        except MessageError as err:
            skipped.append(SkippedMessage(topic, stamp_ns_from_msg(msg.header.stamp), str(err)))
            continue
        one = PoseTrack.from_transforms([pose.stamp_ns], pose.T_base_flange)
        records.stamps_ns[k] = pose.stamp_ns
        position[k], q_xyzw[k], norm[k] = one.translation[0], one.rotation_xyzw[0], 1.0
        frame_of[k], good[k] = len(frame_ids), True
        frame_ids.append(pose.frame_id)
    usable = np.flatnonzero(good)
    frame = frame_ids[frame_of[usable[0]]] if len(usable) else ""
    track = PoseTrack(
        records.stamps_ns[usable],
        position[usable],
        q_xyzw[usable] / norm[usable, None],
        frame,
    )
    return track, skipped
