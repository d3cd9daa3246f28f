"""Message classes from either message world, and the small building blocks shared by adapters.

The adapters build and read messages by field name only, so they work on rclpy message
objects (``sensor_msgs.msg.PointCloud2``) and on rosbags dataclasses
(``typestore.types['sensor_msgs/msg/PointCloud2']``) alike. Building needs the classes: a
:data:`TypeResolver` maps a ROS type name such as ``'sensor_msgs/msg/PointCloud2'`` to the
class of one world. :func:`rclpy_types` and :func:`rosbags_types` make one for each world.

Messages are always built with a keyword for every field, because rosbags dataclasses have no
defaults. The one difference between the worlds is the ``uint8[]`` field: rosbags needs an
``np.ndarray`` of ``uint8``, while rclpy copies an ``np.ndarray`` element by element (slow)
but takes ``bytes`` in one copy; :func:`uint8_field` picks the right form.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_adapters.errors import MessageError

#: Maps a ROS 2 type name (``'pkg/msg/Name'``) to the message class of one message world.
TypeResolver = Callable[[str], type]

NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1


def _split_type_name(name: str) -> tuple[str, str]:
    """``('sensor_msgs.msg', 'PointCloud2')`` from ``'sensor_msgs/msg/PointCloud2'``."""
    parts = name.split("/")
    if len(parts) != 3 or not all(parts):
        raise MessageError(f"message type name must look like 'pkg/msg/Name', got {name!r}")
    return f"{parts[0]}.{parts[1]}", parts[2]


def rclpy_types() -> TypeResolver:
    """Resolver returning rclpy message classes, imported on first use of each package.

    ``msg_adapters`` itself imports without rclpy; only calling the resolver needs the ROS
    interface packages (e.g. ``sensor_msgs``) to be importable.
    """

    def resolve(name: str) -> type:
        module_name, class_name = _split_type_name(name)
        try:
            module = importlib.import_module(module_name)
            cls = getattr(module, class_name)
        except (ImportError, AttributeError) as err:
            raise MessageError(
                f"cannot import ROS message class {name!r} ({err}); source a ROS 2 install "
                "or install the interface package"
            ) from err
        if not isinstance(cls, type):
            raise MessageError(f"{module_name}.{class_name} is not a message class")
        return cls

    return resolve


def rosbags_types(typestore: Any) -> TypeResolver:
    """Resolver returning rosbags dataclasses from a typestore.

    Parameters
    ----------
    typestore : rosbags.typesys.store.Typestore
        For example ``get_typestore(Stores.ROS2_JAZZY)``.
    """

    def resolve(name: str) -> type:
        try:
            cls = typestore.types[name]
        except KeyError:
            raise MessageError(f"message type {name!r} is not in the rosbags typestore") from None
        return cls  # type: ignore[no-any-return]

    return resolve


def uint8_field(cls: type, data: NDArray[np.uint8]) -> Any:
    """Value for a ``uint8[]`` field of a message of class ``cls``.

    Parameters
    ----------
    cls : type
        The message class that gets the field (rosbags dataclass or rclpy class).
    data : ndarray of uint8, shape (B,)

    Returns
    -------
    ndarray of uint8 for rosbags dataclasses, ``bytes`` otherwise (rclpy).
    """
    flat = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
    return flat if dataclasses.is_dataclass(cls) else flat.tobytes()


def uint8_array(data: Any) -> NDArray[np.uint8]:
    """Read-only ``uint8`` view (B,) of a ``uint8[]`` field from any message world.

    Accepts ``np.ndarray`` (rosbags), ``array.array``/``bytes``/``memoryview`` (rclpy, mcap)
    and, as a slow fallback, a list of ints.
    """
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
    try:
        return np.frombuffer(data, dtype=np.uint8)
    except TypeError:
        return np.asarray(data, dtype=np.uint8).reshape(-1)


def stamp_ns_from_msg(stamp: Any) -> int:
    """Integer nanoseconds from a ``builtin_interfaces/msg/Time`` (``sec``, ``nanosec``)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def time_msg_from_ns(stamp_ns: int, types: TypeResolver) -> Any:
    """``builtin_interfaces/msg/Time`` for a stamp in integer nanoseconds (0 <= stamp < 2^31 s).

    Raises
    ------
    MessageError
        For a negative stamp or one beyond the int32 seconds of ROS 2 time.
    """
    stamp_ns = int(stamp_ns)
    sec, nanosec = divmod(stamp_ns, NS_PER_S)
    if stamp_ns < 0 or sec > _INT32_MAX:
        raise MessageError(f"stamp {stamp_ns} ns is outside ROS 2 time [0, 2^31) s")
    return types("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header_msg(stamp_ns: int, frame_id: str, types: TypeResolver) -> Any:
    """``std_msgs/msg/Header`` with a stamp in integer nanoseconds."""
    return types("std_msgs/msg/Header")(
        stamp=time_msg_from_ns(stamp_ns, types), frame_id=str(frame_id)
    )


def vector_fields(values: ArrayLike, names: str = "xyz") -> dict[str, float]:
    """Keyword arguments ``{'x': ..., 'y': ..., 'z': ...}`` of plain floats from an array.

    ``names`` gives the field names in order, e.g. ``'xyzw'`` for a quaternion.
    """
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    if array.shape != (len(names),):
        raise MessageError(f"expected {len(names)} values for fields {names}, got {array.shape}")
    return {name: float(value) for name, value in zip(names, array, strict=True)}


def vector_from_msg(msg: Any, names: str = "xyz") -> NDArray[np.float64]:
    """Array (len(names),) float64 of the named float fields of a message."""
    return np.array([float(getattr(msg, name)) for name in names], dtype=np.float64)
