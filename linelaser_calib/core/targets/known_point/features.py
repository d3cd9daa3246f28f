"""Per profile: the V corner of the weld seam (the known point)."""

from __future__ import annotations

import numpy as np

from ...profile.corner import CornerSample, check_corner_recording, extract_corner_sample
from ...types import Rejection, Sample
from ..base import Progress
from ..runs import extract_each
from .config import KnownPointConfig


def extract_corner(
    sample: Sample, config: KnownPointConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """:func:`~...profile.corner.extract_corner_sample` with the known point's ``cleaning``
    and ``corner`` settings."""
    return extract_corner_sample(sample, config.cleaning, config.corner, rng)


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
    ``workers`` as in :func:`~linelaser_calib.core.targets.runs.extract_each`), corners that
    are outliers among the recording's set aside
    (:func:`~...profile.corner.check_corner_recording`).
    """
    corners, rejections = extract_each(
        samples, config, seed, extract_corner, progress, "corner", workers
    )
    return check_corner_recording(corners, rejections, config.corner.profile_outlier_sigmas)
