"""``sensor_msgs/msg/PointCloud2`` <-> numpy point arrays.

Reading accepts any layout the message definition allows: fields in any order and at any
offset, extra fields and padding bytes, FLOAT32 or FLOAT64 coordinates, either byte order,
organised (height > 1) or dense clouds. Invalid points (REP 117: NaN or +-Inf in x, y or z,
and the depths z a driver uses as a sentinel for no return, such as Keyence's -999.999 mm or
0, when given) are dropped unless the caller asks to keep the organised layout. A layout that
contradicts itself raises :class:`~msg_adapters.errors.MessageError` naming the inconsistency.

Points are rows of an (N, 3) float64 array in the message frame, in metres; the row order
is the message's row-major point order (``index = row * width + column``).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linelaser_calib.core.types import Profile
from msg_adapters.errors import MessageError
from msg_adapters.message_types import (
    TypeResolver,
    header_msg,
    stamp_ns_from_msg,
    uint8_array,
    uint8_field,
)

FloatArray = NDArray[np.float64]

#: ``sensor_msgs/msg/PointField`` datatype constants and their numpy kind and size in bytes.
POINTFIELD_DTYPES: dict[int, tuple[str, int]] = {
    1: ("i1", 1),  # INT8
    2: ("u1", 1),  # UINT8
    3: ("i2", 2),  # INT16
    4: ("u2", 2),  # UINT16
    5: ("i4", 4),  # INT32
    6: ("u4", 4),  # UINT32
    7: ("f4", 4),  # FLOAT32
    8: ("f8", 8),  # FLOAT64
}
_FLOAT_DATATYPES = {"f4": 7, "f8": 8}
_XYZ = ("x", "y", "z")
#: A depth z within this relative distance of a sentinel is that sentinel (float32 rounding).
SENTINEL_RTOL = 1e-6


@dataclass(frozen=True)
class DecodedCloud:
    """Points and optional extra fields read from one PointCloud2.

    Attributes
    ----------
    points : ndarray, shape (N, 3), float64
        x, y, z in the message frame, m.
    extras : dict of str to ndarray, shape (N,), float64
        The requested extra fields (first element of each), row-aligned with ``points``.
    """

    points: FloatArray
    extras: dict[str, FloatArray] = field(default_factory=dict)


def _field_table(msg: Any) -> dict[str, tuple[int, str, int]]:
    """``name -> (offset, numpy kind, size in bytes)`` of every field; validates each field."""
    table: dict[str, tuple[int, str, int]] = {}
    for pf in msg.fields:
        name = str(pf.name)
        if name in table:
            raise MessageError(f"PointCloud2 field {name!r} appears twice")
        datatype = int(pf.datatype)
        if datatype not in POINTFIELD_DTYPES:
            raise MessageError(f"PointCloud2 field {name!r} has unknown datatype {datatype}")
        count = int(pf.count)
        kind, size = POINTFIELD_DTYPES[datatype]
        offset = int(pf.offset)
        if count < 1:
            raise MessageError(f"PointCloud2 field {name!r} has count {count}, expected >= 1")
        end = offset + size * count
        if end > int(msg.point_step):
            raise MessageError(
                f"PointCloud2 point_step {int(msg.point_step)} B is smaller than field {name!r} "
                f"needs (offset {offset} + {count} x {size} B = {end} B)"
            )
        table[name] = (offset, kind, size)
    return table


def _check_layout(msg: Any) -> None:
    """Raise :class:`MessageError` when height, width, steps and data length disagree."""
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    n_bytes = len(msg.data)
    if height * width and point_step <= 0:
        raise MessageError(f"PointCloud2 point_step is {point_step} B for a non-empty cloud")
    if height * width and row_step != width * point_step:
        raise MessageError(
            f"PointCloud2 row_step {row_step} B is inconsistent with width {width} x "
            f"point_step {point_step} B = {width * point_step} B"
        )
    if n_bytes != height * row_step:
        raise MessageError(
            f"PointCloud2 data holds {n_bytes} B but height {height} x row_step {row_step} B "
            f"= {height * row_step} B"
        )


@functools.lru_cache(maxsize=16)
def _record_dtype(layout: tuple[tuple[str, str, int], ...], point_step: int) -> np.dtype[Any]:
    """The numpy record of one point: (name, format, offset) of each field read (one per
    layout, not per message: a recording's profiles share theirs)."""
    return np.dtype(
        {
            "names": [name for name, _, _ in layout],
            "formats": [kind for _, kind, _ in layout],
            "offsets": [offset for _, _, offset in layout],
            "itemsize": point_step,
        }
    )


def invalid_rows(points: FloatArray, invalid_values_m: Sequence[float] = ()) -> NDArray[np.bool_]:
    """Mask (N,) of points that are no return: NaN or +-Inf anywhere, or a sentinel depth.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Sensor-frame points, m.
    invalid_values_m : sequence of float
        Depths z, m, that mean no return (equal within :data:`SENTINEL_RTOL` relative, so
        that a float32 -0.999999 matches; 0 matches exactly 0 only).
    """
    invalid = ~np.all(np.isfinite(points), axis=1)
    depth = np.asarray(points[:, 2], dtype=np.float64) if invalid_values_m else points[:, 2]
    for value in invalid_values_m:
        invalid |= np.isclose(depth, float(value), rtol=SENTINEL_RTOL, atol=0.0)
    return invalid


def cloud_from_pointcloud2(
    msg: Any,
    *,
    extra_fields: Sequence[str] = (),
    keep_invalid: bool = False,
    invalid_values_m: Sequence[float] = (),
    keep_float32: bool = False,
) -> DecodedCloud:
    """Decode x, y, z (and optional extra fields) of a PointCloud2.

    Parameters
    ----------
    msg : sensor_msgs/msg/PointCloud2
        rclpy message, rosbags dataclass or any object with the same fields.
    extra_fields : sequence of str
        Further fields to return as float64 (e.g. ``('intensity',)``); any datatype.
    keep_invalid : bool
        False (default): drop points with NaN or +-Inf in x, y or z, or a sentinel depth.
        True: keep all ``height * width`` points in row-major order, NaN and +-Inf as sent
        and sentinel points set to NaN, so the caller sees the full scan line.
    invalid_values_m : sequence of float
        Depths z, m, that the driver sends for no return (e.g. -0.999999 for Keyence's
        -999.999 mm, or 0.0); see :func:`invalid_rows`.
    keep_float32 : bool
        True: FLOAT32 coordinates come as float32, the values sent (as a profile held for a
        whole calibration keeps them: half the memory, no widening and narrowing again);
        False (default), and for FLOAT64 coordinates: float64.

    Returns
    -------
    DecodedCloud
        ``points`` (N, 3) float64 (or float32, see ``keep_float32``) in m and ``extras``
        (N,) per requested field.

    Raises
    ------
    MessageError
        Missing x/y/z or requested field, non-float coordinates, fields that do not fit in
        ``point_step``, ``row_step != width * point_step`` or a data length that does not match
        ``height * row_step``.
    """
    table = _field_table(msg)
    wanted = [*_XYZ, *extra_fields]
    missing = [name for name in wanted if name not in table]
    if missing:
        raise MessageError(
            f"PointCloud2 has no field(s) {missing}; it has {sorted(table)} "
            "(a profile needs float x, y, z)"
        )
    for name in _XYZ:
        if table[name][1] not in _FLOAT_DATATYPES:
            raise MessageError(
                f"PointCloud2 field {name!r} has datatype {table[name][1]}; "
                "expected FLOAT32 or FLOAT64"
            )
    _check_layout(msg)

    order = ">" if bool(msg.is_bigendian) else "<"
    unique = tuple(dict.fromkeys(wanted))
    layout = tuple((name, order + table[name][1], table[name][0]) for name in unique)
    n_points = int(msg.height) * int(msg.width)
    records = np.frombuffer(
        uint8_array(msg.data), dtype=_record_dtype(layout, int(msg.point_step)), count=n_points
    )
    narrow = keep_float32 and all(table[name][1] == "f4" for name in _XYZ)
    points = np.empty((n_points, 3), dtype=np.float32 if narrow else np.float64)
    for axis, name in enumerate(_XYZ):
        points[:, axis] = records[name]
    extras = {name: records[name].astype(np.float64) for name in extra_fields}
    invalid = invalid_rows(points, invalid_values_m)
    if keep_invalid:
        sentinel = invalid & np.all(np.isfinite(points), axis=1)
        points[sentinel] = np.nan
    else:
        points = points[~invalid]
        extras = {name: values[~invalid] for name, values in extras.items()}
    return DecodedCloud(points=points, extras=extras)


def points_from_pointcloud2(
    msg: Any,
    *,
    keep_invalid: bool = False,
    invalid_values_m: Sequence[float] = (),
    keep_float32: bool = False,
) -> FloatArray:
    """x, y, z of a PointCloud2 as an (N, 3) float64 array in m.

    See :func:`cloud_from_pointcloud2` for the accepted layouts, ``keep_invalid``,
    ``invalid_values_m``, ``keep_float32`` and errors.
    """
    return cloud_from_pointcloud2(
        msg,
        keep_invalid=keep_invalid,
        invalid_values_m=invalid_values_m,
        keep_float32=keep_float32,
    ).points


def profile_from_pointcloud2(
    msg: Any,
    *,
    keep_invalid: bool = False,
    invalid_values_m: Sequence[float] = (),
    keep_float32: bool = False,
) -> Profile:
    """A :class:`~linelaser_calib.core.types.Profile` (stamp, points, frame) from a PointCloud2.

    See :func:`cloud_from_pointcloud2` for ``keep_invalid``, ``invalid_values_m`` and
    ``keep_float32``.
    """
    return Profile(
        stamp_ns=stamp_ns_from_msg(msg.header.stamp),
        points=points_from_pointcloud2(
            msg,
            keep_invalid=keep_invalid,
            invalid_values_m=invalid_values_m,
            keep_float32=keep_float32,
        ),
        frame_id=str(msg.header.frame_id),
    )


def pointcloud2_from_points(
    points: ArrayLike,
    stamp_ns: int,
    frame_id: str,
    *,
    types: TypeResolver,
    intensity: ArrayLike | None = None,
    organised: bool = True,
    padding_bytes: int = 0,
    dtype: type[np.floating[Any]] = np.float32,
    is_bigendian: bool = False,
) -> Any:
    """Build a PointCloud2 from points (N, 3) in m.

    Parameters
    ----------
    points : array-like, shape (N, 3)
        Sensor-frame points, m; NaN/+-Inf rows are invalid returns (REP 117).
    stamp_ns : int
        Header stamp, ns.
    frame_id : str
    types : TypeResolver
        Message classes of the target world (:func:`~msg_adapters.rclpy_types` or
        :func:`~msg_adapters.rosbags_types`).
    intensity : array-like, shape (N,), optional
        Adds a FLOAT32 ``intensity`` field after x, y, z.
    organised : bool
        True: height 1, width N, invalid rows kept, ``is_dense`` False if any is invalid.
        False: invalid rows dropped, ``is_dense`` True.
    padding_bytes : int
        Unused bytes (zero) appended to every point, as some drivers do.
    dtype : np.float32 or np.float64
        Datatype of x, y, z.
    is_bigendian : bool
        Byte order of the data.

    Returns
    -------
    sensor_msgs/msg/PointCloud2 of the resolver's world.
    """
    xyz = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise MessageError(f"points must have shape (N, 3), got {xyz.shape}")
    kind = np.dtype(dtype).str[1:]
    if kind not in _FLOAT_DATATYPES:
        raise MessageError(f"coordinate dtype must be float32 or float64, got {np.dtype(dtype)}")
    if padding_bytes < 0:
        raise MessageError(f"padding_bytes must be >= 0, got {padding_bytes}")
    values = None if intensity is None else np.asarray(intensity, dtype=np.float64).reshape(-1)
    if values is not None and values.shape[0] != xyz.shape[0]:
        raise MessageError(f"intensity has {values.shape[0]} values for {xyz.shape[0]} points")

    valid = np.all(np.isfinite(xyz), axis=1)
    if not organised:
        xyz = xyz[valid]
        values = None if values is None else values[valid]

    order = ">" if is_bigendian else "<"
    size = np.dtype(dtype).itemsize
    names, formats, offsets = list(_XYZ), [order + kind] * 3, [0, size, 2 * size]
    if values is not None:
        names.append("intensity")
        formats.append(order + "f4")
        offsets.append(3 * size)
    point_step = offsets[-1] + np.dtype(formats[-1]).itemsize + padding_bytes
    record_dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )
    records = np.zeros(xyz.shape[0], dtype=record_dtype)
    for axis, name in enumerate(_XYZ):
        records[name] = xyz[:, axis]
    if values is not None:
        records["intensity"] = values

    point_field = types("sensor_msgs/msg/PointField")
    cloud_cls = types("sensor_msgs/msg/PointCloud2")
    fields = [
        point_field(
            name=name,
            offset=offset,
            datatype=_FLOAT_DATATYPES[fmt[1:]],
            count=1,
        )
        for name, fmt, offset in zip(names, formats, offsets, strict=True)
    ]
    width = int(xyz.shape[0])
    return cloud_cls(
        header=header_msg(stamp_ns, frame_id, types),
        height=1,
        width=width,
        fields=fields,
        is_bigendian=bool(is_bigendian),
        point_step=point_step,
        row_step=width * point_step,
        data=uint8_field(cloud_cls, records.view(np.uint8).reshape(-1)),
        is_dense=bool(np.all(np.isfinite(xyz))),
    )
