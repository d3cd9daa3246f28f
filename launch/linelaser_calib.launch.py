"""Launch the collector and the calibration service with their parameter files.

    ros2 launch linelaser_calib linelaser_calib.launch.py \
        profile_topic:=/scancontrol_pointcloud flange_pose_topic:=/tcp_pose_broadcaster/pose

Needs a ROS 2 install with ``launch`` and ``launch_ros`` (not on PyPI); without them the file
still imports, and :func:`generate_launch_description` says what is missing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

try:
    from ament_index_python.packages import get_package_share_directory
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    from launch import LaunchDescription
except ImportError as err:
    _MISSING: ImportError | None = err
else:
    _MISSING = None

PACKAGE = "linelaser_calib"


def generate_launch_description() -> Any:
    """Both nodes, their config/*.yaml parameters, and the two input topics as arguments."""
    if _MISSING is not None:
        raise RuntimeError(
            f"this launch file needs the ROS 2 launch packages ({_MISSING}); source a ROS 2 "
            "install, or start the nodes with `ros2 run linelaser_calib collector` and "
            "`ros2 run linelaser_calib calibration_service`"
        )
    config = Path(get_package_share_directory(PACKAGE)) / "config"
    profile_topic = LaunchConfiguration("profile_topic")
    flange_pose_topic = LaunchConfiguration("flange_pose_topic")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "profile_topic", default_value="profile", description="PointCloud2 profiles"
            ),
            DeclareLaunchArgument(
                "flange_pose_topic",
                default_value="flange_pose",
                description="PoseStamped flange poses in the robot base frame",
            ),
            Node(
                package=PACKAGE,
                executable="collector",
                parameters=[str(config / "collector.yaml")],
                remappings=[("profile", profile_topic), ("flange_pose", flange_pose_topic)],
                output="screen",
            ),
            Node(
                package=PACKAGE,
                executable="calibration_service",
                parameters=[str(config / "calibration_service.yaml")],
                output="screen",
            ),
        ]
    )
