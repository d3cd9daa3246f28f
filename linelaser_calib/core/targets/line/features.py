"""Each profile's feature point for the straight-line target: the seam corner.

Two kinds of input:

- A whole profile of a V or fillet joint: the V-corner fit of the known-point target
  (:func:`~...profile.corner.extract_corner_sample`: cleaning, two RANSAC lines,
  their intersection and its covariance).
- Feature points only, as seam trackers publish them: a message with at most
  ``max_feature_points`` finite points. One point is the seam point. With three or more,
  the seam point is the vertex of the polyline (in x order) farthest from the chord between
  its two end points, the root of the groove between its edges; the polyline must bend there
  by at least the corner fit's ``min_bend_rad``. Two points do not say which is the seam.
  Such messages are not cleaned (a handful of points is all there is) and their corner
  covariance is the configured feature-point σ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...profile.cleaning import CleaningConfig
from ...profile.corner import CornerConfig, CornerSample, extract_corner_sample
from ...types import Rejection, Sample

#: Default largest number of finite points of a feature-point message.
MAX_FEATURE_POINTS = 8


@dataclass(frozen=True)
class LineFeatureConfig:
    """How the seam corner of each profile is found (SI units).

    Attributes
    ----------
    cleaning : CleaningConfig
        Cleaning of whole profiles before the corner fit.
    corner : CornerConfig
        The V-corner fit; its ``min_bend_rad`` also applies to feature points.
    max_feature_points : int
        A message with at most this many finite points holds feature points, not a profile.
        Default 8.
    feature_point_sigma_m : float
        1σ per axis (x, z) of a seam point from feature points, m. Default 10 µm.
    """

    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    corner: CornerConfig = field(default_factory=CornerConfig)
    max_feature_points: int = MAX_FEATURE_POINTS
    feature_point_sigma_m: float = 1e-5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.feature_point_sigma_m) and self.feature_point_sigma_m > 0):
            raise InputError(
                "LineFeatureConfig.feature_point_sigma_m must be positive, got "
                f"{self.feature_point_sigma_m}"
            )
        if self.max_feature_points < 1:
            raise InputError(
                f"LineFeatureConfig.max_feature_points must be >= 1, got {self.max_feature_points}"
            )


def _feature_corner(
    sample: Sample, finite: np.ndarray, config: LineFeatureConfig
) -> CornerSample | Rejection:
    """The seam point of a feature-point message (see the module docstring)."""
    p = np.asarray(sample.points[finite], dtype=np.float64)
    xz = p[:, [0, 2]][np.argsort(p[:, 0])]
    if len(xz) == 2:
        return Rejection(
            sample.index,
            sample.stamp_ns,
            "corner",
            "two feature points do not say which one is the seam point: publish the seam "
            "point alone, or with the groove's edges on both sides",
        )
    vertex = 0
    if len(xz) >= 3:
        chord = xz[-1] - xz[0]
        normal = np.array([-chord[1], chord[0]]) / max(float(np.linalg.norm(chord)), 1e-300)
        vertex = 1 + int(np.argmax(np.abs((xz[1:-1] - xz[0]) @ normal)))
        a, b = xz[0] - xz[vertex], xz[-1] - xz[vertex]
        cosine = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300)
        bend = math.pi - math.acos(min(1.0, max(-1.0, cosine)))
        if bend < config.corner.min_bend_rad:
            return Rejection(
                sample.index,
                sample.stamp_ns,
                "corner",
                f"the {len(xz)} feature points bend by only {math.degrees(bend):.1f} deg (at "
                f"least {math.degrees(config.corner.min_bend_rad):.1f} deg needed): no groove "
                "root among them",
            )
    return CornerSample(
        sample.index,
        sample.stamp_ns,
        np.asarray(sample.T_base_flange, dtype=np.float64),
        np.asarray(xz[vertex], dtype=np.float64),
        np.eye(2) * config.feature_point_sigma_m**2,
        np.asarray(p, dtype=np.float64),
    )


def extract_line_feature(
    sample: Sample, config: LineFeatureConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """The seam corner of one sample; a rejection (stage ``cleaning`` or ``corner``) says why not.

    Parameters
    ----------
    sample : Sample
        A profile or a feature-point message (sensor frame, m) with its flange pose.
    config : LineFeatureConfig
    rng : numpy.random.Generator
        For the RANSAC line fits of whole profiles.
    """
    points = np.asarray(sample.points, dtype=np.float64)
    finite = np.all(np.isfinite(points), axis=1) if points.ndim == 2 else np.zeros(0, bool)
    count = int(finite.sum())
    if count == 0:
        return Rejection(
            sample.index, sample.stamp_ns, "cleaning", "the profile has no valid points"
        )
    if count <= config.max_feature_points:
        return _feature_corner(sample, finite, config)
    return extract_corner_sample(sample, config.cleaning, config.corner, rng)
