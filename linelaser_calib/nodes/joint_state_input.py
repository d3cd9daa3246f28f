# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""Live flange poses from ``sensor_msgs/JointState`` (the collector's ``pose_source:
joint_states``).

Every joint state goes through the forward kinematics of the robot model
(:func:`~linelaser_calib.core.kinematics.flange_poses_from_joint_states`, the function the
offline ``--pose-source joint_states`` uses) and gives one flange pose at its stamp, which
then goes through the collector's ordinary pairing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.kinematics import (
    JointStates,
    KinematicModel,
    flange_poses_from_joint_states,
)
from linelaser_calib.core.types import FlangePose
from linelaser_calib.io.kinematics import load_model
from msg_adapters import MessageError, joint_state_from_msg

#: Topic of the joint states (remap it to the driver's).
JOINT_STATE_TOPIC = "joint_states"


def live_kinematic_model(spec: str, base_frame: str, flange_frame: str) -> KinematicModel:
    """The robot model of the ``kinematics`` parameter (pose_source joint_states).

    Raises
    ------
    InputError
        When the parameter is empty or names no usable model.
    """
    if not spec.strip():
        raise InputError(
            "pose_source joint_states needs the robot's kinematic model: set the kinematics "
            "parameter to a preset (ur5e, ur10e), a URDF file, or the URDF text of "
            "robot_description (e.g. -p kinematics:=ur5e)"
        )
    try:
        return load_model(spec, base_frame=base_frame, flange_frame=flange_frame)
    except InputError as err:
        raise InputError(f"kinematics parameter: {err}") from None


class JointStatePoseInput:
    """Subscribes ``joint_states`` and hands the flange pose of each message to ``on_pose``.

    Parameters
    ----------
    node : rclpy Node
    model : KinematicModel
        The robot's kinematic model; the poses are in its base frame.
    qos : QoSProfile
        QoS of the subscription.
    on_pose : callable(FlangePose)
    on_problem : callable(str)
        Called with the reason when a message gives no pose (undecodable, or a joint of the
        model missing from it: both name lists are given).
    """

    def __init__(
        self,
        node: Node,
        model: KinematicModel,
        qos: QoSProfile,
        on_pose: Callable[[FlangePose], None],
        on_problem: Callable[[str], None],
    ) -> None:
        self.model = model
        self._on_pose, self._on_problem = on_pose, on_problem
        self.subscription = node.create_subscription(
            JointState, JOINT_STATE_TOPIC, self._on_joint_state, qos
        )

    def _on_joint_state(self, msg: Any) -> None:
        try:
            record = joint_state_from_msg(msg)
            states = JointStates(
                record.names,
                np.array([record.stamp_ns], dtype=np.int64),
                record.positions[None, :],
            )
            (pose,) = flange_poses_from_joint_states(self.model, states)
        except (MessageError, InputError) as err:
            self._on_problem(str(err))
            return
        self._on_pose(pose)
