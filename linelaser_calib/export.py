"""A calibration result in the forms a ROS system loads: URDF joint, static TF, launch file.

``linelaser-calib export RESULT.yaml --format urdf|static-tf|launch`` prints one of them;
``launch/publish.launch.py`` publishes the result with :func:`static_transform_arguments`.
Numbers are written with ``repr`` (the shortest text that reads back to the same float), so
nothing is lost on the way: the URDF ``rpy`` gives the result's rotation back to 1e-15.
"""

from __future__ import annotations

import warnings
from enum import Enum

import numpy as np

from linelaser_calib.core.geometry import (
    FloatArray,
    rpy_from_matrix,
    translation_quaternion_from_transform,
)
from linelaser_calib.core.types import CalibrationResult


class ExportFormat(Enum):
    """What ``export`` prints."""

    URDF = "urdf"
    STATIC_TF = "static-tf"
    LAUNCH = "launch"


def _numbers(values: FloatArray) -> list[str]:
    return [repr(float(v)) for v in values]


def rpy_of(T: FloatArray) -> FloatArray:
    """Roll, pitch, yaw (3,) in rad of a (4, 4) transform, URDF's fixed-axis x-y-z."""
    with warnings.catch_warnings():
        # At pitch +-90 deg roll and yaw share one axis: one of them is set to 0, exactly.
        warnings.simplefilter("ignore", UserWarning)
        return rpy_from_matrix(T[:3, :3])


def static_transform_arguments(result: CalibrationResult) -> list[str]:
    """Arguments of Jazzy's ``tf2_ros static_transform_publisher`` for the hand-eye.

    Returns
    -------
    list of str
        ``--x X --y Y --z Z --qx .. --qy .. --qz .. --qw .. --frame-id PARENT
        --child-frame-id CHILD`` (translation in m, quaternion ``xyzw``).
    """
    translation, q_xyzw = translation_quaternion_from_transform(result.T_flange_sensor)
    words: list[str] = []
    for flag, value in zip(
        ("--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw"),
        _numbers(np.concatenate([translation, q_xyzw])),
        strict=True,
    ):
        words += [flag, value]
    return [*words, "--frame-id", result.parent_frame, "--child-frame-id", result.child_frame]


def _sigma_note(result: CalibrationResult) -> str:
    """One line with the 1-sigma of the hand-eye, in mm and deg, or '' without one."""
    if result.uncertainty_translation_m is None or result.uncertainty_rotation_rad is None:
        return ""
    mm = ", ".join(f"{v * 1e3:.3f}" for v in result.uncertainty_translation_m)
    deg = ", ".join(f"{np.degrees(v):.4f}" for v in result.uncertainty_rotation_rad)
    return f"1 sigma: translation [{mm}] mm, rotation [{deg}] deg"


def urdf_joint(result: CalibrationResult) -> str:
    """A fixed URDF ``<joint>`` from the flange link to the sensor link.

    ``xyz`` in m and ``rpy`` in rad (fixed axes x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll)).
    """
    xyz = " ".join(_numbers(result.T_flange_sensor[:3, 3]))
    rpy = " ".join(_numbers(rpy_of(result.T_flange_sensor)))
    note = _sigma_note(result)
    comment = f"<!-- hand-eye T_{result.parent_frame}_{result.child_frame} (linelaser_calib"
    comment += f", method {result.method}){'; ' + note if note else ''} -->"
    return "\n".join(
        [
            comment,
            f'<joint name="{result.child_frame}_joint" type="fixed">',
            f'  <parent link="{result.parent_frame}"/>',
            f'  <child link="{result.child_frame}"/>',
            f'  <origin xyz="{xyz}" rpy="{rpy}"/>',
            "</joint>",
        ]
    )


def static_tf_command(result: CalibrationResult) -> str:
    """The ``ros2 run tf2_ros static_transform_publisher ...`` command line (Jazzy flags)."""
    words = ["ros2", "run", "tf2_ros", "static_transform_publisher"]
    return " ".join([*words, *static_transform_arguments(result)])


_LAUNCH_BODY = """

from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    return LaunchDescription(
        [
            Node(
                package="tf2_ros",
                executable="static_transform_publisher",
                name="{name}",
                arguments=[
{arguments}
                ],
            )
        ]
    )
"""


def launch_file(result: CalibrationResult) -> str:
    """A Python launch file that publishes the hand-eye with static_transform_publisher."""
    doc = [
        f'"""Publish the hand-eye {result.parent_frame} -> {result.child_frame} on /tf_static.',
        "",
        f"Written by `linelaser-calib export --format launch` (method {result.method}).",
    ]
    note = _sigma_note(result)
    doc += [note, '"""'] if note else ['"""']
    arguments = "\n".join(
        f"                    {word!r}," for word in static_transform_arguments(result)
    )
    return "\n".join(doc) + _LAUNCH_BODY.format(
        name=f"{result.child_frame}_hand_eye", arguments=arguments
    )


def export_text(result: CalibrationResult, form: ExportFormat) -> str:
    """The result as ``form``."""
    if form is ExportFormat.URDF:
        return urdf_joint(result)
    if form is ExportFormat.STATIC_TF:
        return static_tf_command(result)
    return launch_file(result)
