"""Each sample's features extracted in runs of samples, the runs shared with a forked
worker.

A target extracts a feature (or a :class:`~linelaser_calib.core.types.Rejection`) from each
sample on its own (:func:`extract_each`) or from a run of samples at once, as one stack of
arrays (:func:`extract_chunks`). Every sample draws its random numbers from its own
generator (:func:`sample_rng`), so the outcome does not depend on the run, the order or the
process a sample was extracted in.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..errors import CalibrationError
from ..forked import map_forked
from ..types import Rejection, Sample
from .base import ConfigT, Progress


def sample_rng(seed: int, index: int) -> np.random.Generator:
    """The random generator of one sample's feature extraction (RANSAC draws): seeded by the
    run's seed and the sample's profile index, so that a profile's feature does not depend on
    which profiles came before it (the collector's check of a live profile, a subset, the
    order, a forked worker all draw the same numbers for it)."""
    return np.random.default_rng([seed, index])


def extract_each(
    samples: list[Sample],
    config: ConfigT,
    seed: int,
    extract_one: Callable[[Sample, ConfigT, np.random.Generator], Any],
    progress: Progress,
    stage: str,
    workers: int = 1,
) -> tuple[list[Any], list[Rejection]]:
    """:func:`extract_chunks` of ``extract_one`` (feature or Rejection) on each sample."""

    def chunk(run: Sequence[Sample], cfg: ConfigT, rngs: Sequence[np.random.Generator]) -> Any:
        return [extract_one(sample, cfg, rng) for sample, rng in zip(run, rngs, strict=True)]

    return extract_chunks(samples, config, seed, chunk, progress, stage, workers)


def extract_chunks(
    samples: list[Sample],
    config: ConfigT,
    seed: int,
    extract_chunk: Callable[[Sequence[Sample], ConfigT, Sequence[np.random.Generator]], list[Any]],
    progress: Progress,
    stage: str,
    workers: int = 1,
    chunk_size: int = 1,
) -> tuple[list[Any], list[Rejection]]:
    """Features of every sample (feature or Rejection), in order, by ``extract_chunk`` on
    runs of ``chunk_size`` samples. Each sample draws from its own generator
    (:func:`sample_rng`), so ``workers`` 2 shares the runs with a forked child
    (:func:`~linelaser_calib.core.forked.map_forked`) with the same outcome. The first
    CalibrationError raised (in the runs' order) is raised here."""
    parent, reported = os.getpid(), [0]

    def run(start: int) -> list[Any]:
        chunk = samples[start : start + chunk_size]
        outcomes = extract_chunk(chunk, config, [sample_rng(seed, s.index) for s in chunk])
        if os.getpid() == parent:  # the forked child reports nothing
            reported[0] = start + len(chunk)
            progress(stage, reported[0], len(samples))
        return outcomes

    features: list[Any] = []
    rejections: list[Rejection] = []
    for outcomes in map_forked(run, range(0, len(samples), chunk_size), workers):
        if isinstance(outcomes, CalibrationError):
            raise outcomes
        for outcome in outcomes:
            (rejections if isinstance(outcome, Rejection) else features).append(outcome)
    if reported[0] < len(samples):
        progress(stage, len(samples), len(samples))
    return features, rejections
