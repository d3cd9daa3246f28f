# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""Live flange poses from ``/tf`` and ``/tf_static`` (the collector's ``pose_source: tf``).

The transforms go into the same :class:`~linelaser_calib.core.tf.TransformTree` as offline;
each ``/tf`` message that moves a dynamic link of the chain base frame -> flange frame
gives one flange pose at its stamp, which then goes through the collector's ordinary
pairing. ``/tf`` is subscribed with the QoS of the other pose inputs (a deep keep-last
history; best effort by default, which hears reliable publishers such as
robot_state_publisher and best-effort ones alike; reliable with ``reliable_inputs``, which
loses nothing under load); ``/tf_static`` reliable and transient local, so static transforms
sent before the collector started arrive too; when they complete the chain, the /tf
transforms already buffered give their flange poses. When a profile finds no flange pose,
:meth:`TfPoseInput.why_no_pose` names the link that is missing or stale.

``tf2_msgs`` comes with every ROS 2 install; ``make venv`` builds it where the PyPI wheels
are all there is (resource/tf2_msgs). Without it, :class:`TfPoseInput` refuses to start
with a clear message.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.tf import (
    StampedTransform,
    TfChainError,
    TransformTree,
    live_flange_poses,
)
from linelaser_calib.core.types import FlangePose
from linelaser_calib.nodes.common import latched_qos
from linelaser_calib.settings import Front, render
from msg_adapters import stamped_transforms_from_msgs

try:  # a full ROS install has tf2_msgs; the PyPI wheels do not
    from tf2_msgs.msg import TFMessage
except ImportError as err:
    _MISSING: ImportError | None = err
else:
    _MISSING = None

#: Depth of the /tf_static subscription (publishers latch one message each).
TF_STATIC_DEPTH = 100


class TfPoseInput:
    """Subscribes ``/tf`` and ``/tf_static`` and hands flange poses to ``on_pose``.

    Parameters
    ----------
    node : rclpy Node
    base_frame, flange_frame : str
        The chain's ends.
    tolerance_s : float
        Largest gap to another dynamic transform interpolated at a stamp, s.
    max_age_s : float
        Dynamic transforms kept behind the newest of their link, s.
    qos : QoSProfile
        QoS of the ``/tf`` subscription.
    on_pose : callable(FlangePose)
    on_problem : callable(str)
        Called with the reason when a message gives no pose (e.g. the chain is incomplete).

    Raises
    ------
    InputError
        Without ``tf2_msgs``.
    """

    def __init__(
        self,
        node: Node,
        base_frame: str,
        flange_frame: str,
        tolerance_s: float,
        max_age_s: float,
        qos: QoSProfile,
        on_pose: Callable[[FlangePose], None],
        on_problem: Callable[[str], None],
    ) -> None:
        if _MISSING is not None:
            raise InputError(
                f"pose_source 'tf' needs the tf2_msgs message package ({_MISSING}), part of "
                "every ROS 2 install and built into .venv by `make venv` (cmake and a C/C++ "
                "compiler needed); source the install or run make venv, or publish the flange "
                "pose as geometry_msgs/PoseStamped and use pose_source 'pose'"
            )
        self.tree = TransformTree(max_age_s)
        self._base, self._flange, self._tolerance_s = base_frame, flange_frame, tolerance_s
        self._on_pose, self._on_problem = on_pose, on_problem
        node.create_subscription(TFMessage, "/tf", self._on_tf, qos)
        node.create_subscription(
            TFMessage, "/tf_static", self._on_tf_static, latched_qos(TF_STATIC_DEPTH)
        )

    def _transforms(self, msg: Any) -> list[StampedTransform]:
        transforms = []
        for item in stamped_transforms_from_msgs(msg.transforms):
            if isinstance(item, str):
                self._on_problem(item)
            else:
                transforms.append(item)
        return transforms

    def _moving_chain(self) -> bool:
        """True when the tree links the base to the flange through a dynamic link."""
        try:
            up, down = self.tree.chain(self._base, self._flange)
        except TfChainError:
            return False
        return not all(edge.static for edge in up + down)

    def _on_tf_static(self, msg: Any) -> None:
        """Add static transforms; when they complete the chain, the /tf transforms already
        buffered give their flange poses (as a tf2 buffer answers for past stamps)."""
        linked = self._moving_chain()
        self.tree.extend(self._transforms(msg), static=True)
        if not linked and self._moving_chain():
            for pose in self.tree.flange_poses(self._base, self._flange, self._tolerance_s):
                self._on_pose(pose)

    def _on_tf(self, msg: Any) -> None:
        poses, problems = live_flange_poses(
            self.tree, self._transforms(msg), self._base, self._flange, self._tolerance_s
        )
        for problem in problems:
            self._on_problem(render(problem, Front.NODE))
        for pose in poses:
            self._on_pose(pose)

    def why_no_pose(self, stamp_ns: int) -> str | None:
        """Why the TF tree gives no flange pose at ``stamp_ns`` (the frames), or None."""
        why = self.tree.why_no_pose(self._base, self._flange, stamp_ns, self._tolerance_s)
        return None if why is None else render(why, Front.NODE)
