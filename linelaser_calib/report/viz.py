"""The calibration as ROS 2 messages in one MCAP file, to open in Foxglove (or play to RViz).

The file holds, with the samples' original stamps:

- ``/tf_static`` (``tf2_msgs/msg/TFMessage``): the hand-eye, parent flange, child sensor, once
  at the first sample's stamp.
- ``/tf`` (``tf2_msgs/msg/TFMessage``): base to flange (the recorded flange pose) at each
  sample's stamp.
- ``/linelaser_calib/profiles`` (``sensor_msgs/msg/PointCloud2``): each sample's inlier points
  in the base frame, ``T_base_flange · T_flange_sensor · p``, at the sample's stamp.
- ``/linelaser_calib/cloud`` (``sensor_msgs/msg/PointCloud2``): all of them in one cloud, at
  the first stamp, so that a viewer shows every profile at once.
- ``/linelaser_calib/markers`` (``visualization_msgs/msg/MarkerArray``): the target's shapes
  (e.g. the fitted cylinder over the scanned length, the known point), at the first stamp.

It is a plain MCAP file as rosbag2 writes them (``ros2msg`` schemas from the rosbags
typestore, CDR messages), written with the ``mcap`` library: Foxglove opens it directly and
``ros2 bag play`` (Jazzy) plays it.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import Writer
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder.residuals import sample_points_base
from linelaser_calib.core.types import FloatArray
from linelaser_calib.report.errors import ReportError
from msg_adapters import (
    marker_array,
    pointcloud2_from_points,
    rosbags_types,
    shape_markers,
    transform_stamped_from_matrix,
)

#: Topic of each kind of message in the file.
VIZ_TOPICS = {
    "tf_static": "/tf_static",
    "tf": "/tf",
    "profiles": "/linelaser_calib/profiles",
    "cloud": "/linelaser_calib/cloud",
    "markers": "/linelaser_calib/markers",
}

_TYPES = {
    "tf_static": "tf2_msgs/msg/TFMessage",
    "tf": "tf2_msgs/msg/TFMessage",
    "profiles": "sensor_msgs/msg/PointCloud2",
    "cloud": "sensor_msgs/msg/PointCloud2",
    "markers": "visualization_msgs/msg/MarkerArray",
}


@functools.cache
def _typestore() -> Typestore:
    return get_typestore(Stores.ROS2_JAZZY)


class _Channels:
    """One MCAP channel per topic of the given kinds, each with its ``ros2msg`` schema."""

    def __init__(self, writer: Writer, kinds: Sequence[str] = tuple(_TYPES)) -> None:
        self.writer = writer
        self.ids: dict[str, int] = {}
        schemas: dict[str, int] = {}
        for kind in kinds:
            msgtype = _TYPES[kind]
            if msgtype not in schemas:
                text, _ = _typestore().generate_msgdef(msgtype, ros_version=2)
                schemas[msgtype] = writer.register_schema(
                    msgtype, SchemaEncoding.ROS2, text.encode()
                )
            self.ids[kind] = writer.register_channel(
                VIZ_TOPICS[kind], MessageEncoding.CDR, schemas[msgtype]
            )

    def write(self, kind: str, stamp_ns: int, msg: Any) -> None:
        data = _typestore().serialize_cdr(msg, _TYPES[kind])
        self.writer.add_message(self.ids[kind], stamp_ns, bytes(data), stamp_ns)


def _write(writer: Writer, result: CalibrationResult) -> None:
    types = rosbags_types(_typestore())
    tf_message = types("tf2_msgs/msg/TFMessage")
    fits = sorted(result.sample_fits, key=lambda f: f.stamp_ns)
    first = fits[0].stamp_ns if fits else 0
    base, flange, sensor = result.base_frame, result.parent_frame, result.child_frame
    channels = _Channels(writer)

    hand_eye = transform_stamped_from_matrix(
        result.T_flange_sensor, first, flange, sensor, types=types
    )
    channels.write("tf_static", first, tf_message(transforms=[hand_eye]))
    points = [sample_points_base(f, result.T_flange_sensor) for f in fits]
    every = np.concatenate(points) if points else np.zeros((0, 3))
    markers = shape_markers(result.target.shapes(every), base, types=types)
    channels.write("markers", first, marker_array(markers, types=types))
    channels.write("cloud", first, pointcloud2_from_points(every, first, base, types=types))
    for fit, sample_points in zip(fits, points, strict=True):
        pose = transform_stamped_from_matrix(
            fit.T_base_flange, fit.stamp_ns, base, flange, types=types
        )
        channels.write("tf", fit.stamp_ns, tf_message(transforms=[pose]))
        channels.write(
            "profiles",
            fit.stamp_ns,
            pointcloud2_from_points(sample_points, fit.stamp_ns, base, types=types),
        )


def write_viz_mcap(path: str | Path, result: CalibrationResult) -> Path:
    """Write the calibration's visualisation MCAP file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file; replaced atomically if it exists. Its directory must exist.
    result : CalibrationResult
        With ``sample_fits``.

    Returns
    -------
    Path

    Raises
    ------
    ReportError
        If the file cannot be written.
    """
    return _write_atomically(path, lambda writer: _write(writer, result))


def _write_atomically(path: str | Path, body: Callable[[Writer], None]) -> Path:
    """Write an MCAP file with ``body`` into a hidden file, then rename it to ``path``."""
    target = Path(path)
    partial = target.with_name(f".{target.name}.partial")
    try:
        try:
            with partial.open("wb") as stream:
                writer = Writer(stream)
                writer.start(profile="ros2", library="linelaser_calib")
                body(writer)
                writer.finish()  # type: ignore[no-untyped-call]  # mcap has no annotation here
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)
    except OSError as err:
        raise ReportError(f"cannot write {target}: {err.strerror or err}") from err
    return target


def write_cloud_mcap(
    path: str | Path,
    clouds: Sequence[tuple[int, FloatArray]],
    frame_id: str,
    intensities: Sequence[FloatArray] | None = None,
) -> Path:
    """Write point clouds as PointCloud2 messages in one MCAP file (Foxglove, RViz).

    Each cloud goes on ``/linelaser_calib/profiles`` at its stamp; all of them together on
    ``/linelaser_calib/cloud`` once, at the first stamp.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file; replaced atomically if it exists.
    clouds : sequence of (int, ndarray (N, 3))
        Stamp (ns) and points (m) in ``frame_id``, in stamp order.
    frame_id : str
    intensities : sequence of ndarray (N,), optional
        Per cloud, the points' intensities (an ``intensity`` field).

    Raises
    ------
    ReportError
        If the file cannot be written.
    """

    def body(writer: Writer) -> None:
        types = rosbags_types(_typestore())
        channels = _Channels(writer, ("profiles", "cloud"))
        first = clouds[0][0] if clouds else 0
        every = np.concatenate([c for _, c in clouds]) if clouds else np.zeros((0, 3))
        values = None
        if intensities is not None and len(intensities):
            values = np.concatenate(list(intensities))
        channels.write(
            "cloud",
            first,
            pointcloud2_from_points(every, first, frame_id, types=types, intensity=values),
        )
        for k, (stamp_ns, points) in enumerate(clouds):
            value = None if intensities is None else intensities[k]
            msg = pointcloud2_from_points(points, stamp_ns, frame_id, types=types, intensity=value)
            channels.write("profiles", stamp_ns, msg)

    return _write_atomically(path, body)
