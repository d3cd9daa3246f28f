"""Per profile: the cleaned points and a RANSAC ellipse (the cylinder's cut by the laser plane),
found among the planes of the scene (:mod:`linelaser_calib.core.targets.cylinder.arc`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import InputError, ProfileRejected
from ...geometry import FloatArray
from ...model_check import Comparison
from ...profile.cleaning import CleanedProfile, clean_profiles
from ...profile.segmentation import SegmentedProfile, segment_profiles
from ...types import BoolArray, Rejection, Sample, SampleFit, StoredArray, stored_points
from ..base import Progress
from ..runs import extract_chunks, sample_rng
from .arc import (
    circle_centre,
    circle_radius,
    fit_arc_in_scene,
    grazing_ends_biased,
    radius_mismatch,
    trimming_note,
    without_grazing_ends,
)
from .config import CylinderConfig
from .ellipse import EllipseConfig, EllipseFit
from .shape import (
    arc_rival_rejection,
    compare_ellipse,
    compare_with_line,
    compare_without_arc,
)

#: Fewest cleaned points of a profile without an arc that are weighed against the rivals
#: (a line pair needs 8).
MIN_RIVAL_POINTS = 8


@dataclass
class FittedSample:
    """A sample's pairing (its profile's ``index`` and ``stamp_ns``, its flange pose) with
    the points of its arc and its fitted ellipse (the cylinder target's feature); ``trimmed``
    says how many grazing-angle points were trimmed from the arc, ``rival`` gives the
    comparison when a rival shape fits this one profile clearly better than its ellipse
    (kept: where most profiles are so, the whole recording decides,
    :meth:`~.target.CylinderTarget.model_doubt`).

    A feature is held through the whole calibration, so it keeps only what the later stages
    use: not the sample's raw points, and its arc's points as stored points
    (:func:`~linelaser_calib.core.types.stored_points`); ``grazing``,
    ``noise_sigma_m``, ``grazing_shift_sigmas`` and ``ellipse_config`` are those of its arc
    (:class:`.arc.ArcFit`), for the refit without the grazing ends."""

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    points: StoredArray
    ellipse: EllipseFit
    ellipse_config: EllipseConfig
    grazing: BoolArray
    noise_sigma_m: float
    grazing_shift_sigmas: float = math.nan
    trimmed: int = 0
    rival: Comparison | None = None
    _inliers: tuple[EllipseFit, StoredArray] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    def __getstate__(self) -> dict[str, Any]:
        """Pickled (a forked worker's result) without the inlier cache, taken again on use."""
        return {**self.__dict__, "_inliers": None}

    @property
    def inlier_points(self) -> FloatArray:
        """Inlier points (K, 3) in the sensor frame, m (float64)."""
        return np.asarray(self.stored_inliers, dtype=np.float64)

    @property
    def stored_inliers(self) -> StoredArray:
        """The inlier points as stored (float32 where exact, :attr:`points`), for a consumer
        that converts them itself (the refinement's padded arrays): taken once per ellipse,
        so every solve's sample records, the self-check's included, share one array."""
        if self._inliers is None or self._inliers[0] is not self.ellipse:
            inliers = self.ellipse.inliers
            self._inliers = (self.ellipse, self.points if inliers.all() else self.points[inliers])
        return self._inliers[1]

    @property
    def points_xz(self) -> FloatArray:
        """The arc's points (M, 2) in the laser plane, (x, z), m."""
        return np.asarray(self.points[:, [0, 2]], dtype=np.float64)

    def centre_xz(self, radius_m: float) -> FloatArray:
        """The centre (2,) a solve on the centres uses, m: the ellipse's, or for a short arc
        the centre of the circle of radius ``radius_m`` (m) through its points
        (:func:`.arc.circle_centre`), which a short arc fixes far better than an ellipse."""
        if not self.ellipse.short:
            return self.ellipse.centre_xz
        return circle_centre(self.inlier_points[:, [0, 2]], radius_m)

    def record(self) -> SampleFit:
        """The plain record kept in the result."""
        return SampleFit(
            self.index,
            self.stamp_ns,
            self.T_base_flange,
            self.stored_inliers,
            self.ellipse.centre_xz,
        )


#: Samples whose cleaning and segmentation run as one batch (:func:`fit_chunk`): the stages'
#: array calls cost about the same for one profile as for a few dozen.
CHUNK_SIZE = 32


def fit_sample(
    sample: Sample,
    config: CylinderConfig,
    rng: np.random.Generator,
    radius_m: float | None = None,
) -> FittedSample | Rejection:
    """Clean one sample's profile and fit its ellipse; a rejection says why it failed:
    :func:`fit_chunk` of this one sample."""
    (outcome,) = fit_chunk([sample], config, [rng], radius_m)
    return outcome


def fit_chunk(
    samples: Sequence[Sample],
    config: CylinderConfig,
    rngs: Sequence[np.random.Generator],
    radius_m: float | None = None,
) -> list[FittedSample | Rejection]:
    """Clean and segment the samples' profiles (all at once,
    :func:`~linelaser_calib.core.profile.cleaning.clean_profiles`,
    :func:`~linelaser_calib.core.profile.segmentation.segment_profiles`) and fit each one's
    ellipse, drawing from its generator in ``rngs``; a rejection says why a sample failed.

    ``radius_m`` (m), when given, bounds the plausible ellipse semi-axes. A profile without
    an arc that a rival shape (a line, a V) fits clearly better than any conic gives a
    :class:`~linelaser_calib.core.model_check.RivalRejection` (:mod:`.shape`); an arc that
    a rival fits clearly better is kept, with the comparison (:attr:`FittedSample.rival`):
    one profile does not decide what the recording shows. A short arc
    (:attr:`~.ellipse.EllipseFit.short`) must also fit its ellipse clearly better than a
    line.
    """
    cleaned = clean_profiles([sample.points for sample in samples], config.cleaning)
    kept = [profile for profile in cleaned if not isinstance(profile, ProfileRejected)]
    segmented = iter(segment_profiles([c.points_xz for c in kept], config.arc.segmentation))
    return [
        Rejection(sample.index, sample.stamp_ns, "cleaning", str(profile))
        if isinstance(profile, ProfileRejected)
        else _fit_cleaned(sample, profile, next(segmented), config, rng, radius_m)
        for sample, profile, rng in zip(samples, cleaned, rngs, strict=True)
    ]


def _fit_cleaned(
    sample: Sample,
    cleaned: CleanedProfile,
    segmented: SegmentedProfile,
    config: CylinderConfig,
    rng: np.random.Generator,
    radius_m: float | None,
) -> FittedSample | Rejection:
    """The ellipse of one sample's cleaned and segmented profile (:func:`fit_chunk`)."""
    try:
        arc = fit_arc_in_scene(
            cleaned.points_xz, config.ellipse, rng, radius_m, config.arc, segmented
        )
    except ProfileRejected as exc:
        if len(cleaned.points_xz) >= MIN_RIVAL_POINTS:
            comparison = compare_without_arc(cleaned.points_xz)
            if comparison.rival_wins:
                return arc_rival_rejection(sample.index, sample.stamp_ns, comparison)
        return Rejection(sample.index, sample.stamp_ns, "ellipse", str(exc))
    comparison = compare_ellipse(arc.points_xz, arc.ellipse.conic)
    if arc.ellipse.short:
        to_line = compare_with_line(arc.points_xz[arc.ellipse.inliers], arc.ellipse.conic)
        if not to_line.model_wins:
            return Rejection(
                sample.index,
                sample.stamp_ns,
                "ellipse",
                f"the short arc is not clearly curved: {to_line.describe()}",
            )
    return FittedSample(
        sample.index,
        sample.stamp_ns,
        sample.T_base_flange,
        stored_points(cleaned.points[arc.rows]),
        arc.ellipse,
        arc.ellipse_config,
        arc.grazing,
        arc.noise_sigma_m,
        arc.grazing_shift_sigmas,
        rival=comparison if comparison.rival_wins else None,
    )


def fit_samples(
    samples: list[Sample],
    config: CylinderConfig,
    seed: int,
    progress: Progress,
    workers: int = 1,
) -> tuple[list[FittedSample], list[Rejection]]:
    """Fit every sample's ellipse (semi-axes bounded by ``config.radius_m`` when given);
    ``workers`` as in :func:`~linelaser_calib.core.targets.runs.extract_chunks`.

    Arcs that a rival shape fits better one by one are used: a real profiler's shape error
    makes a V or a line beat an ellipse now and then, and the refinement's outlier test sets
    aside an arc that the one cylinder does not explain.

    Raises
    ------
    InputError
        When a configured radius disagrees with the profiles (:func:`settle_radius`).
    """

    def fit_bounded(
        chunk: Sequence[Sample], cfg: CylinderConfig, rngs: Sequence[np.random.Generator]
    ) -> list[FittedSample | Rejection]:
        return fit_chunk(chunk, cfg, rngs, cfg.radius_m)

    fitted, rejections = extract_chunks(
        samples, config, seed, fit_bounded, progress, "ellipse", workers, CHUNK_SIZE
    )
    if config.radius_m is not None and len(fitted) < max(config.min_samples, len(samples) // 2):
        # Most profiles failed with the given radius: fit freely to tell the user why.
        free = [fit_sample(s, config, sample_rng(seed, s.index)) for s in samples]
        free_fitted = [f for f in free if isinstance(f, FittedSample)]
        if len(free_fitted) > len(fitted):
            settle_radius(free_fitted, config.radius_m)
    _trim_biased_grazing_ends(fitted, config.radius_m)
    return fitted, rejections


def _trim_biased_grazing_ends(fitted: list[FittedSample], radius_m: float | None) -> None:
    """Fit the long arcs again without their grazing ends when those ends are biased."""
    long = long_arcs(fitted)
    if grazing_ends_biased([f.grazing_shift_sigmas for f in long]) is None:
        return
    for f in long:
        trimmed = without_grazing_ends(
            f.points_xz, f.grazing, f.ellipse_config, f.noise_sigma_m, radius_m
        )
        if trimmed is not None:
            f.trimmed = int(f.ellipse.inliers.sum() - trimmed.inliers.sum())
            f.ellipse = trimmed


def long_arcs(fitted: list[FittedSample]) -> list[FittedSample]:
    """The samples whose ellipse is a measurement (not a short arc's)."""
    return [f for f in fitted if not f.ellipse.short]


def arc_notes(fitted: list[FittedSample], config: CylinderConfig) -> list[str]:
    """Warnings on the arcs: a given radius the long arcs contradict, trimmed grazing ends,
    short arcs."""
    long = long_arcs(fitted)
    notes = [radius_mismatch([f.ellipse.semi_axes[1] for f in long], config.radius_m)]
    shift = grazing_ends_biased([f.grazing_shift_sigmas for f in long])
    if shift is not None:
        notes.append(trimming_note([f.trimmed for f in long], shift, config.arc))
    return [note for note in notes if note is not None]


def settle_radius(fitted: list[FittedSample], radius_m: float | None) -> float:
    """Radius from the long arcs' semi-minor axes (a cylinder cut's semi-minor axis is its
    radius; :func:`long_arcs`; without long arcs, the median radius of the circles through
    the short ones, :func:`.arc.circle_radius`), checked against a given radius, m.

    Raises
    ------
    InputError
        When the given radius disagrees with the profiles.
    """
    long = long_arcs(fitted)
    if not long and radius_m is not None:
        return radius_m  # short arcs: their semi-minor axes do not contradict it
    if long:
        measured = float(np.median([f.ellipse.semi_axes[1] for f in long]))
    else:
        measured = float(np.median([circle_radius(f.inlier_points[:, [0, 2]]) for f in fitted]))
    if radius_m is None:
        return measured
    if abs(measured - radius_m) > max(0.1 * radius_m, 0.002):
        raise InputError(
            f"the given radius {radius_m * 1e3:.2f} mm disagrees with the profiles, whose "
            f"ellipses have a median semi-minor axis of {measured * 1e3:.2f} mm; check the "
            "radius (metres, not the diameter) or omit it to estimate it."
        )
    return radius_m
