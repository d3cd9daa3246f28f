"""``geometry_msgs/msg/TransformStamped`` <-> 4x4 transforms (the hand-eye result, /tf)."""

from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike

from linelaser_calib.core.tf import StampedTransform
from msg_adapters.message_types import TypeResolver, header_msg, stamp_ns_from_msg, vector_fields
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
