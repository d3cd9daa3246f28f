"""Write a rosbag2 MCAP bag that appears under its name only once complete and on disk."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag2 import StoragePlugin, Writer

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.tf import StampedTransform
from linelaser_calib.core.types import FlangePose, Profile, StoredArray
from linelaser_calib.io.bags.cdr import jazzy_typestore
from linelaser_calib.io.bags.records import (
    JOINT_STATE_TYPE,
    POSE_TYPE,
    PROFILE_TYPE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TF_TYPE,
)
from linelaser_calib.io.errors import BagError
from msg_adapters import (
    joint_state_msg,
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    rosbags_types,
    transform_stamped_from_matrix,
)


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
        points: StoredArray,
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
