"""The collector's session directories: naming a new one, finding the newest, reading one back.

A session is a directory ``session_YYYYmmdd_HHMMSS`` under the node's ``session_dir``
(:class:`~linelaser_calib.io.bags.SessionBagWriter` writes it); ``~/clear`` starts a new
one and ``reload_session`` seeds a new one with an old one's samples.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np

from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import BagError, read_bag
from linelaser_calib.io.bags import JOINT_STATE_TYPE, SESSION_MARKER, bag_info, read_joint_states


def find_latest_session(root: Path) -> Path:
    """The newest session directory under ``root`` (names sort by start time).

    Raises
    ------
    BagError
        When ``root`` holds no session.
    """
    sessions = sorted(p for p in root.glob("session_*") if (p / SESSION_MARKER).is_file())
    if not sessions:
        raise BagError(f"reload_session is 'latest' but {root} holds no session to reload")
    return sessions[-1]


def new_session_path(root: Path, now: datetime.datetime) -> Path:
    """``root/session_YYYYmmdd_HHMMSS``, with a numeric suffix if that exists already."""
    base = root / now.strftime("session_%Y%m%d_%H%M%S")
    path, k = base, 1
    while path.exists():
        k += 1
        path = base.with_name(f"{base.name}_{k}")
    return path


#: A stored sample: the profile, the flange pose at its stamp and, with joint states, the
#: joint vector (names, positions) that pose came from.
StoredSample = tuple[Profile, FlangePose, tuple[tuple[str, ...], np.ndarray] | None]


def session_samples(path: Path) -> list[StoredSample]:
    """The samples of a session: each profile with the flange pose (and the joint vector,
    where the session holds joint states) of identical stamp."""
    contents = read_bag(path)
    poses = {pose.stamp_ns: pose for pose in contents.poses}
    joints = {}
    if any(t.msgtype == JOINT_STATE_TYPE for t in bag_info(path).topics):
        states = read_joint_states(path)
        joints = {
            int(stamp): (states.names, states.positions[i])
            for i, stamp in enumerate(states.stamps_ns)
        }
    return [
        (p, poses[p.stamp_ns], joints.get(p.stamp_ns))
        for p in contents.profiles
        if p.stamp_ns in poses
    ]
