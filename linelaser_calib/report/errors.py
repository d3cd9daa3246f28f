"""Errors of the report module; each message names the file and what to do."""

from __future__ import annotations

from linelaser_calib.core.errors import CalibrationError


class ReportError(CalibrationError):
    """A report or visualisation file cannot be made or written as asked."""
