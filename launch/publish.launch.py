"""Publish a calibration result's hand-eye on /tf_static.

    ros2 launch linelaser_calib publish.launch.py calibration:=RESULT.yaml

Runs ``tf2_ros static_transform_publisher`` with the result's translation, rotation and
frames (``hand_eye.parent_frame`` -> ``hand_eye.child_frame``). Needs a ROS 2 install with
``launch`` and ``launch_ros`` (not on PyPI); without them the file still imports,
:func:`node_arguments` still says what would be published, and
:func:`generate_launch_description` says what is missing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from linelaser_calib.export import static_transform_arguments
from linelaser_calib.io.results import read_result_yaml

try:
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    from launch import LaunchDescription
except ImportError as err:
    _MISSING: ImportError | None = err
else:
    _MISSING = None

#: Where calibration_service writes its result by default (its output_path parameter).
DEFAULT_CALIBRATION = "~/.ros/linelaser_calib/hand_eye.yaml"


def node_arguments(calibration: str) -> list[str]:
    """``static_transform_publisher`` arguments for the result file ``calibration``.

    Raises
    ------
    ResultFileError
        When the file is missing or is not a result.
    """
    return static_transform_arguments(read_result_yaml(Path(calibration).expanduser()))


def _publisher(context: Any) -> list[Any]:
    calibration = LaunchConfiguration("calibration").perform(context)
    return [
        Node(
            package="tf2_ros",
            executable="static_transform_publisher",
            name="linelaser_calib_hand_eye",
            arguments=node_arguments(calibration),
            output="screen",
        )
    ]


def generate_launch_description() -> Any:
    """The ``calibration`` argument and the static transform publisher it configures."""
    if _MISSING is not None:
        raise RuntimeError(
            f"this launch file needs the ROS 2 launch packages ({_MISSING}); source a ROS 2 "
            "install, or print the equivalent command with "
            "`linelaser-calib export RESULT.yaml --format static-tf`"
        )
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "calibration",
                default_value=DEFAULT_CALIBRATION,
                description="Result YAML of linelaser_calib (hand_eye section)",
            ),
            OpaqueFunction(function=_publisher),
        ]
    )
