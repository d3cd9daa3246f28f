"""ROS message <-> numpy adapters for rclpy message objects and rosbags dataclasses alike.

Reading needs only the field names, so any message world works. Building needs the message
classes: pass ``types=rclpy_types()`` (live nodes) or ``types=rosbags_types(typestore)``
(bag files). Malformed messages raise :class:`MessageError`.
"""

from __future__ import annotations

from msg_adapters.errors import MessageError
from msg_adapters.joint_state import JointStateRecord, joint_state_from_msg, joint_state_msg
from msg_adapters.markers import cylinder_marker, marker_array, points_marker, shape_markers
from msg_adapters.message_types import (
    TypeResolver,
    rclpy_types,
    rosbags_types,
    stamp_ns_from_msg,
    time_msg_from_ns,
)
from msg_adapters.pointcloud2 import (
    DecodedCloud,
    cloud_from_pointcloud2,
    pointcloud2_from_points,
    points_from_pointcloud2,
    profile_from_pointcloud2,
)
from msg_adapters.pose import (
    flange_pose_from_pose_stamped,
    pose_array_from_transforms,
    pose_stamped_from_flange_pose,
)
from msg_adapters.transform import (
    stamped_transform_from_msg,
    stamped_transforms_from_msgs,
    transform_stamped_from_matrix,
)

__all__ = [
    "DecodedCloud",
    "JointStateRecord",
    "MessageError",
    "TypeResolver",
    "cloud_from_pointcloud2",
    "cylinder_marker",
    "flange_pose_from_pose_stamped",
    "joint_state_from_msg",
    "joint_state_msg",
    "marker_array",
    "pointcloud2_from_points",
    "points_from_pointcloud2",
    "points_marker",
    "pose_array_from_transforms",
    "pose_stamped_from_flange_pose",
    "profile_from_pointcloud2",
    "rclpy_types",
    "rosbags_types",
    "shape_markers",
    "stamp_ns_from_msg",
    "stamped_transform_from_msg",
    "stamped_transforms_from_msgs",
    "time_msg_from_ns",
    "transform_stamped_from_matrix",
]
