"""The calibration pipeline: pair, clean, fit ellipses, solve globally, refine, diagnose.

This is the one pipeline. The CLI (offline, from a bag) and the calibration_service node
(online, from collected samples) both call :func:`run_pipeline` or :func:`calibrate_samples`.

Methods
-------
``paper``
    The cylinder paper as published: RANSAC ellipse centres, centre-to-axis cost (eq. 12),
    PSO + generalized-Lagrange-multiplier hybrid (Fig. 4).
``default``
    The paper's solve as a seed, then maximum likelihood on every inlier point with the
    robot's per-sample pose error as nuisance parameters, outlier-sample rejection,
    covariance and observability diagnostics (:mod:`linelaser_calib.core.refine`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from .arc import (
    ArcConfig,
    ArcFit,
    fit_arc_in_scene,
    grazing_ends_biased,
    radius_mismatch,
    trimming_note,
    without_grazing_ends,
)
from .cylinder_model import centre_distances
from .ellipse import EllipseConfig
from .errors import CalibrationError, DegenerateError, InputError, PairingError, ProfileRejected
from .geometry import FloatArray, check_transform
from .known_point import CornerSample, KnownPointConfig, calibrate_known_point, extract_corner
from .pairing import NS_PER_S, PairingConfig, PoseBuffer, pair_profiles
from .profile import CleaningConfig, clean_profile
from .pso_alm import HybridConfig, PaperSolution, solve_pso_galm
from .refine import RefineConfig, refine, refine_with_outlier_rejection
from .types import (
    CalibrationResult,
    EllipseFit,
    FlangePose,
    KnownPoint,
    Profile,
    Rejection,
    Sample,
    SampleFit,
)

#: Progress callback: (stage name, done, total).
Progress = Callable[[str, int, int], None]

#: Fewest fitted samples the hand-eye plus axis can be solved from with any margin.
MIN_SAMPLES = 8
#: A profiler's depth is below this, m; larger values mean the data is in millimetres.
MAX_PLAUSIBLE_DEPTH_M = 5.0
#: Points per profile in the refinements of the clock-offset search.
OFFSET_SEARCH_POINTS = 50
#: A robot's flange is within this distance of its base, m.
MAX_PLAUSIBLE_REACH_M = 20.0


class Method(str, Enum):
    """Calibration methods (the ``--method`` choices)."""

    DEFAULT = "default"
    PAPER = "paper"


class Target(str, Enum):
    """What the sensor scans (the ``--target`` choices)."""

    CYLINDER = "cylinder"
    KNOWN_POINT = "known_point"


@dataclass(frozen=True)
class PipelineConfig:
    """Every parameter of the pipeline; each stage's defaults are documented in its module.

    Attributes
    ----------
    method : Method
    target : Target
        ``cylinder`` (the cylinder paper, and our refinement) or ``known_point`` (one fixed
        point such as a weld-seam corner, the weld-seam paper).
    known_point : ndarray, shape (3,), or None
        The taught point in the base frame, m (known-point target); None estimates it.
    radius_m : float or None
        Cylinder radius, m; None estimates it.
    seed : int
        Seed of every random stage (RANSAC, PSO); runs are deterministic given it.
    min_samples : int
        Fewest fitted samples accepted.
    initial_T_flange_sensor : ndarray, shape (4, 4), or None
        Optional initial hand-eye (e.g. from CAD). When given, the default method starts its
        refinement from it and the global solve only supplies the axis.
    hybrid : HybridConfig
        The global solve of the ``paper`` method.
    seed_hybrid : HybridConfig
        The global solve that seeds the ``default`` method's refinement. It only has to
        reach the refinement's basin, so by default it stops as soon as a polished solution
        is accepted (``accept_early``): ~10-100 ms instead of 0.3-0.7 s, same result after
        refinement (bench/accuracy.py).
    """

    method: Method = Method.DEFAULT
    target: Target = Target.CYLINDER
    known_point: FloatArray | None = None
    radius_m: float | None = None
    seed: int = 0
    min_samples: int = MIN_SAMPLES
    pairing: PairingConfig = field(default_factory=PairingConfig)
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    ellipse: EllipseConfig = field(default_factory=EllipseConfig)
    arc: ArcConfig = field(default_factory=ArcConfig)
    hybrid: HybridConfig = field(default_factory=HybridConfig)
    seed_hybrid: HybridConfig = field(default_factory=lambda: HybridConfig(accept_early=True))
    refine: RefineConfig = field(default_factory=RefineConfig)
    known_point_config: KnownPointConfig = field(default_factory=KnownPointConfig)
    initial_T_flange_sensor: FloatArray | None = None

    def __post_init__(self) -> None:
        if self.radius_m is not None and not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise InputError(
                f"the cylinder radius must be a positive length in m, got {self.radius_m}"
            )
        if self.initial_T_flange_sensor is not None:
            try:
                check_transform(self.initial_T_flange_sensor, 1e-4)
            except ValueError as exc:
                raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc


@dataclass
class FittedSample:
    """A sample with the points of its arc, its fitted ellipse (``arc``: how it was found)
    and the number of grazing-angle points trimmed from it."""

    sample: Sample
    points: FloatArray
    ellipse: EllipseFit
    arc: ArcFit | None = None
    trimmed: int = 0

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


def _no_progress(stage: str, done: int, total: int) -> None:
    """Default progress callback: silent."""


def fit_sample(
    sample: Sample,
    config: PipelineConfig,
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
        arc = fit_arc_in_scene(cleaned.points_xz, config.ellipse, rng, radius_m, config.arc)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "ellipse", str(exc))
    return FittedSample(sample, cleaned.points[arc.rows], arc.ellipse, arc)


def validate_sample(
    sample: Sample, config: PipelineConfig, rng: np.random.Generator
) -> Rejection | None:
    """Whether one sample is usable for ``config.target``; a rejection says why it is not.

    The same checks the calibration applies to each sample (the collector validates live
    profiles with it): ``cylinder``, the cleaning and ellipse fit of :func:`fit_sample`,
    the semi-axes bounded by ``config.radius_m`` when given; ``known_point``, the cleaning
    and V-corner fit of :func:`~linelaser_calib.core.known_point.extract_corner`.

    Returns
    -------
    Rejection or None
        None when the sample is usable.
    """
    if config.target is Target.KNOWN_POINT:
        outcome: CornerSample | FittedSample | Rejection = extract_corner(
            sample, config.known_point_config, rng
        )
    else:
        outcome = fit_sample(sample, config, rng, config.radius_m)
    return outcome if isinstance(outcome, Rejection) else None


def fit_samples(
    samples: list[Sample], config: PipelineConfig, progress: Progress = _no_progress
) -> tuple[list[FittedSample], list[Rejection], float]:
    """Fit every sample's ellipse and settle the radius.

    Returns the fitted samples, the rejections and the radius (m): the configured one, or the
    median semi-minor axis of the ellipses (a cylinder cut's semi-minor axis is its radius).

    Raises
    ------
    InputError
        When a configured radius disagrees with the profiles.
    """
    rng = np.random.default_rng(config.seed)
    fitted: list[FittedSample] = []
    rejections: list[Rejection] = []
    for k, sample in enumerate(samples):
        outcome = fit_sample(sample, config, rng, config.radius_m)
        if isinstance(outcome, Rejection):
            rejections.append(outcome)
        else:
            fitted.append(outcome)
        progress("ellipse", k + 1, len(samples))
    if config.radius_m is not None and len(fitted) < max(config.min_samples, len(samples) // 2):
        # Most profiles failed with the given radius: fit freely to tell the user why.
        free = [fit_sample(s, config, np.random.default_rng(config.seed)) for s in samples]
        free_fitted = [f for f in free if isinstance(f, FittedSample)]
        if len(free_fitted) > len(fitted):
            _check_radius(free_fitted, config.radius_m)
    if not fitted:
        return fitted, rejections, config.radius_m or 0.0
    _trim_biased_grazing_ends(fitted, config.radius_m)
    return fitted, rejections, _check_radius(fitted, config.radius_m)


def _trim_biased_grazing_ends(fitted: list[FittedSample], radius_m: float | None) -> None:
    """Fit the arcs again without their grazing ends when those ends are biased."""
    arcs = [f.arc for f in fitted if f.arc is not None]
    if grazing_ends_biased([a.grazing_shift_sigmas for a in arcs]) is None:
        return
    for f in fitted:
        trimmed = None if f.arc is None else without_grazing_ends(f.arc, radius_m)
        if trimmed is not None:
            f.trimmed = int(f.ellipse.inliers.sum() - trimmed.inliers.sum())
            f.ellipse = trimmed


def check_units(samples: list[Sample]) -> None:
    """Raise InputError when the data is evidently in millimetres rather than metres."""
    depths = [float(np.nanmedian(np.abs(s.points[:, 2]))) for s in samples if s.points.size]
    reach = [float(np.linalg.norm(s.T_base_flange[:3, 3])) for s in samples]
    if depths and float(np.median(depths)) > MAX_PLAUSIBLE_DEPTH_M:
        raise InputError(
            f"the profile points have a median depth of {np.median(depths):.1f} m, which no "
            "profiler measures: the profiles look recorded in millimetres. ROS (REP 103) uses "
            "metres; rescale the points by 0.001 in the driver or when recording."
        )
    if reach and float(np.median(reach)) > MAX_PLAUSIBLE_REACH_M:
        raise InputError(
            f"the flange poses are a median {np.median(reach):.1f} m from the robot base: the "
            "poses look recorded in millimetres. ROS (REP 103) uses metres; rescale the "
            "positions by 0.001."
        )


def _check_radius(fitted: list[FittedSample], radius_m: float | None) -> float:
    """Radius from the ellipses' semi-minor axes, checked against a given radius, m."""
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


def _arc_notes(fitted: list[FittedSample], config: PipelineConfig) -> list[str]:
    """Warnings on the arcs: a given radius the profiles contradict, trimmed grazing ends."""
    notes = [radius_mismatch([f.ellipse.semi_axes[1] for f in fitted], config.radius_m)]
    shift = grazing_ends_biased([f.arc.grazing_shift_sigmas for f in fitted if f.arc is not None])
    if shift is not None:
        notes.append(trimming_note([f.trimmed for f in fitted], shift, config.arc))
    return [note for note in notes if note is not None]


def calibrate_samples(
    samples: list[Sample],
    config: PipelineConfig,
    rejected: list[Rejection] | None = None,
    progress: Progress = _no_progress,
) -> CalibrationResult:
    """Calibrate from paired samples (the online path enters here).

    Parameters
    ----------
    samples : list of Sample
    config : PipelineConfig
    rejected : list of Rejection, optional
        Rejections from earlier stages (pairing), carried into the result.
    progress : callable, optional

    Raises
    ------
    InputError, DegenerateError, SolverError
        With a message saying what to do.
    """
    rejections = list(rejected or [])
    if not samples:
        raise DegenerateError("no samples to calibrate from: collect profiles of the target first")
    check_units(samples)
    if config.target is Target.KNOWN_POINT:
        return _known_point_result(samples, config, rejections)
    fitted, fit_rejections, radius = fit_samples(samples, config, progress)
    rejections += fit_rejections
    if len(fitted) < config.min_samples:
        raise DegenerateError(
            f"only {len(fitted)} of {len(samples)} profiles gave a usable ellipse, and at least "
            f"{config.min_samples} are needed. "
            + _rejection_digest(rejections)
            + (
                "Scan the cylinder from more poses, with the laser line across the cylinder."
                if fitted
                else "None of the profiles shows the cylinder's arc: check that the laser line "
                "falls across the cylinder within the measuring range."
            )
        )
    rng = np.random.default_rng(config.seed + 1)
    centres = np.array([f.ellipse.centre_xz for f in fitted])
    T_base_flange = np.stack([f.sample.T_base_flange for f in fitted])
    progress("global solve", 0, 1)
    hybrid = config.hybrid if config.method is Method.PAPER else config.seed_hybrid
    seed_solution = solve_pso_galm(centres, T_base_flange, hybrid, rng)
    progress("global solve", 1, 1)
    notes = _arc_notes(fitted, config)
    if config.method is Method.PAPER:
        result = _paper_result(seed_solution, fitted, rejections, radius, config)
        result.warnings.extend(notes)
        return result
    T_init = (
        seed_solution.T_flange_sensor
        if config.initial_T_flange_sensor is None
        else np.asarray(config.initial_T_flange_sensor, dtype=np.float64)
    )
    cylinder0 = replace(seed_solution.cylinder, radius=radius)
    progress("refine", 0, 1)
    refined = refine_with_outlier_rejection(
        [f.inlier_points for f in fitted],
        T_base_flange,
        T_init,
        cylinder0,
        config.refine,
        radius_m=config.radius_m,
    )
    progress("refine", 1, 1)
    indices = [f.sample.index for f in fitted]
    for j, reason in refined.dropped:
        f = fitted[j]
        rejections.append(Rejection(f.sample.index, f.sample.stamp_ns, "outlier", reason))
    used = [indices[j] for j in refined.used]
    return CalibrationResult(
        T_flange_sensor=refined.T_flange_sensor,
        cylinder=refined.cylinder,
        method=Method.DEFAULT.value,
        samples_used=used,
        samples_rejected=sorted(rejections, key=lambda r: r.index),
        rms_residual_m=refined.rms_residual_m,
        sample_residuals_m={indices[j]: r for j, r in refined.sample_residuals_m.items()},
        uncertainty_translation_m=refined.sigma_translation_m,
        uncertainty_rotation_rad=refined.sigma_rotation_rad,
        radius_estimated=refined.radius_estimated,
        warnings=[*refined.warnings, *notes],
        history={**seed_solution.history, "refine_cost": list(refined.cost_history)},
        sample_fits=[fitted[j].record() for j in refined.used],
    )


def _paper_result(
    solution: PaperSolution,
    fitted: list[FittedSample],
    rejections: list[Rejection],
    radius: float,
    config: PipelineConfig,
) -> CalibrationResult:
    """CalibrationResult of the paper's method."""
    T = solution.T_flange_sensor
    cylinder = replace(solution.cylinder, radius=radius)
    centres = np.array([f.ellipse.centre_xz for f in fitted])
    T_base_flange = np.stack([f.sample.T_base_flange for f in fitted])
    distances = centre_distances(centres, T_base_flange, T, cylinder)
    return CalibrationResult(
        T_flange_sensor=T,
        cylinder=cylinder,
        method=Method.PAPER.value,
        samples_used=[f.sample.index for f in fitted],
        samples_rejected=sorted(rejections, key=lambda r: r.index),
        rms_residual_m=float(np.sqrt(np.mean(distances**2))),
        sample_residuals_m={
            f.sample.index: float(d) for f, d in zip(fitted, distances, strict=True)
        },
        radius_estimated=config.radius_m is None,
        warnings=_seed_warnings(solution),
        history=dict(solution.history),
        sample_fits=[f.record() for f in fitted],
    )


def _seed_warnings(solution: PaperSolution) -> list[str]:
    """Warnings about the global solve."""
    if solution.accepted:
        return []
    return [
        f"the global solve did not reach its acceptance level: the RMS centre-to-axis "
        f"distance is {solution.rms_m * 1e3:.3f} mm; check the rejected samples and the poses"
    ]


def _rejection_digest(rejections: list[Rejection]) -> str:
    """'Rejected: 3 x reason; ...' for error messages."""
    if not rejections:
        return ""
    counts: dict[str, int] = {}
    for r in rejections:
        key = f"{r.stage}: {r.reason.split(' (')[0]}"
        counts[key] = counts.get(key, 0) + 1
    top = sorted(counts.items(), key=lambda kv: -kv[1])[:4]
    return "Rejected: " + "; ".join(f"{n} x {k}" for k, n in top) + ". "


def run_pipeline(
    profiles: list[Profile],
    poses: list[FlangePose],
    config: PipelineConfig,
    progress: Progress = _no_progress,
) -> CalibrationResult:
    """Pair profiles with flange poses, then :func:`calibrate_samples` (the offline path).

    Raises
    ------
    PairingError
        When no profile pairs with a pose; the message gives the median stamp offset.
    """
    if not profiles:
        raise InputError("there are no profiles to calibrate from")
    if not poses:
        raise InputError("there are no flange poses to pair the profiles with")
    paired = pair_profiles(profiles, poses, config.pairing)
    progress("pairing", len(profiles), len(profiles))
    if not paired.samples:
        raise PairingError(paired.explain_nothing_paired(config.pairing))
    result = calibrate_samples(paired.samples, config, paired.rejected, progress)
    result.warnings[:0] = paired.notes
    result.clock_offset_s = config.pairing.clock_offset_s
    return result


def _known_point_result(
    samples: list[Sample], config: PipelineConfig, rejections: list[Rejection]
) -> CalibrationResult:
    """Calibrate against one fixed point (:mod:`linelaser_calib.core.known_point`)."""
    outcome = calibrate_known_point(
        samples,
        config.initial_T_flange_sensor,
        config.known_point,
        config.known_point_config,
        config.method.value,
        np.random.default_rng(config.seed),
    )
    used = set(outcome.samples_used)
    return CalibrationResult(
        T_flange_sensor=outcome.T_flange_sensor,
        cylinder=None,
        method=config.method.value,
        samples_used=list(outcome.samples_used),
        samples_rejected=sorted(rejections + outcome.samples_rejected, key=lambda r: r.index),
        rms_residual_m=outcome.rms_residual_m,
        sample_residuals_m=dict(outcome.sample_residuals_m),
        uncertainty_translation_m=outcome.uncertainty_translation_m,
        uncertainty_rotation_rad=outcome.uncertainty_rotation_rad,
        warnings=list(outcome.warnings),
        history=dict(outcome.history),
        known_point=KnownPoint(
            outcome.point_base, outcome.point_estimated, outcome.uncertainty_point_m
        ),
        sample_fits=[
            SampleFit(c.index, c.stamp_ns, c.T_base_flange, c.points, c.corner_xz)
            for c in outcome.corners
            if c.index in used
        ],
    )


def estimate_clock_offset(
    profiles: list[Profile],
    poses: list[FlangePose],
    config: PipelineConfig,
    half_range_s: float = 0.05,
    tolerance_s: float = 1e-4,
) -> float:
    """The clock offset (s) between profile and pose stamps that fits the cylinder best.

    In continuous scanning a profile stamped with latency τ is paired with the pose the
    flange had τ earlier or later, and every profile lands slightly off the cylinder. The
    refinement's cost (maximum likelihood over every point, robot pose error modelled) is
    evaluated at offsets within ``half_range_s`` of ``config.pairing.clock_offset_s``: a grid
    of 11, then a golden-section search to ``tolerance_s``. The ellipses and the seed solve do
    not depend on the offset and are computed once. Where the cost is flat (step-and-shoot:
    the flange stands still at every profile) the configured offset is returned.

    Raises
    ------
    PairingError, DegenerateError
        As :func:`run_pipeline` would for the same data.
    """
    if config.target is not Target.CYLINDER:
        raise InputError("the clock offset is estimated from cylinder scans only")
    start = config.pairing.clock_offset_s
    moving = replace(config.pairing, max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
    paired = pair_profiles(profiles, poses, moving)
    if not paired.samples:
        raise PairingError(paired.explain_nothing_paired(config.pairing))
    fitted, rejections, radius = fit_samples(paired.samples, config)
    if len(fitted) < config.min_samples:
        raise DegenerateError(
            f"only {len(fitted)} profiles gave a usable ellipse; at least {config.min_samples} "
            "are needed to estimate the clock offset. " + _rejection_digest(rejections)
        )
    T_paired = np.stack([f.sample.T_base_flange for f in fitted])
    centres = np.array([f.ellipse.centre_xz for f in fitted])
    seed = solve_pso_galm(
        centres, T_paired, config.seed_hybrid, np.random.default_rng(config.seed + 1)
    )
    cylinder0 = replace(seed.cylinder, radius=radius)
    points = [f.inlier_points for f in fitted]
    buffer = PoseBuffer()
    buffer.extend(poses)
    tolerance_ns = round(config.pairing.sync_tolerance_s * NS_PER_S)
    # A few dozen points per profile pin the offset as well as all of them (faster search).
    light = replace(config.refine, max_points_per_profile=OFFSET_SEARCH_POINTS)

    def cost(offset_s: float) -> float:
        shift = round(offset_s * NS_PER_S)
        found = [buffer.pose_at(f.sample.stamp_ns + shift, tolerance_ns) for f in fitted]
        if any(isinstance(T, str) for T in found):
            return float("inf")
        try:
            refined = refine(
                points,
                np.stack(found),
                seed.T_flange_sensor,
                cylinder0,
                light,
                config.radius_m,
            )
        except CalibrationError:
            return float("inf")
        return refined.cost_history[-1]

    grid = np.linspace(start - half_range_s, start + half_range_s, 11)
    costs = np.array([cost(float(t)) for t in grid])
    finite = costs[np.isfinite(costs)]
    if finite.size == 0 or float(np.max(finite) - np.min(finite)) < 1.0:
        return start
    best = int(np.argmin(costs))
    step = float(grid[1] - grid[0])
    lo, hi = float(grid[best]) - step, float(grid[best]) + step
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    cost_a, cost_b = cost(a), cost(b)
    while hi - lo > tolerance_s:
        if cost_a < cost_b:
            hi, b, cost_b = b, a, cost_a
            a = hi - ratio * (hi - lo)
            cost_a = cost(a)
        else:
            lo, a, cost_a = a, b, cost_b
            b = lo + ratio * (hi - lo)
            cost_b = cost(b)
    return 0.5 * (lo + hi)
