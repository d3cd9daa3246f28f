"""The cylinder target's part of a result: the fitted cylinder in the base frame."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...geometry import FloatArray, apply_transform
from ...residuals import axis_extent
from ...types import Cylinder, SampleFit
from ..base import Shape, mm_text, plain_floats, read_vector


@dataclass(frozen=True)
class CylinderSection:
    """The ``cylinder`` section of a result.

    Attributes
    ----------
    cylinder : Cylinder
        Axis point, unit direction and radius in the base frame, m.
    radius_estimated : bool
        True if the radius was estimated rather than given.
    noise_levels : dict of str to float, or None
        The noise levels re-estimated from the residuals (``sensor_sigma_m``,
        ``robot_sigma_t_m``, ``robot_sigma_r_rad``; default method), or None.
    """

    key: ClassVar[str] = "cylinder"
    title: ClassVar[str] = "cylinder"

    cylinder: Cylinder
    radius_estimated: bool = False
    noise_levels: Mapping[str, float] | None = None

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point, direction, radius}`` (m)."""
        c = self.cylinder
        return {
            "frame": base_frame,
            "point": plain_floats(c.point),
            "direction": plain_floats(c.direction),
            "radius": float(c.radius),
        }

    def quality_entries(self) -> dict[str, Any]:
        """``radius_estimated`` and the re-estimated noise levels (``noise_estimated``)."""
        entries: dict[str, Any] = {"radius_estimated": bool(self.radius_estimated)}
        if self.noise_levels:
            entries["noise_estimated"] = {k: float(v) for k, v in self.noise_levels.items()}
        return entries

    def describe(self, base_frame: str) -> str:
        """The axis point, direction and radius (mm)."""
        c = self.cylinder
        return (
            f"Cylinder in {base_frame}: point {mm_text(c.point)}, direction "
            + "["
            + ", ".join(f"{v:+.5f}" for v in c.direction)
            + f"], radius {c.radius * 1e3:.3f} mm"
            + (" (estimated)" if self.radius_estimated else " (given)")
        )

    def residual_kind(self, method: str) -> str:
        """Centre-to-axis for ``paper``, point-to-surface for ``default``."""
        if method == "paper":
            return "ellipse centre-to-axis distance"
        return "point-to-surface distance, flange poses corrected for the estimated robot error"

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """The piece of the cylinder the points cover (its axis ends)."""
        c = self.cylinder
        centre, length = axis_extent(points_base, c)
        half = 0.5 * length * c.direction / np.linalg.norm(c.direction)
        return [Shape("cylinder", np.stack([centre - half, centre + half]), c.radius, "cylinder")]

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance of the sample's points to the axis minus the radius (N,), m."""
        c = self.cylinder
        v = apply_transform(T_base_sensor, fit.points) - c.point
        radial = v - np.outer(v @ c.direction, c.direction)
        return np.asarray(np.linalg.norm(radial, axis=1) - c.radius)

    def given_settings(self) -> dict[str, Any]:
        """None: a cylinder result fixes no setting of a later calibration."""
        return {}


def read_cylinder_section(
    mapping: Mapping[str, Any], quality: Mapping[str, Any]
) -> CylinderSection:
    """The section from a result file's ``cylinder`` mapping (ValueError naming the key)."""
    point = read_vector(mapping, "point")
    direction = read_vector(mapping, "direction")
    radius = mapping.get("radius")
    norm = float(np.linalg.norm(direction))
    if isinstance(radius, bool) or not isinstance(radius, (int, float)):
        raise ValueError(f"key radius must be a number, got {radius!r}")
    if norm < 1e-12 or not radius > 0.0:
        raise ValueError(
            f"needs a non-zero direction and a radius > 0 m, got direction "
            f"{direction.tolist()} and radius {radius} m"
        )
    estimated = quality.get("radius_estimated", False)
    if not isinstance(estimated, bool):
        raise ValueError(f"key quality.radius_estimated must be true or false, got {estimated!r}")
    return CylinderSection(
        Cylinder(point, direction / norm, float(radius)),
        estimated,
        dict(quality.get("noise_estimated") or {}) or None,
    )
