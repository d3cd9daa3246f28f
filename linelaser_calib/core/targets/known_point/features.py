"""Per profile: the cleaned points and the V corner of the weld seam (the known point)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ProfileRejected
from ...geometry import FloatArray
from ...profile.cleaning import clean_profile
from ...profile.corner import CornerFit, fit_corner
from ...types import Rejection, Sample, SampleFit
from ..base import Progress, extract_each
from .config import KnownPointConfig


@dataclass(frozen=True)
class CornerSample:
    """A sample whose profile gave a weld-seam corner.

    Attributes
    ----------
    index : int
        Profile index in the input stream.
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
        Flange pose as paired (recorded).
    corner_xz : ndarray, shape (2,)
        Corner in the sensor x-z plane, m.
    covariance_xz : ndarray, shape (2, 2)
        From the line fits, m².
    points : ndarray, shape (K, 3)
        The two lines' inlier points, sensor frame, m.
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    corner_xz: FloatArray
    covariance_xz: FloatArray
    points: FloatArray

    def record(self) -> SampleFit:
        """The plain record kept in the result (the V corner as the feature point)."""
        return SampleFit(self.index, self.stamp_ns, self.T_base_flange, self.points, self.corner_xz)


def extract_corner(
    sample: Sample, config: KnownPointConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """Clean one sample's profile and fit its V corner; a rejection says why it failed.

    Parameters
    ----------
    sample : Sample
        Profile (sensor frame, m) paired with its flange pose.
    config : KnownPointConfig
        Its ``cleaning`` and ``corner`` settings apply.
    rng : numpy.random.Generator
        For the RANSAC line fits.

    Returns
    -------
    CornerSample or Rejection
        A rejection has stage ``cleaning`` or ``corner``.
    """
    try:
        cleaned = clean_profile(sample.points, config.cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    try:
        fit: CornerFit = fit_corner(cleaned.points_xz, config.corner, rng)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "corner", str(exc))
    return CornerSample(
        sample.index,
        sample.stamp_ns,
        np.asarray(sample.T_base_flange, dtype=np.float64),
        fit.corner_xz,
        fit.covariance_xz,
        cleaned.points[fit.inliers.any(axis=0)],
    )


def _silent(stage: str, done: int, total: int) -> None:
    """No progress report."""


def extract_corners(
    samples: list[Sample],
    config: KnownPointConfig,
    seed: int,
    progress: Progress = _silent,
    workers: int = 1,
) -> tuple[list[CornerSample], list[Rejection]]:
    """:func:`extract_corner` of every sample: the corners and the rejections (``seed`` and
    ``workers`` as in :func:`~linelaser_calib.core.targets.base.extract_each`)."""
    return extract_each(samples, config, seed, extract_corner, progress, "corner", workers)
