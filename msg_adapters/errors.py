"""Errors raised when a ROS message cannot be turned into arrays (or the reverse)."""

from __future__ import annotations

from linelaser_calib.core.errors import CalibrationError


class MessageError(CalibrationError, ValueError):
    """A message is malformed: inconsistent PointCloud2 layout, missing fields, bad quaternion.

    It is a :class:`ValueError` (the message holds a bad value) and a
    :class:`~linelaser_calib.core.errors.CalibrationError`, so the CLI and the nodes report it
    as a user-facing error rather than a traceback.
    """
