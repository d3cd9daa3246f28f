# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""Live flange poses from ``sensor_msgs/JointState`` (the collector's ``pose_source:
joint_states``).

Every joint state goes through the forward kinematics of the robot model
(:func:`~linelaser_calib.core.robot.kinematics.flange_poses_from_joint_states`, the function the
offline ``--pose-source joint_states`` uses) and gives one flange pose at its stamp, which
then goes through the collector's ordinary pairing.
"""

from __future__ import annotations

import bisect
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import (
    JointStates,
    KinematicModel,
    flange_poses_from_joint_states,
)
from linelaser_calib.core.types import FlangePose, FloatArray
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


#: How long the joint vectors are kept for storing each sample's (:meth:`JointStatePoseInput.
#: joints_at`), s: samples are stored within a few seconds of their profile.
JOINT_HISTORY_S = 30.0


class JointStatePoseInput:
    """Subscribes ``joint_states`` and hands the flange pose of each message to ``on_pose``.

    It keeps the last :data:`JOINT_HISTORY_S` of joint vectors (in the model's joint order), so
    that the collector stores each sample's joint vector with it: the session can then be
    calibrated with the robot's kinematics.

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
        self._lock = threading.Lock()
        self._stamps: deque[int] = deque()
        self._positions: deque[FloatArray] = deque()
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
        self._keep(record.stamp_ns, record.names, record.positions)
        self._on_pose(pose)

    def _keep(self, stamp_ns: int, names: tuple[str, ...], positions: FloatArray) -> None:
        """Keep a joint vector (in the model's order); a stamp going back clears the history."""
        q = positions[[names.index(j) for j in self.model.joint_names]]
        horizon = stamp_ns - round(JOINT_HISTORY_S * 1e9)
        with self._lock:
            if self._stamps and stamp_ns <= self._stamps[-1]:
                self._stamps.clear()
                self._positions.clear()
            self._stamps.append(stamp_ns)
            self._positions.append(q)
            while self._stamps[0] < horizon:
                self._stamps.popleft()
                self._positions.popleft()

    def joints_at(self, stamp_ns: int) -> tuple[tuple[str, ...], FloatArray] | None:
        """The model's joint names and the joint vector at ``stamp_ns`` (interpolated
        linearly between the bracketing messages, rad or m), or None outside the history."""
        with self._lock:
            stamps = list(self._stamps)
            k = bisect.bisect_left(stamps, stamp_ns)
            if k == len(stamps) or (stamps[k] != stamp_ns and k == 0):
                return None
            if stamps[k] == stamp_ns:
                return self.model.joint_names, self._positions[k].copy()
            w = (stamp_ns - stamps[k - 1]) / (stamps[k] - stamps[k - 1])
            q = (1.0 - w) * self._positions[k - 1] + w * self._positions[k]
        return self.model.joint_names, q
