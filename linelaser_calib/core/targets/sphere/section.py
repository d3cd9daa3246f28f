"""The sphere target's part of a result: the sphere in the base frame."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...errors import InputError
from ...geometry import FloatArray, apply_transform
from ...profile.along_line import measured_to_true, scale_text
from ...types import SampleFit
from ..base import Shape, SurfaceMap, mm_text, plain_floats, read_vector
from .model import SIDE_LABELS, side_from_label


def read_sphere_section(mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> SphereSection:
    """The section from a result file's ``sphere`` mapping (ValueError naming a bad key)."""
    centre = read_vector(mapping, "centre")
    try:
        radius = float(mapping["radius"])
        side = side_from_label(str(mapping["centre_side"]))
    except (KeyError, TypeError, ValueError, InputError) as exc:
        raise ValueError(f"sphere needs a radius (m) and centre_side +y or -y: {exc}") from None
    if not radius > 0.0:
        raise ValueError(f"key radius must be > 0 m, got {radius}")
    sigma = mapping.get("uncertainty_m")
    ratio = mapping.get("along_line_scale")
    if ratio is not None and not (isinstance(ratio, (int, float)) and ratio > 0.0):
        raise ValueError(f"key along_line_scale must be a ratio > 0, got {ratio!r}")
    scale_sigma = mapping.get("along_line_scale_sigma")
    return SphereSection(
        centre_m=centre,
        radius_m=radius,
        centre_side=side,
        radius_estimated=bool(quality.get("radius_estimated", False)),
        side_estimated=bool(quality.get("centre_side_estimated", False)),
        centre_sigma_m=None if sigma is None else np.asarray(sigma, dtype=np.float64),
        noise_levels=dict(quality.get("noise_estimated") or {}),
        scale=None if ratio is None else float(ratio) - 1.0,
        scale_sigma=None if ratio is None or scale_sigma is None else float(scale_sigma),
    )


@dataclass(frozen=True)
class SphereSection:
    """The sphere of a result, base frame.

    Attributes
    ----------
    centre_m : ndarray, shape (3,)
    radius_m : float
    centre_side : int
        +1 or −1: the sensor y side of the laser plane the centre lies on.
    radius_estimated, side_estimated : bool
        Estimated from the data (True) or given.
    centre_sigma_m : ndarray, shape (3,), or None
        1σ of the centre per base axis, m (default method).
    noise_levels : dict of str to float
        The noise levels re-estimated from the residuals (``sensor_sigma_m``,
        ``robot_sigma_t_m``, ``robot_sigma_r_rad``; default method), or empty.
    scale, scale_sigma : float or None
        The sensor's along-line scale error s estimated with the sphere, and its 1σ
        (``--scale``); None when it was not estimated.
    """

    key: ClassVar[str] = "sphere"
    title: ClassVar[str] = "sphere"

    centre_m: FloatArray
    radius_m: float
    centre_side: int
    radius_estimated: bool
    side_estimated: bool
    centre_sigma_m: FloatArray | None = None
    noise_levels: Mapping[str, float] | None = None
    scale: float | None = None
    scale_sigma: float | None = None

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, centre, radius, centre_side, uncertainty_m}`` in m, and with an
        estimated scale ``along_line_scale`` (the ratio 1 + s) and its 1σ."""
        scale = (
            {}
            if self.scale is None
            else {
                "along_line_scale": 1.0 + float(self.scale),
                "along_line_scale_sigma": None
                if self.scale_sigma is None
                else float(self.scale_sigma),
            }
        )
        return {
            "frame": base_frame,
            "centre": plain_floats(self.centre_m),
            "radius": float(self.radius_m),
            "centre_side": SIDE_LABELS[self.centre_side],
            "uncertainty_m": None
            if self.centre_sigma_m is None
            else plain_floats(self.centre_sigma_m),
            **scale,
        }

    def quality_entries(self) -> dict[str, Any]:
        """Whether the radius and side were estimated, and the re-estimated noise levels."""
        entries: dict[str, Any] = {
            "radius_estimated": self.radius_estimated,
            "centre_side_estimated": self.side_estimated,
        }
        if self.noise_levels:
            entries["noise_estimated"] = {k: float(v) for k, v in self.noise_levels.items()}
        return entries

    def describe(self, base_frame: str) -> str:
        """One line: centre and radius in mm, side."""
        return (
            f"Sphere in {base_frame}: centre {mm_text(self.centre_m)}, radius "
            f"{self.radius_m * 1e3:.3f} mm ({'estimated' if self.radius_estimated else 'given'})"
            f", centre on the sensor's {SIDE_LABELS[self.centre_side]} side "
            f"({'from the data' if self.side_estimated else 'given'})"
            + ("" if self.scale is None else f"; {scale_text(self.scale, self.scale_sigma)}")
        )

    def residual_kind(self, method: str) -> str:
        """In-plane distance from the sphere (default) or sphere-centre distance (paper)."""
        if method == "paper":
            return "distance of the profile's sphere centre from the common centre"
        return "distance from the sphere, in the laser plane"

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """The sphere."""
        return [Shape("sphere", self.centre_m[None], self.radius_m, "sphere")]

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance of the sample's points from the centre minus the radius (N,), m."""
        points = apply_transform(T_base_sensor, self.sensor_points(fit.points))
        return np.asarray(np.linalg.norm(points - self.centre_m, axis=1) - self.radius_m)

    def surface_map(self, points_base: FloatArray) -> SurfaceMap:
        """Longitude about the base z axis and latitude above the centre's x-y plane, rad."""
        v = np.asarray(points_base, dtype=np.float64).reshape(-1, 3) - self.centre_m
        return SurfaceMap(
            np.arctan2(v[:, 1], v[:, 0]),
            np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1])),
            "longitude about the base z axis",
            "latitude above the centre",
            along_unit="rad",
        )

    def given_settings(self) -> dict[str, Any]:
        """None: a sphere result fixes nothing of a later calibration."""
        return {}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points with the estimated along-line scale error removed (x / (1 + s))."""
        return points if self.scale is None else measured_to_true(points, self.scale)
