"""``geometry_msgs/msg/TransformStamped`` <-> 4x4 transforms (the hand-eye result, /tf)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.geometry import (
    QUATERNION_NORM_TOLERANCE,
    matrices_from_quaternions_xyzw,
)
from linelaser_calib.core.tf import StampedTransform
from msg_adapters.errors import MessageError
from msg_adapters.message_types import (
    TypeResolver,
    header_msg,
    stamp_ns_from_msg,
    vector_fields,
    vector_from_msg,
)
from msg_adapters.pose import checked_translation_quaternion, transform_from_vector_quaternion_msgs


def transform_stamped_from_matrix(
    T_parent_child: ArrayLike,
    stamp_ns: int,
    parent_frame: str,
    child_frame: str,
    *,
    types: TypeResolver,
) -> Any:
    """TransformStamped giving the pose of ``child_frame`` in ``parent_frame``.

    Parameters
    ----------
    T_parent_child : array-like, shape (4, 4)
        Rigid transform mapping child coordinates into the parent frame (translation in m),
        e.g. ``T_flange_sensor`` with parent ``tool0`` and child ``laser``.
    stamp_ns : int
        Header stamp, ns.
    parent_frame, child_frame : str
        ``header.frame_id`` and ``child_frame_id``.
    types : TypeResolver

    Raises
    ------
    MessageError
        If ``T_parent_child`` is not a rigid transform.
    """
    translation, q_xyzw = checked_translation_quaternion(T_parent_child, "TransformStamped")
    return types("geometry_msgs/msg/TransformStamped")(
        header=header_msg(stamp_ns, parent_frame, types),
        child_frame_id=str(child_frame),
        transform=types("geometry_msgs/msg/Transform")(
            translation=types("geometry_msgs/msg/Vector3")(**vector_fields(translation)),
            rotation=types("geometry_msgs/msg/Quaternion")(**vector_fields(q_xyzw, "xyzw")),
        ),
    )


def stamped_transform_from_msg(msg: Any) -> StampedTransform:
    """The transform of a ``geometry_msgs/msg/TransformStamped`` (e.g. one of a /tf message).

    Raises
    ------
    MessageError
        For a NaN translation or a zero, NaN or non-unit rotation quaternion; the message
        names the frames and the stamp.
    """
    stamp_ns = stamp_ns_from_msg(msg.header.stamp)
    parent, child = str(msg.header.frame_id), str(msg.child_frame_id)
    what = f"TransformStamped {parent} -> {child} at stamp {stamp_ns} ns"
    T = transform_from_vector_quaternion_msgs(
        msg.transform.translation, msg.transform.rotation, what
    )
    return StampedTransform(stamp_ns, parent, child, T)


def stamped_transforms_from_msgs(msgs: Sequence[Any]) -> list[StampedTransform | str]:
    """:func:`stamped_transform_from_msg` of many TransformStamped at once (a /tf recording).

    The quaternions are checked and turned into matrices in one vectorised pass; a message
    that fails a check goes through :func:`stamped_transform_from_msg` for its reason.

    Returns
    -------
    list of StampedTransform or str
        One per message, in order; a str is why that message is unusable.
    """
    count = len(msgs)
    values = np.array(
        [
            vector_from_msg(m.transform.translation).tolist()
            + vector_from_msg(m.transform.rotation, "xyzw").tolist()
            for m in msgs
        ],
        dtype=np.float64,
    ).reshape(count, 7)
    norm = np.linalg.norm(values[:, 3:], axis=1)
    with np.errstate(invalid="ignore"):
        good = np.all(np.isfinite(values), axis=1) & (
            np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE
        )
    T = np.zeros((count, 4, 4))
    T[:, 3, 3] = 1.0
    T[:, :3, 3] = values[:, :3]
    if good.any():
        T[good, :3, :3] = matrices_from_quaternions_xyzw(values[good, 3:])
    out: list[StampedTransform | str] = []
    for k, msg in enumerate(msgs):
        if not good[k]:
            try:
                out.append(stamped_transform_from_msg(msg))
            except MessageError as err:
                out.append(str(err))
            continue
        out.append(
            StampedTransform(
                stamp_ns_from_msg(msg.header.stamp),
                str(msg.header.frame_id),
                str(msg.child_frame_id),
                T[k],
            )
        )
    return out
