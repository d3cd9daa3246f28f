"""Errors of the file I/O module; each message names the file (and topic) and what to do."""

from __future__ import annotations

from linelaser_calib.core.errors import CalibrationError


class BagError(CalibrationError):
    """A rosbag2 recording cannot be read or written as asked."""


class ResultFileError(CalibrationError):
    """A result or truth YAML file is missing, malformed or cannot be written."""
