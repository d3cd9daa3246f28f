"""Errors of the report module; each message names the file and what to do."""

from __future__ import annotations

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import placement_adviser
from linelaser_calib.core.targets.cylinder.model import Cylinder


class ReportError(CalibrationError):
    """A report or visualisation file cannot be made or written as asked."""


def require_cylinder(result: CalibrationResult) -> Cylinder:
    """The result's cylinder, or ReportError for a target whose placement is not a cylinder.

    The report's figures and the visualisation draw profiles against a fitted cylinder;
    they exist for a target whose placement (its
    :class:`~linelaser_calib.core.targets.base.PlacementAdviser`) is a cylinder.
    """
    adviser = placement_adviser(get_target(result.target.key))
    placement = None if adviser is None else adviser.placement_of(result.target)
    if not isinstance(placement, Cylinder):
        raise ReportError(
            "the report and the visualisation show profiles against the fitted cylinder; "
            f"this result ({result.target.title} target) has no cylinder: use the result "
            "YAML instead"
        )
    return placement
