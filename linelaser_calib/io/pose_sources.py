"""Flange poses of a recording, from the chosen pose source (``PoseSource``).

Each source is one function ``(bag, request) -> FlangePoses`` in :data:`POSE_SOURCES`;
the profiles always come from :func:`~linelaser_calib.io.bags.read_bag`.

- ``pose``: the PoseStamped topic ``read_bag`` read.
- ``joint_states``: the ``sensor_msgs/msg/JointState`` stream of the bag through the robot
  model (:func:`~linelaser_calib.core.kinematics.flange_poses_from_joint_states`); each
  flange pose keeps its joint state's stamp, so that pairing interpolates between them as
  between recorded poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.kinematics import KinematicModel, flange_poses_from_joint_states
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.types import FlangePose
from linelaser_calib.io.bags import BagContents, read_joint_states


@dataclass(frozen=True)
class PoseRequest:
    """What a pose source needs besides the bag.

    Attributes
    ----------
    model : KinematicModel or None
        ``joint_states``: the robot's kinematic model (required).
    joint_state_topic : str or None
        ``joint_states``: the JointState topic (default ``/joint_states``, else the only one).
    """

    model: KinematicModel | None = None
    joint_state_topic: str | None = None


@dataclass(frozen=True)
class FlangePoses:
    """The flange-pose stream of a run and where it came from.

    Attributes
    ----------
    poses : list of FlangePose
        ``T_base_flange`` (4, 4) in m, sorted by stamp.
    base_frame : str
        Frame of the poses (the result's base frame).
    description : str
        Where they came from, for the printed input line (e.g. ``'1200 on /flange_pose'``).
    """

    poses: list[FlangePose]
    base_frame: str
    description: str


def poses_from_pose_topic(bag: BagContents, request: PoseRequest) -> FlangePoses:
    """The PoseStamped flange poses ``read_bag`` read."""
    return FlangePoses(
        bag.poses,
        bag.base_frame,
        f"{len(bag.poses)} poses on {bag.pose_topic} (frame {bag.base_frame})",
    )


def poses_from_joint_states(bag: BagContents, request: PoseRequest) -> FlangePoses:
    """Forward kinematics of the bag's joint states through ``request.model``.

    Raises
    ------
    InputError
        Without a model, or when the joint states do not name the model's joints (both
        lists are given).
    BagError
        When the bag holds no JointState messages (its topics are listed).
    """
    model = request.model
    if model is None:
        raise InputError(
            "the joint_states pose source needs the robot's kinematic model: pass "
            "--kinematics ur5e, ur10e or a URDF file"
        )
    states = read_joint_states(bag.path, topic=request.joint_state_topic)
    try:
        poses = flange_poses_from_joint_states(model, states)
    except InputError as err:
        raise InputError(f"bag {bag.path}: {err}") from None
    return FlangePoses(
        poses,
        model.base_frame,
        f"{len(poses)} poses from joint states ({model.name} model, frame {model.base_frame})",
    )


#: One function per pose source; a new source adds its member and its function here.
POSE_SOURCES: dict[PoseSource, Callable[[BagContents, PoseRequest], FlangePoses]] = {
    PoseSource.POSE: poses_from_pose_topic,
    PoseSource.JOINT_STATES: poses_from_joint_states,
}
