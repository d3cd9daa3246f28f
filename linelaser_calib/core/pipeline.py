"""The calibration pipeline: pair, extract features, solve, check the model, diagnose.

This is the one pipeline. The CLI (offline, from a bag: :func:`run_pipeline`) and the
calibration_service node (online, from collected samples) both enter it through
:func:`calibrate_paired`; where a recording holds many profiles from nearly the same flange
pose, a representative subset is kept (:mod:`.thinning`); where the clock offset is
estimated, :mod:`.offset_search` searches it first and hands on what it extracted.
What is scanned is a target (:mod:`linelaser_calib.core.targets`): the pipeline hands the
samples to the chosen target's feature extraction, its ``paper`` or ``default`` solve and its
model-fit checks, and never asks which target it is.

Methods
-------
``paper``
    The target's paper as published (e.g. the cylinder paper's PSO + generalized Lagrange
    multiplier solve on the ellipse centres).
``default``
    Maximum likelihood on the measurements with the robot's per-sample pose error as nuisance
    parameters, outlier-sample rejection, covariance and observability diagnostics, through
    the shared solver (:mod:`linelaser_calib.core.solver`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from enum import Enum
from functools import reduce
from typing import Any

import numpy as np

from .errors import CalibrationError, DegenerateError, InputError, PairingError, TooFewFeatures
from .geometry import FloatArray, check_transform
from .latency import ClockProbe, add_clock_diagnosis
from .pairing import PairingConfig, PairingResult, pair_profiles
from .pose_track import PoseTrack
from .regions import PLAIN_PRIOR_SCALE
from .result import CalibrationResult
from .robot.joint_calibration import KinematicSetup
from .robot.kinematics import forward_kinematics
from .selfcheck import DEFAULT_ARM_ACCURACY_M, DEFAULT_FOLDS, measuring_centre_depth, self_check
from .sigma_budget import solution_budget
from .targets import DEFAULT_TARGET, get_target
from .targets.base import (
    Placement,
    Progress,
    SolveContext,
    Target,
    TargetSolution,
    configure,
    rejection_digest,
)
from .targets.extraction import Extractions
from .targets.rivals import RivalSamples, check_model, refuse_without_fit
from .targets.runs import sample_rng
from .thinning import DEFAULT_PER_NEIGHBOURHOOD, thin_samples
from .types import FlangePose, Profile, Rejection, Sample
from .verdict import no_self_check_reason, warning_kind

#: A profiler's depth is below this, m; larger values mean the data is in millimetres.
MAX_PLAUSIBLE_DEPTH_M = 5.0
#: A robot's flange is within this distance of its base, m.
MAX_PLAUSIBLE_REACH_M = 20.0


class Method(str, Enum):
    """Calibration methods (the ``--method`` choices)."""

    DEFAULT = "default"
    PAPER = "paper"


@dataclass(frozen=True)
class PipelineConfig:
    """Every parameter of the pipeline: the shared ones, and the chosen target's own config.

    Attributes
    ----------
    method : Method
    target : str
        Name of a registered target (:func:`linelaser_calib.core.targets.target_names`).
    target_config : object, optional
        The target's config (its ``config_type``); None takes the target's defaults. Build it
        from user settings with :func:`linelaser_calib.core.targets.base.configure`, which
        refuses settings that do not act on the target.
    seed : int
        Seed of every random stage (RANSAC, PSO); runs are deterministic given it.
    pairing : PairingConfig
    initial_T_flange_sensor : ndarray, shape (4, 4), or None
        Optional initial hand-eye (e.g. from CAD or an earlier result): the start of the
        solve where the target's method uses one.
    kinematics : KinematicSetup or None
        The robot model and the joint states of the recording: the default method then
        estimates the identifiable kinematic corrections with the hand-eye.
    self_check_folds : int
        Folds of the default method's self-check (:mod:`.selfcheck`: cross-validated
        accuracy in use, halves, a 1σ widened for systematic robot error); 0 skips it.
    arm_accuracy_m : float
        Prior 1σ per axis of the robot's error common to the whole scanned workspace, m
        (:mod:`.selfcheck`): part of the 1σ when the robot's error looks systematic and no
        kinematic model corrects the poses. Default 0.1 mm.
    workers : int
        Processes for the self-check's solves: 1, or 2 to share them with a forked child
        (:mod:`.forked`: same result, less wall time on a second core). Not for a process
        with threads that hold locks (a ROS node).
    per_neighbourhood : int
        Most samples kept from one neighbourhood of flange poses, evenly spaced in time
        (:mod:`.thinning`: where thousands of profiles come from nearly the same pose); 0
        keeps every sample.
    """

    method: Method = Method.DEFAULT
    target: str = DEFAULT_TARGET
    target_config: Any = None
    seed: int = 0
    pairing: PairingConfig = field(default_factory=PairingConfig)
    initial_T_flange_sensor: FloatArray | None = None
    kinematics: KinematicSetup | None = None
    self_check_folds: int = DEFAULT_FOLDS
    arm_accuracy_m: float = DEFAULT_ARM_ACCURACY_M
    workers: int = 1
    per_neighbourhood: int = DEFAULT_PER_NEIGHBOURHOOD

    def __post_init__(self) -> None:
        if not (isinstance(self.seed, (int, np.integer)) and 0 <= self.seed < 2**32):
            raise InputError(
                f"the seed must be a whole number from 0 to 2**32 - 1, got {self.seed!r}"
            )
        if self.self_check_folds < 0 or self.self_check_folds == 1:
            raise InputError(f"self_check_folds must be 0 or >= 2, got {self.self_check_folds}")
        kept = self.per_neighbourhood
        if not (isinstance(kept, (int, np.integer)) and kept >= 0):
            raise InputError(
                "the samples kept per neighbourhood of flange poses must be a whole number, 0 "
                f"(keep all) or more, got {kept!r}"
            )
        if not (np.isfinite(self.arm_accuracy_m) and self.arm_accuracy_m >= 0.0):
            raise InputError(
                f"the arm accuracy must be a length of 0 m or more, got {self.arm_accuracy_m}"
            )
        target = get_target(self.target)
        if self.target_config is None:
            object.__setattr__(self, "target_config", target.config_type())
        elif not isinstance(self.target_config, target.config_type):
            raise InputError(
                f"the {target.title} target takes a {target.config_type.__name__}, got a "
                f"{type(self.target_config).__name__}"
            )
        if self.initial_T_flange_sensor is not None:
            try:
                check_transform(self.initial_T_flange_sensor, 1e-4)
            except ValueError as exc:
                raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc

    @property
    def target_impl(self) -> Target[Any]:
        """The target object (from the registry)."""
        return get_target(self.target)


@dataclass(frozen=True)
class Extracted:
    """What a clock-offset search (:func:`~.offset_search.search_clock_offset`) hands
    :func:`calibrate_samples` at the offset it found: the run's features, for each profile's
    to be extracted once per run.

    Attributes
    ----------
    indices : tuple of int
        Profile indices of the samples the search extracted the target's features from, in
        order (the thinning keeps the same: :func:`~.thinning.thin_samples`).
    extractions : Extractions
        The run's features: the target's used again where its features do not depend on
        the flange poses and the samples are of profiles among them (a few at the ends of
        the recording may pair at the search's offset only), each rival's extracted once.
    rival_samples : RivalSamples or None
        Each rival target's samples at its own best offset, for the rival checks
        (:meth:`~.offset_search.OffsetSearch.rival`).
    """

    indices: tuple[int, ...]
    extractions: Extractions
    rival_samples: RivalSamples | None = None


def _no_progress(stage: str, done: int, total: int) -> None:
    """Default progress callback: silent."""


def validate_sample(sample: Sample, config: PipelineConfig) -> Rejection | None:
    """Whether one sample is usable for ``config.target``; a rejection says why it is not.

    The same checks the calibration applies to each sample (the collector validates live
    profiles with it): the target's cleaning and feature fit, with the sample's own random
    draws (:func:`~linelaser_calib.core.targets.runs.sample_rng` of ``config.seed`` and its
    index), as in the calibration.

    Returns
    -------
    Rejection or None
        None when the sample is usable.
    """
    return config.target_impl.validate(
        sample, config.target_config, sample_rng(config.seed, sample.index)
    )


#: Samples whose depths :func:`_median_depths` sorts at once (a block of a long recording's
#: profiles padded to the longest: a few MB).
DEPTH_BLOCK = 256


def _median_depths(samples: Sequence[Sample]) -> FloatArray:
    """The median |z| (m) of each sample's finite points, samples without one left out: the
    rows of a block of samples sorted at once, padded with NaN (sorted last), instead of a
    median per sample (~40 µs each, 1,600 of them on the critical path)."""
    found = []
    for first in range(0, len(samples), DEPTH_BLOCK):
        block = samples[first : first + DEPTH_BLOCK]
        lengths = np.array([len(s.points) for s in block])
        width = int(lengths.max(initial=0))
        depths = np.full((len(block), width), np.nan)
        depths[np.arange(width) < lengths[:, None]] = np.abs(
            np.concatenate([s.points[:, 2] for s in block]) if width else []
        )
        depths.sort(axis=1)
        counts = np.count_nonzero(np.isfinite(depths), axis=1)
        rows, n = np.flatnonzero(counts), counts[counts > 0]
        found.append((depths[rows, (n - 1) // 2] + depths[rows, n // 2]) / 2.0)
    return np.concatenate(found) if found else np.zeros(0)


def check_units(samples: list[Sample]) -> None:
    """Raise InputError when the data is evidently in millimetres rather than metres."""
    depths = _median_depths(samples)
    reach = np.linalg.norm(np.reshape([s.T_base_flange[:3, 3] for s in samples], (-1, 3)), axis=1)
    if len(depths) and float(np.median(depths)) > MAX_PLAUSIBLE_DEPTH_M:
        raise InputError(
            f"the profile points have a median depth of {np.median(depths):.1f} m, which no "
            "profiler measures: the profiles look recorded in millimetres. ROS (REP 103) uses "
            "metres; rescale the points by 0.001 in the driver or when recording."
        )
    if len(reach) and float(np.median(reach)) > MAX_PLAUSIBLE_REACH_M:
        raise InputError(
            f"the flange poses are a median {np.median(reach):.1f} m from the robot base: the "
            "poses look recorded in millimetres. ROS (REP 103) uses metres; rescale the "
            "positions by 0.001."
        )


def _within_joint_states(
    samples: list[Sample], setup: KinematicSetup
) -> tuple[list[Sample], list[Rejection]]:
    """The samples whose stamps the joint-state stream covers, and a rejection for each
    other (a recording started or stopped by hand: joint states a few ms short).

    Raises
    ------
    DegenerateError
        When the stream covers none of them.
    """
    outside = setup.outside([s.stamp_ns for s in samples])
    if outside.all():
        raise DegenerateError(
            f"none of the {len(samples)} profiles lies within the joint-state stream: "
            f"{setup.outside_reason(samples[0].stamp_ns)} for the first; record the joint "
            "states for the whole scan, or check the clock offset"
        )
    dropped = [
        Rejection(s.index, s.stamp_ns, "pairing", setup.outside_reason(s.stamp_ns))
        for s, out in zip(samples, outside, strict=True)
        if out
    ]
    return [s for s, out in zip(samples, outside, strict=True) if not out], dropped


def _outside_note(dropped: list[Rejection], where: str) -> str:
    """A warning naming the profiles left out because the joint states do not cover them."""
    indices = ", ".join(f"#{r.index}" for r in dropped)
    return (
        f"{len(dropped)} profile(s) of {where} lie outside the joint-state stream and were "
        f"left out ({indices}): the joint states start after or stop before them; record "
        "the joint states for the whole scan to use them"
    )


def calibrate_samples(
    samples: list[Sample],
    config: PipelineConfig,
    rejected: list[Rejection] | None = None,
    progress: Progress = _no_progress,
    placements: Sequence[tuple[list[Sample], KinematicSetup]] = (),
    extracted: Extracted | None = None,
) -> CalibrationResult:
    """Calibrate from paired samples (the online path enters here).

    Parameters
    ----------
    samples : list of Sample
    config : PipelineConfig
    rejected : list of Rejection, optional
        Rejections from earlier stages (pairing), carried into the result.
    progress : callable, optional
    placements : sequence of (list of Sample, KinematicSetup), optional
        Other placements of the target scanned by the same arm, each with its recording's
        joint states, for a joint kinematic calibration (``config.kinematics`` set, the
        default method): one hand-eye and one set of kinematic corrections from all of them.
        The result's target section, samples and residuals are those of ``samples``.
    extracted : Extracted, optional
        What a clock-offset search extracted from these samples' profiles (at other flange
        poses): used again, re-paired, where the target allows it, instead of extracting
        them twice.

    Raises
    ------
    InputError, DegenerateError, SolverError
        With a message saying what to do; InputError also for ``placements`` where no
        joint kinematic calibration runs.
    ModelMismatch
        The target's model does not fit the data; nothing is to be written then.
    """
    rejections = list(rejected or [])
    recorded = len(samples) + len(rejections)
    if not samples:
        raise DegenerateError("no samples to calibrate from: collect profiles of the target first")
    target, target_config = config.target_impl, config.target_config
    if placements and (config.kinematics is None or config.method is not Method.DEFAULT):
        raise InputError(
            f"{len(placements) + 1} recordings are calibrated together only by the joint "
            "kinematic calibration (the default method with the robot's kinematic model and "
            "joint states, {setting:kinematics}): calibrate one recording at a time otherwise"
        )
    check_units(samples)
    joint_notes = []
    if config.kinematics is not None:
        samples, outside = _within_joint_states(samples, config.kinematics)
        rejections += outside
        if outside:
            joint_notes.append(_outside_note(outside, "the recording"))
    chosen = None if extracted is None else extracted.indices
    samples, thinning = thin_samples(samples, config.per_neighbourhood, chosen)
    extractions = (
        Extractions(config.seed, config.workers) if extracted is None else extracted.extractions
    )
    features, feature_rejections = extractions.of(target, target_config, samples, progress)
    rejections += feature_rejections
    target.check_features(features, target_config)
    others = []
    placement_notes = []
    for k, (more, setup) in enumerate(placements, start=2):
        check_units(more)
        more, outside = _within_joint_states(more, setup)
        if outside:
            placement_notes.append(_outside_note(outside, f"recording {k}"))
        found, lost = target.extract(more, target_config, config.seed, progress, config.workers)
        target.check_features(found, target_config)
        others.append(Placement(found, setup))
        if lost:
            placement_notes.append(
                f"recording {k}: {len(lost)} of its {len(more)} paired profiles gave no "
                f"feature and were left out. {rejection_digest(lost)}".rstrip()
            )
    context = SolveContext(
        initial_T_flange_sensor=config.initial_T_flange_sensor,
        seed=config.seed,
        rejections=rejections,
        n_samples=recorded,
        progress=progress,
        kinematics=config.kinematics,
        placements=others,
        workers=config.workers,
    )
    solve = {Method.PAPER: target.solve_paper, Method.DEFAULT: target.solve_default}
    rival_samples = None if extracted is None else extracted.rival_samples
    try:
        solution = solve[config.method](features, target_config, context)
    except TooFewFeatures as refusal:
        refuse_without_fit(target, samples, refusal, context, rival_samples, extractions)
        raise
    check_model(
        target, target_config, samples, features, solution, context, rival_samples, extractions
    )
    if placements and solution.kinematics is None:
        raise InputError(
            f"the {target.title} target does not estimate kinematic corrections, so its "
            f"{len(placements) + 1} recordings cannot be calibrated together; calibrate one "
            "recording at a time (the cylinder target's default method does the joint "
            "calibration)"
        )
    if config.kinematics is not None and solution.kinematics is None:
        solution.warnings.append(
            f"the {solution.method} method of the {target.title} target does not estimate "
            "kinematic corrections: the flange poses are the nominal model's forward "
            "kinematics of the joint states (the cylinder target's default method estimates "
            "them)"
        )
    check = None
    if config.method is Method.DEFAULT and config.self_check_folds:
        quiet = _subset_context(context, solution)
        check = self_check(
            features,
            solution,
            lambda subset: target.solve_default(subset, target_config, quiet),
            config.self_check_folds,
            None if config.kinematics is None else _corrected_poses(config.kinematics),
            config.workers,
            None
            if config.kinematics is not None
            else lambda: _plain(target, target_config, solution, features, quiet),
            config.arm_accuracy_m,
            progress,
        )
    sigma_t, sigma_r = solution.sigma_translation_m, solution.sigma_rotation_rad
    carried: list[str] = []
    if check is not None:
        if check.solution is not solution:
            # The plain model chosen: its 1σ keeps the default solve's model spread; say so.
            carried = [w for w in solution.warnings if warning_kind(w).id == "scale-model-spread"]
        solution = check.solution
        sigma_r, sigma_t = check.sigma_honest[:3], check.sigma_honest[3:]
    return CalibrationResult(
        T_flange_sensor=solution.T_flange_sensor,
        target=solution.section,
        method=solution.method,
        samples_used=list(solution.samples_used),
        samples_rejected=sorted(rejections + solution.rejections, key=lambda r: r.index),
        rms_residual_m=solution.rms_residual_m,
        sample_residuals_m=dict(solution.sample_residuals_m),
        uncertainty_translation_m=sigma_t,
        uncertainty_rotation_rad=sigma_r,
        warnings=list(solution.warnings)
        + carried
        + joint_notes
        + placement_notes
        + ([] if check is None else check.warnings),
        self_check=check,
        history=dict(solution.history),
        sample_fits=list(solution.sample_fits),
        kinematics=solution.kinematics,
        identifiability=solution.identifiability,
        placement_sections=list(solution.placement_sections),
        measuring_centre_depth_m=measuring_centre_depth(solution.sample_fits),
        initial_T_flange_sensor=config.initial_T_flange_sensor,
        self_check_skipped_because=""
        if check is not None
        else no_self_check_reason(
            config.method is Method.DEFAULT,
            config.self_check_folds,
            len(solution.samples_used),
            solution.sigma_translation_m is not None,
        ),
        thinning=thinning,
        sigma_budget=solution_budget(solution) if check is None else check.sigma_budget,
    )


def _subset_context(context: SolveContext, solution: TargetSolution) -> SolveContext:
    """The context of the self-check's solves (the default model's subsets, the plain
    model's solve of all and of subsets): started at ``solution``, silent, and setting no
    profile aside (``screen_outliers`` False). They solve profiles the default solve kept,
    and whether a profile is an outlier is decided once, by that solve on the whole
    recording: a subset's own outlier rounds judge it against fewer profiles (a held-out
    region's neighbours missing), and a subset that drops a profile the whole solve kept
    makes the self-check judge another recording than the result's. The plain model's
    residual holds the robot's error by design, so its outlier test would judge the robot,
    not the profile (a twin of the real cylinder: two profiles whose robot error was the
    recording's smallest stood out, robust z 8 and 7). The self-check shares its subsets
    between the processes, so each solve uses one (``workers`` 1)."""
    return replace(
        context, progress=_no_progress, warm_start=solution, screen_outliers=False, workers=1
    )


def _plain_config(target: Target[Any], target_config: Any) -> Any | None:
    """The target's config for the plain model (:mod:`.regions`): its per-pose robot-error
    prior :data:`~.regions.PLAIN_PRIOR_SCALE` times tighter; None when the default method
    takes no such prior."""
    settings = {}
    for name in ("robot_sigma_t_m", "robot_sigma_r_rad"):
        option = target.options.get(name)
        if option is None or not option.field or Method.DEFAULT.value not in option.methods:
            return None
        value = reduce(getattr, option.field.split("."), target_config)
        settings[name] = float(value) * PLAIN_PRIOR_SCALE
    return configure(target, Method.DEFAULT.value, settings, {}, target_config)


def _plain(
    target: Target[Any],
    target_config: Any,
    solution: TargetSolution,
    features: list[Any],
    context: SolveContext,
) -> tuple[TargetSolution, Callable[[list[Any]], TargetSolution]] | None:
    """The plain model (:mod:`.regions`): its solve of the features the default ``solution``
    used, started there (a target with a subset start re-solves that solved problem under
    the tighter prior: no seed solve, point trimming or line-noise learning again), with the
    default solve's rejections, and its solve of a subset, started at its own; ``context``
    is the self-check's (:func:`_subset_context`: neither sets a profile aside). No
    model-fit check: the default solve passed it on the same data. None when the target's
    default method takes no robot prior or the plain solve fails."""
    plain_config = _plain_config(target, target_config)
    if plain_config is None:
        return None

    def solve_from(start: TargetSolution) -> Callable[[list[Any]], TargetSolution]:
        def solve(subset: list[Any]) -> TargetSolution:
            return target.solve_default(subset, plain_config, replace(context, warm_start=start))

        return solve

    used = set(solution.samples_used)
    try:
        full = solve_from(solution)([f for f in features if f.index in used])
    except CalibrationError:
        return None
    full.rejections = list(solution.rejections) + list(full.rejections)
    return full, solve_from(full)


def _corrected_poses(
    setup: KinematicSetup,
) -> Callable[[TargetSolution, list[Any]], FloatArray]:
    """Flange poses of held-out features through a fold's corrected kinematics (its
    ``kinematics``; nominal where it has none), for the self-check of a joint calibration."""

    def poses(fold: TargetSolution, held: list[Any]) -> FloatArray:
        model = setup.model if fold.kinematics is None else fold.kinematics.apply(setup.model)
        q = setup.joint_positions([f.stamp_ns for f in held])
        return forward_kinematics(model, q)

    return poses


def calibrate_paired(
    samples: list[Sample],
    poses: ClockProbe | PoseTrack | Sequence[FlangePose] | None,
    config: PipelineConfig,
    rejected: list[Rejection] | None = None,
    notes: Sequence[str] = (),
    progress: Progress = _no_progress,
    placements: Sequence[tuple[list[Sample], KinematicSetup]] = (),
    extracted: Extracted | None = None,
    diagnose_clock: bool = True,
) -> CalibrationResult:
    """:func:`calibrate_samples` of samples paired with ``config.pairing`` from the flange
    pose stream ``poses``, and what that pairing tells: its ``notes`` (warnings) first, the
    pairing itself (``result.pairing``, its clock offset) and, with ``diagnose_clock``, the
    test of a clock offset left out (:func:`~.latency.add_clock_diagnosis`, whose warning
    goes first; off where the offset was estimated). Both paths enter here:
    :func:`run_pipeline` with the recording's pose stream, the offline calibration
    (:func:`linelaser_calib.offline.calibrate_bag`) with its :class:`~.latency.ClockProbe`
    at the samples' stamps (the stream released before the solve), the calibration service
    with the poses of its samples. ``poses`` None: the pairing is not known (samples paired
    elsewhere), and neither is recorded or tested."""
    result = calibrate_samples(samples, config, rejected, progress, placements, extracted)
    result.warnings[:0] = notes
    if poses is None:
        return result
    result.clock_offset_s = config.pairing.clock_offset_s
    result.pairing = config.pairing
    if diagnose_clock:
        add_clock_diagnosis(result, poses, config.pairing)
    return result


def pair_recording(
    profiles: list[Profile],
    poses: PoseTrack | Sequence[FlangePose],
    config: PipelineConfig,
    progress: Progress = _no_progress,
) -> PairingResult:
    """The profiles paired with the flange poses (``config.pairing``): the first half of
    :func:`run_pipeline`.

    Raises
    ------
    PairingError
        When no profile pairs with a pose; the message gives the median stamp offset.
    """
    if not profiles:
        raise InputError("there are no profiles to calibrate from")
    if not len(poses):
        raise InputError("there are no flange poses to pair the profiles with")
    paired = pair_profiles(profiles, poses, config.pairing)
    progress("pairing", len(profiles), len(profiles))
    if not paired.samples:
        raise PairingError(paired.explain_nothing_paired(config.pairing))
    return paired


def run_pipeline(
    profiles: list[Profile],
    poses: PoseTrack | Sequence[FlangePose],
    config: PipelineConfig,
    progress: Progress = _no_progress,
    placements: Sequence[tuple[list[Sample], KinematicSetup]] = (),
    extracted: Extracted | None = None,
    diagnose_clock: bool = True,
) -> CalibrationResult:
    """Pair profiles with flange poses (:func:`pair_recording`), then
    :func:`calibrate_paired`.

    ``placements`` are other recordings' samples for a joint calibration, ``extracted`` the
    features of a clock-offset search (:func:`calibrate_samples`); ``diagnose_clock`` False
    where the clock offset was estimated.

    Raises
    ------
    PairingError
        When no profile pairs with a pose; the message gives the median stamp offset.
    """
    paired = pair_recording(profiles, poses, config, progress)
    return calibrate_paired(
        paired.samples,
        poses,
        config,
        paired.rejected,
        paired.notes,
        progress,
        placements,
        extracted,
        diagnose_clock,
    )
