"""Read a bag or session: its parts, topics, profiles, flange poses, joint states.

Topics are auto-detected by type when exactly one topic of each type holds messages; a
single malformed message is skipped and reported in :attr:`BagContents.skipped`.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from functools import cache, partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml
from numpy.typing import NDArray
from rosbags.rosbag2 import Reader
from rosbags.typesys.store import Typestore

from linelaser_calib.core.pose_track import PoseTrack
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.types import Profile, stored_points
from linelaser_calib.io.bags.cdr import (
    decode_message,
    flange_poses,
    pointcloud2_from_cdr,
    reading_store,
)
from linelaser_calib.io.bags.indexed import indexed_messages, indexed_topics
from linelaser_calib.io.bags.records import (
    JOINT_STATE_TOPIC,
    JOINT_STATE_TYPE,
    POSE_TYPE,
    PROFILE_TYPE,
    BagContents,
    Progress,
    RawMessages,
    SkippedMessage,
    TopicSummary,
)
from linelaser_calib.io.bags.session import (
    SAMPLE_PREFIX,
    SESSION_FILE,
    SESSION_MARKER,
    SessionReader,
    is_session_file,
)
from linelaser_calib.io.errors import BagError
from msg_adapters import (
    MessageError,
    cloud_from_pointcloud2,
    joint_state_from_msg,
    profile_from_pointcloud2,
    stamp_ns_from_msg,
)


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


@contextmanager
def open_part(part: Path, bag: Path) -> Iterator[Reader | SessionReader]:
    """Open one bag (rosbags) or session file; any failure to parse it becomes a
    :class:`BagError`."""
    _check_files_present(part, bag)
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


def _check_files_present(part: Path, bag: Path) -> None:
    """Refuse a bag directory whose metadata.yaml names a storage file that is not there,
    naming it (an unreadable metadata.yaml is left to the bag reader's own message)."""
    metadata = part / "metadata.yaml"
    if not metadata.is_file():
        return
    try:
        info = yaml.safe_load(metadata.read_text(encoding="utf-8"))
        names = [str(n) for n in info["rosbag2_bagfile_information"]["relative_file_paths"]]
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):
        return
    missing = [name for name in names if not (part / name).is_file()]
    if missing:
        raise BagError(
            f"bag {bag}: its metadata.yaml names {', '.join(missing)}, which is missing from "
            f"{part}; copy the whole bag directory, or pass the storage file itself if it was "
            "moved or renamed"
        )


def _unreadable(bag: Path, part: Path, err: Exception) -> str:
    where = str(bag) if part == bag else f"{bag} (sample {part.name})"
    what = f"{type(err).__name__}: {str(err).rstrip('. ')}"
    mcap = part if part.suffix == ".mcap" else next(part.glob("*.mcap"), None)
    if mcap is None or not part.exists():
        salvage = ""
    elif shutil.which("mcap") is not None:
        salvage = f"; or salvage what was written: `mcap recover {mcap} -o recovered.mcap`"
    else:
        salvage = (
            "; or salvage what was written with Foxglove's mcap CLI (not installed on this "
            "machine; download it from https://github.com/foxglove/mcap/releases): "
            f"`mcap recover {mcap} -o recovered.mcap`, then pass recovered.mcap"
        )
    return (
        f"cannot read bag {where}: the file is truncated or corrupt ({what}), e.g. the "
        f"recorder was killed before closing it: re-record it{salvage}"
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


#: Serialised messages of one topic that rosbags' reader gives and :func:`message_batches`
#: hands on at once: a batch of flange poses is converted at ~2 µs a pose
#: (:func:`flange_poses`), and the serialised messages of a long recording (140,000 poses in
#: 5 minutes at 500 Hz) are never all held.
BATCH_BYTES = 1 << 20


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


def message_batches(
    reader: Reader | SessionReader, connections: Sequence[Any], bag: Path, part: Path
) -> Iterator[tuple[Any, RawMessages]]:
    """The messages of ``connections``, a batch of one connection's at a time: an MCAP
    chunk's, read through the file's indexes where it has them (:mod:`.indexed`, ~0.1 µs a
    message), else :func:`raw_messages` gathered up to :data:`BATCH_BYTES` (~5 µs a message).
    A damaged chunk raises :class:`BagError`."""
    indexed = None if isinstance(reader, SessionReader) else indexed_topics(part, connections)
    if indexed is not None:
        try:
            yield from indexed_messages(indexed)
        except Exception as err:  # a damaged chunk: see open_part
            raise BagError(_unreadable(bag, part, err)) from err
        return
    pending: dict[tuple[str, str], tuple[Any, list[bytes], list[int]]] = {}
    held = 0
    for conn, log_ns, raw in raw_messages(reader, connections, bag, part):
        _, raws, stamps = pending.setdefault((conn.topic, conn.msgtype), (conn, [], []))
        raws.append(bytes(raw))
        stamps.append(log_ns)
        held += len(raw)
        if held >= BATCH_BYTES:
            yield from ((c, RawMessages.of(r, t)) for c, r, t in pending.values())
            pending.clear()
            held = 0
    yield from ((c, RawMessages.of(r, t)) for c, r, t in pending.values())


def _profile(
    store: Callable[[], Typestore],
    topic: str,
    batch: RawMessages,
    k: int,
    invalid_values_m: Sequence[float],
) -> Profile | SkippedMessage:
    """Profile of the serialised PointCloud2 ``k`` of ``batch``, its points as
    :func:`~linelaser_calib.core.types.stored_points` keeps them (a recording's profiles are
    held through the whole calibration); a malformed one becomes a :class:`SkippedMessage`."""
    raw = batch.raw(k)
    msg = pointcloud2_from_cdr(raw)
    if msg is None:
        msg = decode_message(store(), topic, PROFILE_TYPE, int(batch.log_ns[k]), raw.tobytes())
    if isinstance(msg, SkippedMessage):
        return msg
    try:
        profile = profile_from_pointcloud2(
            msg, invalid_values_m=invalid_values_m, keep_float32=True
        )
    except MessageError as err:
        return SkippedMessage(topic, stamp_ns_from_msg(msg.header.stamp), str(err))
    return replace(profile, points=stored_points(profile.points))


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
        Called after each profile and each batch of flange poses (:func:`message_batches`).
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

    profiles: list[Profile] = []
    tracks: list[PoseTrack] = []
    skipped: list[SkippedMessage] = []
    done = 0
    for part in parts:
        with open_part(part, bag) as reader:
            connections = [c for c in reader.connections if (c.topic, c.msgtype) in wanted]
            # Built only for a profile the hand-written decoder leaves to rosbags (~25 ms).
            store = cache(partial(reading_store, connections))
            for conn, batch in message_batches(reader, connections, bag, part):
                if conn.msgtype == PROFILE_TYPE:
                    for k in range(len(batch)):
                        entry = _profile(store, conn.topic, batch, k, invalid_values_m)
                        if isinstance(entry, Profile):
                            profiles.append(entry)
                        else:
                            skipped.append(entry)
                        done += 1
                        if progress is not None:
                            progress(done, total)
                    continue
                track, lost = flange_poses(conn.topic, batch)
                tracks.append(track)
                skipped.extend(lost)
                done += len(batch)
                if progress is not None:
                    progress(done, total)
    frame = next((t.frame_id for t in tracks if len(t)), "")
    poses = PoseTrack.concatenate(tracks, frame)
    stamps = poses.stamps_ns
    if np.any(stamps[1:] < stamps[:-1]):  # recorded out of order: sorted (a copy)
        poses = poses.take(np.argsort(stamps, kind="stable"))

    for items, topic, what in ((profiles, chosen_profile, "profile"), (poses, chosen_pose, "pose")):
        if not items and topic:
            first = next((s.reason for s in skipped if s.topic == topic), "none")
            raise BagError(
                f"bag {bag}: no readable {what} on {topic} "
                f"({sum(s.topic == topic for s in skipped)} skipped; first reason: {first})"
            )
    profiles.sort(key=lambda p: p.stamp_ns)
    skipped.sort(key=lambda s: s.stamp_ns)
    return BagContents(
        path=bag,
        profiles=profiles,
        poses=poses,
        profile_topic=chosen_profile,
        pose_topic=chosen_pose,
        sensor_frame=profiles[0].frame_id,
        base_frame=poses.frame_id,
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
