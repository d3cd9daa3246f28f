"""The straight-line target's part of a result: the seam line in the base frame."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...geometry import FloatArray, apply_transform
from ...types import SampleFit
from ..base import Shape, direction_text, mm_text, plain_floats
from .model import Line


@dataclass(frozen=True)
class LineSection:
    """The ``line`` section of a result: the seam in the base frame.

    Attributes
    ----------
    line : Line
        Point nearest the base origin (m) and unit direction.
    """

    key: ClassVar[str] = "line"
    title: ClassVar[str] = "straight line"

    line: Line

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point: [x, y, z] (m), direction: [x, y, z]}``."""
        return {
            "frame": base_frame,
            "point": plain_floats(self.line.point),
            "direction": plain_floats(self.line.direction),
        }

    def quality_entries(self) -> dict[str, Any]:
        """No further quality entries."""
        return {}

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance (1,) of the sample's corner, mapped into the base frame, from the line, m."""
        x, z = fit.feature_xz
        v = apply_transform(T_base_sensor, np.array([[x, 0.0, z]])) - self.line.point
        d = self.line.direction
        return np.asarray(np.linalg.norm(v - np.outer(v @ d, d), axis=1))

    def given_settings(self) -> dict[str, Any]:
        """Nothing: a line fixes no setting of a later calibration."""
        return {}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points unchanged: this target estimates nothing of the sensor itself."""
        return points

    def describe(self, base_frame: str) -> str:
        """One line, mm."""
        return (
            f"Seam line in {base_frame}: point {mm_text(self.line.point)} (nearest the base "
            f"origin), direction {direction_text(self.line.direction)}"
        )

    def residual_kind(self, method: str) -> str:
        """What a sample's residual measures."""
        return "distance of the corner (recorded pose) from the seam line"

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """The seam as a segment spanning the points' extent along it."""
        along = (np.asarray(points_base) - self.line.point) @ self.line.direction
        lo, hi = (float(np.min(along)), float(np.max(along))) if along.size else (-0.05, 0.05)
        ends = self.line.point + np.outer([lo, hi], self.line.direction)
        return [Shape("line", ends, 5e-4, "line", (1.0, 0.5, 0.1, 0.8))]
