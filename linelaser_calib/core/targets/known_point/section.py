"""The known-point target's part of a result: the fixed point in the base frame."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...geometry import FloatArray, apply_transform
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
    """

    key: ClassVar[str] = "known_point"
    title: ClassVar[str] = "known point"

    point: FloatArray
    estimated: bool
    sigma_m: FloatArray | None = None

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point, estimated, uncertainty_m}`` (m)."""
        return {
            "frame": base_frame,
            "point": plain_floats(self.point),
            "estimated": bool(self.estimated),
            "uncertainty_m": None if self.sigma_m is None else plain_floats(self.sigma_m),
        }

    def quality_entries(self) -> dict[str, Any]:
        """None."""
        return {}

    def describe(self, base_frame: str) -> str:
        """The point (mm), taught or estimated with its 1σ."""
        text = f"Known point in {base_frame}: point {mm_text(self.point)}"
        if self.estimated and self.sigma_m is not None:
            return text + f" (estimated, 1 sigma {mm_text(self.sigma_m)})"
        return text + (" (estimated)" if self.estimated else " (taught)")

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
        x, z = fit.feature_xz
        corner = apply_transform(T_base_sensor, np.array([[x, 0.0, z]]))
        return np.asarray(np.linalg.norm(corner - self.point, axis=1))

    def given_settings(self) -> dict[str, Any]:
        """A taught point fixes ``point_m`` of a later calibration started from this result."""
        return {} if self.estimated else {"point_m": np.asarray(self.point, dtype=np.float64)}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points unchanged: this target estimates nothing of the sensor itself."""
        return points


def read_known_point_section(mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> KnownPoint:
    """The section from a result file's ``known_point`` mapping (ValueError naming the key)."""
    sigma = None
    if mapping.get("uncertainty_m") is not None:
        sigma = read_vector(mapping, "uncertainty_m")
    estimated = mapping.get("estimated", False)
    if not isinstance(estimated, bool):
        raise ValueError(f"key estimated must be true or false, got {estimated!r}")
    return KnownPoint(read_vector(mapping, "point"), estimated, sigma)
