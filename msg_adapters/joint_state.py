"""``sensor_msgs/msg/JointState`` <-> joint vectors (names, positions in rad or m)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_adapters.errors import MessageError
from msg_adapters.message_types import TypeResolver, header_msg, stamp_ns_from_msg


class JointStateRecord(NamedTuple):
    """One joint state: stamp (ns), joint names and positions (n,) in rad or m."""

    stamp_ns: int
    names: tuple[str, ...]
    positions: NDArray[np.float64]


def joint_state_from_msg(msg: Any) -> JointStateRecord:
    """Stamp, names and positions of a JointState (rclpy message or rosbags dataclass).

    Raises
    ------
    MessageError
        If the names and positions differ in number or a position is NaN/Inf.
    """
    names = tuple(str(n) for n in msg.name)
    positions = np.asarray(msg.position, dtype=np.float64).reshape(-1)
    if len(names) != len(positions):
        raise MessageError(
            f"JointState names {len(names)} joints but holds {len(positions)} positions"
        )
    if not np.all(np.isfinite(positions)):
        raise MessageError(f"JointState positions contain NaN or Inf: {positions}")
    return JointStateRecord(stamp_ns_from_msg(msg.header.stamp), names, positions)


def joint_state_msg(
    stamp_ns: int,
    names: Sequence[str],
    positions: ArrayLike,
    *,
    types: TypeResolver,
) -> Any:
    """A JointState with positions only (velocity and effort empty), frame id empty."""
    cls = types("sensor_msgs/msg/JointState")
    values = np.asarray(positions, dtype=np.float64).reshape(-1)
    if len(values) != len(names):
        raise MessageError(f"{len(names)} joint names for {len(values)} positions")

    def array(data: NDArray[np.float64]) -> Any:
        return data if dataclasses.is_dataclass(cls) else data.tolist()

    return cls(
        header=header_msg(stamp_ns, "", types),
        name=list(names),
        position=array(values),
        velocity=array(np.zeros(0)),
        effort=array(np.zeros(0)),
    )
