"""Errors of the report module; each message names the file and what to do."""

from __future__ import annotations

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.types import CalibrationResult, Cylinder


class ReportError(CalibrationError):
    """A report or visualisation file cannot be made or written as asked."""


def require_cylinder(result: CalibrationResult) -> Cylinder:
    """The result's cylinder, or ReportError for a target that has none (known point)."""
    if result.cylinder is None:
        raise ReportError(
            "the report and the visualisation show profiles against the fitted cylinder; "
            "this result (known-point target) has no cylinder: use the result YAML instead"
        )
    return result.cylinder
