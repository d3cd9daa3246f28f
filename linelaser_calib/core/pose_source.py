"""Where the flange pose of each profile comes from: one source per run."""

from __future__ import annotations

from enum import Enum


class PoseSource(Enum):
    """The flange-pose sources (``calibrate --pose-source``, ``reconstruct --pose-source``).

    ``pose``: ``geometry_msgs/PoseStamped`` of the flange in the base frame (e.g. UR's
    tcp_pose_broadcaster). ``joint_states``: forward kinematics of every
    ``sensor_msgs/JointState`` through the robot's kinematic model
    (:mod:`linelaser_calib.core.kinematics`).
    """

    POSE = "pose"
    JOINT_STATES = "joint_states"
