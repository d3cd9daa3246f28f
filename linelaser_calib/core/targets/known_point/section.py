"""The known-point target's part of a result: the fixed point in the base frame, and the
profiler's x and z scales where they were estimated with it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...geometry import FloatArray, apply_transform
from ...profile.along_line import (
    ScalePair,
    measured_to_true,
    xz_scale_entries,
    xz_scale_text,
    xz_scales_from_mapping,
)
from ...types import SampleFit
from ..base import Shape, mm_text, plain_floats, read_vector

#: Diameter of the sphere marker at the known point, m.
MARKER_DIAMETER_M = 0.004


@dataclass(frozen=True)
class KnownPoint:
    """A fixed point (e.g. a weld-seam corner) in the base frame: the ``known_point`` section.

    Attributes
    ----------
    point : ndarray, shape (3,)
        m.
    estimated : bool
        True if solved for, False if taught (given).
    sigma_m : ndarray, shape (3,) or None
        1-sigma per base axis when estimated, m.
    scales : (float or None, float or None)
        The profiler's x and z scale errors (s_x, s_z; about the sensor origin) estimated
        with the hand-eye; None where held at 1.
    scale_sigmas : (float or None, float or None)
        Their 1σ; None where held.
    """

    key: ClassVar[str] = "known_point"
    title: ClassVar[str] = "known point"

    point: FloatArray
    estimated: bool
    sigma_m: FloatArray | None = None
    scales: ScalePair = (None, None)
    scale_sigmas: ScalePair = (None, None)

    @property
    def free_scales(self) -> tuple[bool, bool]:
        """Whether the x and the z scale were estimated."""
        return (self.scales[0] is not None, self.scales[1] is not None)

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point, estimated, uncertainty_m}`` (m), and per estimated scale
        ``along_line_scale`` / ``depth_scale`` (the ratio 1 + s) with its 1σ."""
        return {
            "frame": base_frame,
            "point": plain_floats(self.point),
            "estimated": bool(self.estimated),
            "uncertainty_m": None if self.sigma_m is None else plain_floats(self.sigma_m),
        } | xz_scale_entries(self.scales, self.scale_sigmas)

    def quality_entries(self) -> dict[str, Any]:
        """None."""
        return {}

    def describe(self, base_frame: str) -> str:
        """The point (mm), taught or estimated with its 1σ, and the estimated scales."""
        text = f"Known point in {base_frame}: point {mm_text(self.point)}"
        if self.estimated and self.sigma_m is not None:
            text += f" (estimated, 1 sigma {mm_text(self.sigma_m)})"
        else:
            text += " (estimated)" if self.estimated else " (taught)"
        return text + xz_scale_text(self.scales, self.scale_sigmas)

    def residual_kind(self, method: str) -> str:
        """The distance of each view's corner, mapped into the base frame, from the point."""
        return "distance of each view's corner, mapped into the base frame, from the point"

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """A sphere marker at the point."""
        return [
            Shape(
                "points",
                np.asarray(self.point, dtype=np.float64)[np.newaxis],
                0.5 * MARKER_DIAMETER_M,
                "known_point",
                (1.0, 0.85, 0.0, 1.0),
            )
        ]

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance (1,) of the sample's corner, mapped into the base frame, from the point, m."""
        x, z = self.sensor_points(np.asarray(fit.feature_xz))
        corner = apply_transform(T_base_sensor, np.array([[x, 0.0, z]]))
        return np.asarray(np.linalg.norm(corner - self.point, axis=1))

    def given_settings(self) -> dict[str, Any]:
        """A taught point fixes ``point_m`` of a later calibration started from this result."""
        return {} if self.estimated else {"point_m": np.asarray(self.point, dtype=np.float64)}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points with the estimated scale errors removed (x / (1 + s_x), z / (1 + s_z))."""
        return measured_to_true(points, self.scales[0] or 0.0, self.scales[1] or 0.0)


def read_known_point_section(mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> KnownPoint:
    """The section from a result file's ``known_point`` mapping (ValueError naming the key)."""
    sigma = None
    if mapping.get("uncertainty_m") is not None:
        sigma = read_vector(mapping, "uncertainty_m")
    estimated = mapping.get("estimated", False)
    if not isinstance(estimated, bool):
        raise ValueError(f"key estimated must be true or false, got {estimated!r}")
    return KnownPoint(
        read_vector(mapping, "point"), estimated, sigma, *xz_scales_from_mapping(mapping)
    )
