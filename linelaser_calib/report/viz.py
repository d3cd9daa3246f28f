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
from pathlib import Path
from typing import Any

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import Writer
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from linelaser_calib.core.residuals import sample_points_base
from linelaser_calib.core.types import CalibrationResult
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
    """One MCAP channel per topic, each with its ``ros2msg`` schema."""

    def __init__(self, writer: Writer) -> None:
        self.writer = writer
        self.ids: dict[str, int] = {}
        schemas: dict[str, int] = {}
        for kind, msgtype in _TYPES.items():
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
    target = Path(path)
    partial = target.with_name(f".{target.name}.partial")
    try:
        try:
            with partial.open("wb") as stream:
                writer = Writer(stream)
                writer.start(profile="ros2", library="linelaser_calib")
                _write(writer, result)
                writer.finish()  # type: ignore[no-untyped-call]  # mcap has no annotation here
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)
    except OSError as err:
        raise ReportError(f"cannot write {target}: {err.strerror or err}") from err
    return target
