# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""The calibration service's ``/tf_static``, as tf2_ros's static broadcaster sends it.

:class:`StaticTfPublisher` is a ``tf2_msgs/msg/TFMessage`` publisher on ``/tf_static``,
reliable, transient local, depth 1, whose one latched message holds every static transform
it has sent (the latest per child frame): a subscriber that starts later receives them all,
as from ``tf2_ros.StaticTransformBroadcaster``, with or without ``tf2_ros``. It also listens
to ``/tf_static`` and keeps the parent that other publishers (robot_state_publisher's fixed
joints) give each frame, for the check that the hand-eye would give the sensor frame a
second parent.

``tf2_msgs`` comes with every ROS 2 install; ``make venv`` builds it where the PyPI wheels
are all there is. Without it, :func:`static_tf_publisher` returns None and the service
publishes no ``/tf_static``.
"""

from __future__ import annotations

from typing import Any

from geometry_msgs.msg import TransformStamped
from rclpy.node import Node

from linelaser_calib.nodes.common import latched_qos
from linelaser_calib.nodes.tf_input import TF_STATIC_DEPTH

try:  # a ROS install has tf2_msgs, and make venv builds it; only the bare wheels lack it
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

TF_STATIC_TOPIC = "/tf_static"


class StaticTfPublisher:
    """Publishes static transforms on ``/tf_static`` and knows the other publishers' parents."""

    def __init__(self, node: Node) -> None:
        self._publisher = node.create_publisher(TFMessage, TF_STATIC_TOPIC, latched_qos(1))
        self._sent: dict[str, TransformStamped] = {}
        #: Parent of each frame as the other /tf_static publishers give it.
        self.parents: dict[str, str] = {}
        node.create_subscription(
            TFMessage, TF_STATIC_TOPIC, self._on_tf_static, latched_qos(TF_STATIC_DEPTH)
        )

    def send(self, transform: TransformStamped) -> None:
        """Add (or replace, by child frame) one static transform and publish them all."""
        self._sent[transform.child_frame_id] = transform
        self._publisher.publish(TFMessage(transforms=list(self._sent.values())))

    def _on_tf_static(self, msg: Any) -> None:
        for transform in msg.transforms:
            child, parent = transform.child_frame_id, transform.header.frame_id
            own = self._sent.get(child)
            if own is None or own.header.frame_id != parent:
                self.parents[child] = parent


def static_tf_publisher(node: Node) -> StaticTfPublisher | None:
    """The node's ``/tf_static`` publisher, or None without ``tf2_msgs``."""
    return None if TFMessage is None else StaticTfPublisher(node)
