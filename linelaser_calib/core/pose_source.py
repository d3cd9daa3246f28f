"""Where the flange pose of each profile comes from: one source per run."""

from __future__ import annotations

from enum import Enum


class PoseSource(Enum):
    """The flange-pose sources, offline (``calibrate --pose-source``) and live (``pose_source``).

    ``pose``: ``geometry_msgs/PoseStamped`` of the flange in the base frame (e.g. UR's
    tcp_pose_broadcaster). ``tf``: the chain base frame -> flange frame from ``/tf`` and
    ``/tf_static`` (robot_state_publisher, MoveIt), each dynamic transform interpolated.
    ``joint_states``: forward kinematics of every ``sensor_msgs/JointState`` through the
    robot's kinematic model (:mod:`linelaser_calib.core.robot.kinematics`).
    """

    POSE = "pose"
    TF = "tf"
    JOINT_STATES = "joint_states"
