"""Per profile: the cleaned points and a RANSAC ellipse (the cylinder's cut by the laser plane)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...ellipse import fit_ellipse_ransac
from ...errors import InputError, ProfileRejected
from ...geometry import FloatArray
from ...profile import clean_profile
from ...types import EllipseFit, Rejection, Sample, SampleFit
from ..base import Progress, extract_each
from .config import CylinderConfig


@dataclass
class FittedSample:
    """A sample with its cleaned points and fitted ellipse (the cylinder target's feature)."""

    sample: Sample
    points: FloatArray
    ellipse: EllipseFit

    @property
    def index(self) -> int:
        """Profile index in the input stream."""
        return self.sample.index

    @property
    def stamp_ns(self) -> int:
        """Profile stamp, ns."""
        return self.sample.stamp_ns

    @property
    def T_base_flange(self) -> FloatArray:
        """Flange pose (4, 4) as paired."""
        return self.sample.T_base_flange

    @property
    def inlier_points(self) -> FloatArray:
        """Inlier points (K, 3) in the sensor frame, m."""
        return self.points[self.ellipse.inliers]

    def record(self) -> SampleFit:
        """The plain record kept in the result."""
        s = self.sample
        return SampleFit(
            s.index, s.stamp_ns, s.T_base_flange, self.inlier_points, self.ellipse.centre_xz
        )


def fit_sample(
    sample: Sample,
    config: CylinderConfig,
    rng: np.random.Generator,
    radius_m: float | None = None,
) -> FittedSample | Rejection:
    """Clean one sample's profile and fit its ellipse; a rejection says why it failed.

    ``radius_m`` (m), when given, bounds the plausible ellipse semi-axes.
    """
    try:
        cleaned = clean_profile(sample.points, config.cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    try:
        ellipse = fit_ellipse_ransac(cleaned.points_xz, config.ellipse, rng, radius_m)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "ellipse", str(exc))
    return FittedSample(sample, cleaned.points, ellipse)


def fit_samples(
    samples: list[Sample], config: CylinderConfig, seed: int, progress: Progress
) -> tuple[list[FittedSample], list[Rejection]]:
    """Fit every sample's ellipse (semi-axes bounded by ``config.radius_m`` when given).

    Raises
    ------
    InputError
        When a configured radius disagrees with the profiles (:func:`settle_radius`).
    """

    def fit_bounded(
        sample: Sample, cfg: CylinderConfig, rng: np.random.Generator
    ) -> FittedSample | Rejection:
        return fit_sample(sample, cfg, rng, cfg.radius_m)

    fitted, rejections = extract_each(
        samples, config, np.random.default_rng(seed), fit_bounded, progress, "ellipse"
    )
    if config.radius_m is not None and len(fitted) < max(config.min_samples, len(samples) // 2):
        # Most profiles failed with the given radius: fit freely to tell the user why.
        free = [fit_sample(s, config, np.random.default_rng(seed)) for s in samples]
        free_fitted = [f for f in free if isinstance(f, FittedSample)]
        if len(free_fitted) > len(fitted):
            settle_radius(free_fitted, config.radius_m)
    return fitted, rejections


def settle_radius(fitted: list[FittedSample], radius_m: float | None) -> float:
    """Radius from the ellipses' semi-minor axes (a cylinder cut's semi-minor axis is its
    radius), checked against a given radius, m.

    Raises
    ------
    InputError
        When the given radius disagrees with the profiles.
    """
    measured = float(np.median([f.ellipse.semi_axes[1] for f in fitted]))
    if radius_m is None:
        return measured
    if abs(measured - radius_m) > max(0.1 * radius_m, 0.002):
        raise InputError(
            f"the given radius {radius_m * 1e3:.2f} mm disagrees with the profiles, whose "
            f"ellipses have a median semi-minor axis of {measured * 1e3:.2f} mm; check the "
            "radius (metres, not the diameter) or omit it to estimate it."
        )
    return radius_m
