"""The cylinder target's part of a result: the fitted cylinder in the base frame, and the
sensor's along-line and depth scales when they were estimated with it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...errors import InputError
from ...geometry import FloatArray, apply_transform
from ...profile.along_line import measured_to_true, scale_entries, scale_text, scales_from_mapping
from ...profile.noise import LineNoise
from ...types import SampleFit
from ..base import Shape, SurfaceMap, direction_text, mm_text, plain_floats, read_vector
from .model import Cylinder
from .residuals import axis_extent, cylinder_coordinates, sample_centre_distances


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
    scale : float or None
        The sensor's along-line scale error s estimated with the cylinder (dimensionless: the
        profiler reports x as (1 + s) times the true value); None when it was not estimated.
    scale_sigma : float or None
        1σ of ``scale``.
    scale_radius_correlation : float or None
        Correlation coefficient of the scale and the radius, when both were estimated.
    depth_scale, depth_scale_sigma : float or None
        The sensor's depth scale error s_z about its origin estimated with the cylinder (the
        profiler reports z as (1 + s_z) times the true value), and its 1σ; None when it was
        not estimated.
    line_noise : LineNoise or None
        The recording's point noise along the line that weighed the points (white σ, smooth
        σ and its correlation length, or a depth σ, learned from the residuals; default
        method), or None when the points were weighed as independent and alike.
    """

    key: ClassVar[str] = "cylinder"
    title: ClassVar[str] = "cylinder"
    feature_kind: ClassVar[str] = (
        "ellipse centre to axis distance (the cylinder paper's residual, eq. 6 and Fig. 10)"
    )

    cylinder: Cylinder
    radius_estimated: bool = False
    noise_levels: Mapping[str, float] | None = None
    scale: float | None = None
    scale_sigma: float | None = None
    scale_radius_correlation: float | None = None
    line_noise: LineNoise | None = None
    depth_scale: float | None = None
    depth_scale_sigma: float | None = None

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, point, direction, radius}`` (m), and with an estimated scale
        ``along_line_scale`` (the ratio 1 + s), ``along_line_scale_sigma`` (its 1σ) and, with
        the radius estimated too, ``along_line_scale_radius_correlation``; with an estimated
        depth scale ``depth_scale`` (1 + s_z) and ``depth_scale_sigma``."""
        c = self.cylinder
        mapping: dict[str, Any] = {
            "frame": base_frame,
            "point": plain_floats(c.point),
            "direction": plain_floats(c.direction),
            "radius": float(c.radius),
        }
        if self.scale is not None:
            mapping["along_line_scale"] = 1.0 + float(self.scale)
            mapping["along_line_scale_sigma"] = (
                None if self.scale_sigma is None else float(self.scale_sigma)
            )
            if self.scale_radius_correlation is not None:
                mapping["along_line_scale_radius_correlation"] = float(
                    self.scale_radius_correlation
                )
        mapping.update(scale_entries("depth_scale", self.depth_scale, self.depth_scale_sigma))
        return mapping

    def quality_entries(self) -> dict[str, Any]:
        """``radius_estimated``, the re-estimated noise levels (``noise_estimated``) and the
        learned point noise along the line (``line_noise``: ``white_sigma_m``,
        ``smooth_sigma_m``, ``length_m``, ``depth_sigma_m``), when there is one."""
        entries: dict[str, Any] = {"radius_estimated": bool(self.radius_estimated)}
        if self.noise_levels:
            entries["noise_estimated"] = {k: float(v) for k, v in self.noise_levels.items()}
        if self.line_noise is not None:
            n = self.line_noise
            entries["line_noise"] = {
                "white_sigma_m": float(n.white_sigma_m),
                "smooth_sigma_m": float(n.smooth_sigma_m),
                "length_m": float(n.length_m),
                "depth_sigma_m": float(n.depth_sigma_m),
            }
        return entries

    def line_noise_text(self) -> str | None:
        """The learned point noise along the line in words (µm, mm), or None."""
        n = self.line_noise
        if n is None:
            return None
        if n.smooth_sigma_m == 0.0:
            return (
                f"learned from the residuals: {n.white_sigma_m * 1e6:.1f} um from point to "
                f"point and {n.depth_sigma_m * 1e6:.1f} um more in depth (a point's variance "
                "grows with its surface's cosine to the depth axis); the points are weighed "
                "each by its own variance"
            )
        return (
            f"learned from the residuals: {n.white_sigma_m * 1e6:.1f} um from point to point "
            f"and {n.smooth_sigma_m * 1e6:.1f} um smooth along the line over "
            f"{n.length_m * 1e3:.1f} mm; the points are weighed as correlated"
        )

    def describe(self, base_frame: str) -> str:
        """The axis point, direction and radius (mm)."""
        c = self.cylinder
        return (
            f"Cylinder in {base_frame}: point {mm_text(c.point)}, direction "
            f"{direction_text(c.direction)}, radius {c.radius * 1e3:.3f} mm"
            + (" (estimated)" if self.radius_estimated else " (given)")
            + (
                ""
                if self.scale is None
                else f"; {scale_text(self.scale, self.scale_sigma)}"
                + correlation_text(self.scale_radius_correlation)
            )
            + (
                ""
                if self.depth_scale is None
                else f"; {scale_text(self.depth_scale, self.depth_scale_sigma, 'depth (z)')}"
            )
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
        v = apply_transform(T_base_sensor, self.sensor_points(fit.points)) - c.point
        radial = v - np.outer(v @ c.direction, c.direction)
        return np.asarray(np.linalg.norm(radial, axis=1) - c.radius)

    def surface_map(self, points_base: FloatArray) -> SurfaceMap:
        """Angle around the axis (rad) and position along it (m), measured from the point
        lowest along the axis, so that the scanned length reads 0 to L whichever way the fitted
        direction points."""
        coordinates = cylinder_coordinates(points_base, self.cylinder)
        along = coordinates.along_m
        start = float(np.min(along)) if along.size else 0.0
        return SurfaceMap(
            coordinates.angle_rad,
            along - start,
            "angle around the axis",
            "position along the axis from the first scanned point",
        )

    def feature_distances(
        self, fits: Sequence[SampleFit], T_flange_sensor: FloatArray
    ) -> FloatArray:
        """Distance (M,) of each fit's ellipse centre, recorded pose, from the axis, m."""
        return sample_centre_distances(fits, T_flange_sensor, self.cylinder)

    def given_settings(self) -> dict[str, Any]:
        """None: a cylinder result fixes no setting of a later calibration."""
        return {}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points with the estimated scale errors removed (x / (1 + s), z / (1 + s_z))."""
        return measured_to_true(points, self.scale or 0.0, self.depth_scale or 0.0)


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
    ratio = _optional_number(mapping, "along_line_scale")
    sigma = _optional_number(mapping, "along_line_scale_sigma")
    correlation = _optional_number(mapping, "along_line_scale_radius_correlation")
    if ratio is not None and not ratio > 0.0:
        raise ValueError(f"key along_line_scale must be a ratio > 0, got {ratio}")
    if sigma is not None and not sigma >= 0.0:
        raise ValueError(f"key along_line_scale_sigma must be >= 0, got {sigma}")
    if correlation is not None and not abs(correlation) <= 1.0:
        raise ValueError(
            f"key along_line_scale_radius_correlation must be within [-1, 1], got {correlation}"
        )
    scaled = ratio is not None
    depth_scale, depth_sigma = scales_from_mapping(mapping, "depth_scale")
    return CylinderSection(
        Cylinder(point, direction / norm, float(radius)),
        estimated,
        dict(quality.get("noise_estimated") or {}) or None,
        scale=None if ratio is None else ratio - 1.0,
        scale_sigma=sigma if scaled else None,
        scale_radius_correlation=correlation if scaled else None,
        line_noise=_line_noise(quality.get("line_noise")),
        depth_scale=depth_scale,
        depth_scale_sigma=depth_sigma,
    )


def _line_noise(mapping: Any) -> LineNoise | None:
    """The ``quality.line_noise`` mapping as a LineNoise, or None when absent (ValueError
    naming the key)."""
    if mapping is None:
        return None
    if not isinstance(mapping, Mapping):
        raise ValueError(f"key quality.line_noise must be a mapping, got {mapping!r}")
    white, smooth, length = (
        _optional_number(mapping, k) for k in ("white_sigma_m", "smooth_sigma_m", "length_m")
    )
    if white is None or smooth is None or length is None:
        raise ValueError(
            "key quality.line_noise needs white_sigma_m, smooth_sigma_m and length_m (m)"
        )
    depth = _optional_number(mapping, "depth_sigma_m")  # absent in files before it
    try:
        return LineNoise(white, smooth, length, depth or 0.0)
    except InputError as err:
        raise ValueError(f"key quality.line_noise: {err}") from None


def _optional_number(mapping: Mapping[str, Any], key: str) -> float | None:
    """A finite number under ``key``, or None when absent or null (ValueError naming the key)."""
    value = mapping.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError(f"key {key} must be a finite number, got {value!r}")
    return float(value)


#: |Correlation| of the along-line scale and the radius named in the description.
HIGH_CORRELATION = 0.9


def correlation_text(correlation: float | None) -> str:
    """The scale-radius correlation in words when high, else empty."""
    if correlation is None or abs(correlation) <= HIGH_CORRELATION:
        return ""
    return (
        f", correlated {correlation:+.2f} with the radius (a profile stretched along the line "
        "looks like a larger cylinder)"
    )
