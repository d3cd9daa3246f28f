"""``visualization_msgs/msg/MarkerArray`` for RViz: a result's target shapes and point sets.

A target's result section lists its markers as shapes
(:class:`~linelaser_calib.core.targets.base.Shape`); :func:`shape_markers` turns them into
markers by their geometric kind, whatever the target.

A ROS CYLINDER marker is centred on its pose, with its axis along the pose's local z,
``scale.x`` and ``scale.y`` the diameters and ``scale.z`` the length. POINTS and SPHERE_LIST
markers draw ``points`` in the pose frame with ``scale`` the point size.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.geometry import orthonormal_basis, transform_from_rotation_translation
from linelaser_calib.core.targets.base import Shape
from linelaser_calib.core.targets.cylinder.model import Cylinder
from msg_adapters.errors import MessageError
from msg_adapters.message_types import TypeResolver, header_msg, uint8_field, vector_fields
from msg_adapters.pose import pose_msg_from_transform

#: RGBA in [0, 1].
Color = tuple[float, float, float, float]


def _marker(
    marker_type: str,
    frame_id: str,
    stamp_ns: int,
    ns: str,
    marker_id: int,
    T_frame_marker: ArrayLike,
    scale: ArrayLike,
    color: Color,
    points: Any,
    types: TypeResolver,
) -> Any:
    """A Marker with ADD action, every field given (rosbags dataclasses have no defaults)."""
    marker_cls: Any = types("visualization_msgs/msg/Marker")
    image_cls = types("sensor_msgs/msg/CompressedImage")
    mesh_cls = types("visualization_msgs/msg/MeshFile")
    no_bytes = np.zeros(0, dtype=np.uint8)
    return marker_cls(
        header=header_msg(stamp_ns, frame_id, types),
        ns=str(ns),
        id=int(marker_id),
        type=int(getattr(marker_cls, marker_type)),
        action=int(marker_cls.ADD),
        pose=pose_msg_from_transform(T_frame_marker, types),
        scale=types("geometry_msgs/msg/Vector3")(**vector_fields(scale)),
        color=types("std_msgs/msg/ColorRGBA")(**vector_fields(color, "rgba")),
        lifetime=types("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False,
        points=points,
        colors=[],
        texture_resource="",
        texture=image_cls(
            header=header_msg(0, "", types), format="", data=uint8_field(image_cls, no_bytes)
        ),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=mesh_cls(filename="", data=uint8_field(mesh_cls, no_bytes)),
        mesh_use_embedded_materials=False,
    )


def cylinder_marker(
    cylinder: Cylinder,
    length_m: float,
    frame_id: str,
    *,
    types: TypeResolver,
    centre: ArrayLike | None = None,
    stamp_ns: int = 0,
    ns: str = "cylinder",
    marker_id: int = 0,
    color: Color = (0.2, 0.6, 1.0, 0.5),
) -> Any:
    """CYLINDER marker of a finite piece of the cylinder.

    Parameters
    ----------
    cylinder : Cylinder
        Axis point (3,) m, unit direction (3,) and radius m, in ``frame_id``.
    length_m : float
        Length of the drawn piece along the axis, m.
    frame_id : str
    types : TypeResolver
    centre : array-like, shape (3,), optional
        Centre of the drawn piece, m; projected onto the axis. Default ``cylinder.point``.
    stamp_ns : int
        Header stamp, ns (0 lets RViz use the latest transform).
    ns, marker_id : str, int
        Marker namespace and id.
    color : (r, g, b, a)

    Raises
    ------
    MessageError
        Non-positive radius or length, or a zero axis direction.
    """
    direction = np.asarray(cylinder.direction, dtype=np.float64)
    norm = float(np.linalg.norm(direction))
    if not norm > 0.0 or not cylinder.radius > 0.0 or not length_m > 0.0:
        raise MessageError(
            f"cylinder marker needs a non-zero direction, radius > 0 and length > 0; got "
            f"|direction| {norm}, radius {cylinder.radius} m, length {length_m} m"
        )
    direction = direction / norm
    point = np.asarray(cylinder.point, dtype=np.float64)
    if centre is not None:
        offset = np.asarray(centre, dtype=np.float64) - point
        point = point + float(offset @ direction) * direction
    u, v = orthonormal_basis(direction)
    T_frame_marker = transform_from_rotation_translation(np.column_stack([u, v, direction]), point)
    diameter = 2.0 * float(cylinder.radius)
    return _marker(
        "CYLINDER",
        frame_id,
        stamp_ns,
        ns,
        marker_id,
        T_frame_marker,
        (diameter, diameter, float(length_m)),
        color,
        [],
        types,
    )


def points_marker(
    points: ArrayLike,
    frame_id: str,
    *,
    types: TypeResolver,
    size_m: float = 0.002,
    spheres: bool = False,
    stamp_ns: int = 0,
    ns: str = "points",
    marker_id: int = 0,
    color: Color = (1.0, 0.3, 0.1, 1.0),
) -> Any:
    """POINTS (or SPHERE_LIST) marker of points (N, 3) in m; non-finite rows are left out.

    Parameters
    ----------
    points : array-like, shape (N, 3)
    frame_id : str
    types : TypeResolver
    size_m : float
        Point width (POINTS) or sphere diameter (SPHERE_LIST), m.
    spheres : bool
        SPHERE_LIST instead of POINTS.
    stamp_ns, ns, marker_id, color
        As for :func:`cylinder_marker`.
    """
    xyz = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise MessageError(f"marker points must have shape (N, 3), got {xyz.shape}")
    point_cls = types("geometry_msgs/msg/Point")
    msg_points = [point_cls(**vector_fields(p)) for p in xyz[np.all(np.isfinite(xyz), axis=1)]]
    return _marker(
        "SPHERE_LIST" if spheres else "POINTS",
        frame_id,
        stamp_ns,
        ns,
        marker_id,
        np.eye(4),
        (size_m, size_m, size_m),
        color,
        msg_points,
        types,
    )


def marker_array(markers: Sequence[Any], *, types: TypeResolver) -> Any:
    """``visualization_msgs/msg/MarkerArray`` holding ``markers``."""
    return types("visualization_msgs/msg/MarkerArray")(markers=list(markers))


def shape_markers(
    shapes: Sequence[Shape], frame_id: str, *, types: TypeResolver, stamp_ns: int = 0
) -> list[Any]:
    """Markers of a result section's shapes (in ``frame_id``), one per shape.

    ``cylinder``: a CYLINDER between its two axis ends; ``sphere`` and ``points``: a
    SPHERE_LIST of diameter 2·radius; ``line``: a LINE_LIST of width 2·radius.

    Raises
    ------
    MessageError
        A degenerate shape (see :func:`cylinder_marker`).
    """
    markers = []
    for shape in shapes:
        points = np.asarray(shape.points, dtype=np.float64)
        size = 2.0 * float(shape.radius)
        if shape.kind == "cylinder":
            axis = points[1] - points[0]
            length = float(np.linalg.norm(axis))
            centre = 0.5 * (points[0] + points[1])
            cylinder = Cylinder(centre, axis / max(length, 1e-300), float(shape.radius))
            markers.append(
                cylinder_marker(
                    cylinder,
                    length,
                    frame_id,
                    types=types,
                    stamp_ns=stamp_ns,
                    ns=shape.ns,
                    color=shape.color,
                )
            )
        elif shape.kind == "line":
            point_cls = types("geometry_msgs/msg/Point")
            markers.append(
                _marker(
                    "LINE_LIST",
                    frame_id,
                    stamp_ns,
                    shape.ns,
                    0,
                    np.eye(4),
                    (size, 0.0, 0.0),
                    shape.color,
                    [point_cls(**vector_fields(p)) for p in points],
                    types,
                )
            )
        else:
            markers.append(
                points_marker(
                    points,
                    frame_id,
                    types=types,
                    size_m=size,
                    spheres=True,
                    stamp_ns=stamp_ns,
                    ns=shape.ns,
                    color=shape.color,
                )
            )
    return markers
