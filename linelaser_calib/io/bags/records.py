"""The names and records every part of the bag I/O shares: message types, topics, what was read."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.pose_track import PoseTrack
from linelaser_calib.core.types import Profile

PROFILE_TYPE = "sensor_msgs/msg/PointCloud2"


POSE_TYPE = "geometry_msgs/msg/PoseStamped"


JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"


TF_TYPE = "tf2_msgs/msg/TFMessage"


TF_TOPIC = "/tf"


TF_STATIC_TOPIC = "/tf_static"


#: The joint-state topic of a session (and the default one read from any bag).
JOINT_STATE_TOPIC = "/joint_states"


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
    poses : PoseTrack
        The flange poses, sorted by stamp (repeated stamps kept).
    profile_topic, pose_topic : str
        Topics the profiles and poses came from.
    sensor_frame, base_frame : str
        Header frame ids of the first profile and the first pose.
    topics : list of TopicSummary
        Every topic of the bag, sorted by name.
    start_ns, end_ns : int
        Log times of the first and last message of the bag, ns.
    skipped : list of SkippedMessage
        Messages on the two topics that were malformed or undecodable, sorted by stamp.
    """

    path: Path
    profiles: list[Profile]
    poses: PoseTrack
    profile_topic: str
    pose_topic: str
    sensor_frame: str
    base_frame: str
    topics: list[TopicSummary]
    start_ns: int
    end_ns: int
    skipped: list[SkippedMessage]


class SessionConnection(NamedTuple):
    """One channel of a session file, shaped like the rosbags connections read_bag uses."""

    topic: str
    msgtype: str
    msgcount: int


@dataclass(frozen=True)
class RawMessages:
    """Serialised messages of one topic, their bytes in one buffer: no object per message
    (a recording holds 140,000 flange poses).

    Attributes
    ----------
    buffer : ndarray, shape (B,), uint8
        Holds every message's bytes (and maybe other bytes between them, e.g. an MCAP
        chunk's record headers).
    starts, sizes : ndarray, shape (K,), int64
        Where each message's bytes start in ``buffer``, and how many there are.
    log_ns : ndarray, shape (K,), int64
        Each message's log time, ns.
    """

    buffer: NDArray[np.uint8]
    starts: NDArray[np.int64]
    sizes: NDArray[np.int64]
    log_ns: NDArray[np.int64]

    @classmethod
    def of(cls, raws: Sequence[bytes], log_ns: Sequence[int]) -> RawMessages:
        """The messages ``raws`` (logged at ``log_ns``) laid end to end."""
        sizes = np.fromiter((len(r) for r in raws), dtype=np.int64, count=len(raws))
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        buffer = np.frombuffer(b"".join(raws), dtype=np.uint8)
        return cls(buffer, starts, sizes, np.asarray(log_ns, dtype=np.int64).reshape(-1))

    def __len__(self) -> int:
        return len(self.starts)

    def raw(self, k: int) -> NDArray[np.uint8]:
        """The bytes of message ``k`` (a view of the buffer)."""
        start = int(self.starts[k])
        return self.buffer[start : start + int(self.sizes[k])]
