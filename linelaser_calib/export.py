"""A calibration result in the forms a ROS system loads: URDF joint, static TF, launch file,
and the robot's corrected kinematics as the UR description's kinematics YAML.

``linelaser-calib export RESULT.yaml --format urdf|static-tf|launch|ur-kinematics`` prints
one of them;
``launch/publish.launch.py`` publishes the result with :func:`static_transform_arguments`.
Numbers are written with ``repr`` (the shortest text that reads back to the same float), so
nothing is lost on the way: the URDF ``rpy`` gives the result's rotation back to 1e-15.
"""

from __future__ import annotations

import warnings
from enum import Enum

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    FloatArray,
    rpy_from_matrix,
    translation_quaternion_from_transform,
)
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import (
    UR_DH,
    UR_JOINT_NAMES,
    KinematicCorrections,
    model_from_preset,
)


class ExportFormat(Enum):
    """What ``export`` prints."""

    URDF = "urdf"
    STATIC_TF = "static-tf"
    LAUNCH = "launch"
    UR_KINEMATICS = "ur-kinematics"


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
    """The sensor's URDF ``<link>`` and the fixed ``<joint>`` from the flange link to it, to
    paste inside the robot's ``<robot>`` element (which holds the flange link).

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
            f"<!-- paste both inside the <robot> element that holds the link "
            f"{result.parent_frame} -->",
            f'<link name="{result.child_frame}"/>',
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


#: Segment names of the UR description's kinematics YAML, one per joint (its origin).
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _elementary(axis: str, amount: float) -> FloatArray:
    """(4, 4) translation along (``tx``...) or rotation about (``rx``, ``rz``) an axis."""
    T = np.eye(4)
    if axis.startswith("t"):
        T["xyz".index(axis[1]), 3] = amount
        return T
    c, s = np.cos(amount), np.sin(amount)
    i, j = {"rx": (1, 2), "rz": (0, 1)}[axis]
    T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
    return T


def ur_kinematics_yaml(corrections: KinematicCorrections) -> str:
    """The corrected UR arm as the ``kinematics`` YAML that UR's ROS description loads.

    Joint i's origin (its parent link to the joint frame, before the joint's rotation about
    z) is ``Tx(a[i-1]) · Rx(alpha[i-1]) · Tz(d[i]) · Rz(offset[i])`` of the corrected DH
    table (joint 0: ``Tz(d[0]) · Rz(offset[0])``, after the description's 180° turn of
    ``base_link_inertia``), written as x, y, z (m) and roll, pitch, yaw (rad). With the
    nominal table this gives the description's default kinematics.

    Raises
    ------
    InputError
        Corrections that are not for a UR preset, or that change the last link's a or alpha
        (the description's wrist_3 -> tool0 transform is fixed and cannot hold them).
    """
    if corrections.model not in UR_DH:
        raise InputError(
            f"the kinematic corrections are for the model {corrections.model!r}; the "
            f"ur-kinematics format takes a UR preset ({', '.join(sorted(UR_DH))})"
        )
    model = corrections.apply(model_from_preset(corrections.model))
    value = dict(zip(model.parameter_names, model.parameters, strict=True))
    last = UR_JOINT_NAMES[-1]
    fixed = [
        name
        for name in (f"{last}.a", f"{last}.alpha")
        if abs(corrections.corrections.get(name, 0.0)) > 0.0
    ]
    if fixed:
        raise InputError(
            f"the corrections change {', '.join(fixed)}, which the UR description's fixed "
            "wrist_3 -> tool0 transform cannot hold; fold them into the hand-eye or export "
            "another format"
        )
    lines = [
        f"# Kinematics of a {corrections.model} corrected by linelaser_calib: joint origins,",
        "# x y z in m and roll pitch yaw in rad (fixed axes), for UR's ROS description",
        "# (kinematics_params:=FILE). Not from the robot's own calibration: its hash differs.",
        "kinematics:",
    ]
    for i, (joint, segment) in enumerate(zip(UR_JOINT_NAMES, UR_SEGMENTS, strict=True)):
        T = np.eye(4)
        if i:
            previous = UR_JOINT_NAMES[i - 1]
            T = _elementary("tx", value[f"{previous}.a"]) @ _elementary(
                "rx", value[f"{previous}.alpha"]
            )
        T = T @ _elementary("tz", value[f"{joint}.d"]) @ _elementary("rz", value[f"{joint}.offset"])
        lines.append(f"  {segment}:")
        for key, number in zip(
            ("x", "y", "z", "roll", "pitch", "yaw"),
            _numbers(np.concatenate([T[:3, 3], rpy_of(T)])),
            strict=True,
        ):
            lines.append(f"    {key}: {number}")
    lines.append("  hash: linelaser_calib")
    return "\n".join(lines)


def scale_note(result: CalibrationResult) -> str:
    """What no transform can carry: the sensor's along-line (x) and depth (z) scales, where
    the result estimated them (cylinder, sphere and line targets), one line each for people
    (%), or ''."""
    notes = []
    for name, axis, coordinate in (
        ("scale", "along-line (x)", "x"),
        ("depth_scale", "depth (z)", "z"),
    ):
        scale = getattr(result.target, name, None)
        if scale is None:
            continue
        sigma = getattr(result.target, f"{name}_sigma", None)
        spread = "" if sigma is None else f" +- {100.0 * sigma:.2f} %"
        notes.append(
            f"note: the sensor's {axis} scale was estimated as {1.0 + scale:.5f} "
            f"({coordinate} reads {100.0 * scale:+.2f} %{spread} of the true length); no "
            f"transform carries it, so this export does not: divide the profiles' {coordinate} "
            f"by {1.0 + scale:.5f} in the driver or its configuration if the error is real (its "
            "1 sigma is the noise model's)"
        )
    return "\n".join(notes)


def export_text(result: CalibrationResult, form: ExportFormat) -> str:
    """The result as ``form`` (not ``ur-kinematics``: see :func:`ur_kinematics_yaml`)."""
    if form is ExportFormat.URDF:
        return urdf_joint(result)
    if form is ExportFormat.STATIC_TF:
        return static_tf_command(result)
    return launch_file(result)
