"""Self-check of a calibration: accuracy in use by region, the model it picks, an honest 1σ.

One machinery for every target, through the target protocol only (it never asks which target
it is): the target's own default solve is run again on subsets of the features the solution
kept, every one of them used (whether a profile is an outlier was decided once, by the
solve of the whole recording: :attr:`~linelaser_calib.core.targets.base.SolveContext.
screen_outliers`), and the held-out samples are judged by the section's
:meth:`~linelaser_calib.core.targets.base.ResultSection.surface_distances`.

What is computed
----------------
Accuracy in use, region-blocked (:mod:`.regions`):
    The used poses are split into regions of the workspace (as many as there are clusters of
    poses, at most ``folds``); each region is left out in turn, the rest solved, and the
    held-out region's points, mapped with their recorded flange poses and that solve's
    hand-eye, are measured against that solve's target. Their RMS is the **accuracy in use**:
    what a user sees scanning elsewhere in the cell. With fewer than 3 regions it is not
    claimed. The same is done for the plain model (the per-pose robot-error prior made
    :data:`~.regions.PLAIN_PRIOR_SCALE` times tighter) when the caller gives its solve, and
    the model with the better blocked accuracy is chosen (:func:`~.regions.choose_model`).
Pose-interleaved K-fold (a consistency check only):
    ``folds`` interleaved folds of the used samples, each left out in turn and judged as
    above. Every held-out pose keeps neighbours in the fit that share the arm's regional
    error, so this RMS is what the fit's own poses see, not what a user sees elsewhere.
Grouped (per-profile) jackknife covariance of the hand-eye over those folds:
    Cov = (K − 1)/K · Σ_k (θ_k − θ̄)(θ_k − θ̄)ᵀ, a cluster-robust covariance with the profile
    as the cluster (the points of one profile share one pose error).
Jackknife over the regions (:func:`region_jackknife`):
    The delete-a-group jackknife of the region solves about the full one, and what the noise
    model predicts for it (:class:`RegionJackknife`).
Disjoint halves:
    Even and odd samples solved apart; their hand-eye difference in units of the combined
    1σ, against the noise model and against the reported 1σ.

Systematic robot error
----------------------
Per-pose corrections absorb any robot error, so the fit's residual cannot tell an arm with
independent per-pose noise from one whose error is systematic (pose-dependent). Any of these
marks it as systematic, each at a false-alarm probability derived, not tuned:

- **Region offsets**: each used profile's mean signed distance from the fitted target (and
  its tilt across the profile, :func:`tilt`), mapped with the recorded poses, differ between
  regions more than within them: a one-way analysis of variance
  (:func:`scipy.stats.f_oneway`) at :data:`REGION_FALSE_ALARM` (halved for the two
  components).
- **Region dispersion** above :func:`region_limit` (χ² quantile at
  :data:`REGION_FALSE_ALARM`).
- **Neighbour correlation** of the interleaved held-out offsets above :func:`neighbour_limit`.
- Halves that still disagree beyond :data:`HALVES_LIMIT_SIGMAS`.
- **An arm less accurate than its stated repeatability**: the robot's per-pose error that the
  solve's pose corrections show (:class:`~.targets.base.RobotError`) above
  :data:`ROBOT_PRIOR_EXCESS` times the prior (``robot_sigma_t_m``, ``robot_sigma_r_rad``,
  the arm's repeatability). An arm's independent error from pose to pose is its repeatability;
  what it errs beyond that is its absolute-accuracy error, which depends on where the arm is
  and is shared by neighbouring poses, even where the regions above are too few or too alike
  to show it.

The honest 1σ (:func:`honest_sigma`)
------------------------------------
When the error is systematic the hand-eye's 1σ has two parts, added in quadrature:

- the part that varies over the workspace: the region jackknife's 1σ (each region's shared
  error moves the estimate when the region leaves the fit), at least the model's;
- the part common to all regions (e.g. a link length), which no subset of the poses can see:
  a stated prior, the arm's absolute accuracy ``arm_accuracy_m`` (1σ per axis, m; default
  :data:`DEFAULT_ARM_ACCURACY_M`), on the translation, and over the lever of the profile
  points (their median distance from the sensor) on the rotation. Where the pose
  corrections show a larger error from pose to pose, that error is taken instead: the part
  common to the whole workspace is assumed no larger than the part that varies. A joint
  calibration of the kinematics (``flange_poses`` given) estimates that part itself and
  takes no prior.

Halves that still disagree beyond :data:`HALVES_LIMIT_SIGMAS` of that 1σ widen it by their
excess. Recordings not marked keep the model's 1σ.

Every statistic is judged against the solve's statistical 1σ. A target that also solved a
model of the sensor its profiles cannot tell apart (the x/z scale split) reports the move
to it as a model spread (:attr:`~.targets.base.TargetSolution.sigma_model_spread`); that is
added to the final 1σ in quadrature, never to the yardstick of the tests, where it would
hide a systematic robot error.

The 1σ is also given where the user's points are: at the measuring centre, the point
(0, 0, z_c) of the sensor frame at the mean depth z_c of the used profile points
(:func:`sigma_at_point`): a rotation 1σ of 0.1° moves a point 1 m away by 1.7 mm.

All lengths in m and angles in rad; text in mm and degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtri

from .errors import CalibrationError
from .geometry import FloatArray
from .regions import (
    CLUSTER_ANGLE_RAD,
    CLUSTER_RADIUS_M,
    MIN_REGIONS,
    PER_POSE,
    PLAIN,
    FlangePoses,
    ModelChoice,
    blocked_accuracy,
    choose_model,
    held_out_distances,
    nearest_poses,
    workspace_regions,
)
from .sigma_budget import (
    HALVES,
    SCALE_MODEL,
    SYSTEMATIC_ROBOT_ERROR,
    SigmaBudget,
    statistical_budget,
)
from .subsets import (
    halves_difference,
    hand_eye_difference,
    model_sigma,
    region_jackknife,
    region_subsets,
    reporting,
    solve_each,
    solve_subsets,
    statistical_sigma,
)
from .targets.base import ROBOT_PRIOR_EXCESS, Progress, RobotError, TargetSolution
from .types import SampleFit

#: Folds of the pose-interleaved cross-validation, and the most regions of the workspace.
DEFAULT_FOLDS = 5
#: False-alarm probability, under independent per-pose noise, of each statistic that marks
#: the robot's error as systematic (the 3σ convention).
REGION_FALSE_ALARM = 0.0027
#: Nearest poses whose mean held-out offset a sample's is correlated with.
NEIGHBOURS = 3
#: Neighbour correlation of the held-out offsets above which the robot's error is systematic.
NEIGHBOUR_LIMIT = 0.3
#: Default prior 1σ per axis of the part of a systematic robot error that all regions share
#: (the arm's absolute accuracy over the scanned workspace), m: 0.1 mm.
DEFAULT_ARM_ACCURACY_M = 1e-4
#: Halves that differ by more than this many combined σ on an axis disagree.
HALVES_LIMIT_SIGMAS = 3.0
#: Warn when the poses fall into at most this many clusters.
FEW_CLUSTERS = 6


@dataclass
class SelfCheck:
    """The outcome of :func:`self_check`.

    Attributes
    ----------
    folds : int
        Pose-interleaved folds solved.
    accuracy_in_use_m : float or None
        Region-blocked held-out RMS of the chosen model, m (:mod:`.regions`); None with fewer
        than 3 regions.
    regions : int
        Regions of the workspace held out (0 when fewer than 3: no accuracy in use).
    region_rms_m : ndarray, shape (G,) or None
        The chosen model's held-out RMS per region, m.
    target_move_m : float or None
        RMS over the held-out points of how far the fitted target moves there when their
        region joins the fit, m (:class:`~.regions.BlockedAccuracy`; part of the accuracy).
    model : ModelChoice or None
        The model chosen by the region-blocked accuracy and each model's figure; None without
        regions (the per-pose model is kept).
    interleaved_rms_m : float
        The pose-interleaved held-out RMS, m: a consistency check, not the accuracy in use.
    held_out_rms_m : ndarray, shape (M,)
        Per held-out sample RMS of the interleaved folds, m (order of ``indices``).
    indices : list of int
        Profile indices of the interleaved held-out samples.
    sigma_jackknife : ndarray, shape (6,)
        Grouped jackknife 1σ over the interleaved folds: rotation (rad, sensor axes),
        translation (m, flange axes).
    sigma_model : ndarray, shape (6,)
        The chosen solution's own 1σ, same order.
    dispersion_ratio : float
        √(mean (σ_jackknife / σ_model)²).
    sigma_region : ndarray, shape (6,) or None
        Jackknife 1σ of the chosen model over the regions (:func:`region_jackknife`).
    region_ratio : float or None
        The region dispersion (:attr:`RegionJackknife.ratio`).
    region_offset_p : float or None
        Smallest p-value of the region offsets' analysis of variance (offset, tilt).
    neighbour_correlation : float
    offset_rms_m : float
        RMS of the interleaved held-out samples' mean signed offsets, m.
    lever_m : float
        Median distance of the profile points from the sensor origin, m.
    halves_sigmas, halves_model_sigmas : ndarray, shape (6,) or None
        |θ_even − θ_odd| / √(σ_even² + σ_odd²) per axis, against the reported and the model
        1σ; None when the halves could not be solved apart.
    pose_clusters : int
    systematic : bool
    arm_accuracy_m : float
        The prior on the error common to all regions that the 1σ assumes, m (0 when none:
        independent error, or a joint kinematic calibration): the stated one, or the robot's
        per-pose error where that is larger.
    robot_excess : float or None
        The robot's per-pose error over its prior, from the pose corrections (None where the
        solve estimates none).
    sigma_honest : ndarray, shape (6,)
        The 1σ to report (the model's, or widened, with the model spread).
    sigma_widening : ndarray, shape (6,), or None
        Factors (>= 1) by which the chosen solve widened its own 1σ because its profiles
        scatter the hand-eye more than its noise model predicts
        (:attr:`TargetSolution.sigma_widening`); a floor of ``sigma_honest``.
    sigma_model_spread : ndarray, shape (6,), or None
        The part of ``sigma_honest`` (added in quadrature) for a model of the sensor the
        profiles cannot tell apart (:attr:`TargetSolution.sigma_model_spread` of the default
        solve of all features); None where there is none.
    sigma_budget : SigmaBudget or None
        ``sigma_honest`` as the noise model's 1σ and each named widening
        (:mod:`.sigma_budget`); None where the chosen solve has no 1σ.
    solution : TargetSolution
        The chosen model's solve of all features (the result to report).
    region_indices : list of list of int
        Profile indices of each region (empty without regions).
    region_solutions : list of TargetSolution or None
        The chosen model's solve without each region (None where it failed).
    warnings : list of str
    """

    folds: int
    accuracy_in_use_m: float | None
    regions: int
    region_rms_m: FloatArray | None
    target_move_m: float | None
    model: ModelChoice | None
    interleaved_rms_m: float
    held_out_rms_m: FloatArray
    indices: list[int]
    sigma_jackknife: FloatArray
    sigma_model: FloatArray
    dispersion_ratio: float
    sigma_region: FloatArray | None
    region_ratio: float | None
    region_offset_p: float | None
    neighbour_correlation: float
    offset_rms_m: float
    lever_m: float
    halves_sigmas: FloatArray | None
    halves_model_sigmas: FloatArray | None
    pose_clusters: int
    systematic: bool
    arm_accuracy_m: float
    robot_excess: float | None
    sigma_honest: FloatArray
    solution: TargetSolution = field(repr=False)
    sigma_widening: FloatArray | None = None
    sigma_model_spread: FloatArray | None = None
    sigma_budget: SigmaBudget | None = None
    region_indices: list[list[int]] = field(default_factory=list)
    region_solutions: list[TargetSolution | None] = field(default_factory=list, repr=False)
    warnings: list[str] = field(default_factory=list)

    @property
    def no_accuracy_reason(self) -> str:
        """Why no accuracy in use is claimed (empty when one is)."""
        if self.accuracy_in_use_m is not None:
            return ""
        return (
            f"the poses fall into {self.pose_clusters} cluster(s) of the workspace (poses within "
            f"{CLUSTER_RADIUS_M * 1e3:.0f} mm and {np.degrees(CLUSTER_ANGLE_RAD):.0f} deg of "
            f"each other), fewer than {MIN_REGIONS}: no region can be held out with its "
            "neighbours, so the error of scans elsewhere in the cell cannot be measured"
        )

    def quality_entries(self) -> dict[str, Any]:
        """Entries of the result's ``quality`` section (SI units)."""
        return {
            "accuracy_in_use_m": None
            if self.accuracy_in_use_m is None
            else float(self.accuracy_in_use_m),
            "accuracy_in_use": {
                "held_out": "regions of the workspace",
                "regions": int(self.regions),
                "region_rms_m": None
                if self.region_rms_m is None
                else [float(v) for v in self.region_rms_m],
                "target_move_m": None if self.target_move_m is None else float(self.target_move_m),
                "not_measured_because": self.no_accuracy_reason or None,
                "model": PER_POSE if self.model is None else self.model.chosen,
                "model_accuracy_m": None
                if self.model is None
                else {k: float(v) for k, v in self.model.accuracy_m.items()},
            },
            "self_check": {
                "folds": int(self.folds),
                "pose_interleaved_rms_m": float(self.interleaved_rms_m),
                "halves_agreement_sigmas": None
                if self.halves_sigmas is None
                else float(np.max(self.halves_sigmas)),
                "halves_agreement_model_sigmas": None
                if self.halves_model_sigmas is None
                else float(np.max(self.halves_model_sigmas)),
                "jackknife_sigma": _axes(self.sigma_jackknife),
                "model_sigma": _axes(self.sigma_model),
                "dispersion_ratio": float(self.dispersion_ratio),
                "regions": int(self.regions),
                "region_sigma": None if self.sigma_region is None else _axes(self.sigma_region),
                "region_dispersion_ratio": None
                if self.region_ratio is None
                else float(self.region_ratio),
                "region_offset_p": None
                if self.region_offset_p is None
                else float(self.region_offset_p),
                "neighbour_correlation": float(self.neighbour_correlation),
                "pose_clusters": int(self.pose_clusters),
                "systematic_robot_error": bool(self.systematic),
                "arm_accuracy_m": float(self.arm_accuracy_m),
                "robot_error_over_prior": None
                if self.robot_excess is None
                else float(self.robot_excess),
                "sigma_widening": None
                if self.sigma_widening is None
                else _axes(self.sigma_widening),
                "model_spread_sigma": None
                if self.sigma_model_spread is None
                else _axes(self.sigma_model_spread),
            },
        }


def _axes(sigma: FloatArray) -> dict[str, list[float]]:
    """A (6,) [rotation, translation] vector as the YAML's two lists."""
    return {
        "rotation_rad": [float(v) for v in sigma[:3]],
        "translation_m": [float(v) for v in sigma[3:]],
    }


def tilt(x: FloatArray, d: FloatArray) -> float:
    """Change (m) of the distances ``d`` (N,) across the profile: the slope of a line fitted
    to d against the sensor x (N,) of the points, times their x spread (2σ); 0 for fewer than
    3 points. The least-squares slope is cov(x, d) / var(x) (``np.cov``): a self-check of
    1,600 profiles takes 3,200 of them, and ``np.polyfit``'s Vandermonde fit cost a third of
    its statistics."""
    if len(d) < 3:
        return 0.0
    (var_x, cov_xd), _ = np.cov(x, d, bias=True)
    if var_x <= 0.0:
        return 0.0
    return float(2.0 * cov_xd / np.sqrt(var_x))


def neighbour_correlation(residuals: FloatArray, T_base_flange: FloatArray) -> float:
    """Correlation of each held-out sample's residual components (M, C) (mean offset, tilt
    across the profile) with the mean of its :data:`NEIGHBOURS` nearest poses'
    (:func:`~.regions.nearest_poses`); the largest over the components that vary.

    Independent per-pose errors give residuals uncorrelated between neighbours (≈ 0, spread
    about 1/√M per component); a systematic, pose-dependent error gives neighbours alike
    residuals (→ 1) in the offset, the tilt or both.
    """
    nearest = nearest_poses(T_base_flange, min(NEIGHBOURS, len(residuals) - 1))
    centred = residuals - residuals.mean(axis=0)
    a, b = centred, centred[nearest].mean(axis=1)
    denominator = np.sqrt(np.sum(a**2, axis=0) * np.sum(b**2, axis=0))
    varies = denominator > 0.0
    if not np.any(varies):
        return 0.0
    return float(np.max(np.sum(a * b, axis=0)[varies] / denominator[varies]))


def neighbour_limit(n: int) -> float:
    """Neighbour correlation above which the error is systematic for n held-out samples:
    :data:`NEIGHBOUR_LIMIT`, or 2.5 standard deviations of the correlation of independent
    residuals (2.5/√n) when that is larger."""
    return max(NEIGHBOUR_LIMIT, 2.5 / float(np.sqrt(max(n, 1))))


def region_limit(dof: int) -> float:
    """Region dispersion above which the robot's error is systematic, for a jackknife with
    ``dof`` degrees of freedom: √(χ²_dof quantile at 1 − :data:`REGION_FALSE_ALARM` / dof).

    Under the noise model each axis' (σ_region/σ_expected)² is about χ²_dof / dof; taking the six
    axes as one (they move together when one region pulls the estimate) keeps the false
    alarm at or below :data:`REGION_FALSE_ALARM`.
    """
    return float(np.sqrt(chdtri(dof, REGION_FALSE_ALARM) / dof))


def honest_sigma(
    sigma_model: FloatArray,
    sigma_region: FloatArray | None,
    arm_accuracy_m: float,
    lever_m: float,
    robot_error: RobotError | None = None,
) -> FloatArray:
    """The 1σ (6,) under a systematic robot error: the part that varies over the workspace
    (the region jackknife's 1σ, at least the model's) and the part all regions share, added
    in quadrature. The shared part is the prior ``arm_accuracy_m`` on the translation, over
    the lever ``lever_m`` on the rotation, or the robot's per-pose error ``robot_error``
    (translation and rotation) on each where that is larger."""
    varying = sigma_model if sigma_region is None else np.maximum(sigma_model, sigma_region)
    shared = arm_accuracy_m * np.array([1.0 / lever_m] * 3 + [1.0] * 3)
    if robot_error is not None:
        shared = np.maximum(
            shared, np.array([robot_error.rotation_rad] * 3 + [robot_error.translation_m] * 3)
        )
    return np.asarray(np.sqrt(varying**2 + shared**2))


def measuring_centre_depth(fits: Sequence[SampleFit]) -> float | None:
    """Mean depth (sensor z, m) of the used profile points; None without points."""
    depths = [fit.points[:, 2] for fit in fits if len(fit.points)]
    return float(np.mean(np.concatenate(depths))) if depths else None


def sigma_at_point(
    T_flange_sensor: FloatArray,
    sigma_rotation_rad: FloatArray,
    sigma_translation_m: FloatArray,
    point_sensor: FloatArray,
) -> FloatArray:
    """1σ (3,) per flange axis, m, of a sensor-frame point (3,) mapped by the hand-eye.

    A rotation δθ about the sensor axes moves the point by δθ × p (sensor axes), rotated into
    the flange; the translation adds δt (flange axes). The axes are taken as independent (the
    1σ vectors carry no correlations).
    """
    R = T_flange_sensor[:3, :3]
    p = np.asarray(point_sensor, dtype=float)
    # δθ × p for a unit δθ about each sensor axis: the columns of the cross-product matrix.
    lever = np.cross(np.eye(3), p).T
    variance = (R**2) @ ((lever**2) @ (sigma_rotation_rad**2)) + sigma_translation_m**2
    return np.asarray(np.sqrt(variance))


def region_offset_p(
    solution: TargetSolution,
    kept: Sequence[Any],
    label: NDArray[np.int64],
    flange_poses: FlangePoses | None = None,
) -> float:
    """Smallest p-value of the one-way analysis of variance of the profiles' mean signed
    offsets and tilts (:func:`tilt`) from ``solution``'s target, grouped by region ``label``
    (M,): whether regions are off by more than their poses' spread explains."""
    from scipy.stats import f_oneway  # most of a second to import: only where it is used

    d = held_out_distances(solution, kept, flange_poses)
    offsets = np.array([np.mean(di) for di in d])
    tilts = np.array([tilt(f.record().points[:, 0], di) for f, di in zip(kept, d, strict=True)])
    p = []
    for values in (offsets, tilts):
        groups = [values[label == g] for g in range(int(label.max()) + 1)]
        if all(len(v) >= 2 for v in groups) and float(np.ptp(values)) > 0.0:
            p.append(float(f_oneway(*groups).pvalue))
    return min(p, default=1.0)


def self_check(
    features: Sequence[Any],
    solution: TargetSolution,
    solve: Callable[[list[Any]], TargetSolution],
    folds: int = DEFAULT_FOLDS,
    flange_poses: FlangePoses | None = None,
    workers: int = 1,
    plain: Callable[[], tuple[TargetSolution, Callable[[list[Any]], TargetSolution]] | None]
    | None = None,
    arm_accuracy_m: float = DEFAULT_ARM_ACCURACY_M,
    progress: Progress | None = None,
) -> SelfCheck | None:
    """Cross-validate a solution by region and by interleaved poses, choose the model, and
    widen its 1σ when the robot's error looks systematic (see the module docstring).

    Parameters
    ----------
    features : sequence of features
        The target's features (objects with ``index``, ``T_base_flange`` and ``record()``
        giving a :class:`~linelaser_calib.core.types.SampleFit`); only those the solution used
        take part.
    solution : TargetSolution
        The solve of all of them (default method, with a 1σ).
    solve : callable
        The target's default solve of a subset of the features the solution used, setting
        none of them aside (the pipeline's: ``screen_outliers`` False); a subset too small
        for it raises a CalibrationError (the check is then skipped, or that part left out).
    folds : int
        Interleaved folds, and the most regions of the workspace.
    flange_poses : callable, optional
        ``flange_poses(fold, held_out)``: the flange poses (K, 4, 4) a fold's solution gives
        held-out features, when the solve also corrects the poses (a joint kinematic
        calibration). Default: the recorded ``T_base_flange`` of each feature.
    workers : int
        Processes for the subset solves (:func:`solve_subsets`).
    plain : callable, optional
        ``plain()``: the plain model's solve of all features (with a 1σ) and its solve of a
        subset (:mod:`.regions`), or None when it cannot be solved. Called only when the
        robot's error looks systematic; the plain model is then cross-validated by region
        beside the default one and chosen when it does better.
    arm_accuracy_m : float
        Prior 1σ per axis of the robot error common to all regions, m (applied to the 1σ of
        a systematic error; not with ``flange_poses``).
    progress : callable, optional
        Hears of each subset solve, as the stage ``self-check`` (and ``self-check, plain
        model`` for the plain model's).

    Returns
    -------
    SelfCheck or None
        None when there is no 1σ to check or the interleaved folds cannot be solved.
    """
    sigma_per_pose = model_sigma(solution)
    used = set(solution.samples_used)
    kept = [f for f in features if f.index in used]
    if sigma_per_pose is None or len(kept) < 2 * folds:
        return None
    T_kept = np.stack([f.T_base_flange for f in kept])
    label, clusters = workspace_regions(T_kept, folds)
    solved = solve_subsets(kept, folds, solve, label, workers, reporting(progress, "self-check"))
    interleaved, solved = solved[:folds], solved[folds:]
    (even, odd), solved = solved[:2], solved[2:]
    if any(isinstance(fold, CalibrationError) for fold in interleaved):
        return None
    group = np.arange(len(kept)) % folds
    estimates, held_rms, offsets, poses, indices = [], [], [], [], []
    tilts: list[float] = []
    squares, count = 0.0, 0
    for k, fold in enumerate(interleaved):
        assert not isinstance(fold, CalibrationError)
        estimates.append(hand_eye_difference(solution.T_flange_sensor, fold.T_flange_sensor))
        held = [f for f, g in zip(kept, group, strict=True) if g == k]
        for f, d in zip(held, held_out_distances(fold, held, flange_poses), strict=True):
            held_rms.append(float(np.sqrt(np.mean(d**2))))
            offsets.append(float(np.mean(d)))
            tilts.append(tilt(f.record().points[:, 0], d))
            poses.append(f.T_base_flange)
            indices.append(f.index)
            squares += float(np.sum(d**2))
            count += d.size
    theta = np.array(estimates)
    sigma_jk = np.sqrt((folds - 1) / folds * np.sum((theta - theta.mean(axis=0)) ** 2, axis=0))
    ratio = float(np.sqrt(np.mean((sigma_jk / sigma_per_pose) ** 2)))
    correlation = neighbour_correlation(np.stack([offsets, tilts], axis=1), np.stack(poses))
    chosen, sigma_model = solution, sigma_per_pose
    model = blocked = region = None
    offset_p = None
    held_sets: list[list[Any]] = []
    region_solved = solved
    if label is not None:
        G = int(label.max()) + 1
        held_sets = [[f for f, lab in zip(kept, label, strict=True) if lab == g] for g in range(G)]
        blocked = blocked_accuracy(solved, held_sets, solution, flange_poses)
        region = region_jackknife(solved, solution, sigma_per_pose)
        offset_p = region_offset_p(solution, kept, label, flange_poses)
    region_ratio = None if region is None else region.ratio
    systematic = (
        correlation > neighbour_limit(len(offsets))
        or (region is not None and region.ratio > region_limit(region.regions - 1))
        or (offset_p is not None and offset_p < REGION_FALSE_ALARM / 2.0)
    )
    if blocked is not None and label is not None:
        # The plain model is tried only where the robot's error looks systematic: with
        # independent per-pose error the per-pose model is the likelihood of the data.
        tried = plain() if systematic and plain is not None else None
        if tried is None:
            model = choose_model(blocked, None)
        else:
            plain_solution, plain_solve = tried
            plain_solved = solve_each(
                plain_solve,
                region_subsets(kept, label),
                workers,
                reporting(progress, "self-check, plain model"),
            )
            plain_blocked = blocked_accuracy(plain_solved, held_sets, plain_solution, flange_poses)
            model = choose_model(blocked, plain_blocked)
            sigma_plain = model_sigma(plain_solution)
            if model.chosen == PLAIN and sigma_plain is not None:
                chosen, sigma_model, blocked = plain_solution, sigma_plain, plain_blocked
                region_solved = plain_solved
                region = region_jackknife(plain_solved, chosen, sigma_model)
    lever = float(np.median([np.median(np.linalg.norm(f.record().points, axis=1)) for f in kept]))
    robot = solution.robot_error
    beyond_repeatability = robot is not None and robot.excess > ROBOT_PRIOR_EXCESS
    systematic = systematic or (beyond_repeatability and flange_poses is None)
    prior = arm_accuracy_m if systematic and flange_poses is None else 0.0
    robot_prior = robot if prior > 0.0 else None
    sigma = (
        honest_sigma(
            sigma_model, None if region is None else region.sigma, prior, lever, robot_prior
        )
        if systematic
        else sigma_model.copy()
    )
    if robot_prior is not None:
        prior = max(prior, robot_prior.translation_m)
    # The chosen solve's own statistical 1σ, widened where its profiles scatter it beyond the
    # noise model, is a floor: the statistics above judge the robot's error against the model.
    reported = statistical_sigma(chosen)
    if reported is not None:
        sigma = np.maximum(sigma, reported)
    budget = statistical_budget(chosen)
    if budget is not None:
        budget = budget.then(SYSTEMATIC_ROBOT_ERROR, sigma)
    split = halves_difference(even, odd)
    halves = None
    if split is not None:
        difference, combined = split
        halves = difference / (combined * sigma / sigma_model)
        # Halves that disagree while no other statistic saw a systematic error mark it too,
        # and widen the 1σ by their excess only.
        excess = float(np.max(halves)) / HALVES_LIMIT_SIGMAS
        systematic = systematic or excess > 1.0
        if excess > 1.0:
            sigma = sigma * excess
            budget = None if budget is None else budget.then(HALVES, sigma)
    spread = solution.sigma_model_spread
    if spread is not None:
        sigma = np.hypot(sigma, spread)
        budget = None if budget is None else budget.then(SCALE_MODEL, sigma)
    check = SelfCheck(
        folds=folds,
        accuracy_in_use_m=None if blocked is None else blocked.rms_m,
        regions=0 if blocked is None else blocked.regions,
        region_rms_m=None if blocked is None else blocked.region_rms_m,
        target_move_m=None if blocked is None else blocked.target_move_m,
        model=model,
        interleaved_rms_m=float(np.sqrt(squares / max(count, 1))),
        held_out_rms_m=np.array(held_rms),
        indices=indices,
        sigma_jackknife=sigma_jk,
        sigma_model=sigma_model,
        dispersion_ratio=ratio,
        sigma_region=None if region is None else region.sigma,
        region_ratio=region_ratio,
        region_offset_p=offset_p,
        neighbour_correlation=correlation,
        offset_rms_m=float(np.sqrt(np.mean(np.square(offsets)))),
        lever_m=lever,
        halves_sigmas=halves,
        halves_model_sigmas=None if split is None else split[0] / split[1],
        pose_clusters=clusters,
        systematic=systematic,
        arm_accuracy_m=prior,
        robot_excess=None if robot is None else robot.excess,
        sigma_honest=sigma,
        solution=chosen,
        sigma_widening=chosen.sigma_widening,
        sigma_model_spread=spread,
        sigma_budget=budget,
        region_indices=[[f.index for f in held] for held in held_sets],
        region_solutions=[None if isinstance(r, CalibrationError) else r for r in region_solved],
    )
    check.warnings = _warnings(check)
    return check


class Evidence(NamedTuple):
    """A statistic that can mark the robot's error systematic: its name and value in a few
    words, whether it is beyond its false-alarm limit, and what that shows, in words."""

    name: str
    value: str
    shown: bool
    text: str


def systematic_evidence(check: SelfCheck) -> list[Evidence]:
    """Each statistic the self-check tests for a systematic robot error (those it has), with
    whether it is beyond its limit."""
    out = []
    if check.region_offset_p is not None:
        out.append(
            Evidence(
                "regions' offsets",
                f"p = {check.region_offset_p:.1e}",
                check.region_offset_p < REGION_FALSE_ALARM / 2,
                "regions of the workspace are off by more than their poses' spread explains "
                f"(analysis of variance, p = {check.region_offset_p:.1e})",
            )
        )
    out.append(
        Evidence(
            "neighbour correlation",
            f"{check.neighbour_correlation:.2f}",
            check.neighbour_correlation > neighbour_limit(len(check.indices)),
            "neighbouring poses are off alike (correlation "
            f"{check.neighbour_correlation:.2f} of their held-out offsets)",
        )
    )
    if check.region_ratio is not None:
        out.append(
            Evidence(
                "region dispersion",
                f"{check.region_ratio:.1f}x the noise model's",
                check.region_ratio > region_limit(check.regions - 1),
                f"the hand-eye moves {check.region_ratio:.1f} times more when one region of "
                "the workspace is left out than the noise model predicts",
            )
        )
    if check.halves_model_sigmas is not None:
        halves = float(np.max(check.halves_model_sigmas))
        out.append(
            Evidence(
                "halves",
                f"{halves:.1f} combined sigma of the noise model",
                halves > HALVES_LIMIT_SIGMAS,
                f"the even and odd halves differ by up to {halves:.1f} combined sigma of the "
                "noise model",
            )
        )
    if check.robot_excess is not None:
        out.append(
            Evidence(
                "arm error",
                f"{check.robot_excess:.1f}x its stated repeatability",
                check.robot_excess > ROBOT_PRIOR_EXCESS,
                f"the arm errs {check.robot_excess:.1f} times more from pose to pose than its "
                "stated repeatability ({setting:robot_sigma_t_m}, {setting:robot_sigma_r_rad}): "
                "an error beyond repeatability depends on where the arm is",
            )
        )
    return out


def _warnings(check: SelfCheck) -> list[str]:
    """The self-check's warnings in plain words (mm, degrees)."""
    out = []
    if check.systematic:
        factor_t = float(np.max(check.sigma_honest[3:] / check.sigma_model[3:]))
        factor_r = float(np.max(check.sigma_honest[:3] / check.sigma_model[:3]))
        evidence = [f"the held-out profiles are off by {check.offset_rms_m * 1e3:.3f} mm RMS"]
        evidence += [item.text for item in systematic_evidence(check) if item.shown]
        basis = (
            "the spread of the hand-eye over the regions left out"
            if check.sigma_region is not None
            else "the noise model (no regions to leave out)"
        )
        shared = (
            f" plus a prior of {check.arm_accuracy_m * 1e3:.3f} mm (1 sigma) on the "
            "arm's error common to the whole workspace, which no subset of the poses can see "
            "(the larger of {setting:arm_accuracy_m} and the arm's error from pose to pose)"
            if check.arm_accuracy_m > 0.0
            else ""
        )
        use = (
            f"Scans elsewhere in the cell will be off by about {check.accuracy_in_use_m * 1e3:.3f}"
            " mm RMS (held out by region). "
            if check.accuracy_in_use_m is not None
            else ""
        )
        out.append(
            "the robot's pose error looks systematic (pose-dependent, e.g. kinematic "
            "parameters that differ from the nominal ones), not independent per pose: "
            + ", ".join(evidence)
            + ". The hand-eye is off by about the robot's absolute error, not by its "
            f"repeatability; its 1 sigma comes from {basis}{shared}: "
            f"{', '.join(f'{v * 1e3:.3f}' for v in check.sigma_honest[3:])} mm and "
            f"{', '.join(f'{np.degrees(v):.4f}' for v in check.sigma_honest[:3])} deg "
            f"({factor_t:.1f}x and {factor_r:.1f}x the noise model's). "
            + use
            + "Flange poses from a kinematically calibrated robot model ({setting:kinematics} with "
            "joint states) remove the systematic part"
        )
    if check.pose_clusters <= FEW_CLUSTERS:
        out.append(
            f"the {len(check.solution.samples_used)} poses fall into only "
            f"{check.pose_clusters} clusters (poses within {CLUSTER_RADIUS_M * 1e3:.0f} mm and "
            f"{np.degrees(CLUSTER_ANGLE_RAD):.0f} deg of each other): the result rests on "
            "a few independent views, and a robot error shared within a cluster counts once "
            "per cluster, not once per pose; add poses between the clusters"
        )
    return out
