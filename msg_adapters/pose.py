"""``geometry_msgs/msg/PoseStamped`` <-> flange poses (stamp, 4x4 ``T_base_flange``, frame).

The quaternion of a received pose is validated and normalised with
:func:`linelaser_calib.core.geometry.check_quaternion_xyzw`; a zero, NaN or clearly non-unit
quaternion raises :class:`~msg_adapters.errors.MessageError`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linelaser_calib.core.geometry import (
    check_quaternion_xyzw,
    check_transform,
    transform_from_translation_quaternion,
    translation_quaternion_from_transform,
)
from linelaser_calib.core.types import FlangePose
from msg_adapters.errors import MessageError
from msg_adapters.message_types import (
    TypeResolver,
    header_msg,
    stamp_ns_from_msg,
    vector_fields,
    vector_from_msg,
)

FloatArray = NDArray[np.float64]

#: Orthonormality tolerance on outgoing transforms (float32-rounded inputs pass).
ROTATION_TOLERANCE = 1e-4


def transform_from_vector_quaternion_msgs(position: Any, orientation: Any, what: str) -> FloatArray:
    """4x4 transform from a Point or Vector3 (m) and a Quaternion (xyzw) message.

    Parameters
    ----------
    position : geometry_msgs/msg/Point or Vector3
    orientation : geometry_msgs/msg/Quaternion
    what : str
        Names the message in error messages (e.g. ``'PoseStamped at 12.5 s'``).

    Raises
    ------
    MessageError
        NaN/Inf position, or a zero, NaN or non-unit quaternion.
    """
    translation = vector_from_msg(position)
    if not np.all(np.isfinite(translation)):
        raise MessageError(f"{what}: position contains NaN or Inf: {translation} m")
    try:
        q_xyzw = check_quaternion_xyzw(vector_from_msg(orientation, "xyzw"))
    except ValueError as err:
        raise MessageError(f"{what}: invalid orientation: {err}") from None
    return transform_from_translation_quaternion(translation, q_xyzw)


def transform_from_pose_msg(pose: Any, what: str = "pose") -> FloatArray:
    """4x4 transform from a ``geometry_msgs/msg/Pose`` (position m, orientation xyzw).

    Raises
    ------
    MessageError
        See :func:`transform_from_vector_quaternion_msgs`; ``what`` names the pose.
    """
    return transform_from_vector_quaternion_msgs(pose.position, pose.orientation, what)


def checked_translation_quaternion(T: ArrayLike, what: str) -> tuple[FloatArray, FloatArray]:
    """Translation (3,) in m and ``xyzw`` quaternion (4,) of a rigid 4x4 transform.

    Raises
    ------
    MessageError
        If ``T`` is not a rigid transform; ``what`` names the message being built.
    """
    try:
        return translation_quaternion_from_transform(check_transform(T, ROTATION_TOLERANCE))
    except ValueError as err:
        raise MessageError(f"cannot build a {what}: {err}") from None


def pose_msg_from_transform(T: ArrayLike, types: TypeResolver) -> Any:
    """``geometry_msgs/msg/Pose`` from a rigid 4x4 transform (translation in m)."""
    translation, q_xyzw = checked_translation_quaternion(T, "Pose")
    return types("geometry_msgs/msg/Pose")(
        position=types("geometry_msgs/msg/Point")(**vector_fields(translation)),
        orientation=types("geometry_msgs/msg/Quaternion")(**vector_fields(q_xyzw, "xyzw")),
    )


def flange_pose_from_pose_stamped(msg: Any) -> FlangePose:
    """Flange pose (stamp ns, ``T_base_flange`` (4, 4), base frame) from a PoseStamped.

    Raises
    ------
    MessageError
        For a NaN position or a zero/NaN/non-unit quaternion; the message names the stamp.
    """
    stamp_ns = stamp_ns_from_msg(msg.header.stamp)
    frame_id = str(msg.header.frame_id)
    what = f"PoseStamped at stamp {stamp_ns} ns in frame {frame_id!r}"
    return FlangePose(
        stamp_ns=stamp_ns,
        T_base_flange=transform_from_pose_msg(msg.pose, what),
        frame_id=frame_id,
    )


def pose_stamped_from_flange_pose(pose: FlangePose, *, types: TypeResolver) -> Any:
    """``geometry_msgs/msg/PoseStamped`` of a flange pose, in its base frame."""
    return types("geometry_msgs/msg/PoseStamped")(
        header=header_msg(pose.stamp_ns, pose.frame_id, types),
        pose=pose_msg_from_transform(pose.T_base_flange, types),
    )


def pose_array_from_transforms(
    T: ArrayLike, frame_id: str, stamp_ns: int, *, types: TypeResolver
) -> Any:
    """``geometry_msgs/msg/PoseArray`` of rigid transforms (K, 4, 4) (m) in ``frame_id``."""
    return types("geometry_msgs/msg/PoseArray")(
        header=header_msg(stamp_ns, frame_id, types),
        poses=[pose_msg_from_transform(one, types) for one in np.asarray(T, dtype=np.float64)],
    )
