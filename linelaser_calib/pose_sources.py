"""Where a recording's flange poses come from: one function per pose source.

- ``pose``: the ``geometry_msgs/PoseStamped`` flange-pose topic, as recorded.
- ``joint_states``: forward kinematics of a robot model
  (:mod:`linelaser_calib.core.kinematics`) of every ``sensor_msgs/JointState`` message;
  each flange pose keeps its joint state's stamp, so that pairing interpolates between
  them exactly as between recorded poses.

Calibration and reconstruction read recordings through :func:`read_recording`, so both
pair the same flange poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from enum import Enum
from pathlib import Path

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.kinematics import KinematicModel, flange_poses_from_joint_states
from linelaser_calib.io.bags import BagContents, read_bag, read_joint_states

#: Called as ``progress(done, total)`` while messages are decoded.
Progress = Callable[[int, int], None]


class PoseSource(Enum):
    """The pose source of a run (``--pose-source``)."""

    POSE = "pose"
    JOINT_STATES = "joint_states"


def _from_pose_topic(
    path: Path, profile_topic: str | None, pose_topic: str | None, progress: Progress | None
) -> BagContents:
    return read_bag(path, profile_topic=profile_topic, pose_topic=pose_topic, progress=progress)


def _from_joint_states(
    path: Path,
    profile_topic: str | None,
    joint_state_topic: str | None,
    model: KinematicModel,
    progress: Progress | None,
) -> BagContents:
    bag = read_bag(path, profile_topic=profile_topic, progress=progress, with_poses=False)
    states = read_joint_states(path, topic=joint_state_topic)
    try:
        poses = flange_poses_from_joint_states(model, states)
    except InputError as err:
        raise InputError(f"bag {path}: {err}") from None
    topic = joint_state_topic or "/joint_states"
    return replace(bag, poses=poses, pose_topic=topic, base_frame=model.base_frame)


def read_recording(
    path: str | Path,
    source: PoseSource = PoseSource.POSE,
    *,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
    joint_state_topic: str | None = None,
    model: KinematicModel | None = None,
    progress: Progress | None = None,
) -> BagContents:
    """Profiles and flange poses of a recording, the poses from the chosen source.

    Parameters
    ----------
    path : str or Path
        Bag directory, its .mcap file, or a collector session directory.
    source : PoseSource
    profile_topic, pose_topic, joint_state_topic : str, optional
        Auto-detected by message type when there is exactly one topic of the type
        (``/joint_states`` first for joint states).
    model : KinematicModel, optional
        The robot model; required by ``joint_states``.
    progress : callable(done, total), optional

    Returns
    -------
    BagContents
        With ``pose_topic`` the topic the poses came from and ``base_frame`` the model's
        base frame for ``joint_states``.

    Raises
    ------
    CalibrationError
        Bag problems, no joint states, joint names the model does not know, no model.
    """
    bag = Path(path)
    if source is PoseSource.JOINT_STATES:
        if model is None:
            raise InputError(
                "the joint_states pose source needs the robot's kinematic model: pass "
                "--kinematics ur5e, ur10e or a URDF file"
            )
        return _from_joint_states(bag, profile_topic, joint_state_topic, model, progress)
    return _from_pose_topic(bag, profile_topic, pose_topic, progress)
