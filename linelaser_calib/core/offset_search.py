"""The clock offset between profile and pose stamps, estimated from the target's fit.

In continuous scanning a profile stamped with latency τ is paired with the pose the flange
had τ earlier or later, and every profile lands slightly off the target.
:func:`search_clock_offset` finds the offset at which the target's features fit it best,
and hands the calibration at that offset (:func:`~.pipeline.run_pipeline`) what it
extracted (:class:`~.pipeline.Extracted`: each profile's features extracted once per run,
:mod:`.targets.extraction`); :class:`OffsetSearch` runs the same search for each rival
target the whole-recording check fits (:mod:`.targets.rivals`), which is judged at its own
offset.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .errors import InputError, PairingError, TooFewFeatures
from .pairing import NS_PER_S, PairingConfig, PoseBuffer, pair_profiles
from .pipeline import Extracted, PipelineConfig
from .pose_track import PoseTrack
from .targets.base import Progress, SolveContext, Target, _no_progress
from .targets.extraction import Extractions
from .targets.rivals import refuse_without_fit
from .thinning import thin_samples
from .types import FlangePose, Profile, Sample

#: Offsets of the clock-offset search's first grid (:func:`search_clock_offset`).
GRID_POINTS = 11
#: Evaluations the search takes after its grid, for the progress display (Brent's method
#: to 0.1 ms from a 20 ms bracket: 6 on bags/line, where a golden-section search took 13).
REFINING_EVALUATIONS = 8


#: History keys (``CalibrationResult.history``) of the clock offsets tried by
#: :func:`search_clock_offset`, s, in increasing order, and their costs.
OFFSET_TRIALS, OFFSET_COSTS = "clock_offset_trial_s", "clock_offset_cost"


def search_clock_offset(
    profiles: list[Profile],
    poses: PoseTrack | Sequence[FlangePose],
    config: PipelineConfig,
    half_range_s: float = 0.05,
    tolerance_s: float = 1e-4,
    progress: Progress = _no_progress,
    trace: list[tuple[float, float]] | None = None,
) -> tuple[float, Extracted]:
    """The clock offset (s) between profile and pose stamps that fits the target best, and
    the features it was searched on (for :func:`~.pipeline.run_pipeline` to use again).

    In continuous scanning a profile stamped with latency τ is paired with the pose the
    flange had τ earlier or later, and every profile lands slightly off the target. The
    target's offset cost (for the cylinder: the refinement's maximum-likelihood cost over the
    points, robot pose error modelled) is evaluated at offsets within ``half_range_s`` of
    ``config.pairing.clock_offset_s``: a grid of :data:`GRID_POINTS`, then Brent's method
    (:func:`scipy.optimize.minimize_scalar`, bounded: parabolic steps on a cost that is about
    quadratic in the offset near its minimum) between the best grid offset's neighbours, to
    ``tolerance_s``. The features are extracted once. Where the cost is flat (step-and-shoot:
    the flange stands still at every profile) the configured offset is returned.
    ``progress`` hears of the extraction and of each evaluation of the cost; ``trace``, when
    given, receives every (offset in s, cost) evaluated, for a figure. Where the target's
    model is in doubt (here: too few profiles show its feature; after the solve:
    :func:`~.targets.rivals.check_model`), each rival target is judged at its own best
    offset, searched likewise from the same samples (:class:`OffsetSearch`), its features
    extracted once for its search and its fit.

    Raises
    ------
    InputError
        The target cannot estimate the offset.
    PairingError, DegenerateError
        As :func:`~.pipeline.run_pipeline` would for the same data.
    ModelMismatch
        Too few profiles show the target's feature and a rival, at its own offset, explains
        the recording clearly better.
    """
    target, target_config = config.target_impl, config.target_config
    moving = replace(config.pairing, max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
    paired = pair_profiles(profiles, poses, moving)
    if not paired.samples:
        raise PairingError(paired.explain_nothing_paired(config.pairing))
    samples, _ = thin_samples(paired.samples, config.per_neighbourhood)
    extractions = Extractions(config.seed, config.workers)
    features, rejections = extractions.of(target, target_config, samples, progress)
    context = SolveContext(seed=config.seed, rejections=rejections, n_samples=len(paired.samples))
    buffer = PoseBuffer()
    buffer.extend(poses)
    search = OffsetSearch(buffer, config.pairing, extractions, half_range_s, tolerance_s)
    extracted = Extracted(tuple(s.index for s in samples), extractions, search.rival)
    try:
        offset = search.best(target, target_config, features, context, progress, trace)
    except TooFewFeatures as refusal:
        refuse_without_fit(target, samples, refusal, context, search.rival, extractions)
        raise
    return offset, extracted


@dataclass(frozen=True)
class OffsetSearch:
    """The clock-offset search of :func:`search_clock_offset` over one pose stream, for the
    target and for each of its rivals.

    Attributes
    ----------
    buffer : PoseBuffer
        The recording's flange poses.
    pairing : PairingConfig
        The configured pairing: the search is centred on its clock offset.
    extractions : Extractions
        The run's features (a rival's extracted once, for its search and its fit).
    half_range_s, tolerance_s : float
        The offsets searched, ``pairing.clock_offset_s`` +- ``half_range_s``, to
        ``tolerance_s``.
    """

    buffer: PoseBuffer
    pairing: PairingConfig
    extractions: Extractions
    half_range_s: float
    tolerance_s: float

    def best(
        self,
        target: Target[Any],
        target_config: Any,
        features: list[Any],
        context: SolveContext,
        progress: Progress = _no_progress,
        trace: list[tuple[float, float]] | None = None,
    ) -> float:
        """The offset (s) at which ``target``'s features (extracted from samples paired at
        the configured offset) fit it best (see :func:`search_clock_offset`).

        Raises
        ------
        InputError
            The target cannot estimate the offset.
        TooFewFeatures
            As the target's solve would.
        """
        start = self.pairing.clock_offset_s
        cost_of_poses = target.offset_cost(features, target_config, context)
        if cost_of_poses is None:
            raise InputError(
                f"the clock offset cannot be estimated from {target.title} scans; give it "
                "with {setting:clock_offset_s} SECONDS"
            )
        stamps_ns = np.array([f.stamp_ns for f in features], dtype=np.int64)
        tolerance_ns = round(self.pairing.sync_tolerance_s * NS_PER_S)
        step = 2.0 * self.half_range_s / (GRID_POINTS - 1)
        evaluations = GRID_POINTS + REFINING_EVALUATIONS
        evaluated = [0]

        def cost(offset_s: float) -> float:
            evaluated[0] += 1
            progress("clock offset", min(evaluated[0], evaluations - 1), evaluations)
            shift = round(offset_s * NS_PER_S)
            T, found = self.buffer.track.at(stamps_ns + shift, tolerance_ns)
            value = float(cost_of_poses(T)) if found.all() else float("inf")
            if trace is not None:
                trace.append((offset_s, value))
            return value

        grid = np.linspace(start - self.half_range_s, start + self.half_range_s, GRID_POINTS)
        costs = np.array([cost(float(t)) for t in grid])
        finite = costs[np.isfinite(costs)]
        if finite.size == 0 or float(np.max(finite) - np.min(finite)) < 1.0:
            progress("clock offset", evaluations, evaluations)
            return start
        best = float(grid[int(np.argmin(costs))])
        ceiling = float(np.max(finite)) + 1.0  # where poses run out: worse than any offset seen

        def bounded(offset_s: float) -> float:
            return min(cost(offset_s), ceiling)

        found = minimize_scalar(
            bounded,
            bounds=(best - step, best + step),
            method="bounded",
            options={"xatol": self.tolerance_s},
        )
        progress("clock offset", evaluations, evaluations)
        return float(found.x)

    def rival(self, rival: Target[Any], samples: list[Sample]) -> tuple[list[Sample], float | None]:
        """The :data:`~.targets.rivals.RivalSamples` of the search: the profiles of
        ``samples`` paired at the offset that fits ``rival`` best (its default settings,
        searched from the configured offset; the profiles that no pose brackets there left
        out, no speed gate applied again), and that offset; the samples unchanged and None
        for a rival that estimates no offset.

        Raises
        ------
        CalibrationError
            The rival cannot be fitted to these samples.
        """
        if not rival.estimates_clock_offset:
            return samples, None
        rival_config = rival.config_type()
        features, rejections = self.extractions.of(rival, rival_config, samples)
        context = SolveContext(
            seed=self.extractions.seed, rejections=rejections, n_samples=len(samples)
        )
        offset = self.best(rival, rival_config, features, context)
        # The samples passed the speed gates where the target's did: re-paired only.
        at_offset = replace(
            self.pairing,
            clock_offset_s=offset,
            max_linear_speed_m_s=0.0,
            max_angular_speed_rad_s=0.0,
        )
        repaired = self.buffer.pair_many(
            [Profile(s.stamp_ns, s.points) for s in samples], [s.index for s in samples], at_offset
        )
        return [s for s in repaired if isinstance(s, Sample)], offset
