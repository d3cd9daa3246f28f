"""The straight-line target's part of a result: the seam line in the base frame, and the
profiler's x and z scales where they were estimated with it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...geometry import FloatArray, apply_transform
from ...profile.along_line import (
    measured_to_true,
    xz_scale_entries,
    xz_scale_text,
    xz_scales_from_mapping,
)
from ...types import SampleFit
from ..base import Shape, direction_text, mm_text, plain_floats, read_vector
from .model import Line


def read_line_section(mapping: Mapping[str, Any]) -> LineSection:
    """The section of a result file's ``line`` mapping (ValueError naming a bad key)."""
    point, direction = read_vector(mapping, "point"), read_vector(mapping, "direction")
    if not float(np.linalg.norm(direction)) > 0.0:
        raise ValueError("key direction must not be zero")
    return LineSection(Line.through(point, direction), *xz_scales_from_mapping(mapping))


@dataclass(frozen=True)
class LineSection:
    """The ``line`` section of a result: the seam in the base frame.

    Attributes
    ----------
    line : Line
        Point nearest the base origin (m) and unit direction.
    scales : (float or None, float or None)
        The profiler's x and z scale errors (s_x, s_z; both about the sensor origin) estimated
        with the line (``--scale``); None where held at 1.
    scale_sigmas : (float or None, float or None)
        Their 1σ.
    """

    key: ClassVar[str] = "line"
    title: ClassVar[str] = "straight line"

    line: Line
    scales: tuple[float | None, float | None] = (None, None)
    scale_sigmas: tuple[float | None, float | None] = (None, None)

    @property
    def scale(self) -> float | None:
        """The x (along-line) scale error, as the cylinder and the sphere name it."""
        return self.scales[0]

    @property
    def scale_sigma(self) -> float | None:
        """Its 1σ."""
        return self.scale_sigmas[0]

    @property
    def depth_scale(self) -> float | None:
        """The z (depth) scale error, as the cylinder names it."""
        return self.scales[1]

    @property
    def depth_scale_sigma(self) -> float | None:
        """Its 1σ."""
        return self.scale_sigmas[1]

    @property
    def free_scales(self) -> tuple[bool, bool]:
        """Whether the x and the z scale were estimated."""
        return (self.scales[0] is not None, self.scales[1] is not None)

    def scale_estimates(self) -> list[tuple[float, float | None]]:
        """(scale error, 1σ) of each estimated scale, x before z."""
        return [
            (s, sigma)
            for s, sigma in zip(self.scales, self.scale_sigmas, strict=True)
            if s is not None
        ]

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point: [x, y, z] (m), direction: [x, y, z]}``, and per estimated scale
        ``along_line_scale`` / ``depth_scale`` (the ratio 1 + s) with its 1σ."""
        mapping: dict[str, Any] = {
            "frame": base_frame,
            "point": plain_floats(self.line.point),
            "direction": plain_floats(self.line.direction),
        }
        return mapping | xz_scale_entries(self.scales, self.scale_sigmas)

    def quality_entries(self) -> dict[str, Any]:
        """No further quality entries."""
        return {}

    def sensor_corners(self, corners_xz: FloatArray) -> FloatArray:
        """Measured corners (M, 2) (x, z) with the estimated scale errors removed, m."""
        return measured_to_true(corners_xz, self.scales[0] or 0.0, self.scales[1] or 0.0)

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance (1,) of the sample's corner, mapped into the base frame, from the line, m."""
        x, z = self.sensor_corners(np.asarray(fit.feature_xz))
        v = apply_transform(T_base_sensor, np.array([[x, 0.0, z]])) - self.line.point
        d = self.line.direction
        return np.asarray(np.linalg.norm(v - np.outer(v @ d, d), axis=1))

    def given_settings(self) -> dict[str, Any]:
        """Nothing: a line fixes no setting of a later calibration."""
        return {}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points with the estimated scale errors removed (x / (1 + s_x), z / (1 + s_z))."""
        return measured_to_true(points, self.scales[0] or 0.0, self.scales[1] or 0.0)

    def describe(self, base_frame: str) -> str:
        """One line, mm."""
        return (
            f"Seam line in {base_frame}: point {mm_text(self.line.point)} (nearest the base "
            f"origin), direction {direction_text(self.line.direction)}"
            + xz_scale_text(self.scales, self.scale_sigmas)
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
