"""Residuals of a calibration result, for reports and markers.

The fitted samples' profile points are mapped into the base frame with the recorded flange
poses and the calibrated hand-eye, ``x = T_base_flange · T_flange_sensor · p``, and compared
with the fitted cylinder. The default method's own residual (``rms_residual_m``) also
corrects each flange pose by its estimated robot error, so the residuals here, which show
how well the hand-eye works with the poses the robot reports, are larger by about the
robot's repeatability.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...geometry import FloatArray, apply_transform, check_transform, orthonormal_basis
from ...types import SampleFit
from .model import Cylinder, centre_distances


@dataclass(frozen=True)
class CylinderCoordinates:
    """Points expressed in the cylinder's own coordinates.

    Attributes
    ----------
    angle_rad : ndarray, shape (N,)
        Angle around the axis in (-π, π], rad, from the first vector of
        ``orthonormal_basis(cylinder.direction)`` towards the second.
    along_m : ndarray, shape (N,)
        Position along the axis from ``cylinder.point``, m.
    residual_m : ndarray, shape (N,)
        Signed distance to the surface, m: distance to the axis minus the radius
        (positive outside the cylinder).
    """

    angle_rad: FloatArray
    along_m: FloatArray
    residual_m: FloatArray


def cylinder_coordinates(points_base: FloatArray, cylinder: Cylinder) -> CylinderCoordinates:
    """Angle, axial position and signed surface distance of base-frame points.

    Parameters
    ----------
    points_base : ndarray, shape (N, 3)
        Points in the cylinder's frame, m.
    cylinder : Cylinder
        Axis point (3,) m, direction (3,) (normalised here) and radius m.

    Returns
    -------
    CylinderCoordinates
    """
    x = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
    direction = np.asarray(cylinder.direction, dtype=np.float64)
    direction = direction / np.linalg.norm(direction)
    u, v = orthonormal_basis(direction)
    w = x - np.asarray(cylinder.point, dtype=np.float64)
    along = w @ direction
    radial = w - along[:, None] * direction
    return CylinderCoordinates(
        angle_rad=np.arctan2(radial @ v, radial @ u),
        along_m=along,
        residual_m=np.linalg.norm(radial, axis=1) - float(cylinder.radius),
    )


def sample_points_base(fit: SampleFit, T_flange_sensor: FloatArray) -> FloatArray:
    """A fitted sample's inlier points in the base frame, m, shape (K, 3).

    ``T_base_flange · T_flange_sensor · p`` with the sample's recorded flange pose.
    """
    T = check_transform(T_flange_sensor)
    return apply_transform(fit.T_base_flange @ T, fit.points)


def sample_surface_residuals(
    fits: Sequence[SampleFit], T_flange_sensor: FloatArray, cylinder: Cylinder
) -> list[FloatArray]:
    """Signed point-to-surface distance of every fitted sample's inlier points.

    Parameters
    ----------
    fits : sequence of SampleFit
        Inlier points (K_j, 3) in the sensor frame, m, and recorded flange poses.
    T_flange_sensor : ndarray, shape (4, 4)
    cylinder : Cylinder
        In the base frame.

    Returns
    -------
    list of ndarray, shape (K_j,)
        Distances, m (positive outside the cylinder), one array per sample.
    """
    return [
        cylinder_coordinates(sample_points_base(f, T_flange_sensor), cylinder).residual_m
        for f in fits
    ]


def sample_centre_distances(
    fits: Sequence[SampleFit], T_flange_sensor: FloatArray, cylinder: Cylinder
) -> FloatArray:
    """Distance of each sample's ellipse centre, mapped into the base frame, to the axis.

    The cylinder paper's residual (eq. 6, Fig. 10), with the recorded flange poses.

    Returns
    -------
    ndarray, shape (M,)
        Distances, m, in the order of ``fits`` (empty for no fits).
    """
    if not fits:
        return np.zeros(0)
    centres = np.array([f.feature_xz for f in fits])
    T_base_flange = np.stack([f.T_base_flange for f in fits])
    return centre_distances(centres, T_base_flange, T_flange_sensor, cylinder)


def axis_extent(points_base: FloatArray, cylinder: Cylinder) -> tuple[FloatArray, float]:
    """Centre (3,) in m and length in m of the axis piece that the points cover.

    The length has a 10 % margin and is at least the diameter, so a cylinder drawn with it
    covers the scanned part.
    """
    direction = cylinder.direction / np.linalg.norm(cylinder.direction)
    minimum = 2.0 * cylinder.radius
    if len(points_base) == 0:
        return np.asarray(cylinder.point, dtype=np.float64), minimum
    s = (points_base - cylinder.point) @ direction
    lo, hi = float(np.min(s)), float(np.max(s))
    centre = cylinder.point + 0.5 * (lo + hi) * direction
    return np.asarray(centre, dtype=np.float64), max(1.1 * (hi - lo), minimum)
