"""Self-check of a calibration: cross-validation over poses, halves, and an honest 1σ.

One machinery for every target, through the target protocol only (it never asks which target
it is): the target's own default solve is run again on subsets of its features, and the
held-out samples are judged by the section's :meth:`~linelaser_calib.core.targets.base.
ResultSection.surface_distances`.

What is computed
----------------
K-fold cross-validation over poses (``folds`` interleaved folds of the used samples):
    Each fold is left out in turn; the others are solved; the held-out samples' points are
    mapped into the base frame with their *recorded* flange poses (no correction: the
    robot's error at a new pose is unknown) and the fold's hand-eye, and their distances to
    the fold's fitted target are taken. Their RMS is the **accuracy in use**: what a user
    sees scanning with this calibration.
Grouped (per-profile) jackknife covariance of the hand-eye:
    With the K fold estimates θ_k (each without one group of profiles) the delete-a-group
    jackknife gives Cov = (K − 1)/K · Σ_k (θ_k − θ̄)(θ_k − θ̄)ᵀ. It is a cluster-robust
    covariance with the profile as the cluster: the ~100 points of one profile share one pose
    error, which the point residuals cannot show, but which moves the estimate when the
    profile leaves the fit. It needs nothing of the noise model, but an error shared by
    neighbouring poses barely shows in it: every interleaved fold holds every region of the
    workspace (on the kinematic-error arm its dispersion stayed at 0.5-1.3 times the model's
    while the hand-eye was up to 30σ off). A jackknife was chosen over a sandwich estimator
    because the robust point weights and the rejection loop make the scores of the refit
    differ from those of a linearisation.
Jackknife over regions of the workspace:
    The used poses are split into ``folds`` regions by k-means on position and flange
    direction (:func:`region_groups`) and each region is left out in turn. A robot error that
    neighbouring poses share moves the estimate when their region leaves the fit, which the
    interleaved folds (every region in every fold) cannot show. The delete-a-group jackknife
    of these G estimates about the full one is the region 1σ (:func:`region_jackknife`).
Disjoint halves:
    Even and odd samples solved apart; their hand-eye difference in units of the combined
    1σ (√(σ_a² + σ_b²) per axis, each half's own σ), against the noise model and against the
    widened 1σ (each half's σ times the full solution's widening).

Systematic robot error
----------------------
Per-pose corrections absorb any robot error, so the fit's residual cannot tell an arm with
independent per-pose noise from one whose error is systematic (pose-dependent: kinematic
parameters that differ from the nominal ones). Two statistics can, either one marking the
error as systematic:

- **Region dispersion** √(mean over the axes of (σ_region / σ_expected)²), σ_expected what
  the noise model predicts for this jackknife from the region solves' own 1σ
  (:class:`RegionJackknife`; leaving out a region that holds a whole direction of view moves
  the estimate more, and the model knows it). Under the noise model each axis' ratio squared
  is about χ²_{G−1}/(G − 1); treating the six axes as one (one region pulls them together)
  the limit :func:`region_limit` is the χ² quantile at a false-alarm probability of 0.27 %
  (the 3σ convention): 2.02 for 5 regions. Derived, not tuned.
- **Neighbour correlation** of the held-out offsets: each held-out profile's mean signed
  offset from the fitted target is the robot's error at that pose as the target sees it, and
  its tilt across the profile shows the rotation part. Independent errors leave the 3 nearest
  poses' residuals uncorrelated; a systematic error makes them alike. Limit
  :func:`neighbour_limit`, max(0.3, 2.5/√n).
- Halves that still disagree beyond :data:`HALVES_LIMIT_SIGMAS` mark it too.

bench/robot_error.py prints both statistics per preset (min / max over 20 seeds) beside
their limits.

The widened 1σ (:func:`honest_sigma`) has two parts, added in quadrature:

- the part of the error that varies over the workspace: the region 1σ times the Student-t
  over normal quantile ratio at 95 % for its G − 1 degrees of freedom (:func:`t_factor`,
  1.42 for 5 regions: a 1σ from 5 groups is itself uncertain), and at least the model's;
- the part all poses share, which no subset of the poses can see (for a kinematic error,
  whatever of the rest of the chain acts like one more constant flange-side transform over
  the poses scanned; the last link's own error is such a transform at every pose, and
  belongs to the hand-eye these flange poses see, see
  :func:`~linelaser_calib.core.robot.kinematics.effective_hand_eye`): a
  prior of :data:`SYSTEMATIC_FLOOR` times the held-out offsets' RMS for translation, and that
  over the lever of the profile points (their median distance from the sensor) for
  rotation. This factor is a prior, not an estimate.

When the halves still disagree beyond :data:`HALVES_LIMIT_SIGMAS` of the widened 1σ, it is
widened further by their excess. Halves that disagree while neither statistic fires mark the
error as systematic too, and widen the model's 1σ by their excess only. A warning says all
this in words. Recordings not marked keep the model's 1σ.

The region solves cost as much as the folds' (one solve each), so the self-check solves
2·folds + 2 times.

All lengths in m and angles in rad; text in mm and degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtri, ndtri, stdtrit

from .errors import CalibrationError
from .forked import map_forked
from .geometry import FloatArray, rotvec_from_matrix
from .targets.base import TargetSolution
from .types import SampleFit

#: Folds of the cross-validation.
DEFAULT_FOLDS = 5
#: One-sided probability, under the noise model, of a region dispersion above
#: :func:`region_limit` (the 3σ convention).
REGION_FALSE_ALARM = 0.0027
#: Two-sided coverage at which the region jackknife's few degrees of freedom are corrected
#: (:func:`t_factor`): its 2σ interval holds what a normal 2σ interval would.
T_COVERAGE = 0.95
#: Nearest poses whose mean held-out offset a sample's is correlated with.
NEIGHBOURS = 3
#: Neighbour correlation of the held-out offsets above which the robot's error is systematic.
NEIGHBOUR_LIMIT = 0.3
#: Prior 1σ of the part of a systematic error that all poses share, as a multiple of the
#: held-out offsets' RMS (the part that varies): no subset of the poses can see the shared
#: part, so it is a prior, not an estimate. Set against the physical hand-eye (with 1 the
#: kinematic-error arm of bench/robot_error.py was up to 5σ off, with 2 within 3σ); against
#: the hand-eye its flange poses see, the flagged recordings stay within 1.6σ.
SYSTEMATIC_FLOOR = 2.0
#: Halves that differ by more than this many combined σ on an axis disagree.
HALVES_LIMIT_SIGMAS = 3.0
#: Pose clusters: poses closer than this (m) ...
CLUSTER_RADIUS_M = 0.05
#: ... and this (rad) belong to one cluster.
CLUSTER_ANGLE_RAD = float(np.deg2rad(8.0))
#: A linked group of poses counts once per neighbourhood of this many times the limits above
#: that it takes to cover it (a continuous sweep is one linked group).
CLUSTER_SPAN = 2.0
#: Warn when the poses fall into at most this many clusters.
FEW_CLUSTERS = 6
#: Most Lloyd iterations of :func:`region_groups`.
LLOYD_ITERATIONS = 50


@dataclass
class SelfCheck:
    """The outcome of :func:`self_check`.

    Attributes
    ----------
    folds : int
        Folds solved.
    accuracy_in_use_m : float
        RMS distance of the held-out samples' points (recorded poses, fold hand-eye) to the
        fold's fitted target, m.
    held_out_rms_m : ndarray, shape (M,)
        Per held-out sample RMS distance, m (order of ``indices``).
    indices : list of int
        Profile indices of the held-out samples.
    sigma_jackknife : ndarray, shape (6,)
        Grouped jackknife 1σ of the hand-eye over the interleaved folds: rotation (rad,
        sensor axes), translation (m, flange axes).
    sigma_model : ndarray, shape (6,)
        The solution's own 1σ, same order.
    dispersion_ratio : float
        √(mean (σ_jackknife / σ_model)²).
    regions : int
        Regions of the workspace solved without (:func:`region_groups`); 0 when fewer than 3
        could be solved.
    sigma_region : ndarray, shape (6,) or None
        Jackknife 1σ over the regions (:func:`region_jackknife`), same order; None without
        regions.
    region_ratio : float or None
        The region dispersion (:attr:`RegionJackknife.ratio`); None without regions.
    neighbour_correlation : float
        Correlation of the held-out offsets of neighbouring poses (:func:`neighbour_correlation`).
    offset_rms_m : float
        RMS of the held-out samples' mean signed offsets, m.
    lever_m : float
        Median distance of the held-out points from the sensor origin, m.
    halves_sigmas : ndarray, shape (6,) or None
        |θ_even − θ_odd| / √(σ_even² + σ_odd²) per axis, each half's model 1σ widened as the
        full solution's (``sigma_honest / sigma_model``); None when the halves could not be
        solved apart.
    halves_model_sigmas : ndarray, shape (6,) or None
        The same against the halves' model 1σ.
    pose_clusters : int
        Groups of nearby poses (:data:`CLUSTER_RADIUS_M`, :data:`CLUSTER_ANGLE_RAD`).
    systematic : bool
        The robot's error looks systematic (see the module docstring).
    sigma_honest : ndarray, shape (6,)
        The 1σ to report (the model's, or widened).
    warnings : list of str
    """

    folds: int
    accuracy_in_use_m: float
    held_out_rms_m: FloatArray
    indices: list[int]
    sigma_jackknife: FloatArray
    sigma_model: FloatArray
    dispersion_ratio: float
    regions: int
    sigma_region: FloatArray | None
    region_ratio: float | None
    neighbour_correlation: float
    offset_rms_m: float
    lever_m: float
    halves_sigmas: FloatArray | None
    halves_model_sigmas: FloatArray | None
    pose_clusters: int
    systematic: bool
    sigma_honest: FloatArray
    warnings: list[str] = field(default_factory=list)

    def quality_entries(self) -> dict[str, Any]:
        """Entries of the result's ``quality`` section (SI units)."""
        return {
            "accuracy_in_use_m": float(self.accuracy_in_use_m),
            "self_check": {
                "folds": int(self.folds),
                "held_out_rms_m": float(self.accuracy_in_use_m),
                "halves_agreement_sigmas": None
                if self.halves_sigmas is None
                else float(np.max(self.halves_sigmas)),
                "halves_agreement_model_sigmas": None
                if self.halves_model_sigmas is None
                else float(np.max(self.halves_model_sigmas)),
                "jackknife_sigma": {
                    "rotation_rad": [float(v) for v in self.sigma_jackknife[:3]],
                    "translation_m": [float(v) for v in self.sigma_jackknife[3:]],
                },
                "model_sigma": {
                    "rotation_rad": [float(v) for v in self.sigma_model[:3]],
                    "translation_m": [float(v) for v in self.sigma_model[3:]],
                },
                "dispersion_ratio": float(self.dispersion_ratio),
                "regions": int(self.regions),
                "region_sigma": None
                if self.sigma_region is None
                else {
                    "rotation_rad": [float(v) for v in self.sigma_region[:3]],
                    "translation_m": [float(v) for v in self.sigma_region[3:]],
                },
                "region_dispersion_ratio": None
                if self.region_ratio is None
                else float(self.region_ratio),
                "neighbour_correlation": float(self.neighbour_correlation),
                "pose_clusters": int(self.pose_clusters),
                "systematic_robot_error": bool(self.systematic),
            },
        }


def hand_eye_difference(T_a: FloatArray, T_b: FloatArray) -> FloatArray:
    """(6,) rotation of b relative to a (rad, rotation vector of R_aᵀR_b) and translation
    b − a (m, flange axes), in the order of the 1σ vectors."""
    rotation = rotvec_from_matrix(T_a[:3, :3].T @ T_b[:3, :3])
    return np.concatenate([rotation, T_b[:3, 3] - T_a[:3, 3]])


def _sigma(solution: TargetSolution) -> FloatArray | None:
    """(6,) model 1σ [rotation, translation] of a solution, None if it has none."""
    if solution.sigma_rotation_rad is None or solution.sigma_translation_m is None:
        return None
    return np.concatenate([solution.sigma_rotation_rad, solution.sigma_translation_m])


def pose_clusters(T_base_flange: FloatArray) -> int:
    """Number of clusters of poses (M, 4, 4): groups linked by steps within
    :data:`CLUSTER_RADIUS_M` and :data:`CLUSTER_ANGLE_RAD` (single linkage), each counted once
    per neighbourhood of :data:`CLUSTER_SPAN` times those limits that it takes to cover it
    (greedily, around the first pose not yet covered).

    A tight group counts once however many poses it holds; a continuous sweep, which steps
    link into one group across the whole workspace, counts by its extent."""
    t = T_base_flange[:, :3, 3]
    z = T_base_flange[:, :3, 2]
    step = np.linalg.norm(t[:, None] - t[None], axis=2)
    cosine = np.clip(z @ z.T, -1.0, 1.0)
    near = (step < CLUSTER_RADIUS_M) & (cosine > np.cos(CLUSTER_ANGLE_RAD))
    within = (step < CLUSTER_SPAN * CLUSTER_RADIUS_M) & (
        cosine > np.cos(CLUSTER_SPAN * CLUSTER_ANGLE_RAD)
    )
    label = np.arange(len(T_base_flange))
    changed = True
    while changed:
        merged = np.array([label[near[i]].min() for i in range(len(label))])
        changed = bool(np.any(merged != label))
        label = merged[merged]
    count = 0
    for group in np.unique(label):
        members = np.flatnonzero(label == group)
        reach = within[np.ix_(members, members)]
        covered = np.zeros(len(members), dtype=bool)
        while not np.all(covered):
            covered |= reach[int(np.argmin(covered))]
            count += 1
    return count


def pose_distances(T_base_flange: FloatArray) -> FloatArray:
    """(M, M) distances between poses (M, 4, 4): position step over :data:`CLUSTER_RADIUS_M`
    plus the angle between the flange z axes over :data:`CLUSTER_ANGLE_RAD`."""
    t = T_base_flange[:, :3, 3]
    z = T_base_flange[:, :3, 2]
    angle = np.arccos(np.clip(z @ z.T, -1.0, 1.0))
    step = np.linalg.norm(t[:, None] - t[None], axis=2)
    return np.asarray(step / CLUSTER_RADIUS_M + angle / CLUSTER_ANGLE_RAD)


def tilt(x: FloatArray, d: FloatArray) -> float:
    """Change (m) of the distances ``d`` (N,) across the profile: the slope of a line fitted
    to d against the sensor x (N,) of the points, times their x spread (2σ); 0 for fewer than
    3 points."""
    if len(d) < 3 or float(np.std(x)) == 0.0:
        return 0.0
    slope = float(np.polyfit(x, d, 1)[0])
    return slope * 2.0 * float(np.std(x))


def neighbour_correlation(residuals: FloatArray, T_base_flange: FloatArray) -> float:
    """Correlation of each held-out sample's residual components (M, C) (mean offset, tilt
    across the profile) with the mean of its :data:`NEIGHBOURS` nearest poses'
    (:func:`pose_distances`); the largest over the components that vary.

    Independent per-pose errors give residuals uncorrelated between neighbours (≈ 0, spread
    about 1/√M per component); a systematic, pose-dependent error gives neighbours alike
    residuals (→ 1) in the offset, the tilt or both.
    """
    D = pose_distances(T_base_flange)
    np.fill_diagonal(D, np.inf)
    k = min(NEIGHBOURS, len(residuals) - 1)
    nearest = np.argsort(D, axis=1)[:, :k]
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


def region_groups(T_base_flange: FloatArray, groups: int) -> NDArray[np.int64]:
    """Labels (M,) of ``groups`` regions of the workspace: k-means of the poses (M, 4, 4) on
    their position over :data:`CLUSTER_RADIUS_M` and flange z axis over
    :data:`CLUSTER_ANGLE_RAD` (the scales of :func:`pose_distances`).

    Deterministic: the first centre is the pose nearest the mean, each further one the pose
    farthest from the centres so far; then Lloyd iterations. Every region keeps at least one
    pose.
    """
    X = np.concatenate(
        [T_base_flange[:, :3, 3] / CLUSTER_RADIUS_M, T_base_flange[:, :3, 2] / CLUSTER_ANGLE_RAD],
        axis=1,
    )
    first = int(np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1)))
    centres = [X[first]]
    for _ in range(1, groups):
        gap = np.min(np.linalg.norm(X[:, None] - np.array(centres)[None], axis=2), axis=1)
        centres.append(X[int(np.argmax(gap))])
    C = np.array(centres)
    label = np.zeros(len(X), dtype=np.int64)
    for iteration in range(LLOYD_ITERATIONS):
        new = np.argmin(np.linalg.norm(X[:, None] - C[None], axis=2), axis=1)
        if iteration > 0 and np.array_equal(new, label):
            break
        label = new
        C = np.array(
            [X[label == g].mean(axis=0) if np.any(label == g) else C[g] for g in range(groups)]
        )
    return np.asarray(np.unique(label, return_inverse=True)[1], dtype=np.int64)


@dataclass(frozen=True)
class RegionJackknife:
    """The jackknife over regions of the workspace (:func:`region_jackknife`).

    Attributes
    ----------
    sigma : ndarray, shape (6,)
        √((G − 1)/G · Σ_g (θ_g − θ)²) per axis, θ_g the solve without region g and θ the full
        solution (the order of :func:`hand_eye_difference`).
    expected : ndarray, shape (6,)
        What the noise model predicts for it: √((G − 1)/G · Σ_g (σ_g² − σ²)), σ_g the 1σ of
        the solve without region g and σ the full solution's (the variance of θ_g − θ for
        nested estimates), at least σ. A region whose absence leaves the poses weak (a whole
        direction of view missing) moves the estimate more, and the model says so.
    regions : int
        G, the regions solved without.
    """

    sigma: FloatArray
    expected: FloatArray
    regions: int

    @property
    def ratio(self) -> float:
        """√(mean over the axes of (sigma / expected)²), the region dispersion."""
        return float(np.sqrt(np.mean((self.sigma / self.expected) ** 2)))


def region_subsets(kept: list[Any], groups: int) -> list[list[Any]]:
    """The features without each of ``groups`` regions of the workspace
    (:func:`region_groups` of their flange poses), one list per region."""
    label = region_groups(np.stack([f.T_base_flange for f in kept]), groups)
    return [
        [f for f, lab in zip(kept, label, strict=True) if lab != g]
        for g in range(int(label.max()) + 1)
    ]


def region_jackknife(
    solves: Sequence[TargetSolution | CalibrationError],
    solution: TargetSolution,
    sigma_model: FloatArray,
) -> RegionJackknife | None:
    """The jackknife of the hand-eye over the solves of :func:`region_subsets` (each region
    left out in turn; :class:`RegionJackknife`); None when fewer than 3 regions could be
    solved without.

    Leaving a whole region out moves the estimate by what that region's shared robot error
    put into it; interleaved folds keep every region in every fold and cannot show it.
    """
    moves, spreads = [], []
    for fold in solves:
        if isinstance(fold, CalibrationError):
            continue
        moves.append(hand_eye_difference(solution.T_flange_sensor, fold.T_flange_sensor))
        sigma_fold = _sigma(fold)
        spreads.append(np.zeros(6) if sigma_fold is None else sigma_fold**2 - sigma_model**2)
    G = len(moves)
    if G < 3:
        return None
    factor = (G - 1) / G
    return RegionJackknife(
        sigma=np.sqrt(factor * np.sum(np.square(moves), axis=0)),
        expected=np.sqrt(np.maximum(factor * np.sum(spreads, axis=0), sigma_model**2)),
        regions=G,
    )


def region_limit(dof: int) -> float:
    """Region dispersion above which the robot's error is systematic, for a jackknife with
    ``dof`` degrees of freedom: √(χ²_dof quantile at 1 − :data:`REGION_FALSE_ALARM` / dof).

    Under the noise model each axis' (σ_region/σ_expected)² is about χ²_dof / dof; taking the six
    axes as one (they move together when one region pulls the estimate) keeps the false
    alarm at or below :data:`REGION_FALSE_ALARM`.
    """
    return float(np.sqrt(chdtri(dof, REGION_FALSE_ALARM) / dof))


def t_factor(dof: int) -> float:
    """Student-t over normal quantile at :data:`T_COVERAGE` (two-sided) for a 1σ estimated
    with ``dof`` degrees of freedom (2.78 / 1.96 = 1.42 for 4)."""
    q = 0.5 + T_COVERAGE / 2.0
    return float(stdtrit(dof, q) / ndtri(q))


def honest_sigma(
    sigma_model: FloatArray,
    sigma_region: FloatArray | None,
    regions: int,
    offset_rms_m: float,
    lever_m: float,
) -> FloatArray:
    """The 1σ (6,) under a systematic robot error: the part that varies over the workspace
    (the region jackknife, times :func:`t_factor` for its G − 1 degrees of freedom; at least
    the model's) and the part all poses share (prior :data:`SYSTEMATIC_FLOOR` times the
    held-out offsets' RMS, over the lever of the points for rotation), added in quadrature."""
    varying = sigma_model
    if sigma_region is not None:
        varying = np.maximum(sigma_model, t_factor(regions - 1) * sigma_region)
    shared = SYSTEMATIC_FLOOR * offset_rms_m * np.array([1.0 / lever_m] * 3 + [1.0] * 3)
    return np.asarray(np.sqrt(varying**2 + shared**2))


def self_check(
    features: Sequence[Any],
    solution: TargetSolution,
    solve: Callable[[list[Any]], TargetSolution],
    folds: int = DEFAULT_FOLDS,
    flange_poses: Callable[[TargetSolution, list[Any]], FloatArray] | None = None,
    workers: int = 1,
) -> SelfCheck | None:
    """Cross-validate a solution over poses, compare disjoint halves, and widen its 1σ when the
    robot's error looks systematic (see the module docstring).

    Parameters
    ----------
    features : sequence of features
        The target's features (objects with ``index``, ``T_base_flange`` and ``record()``
        giving a :class:`~linelaser_calib.core.types.SampleFit`); only those the solution used
        take part.
    solution : TargetSolution
        The solve of all of them (default method, with a 1σ).
    solve : callable
        The target's default solve of a subset of the features; a subset too small for it
        raises a CalibrationError (the check is then skipped, or the halves left out).
    folds : int
    flange_poses : callable, optional
        ``flange_poses(fold, held_out)``: the flange poses (K, 4, 4) a fold's solution gives
        the held-out features, when the solve also corrects the poses themselves (a joint
        kinematic calibration: forward kinematics with the fold's corrections). Default:
        the recorded ``T_base_flange`` of each feature.
    workers : int
        Processes for the subset solves (:func:`solve_subsets`).

    Returns
    -------
    SelfCheck or None
        None when there is no 1σ to check or the folds cannot be solved.
    """
    sigma_model = _sigma(solution)
    used = set(solution.samples_used)
    kept = [f for f in features if f.index in used]
    if sigma_model is None or len(kept) < 2 * folds:
        return None
    group = np.arange(len(kept)) % folds
    estimates, held_rms, offsets, poses, indices, levers = [], [], [], [], [], []
    tilts: list[float] = []
    squares, count = 0.0, 0
    solved = solve_subsets(kept, folds, solve, workers)
    for k in range(folds):
        fold = solved[k]
        if isinstance(fold, CalibrationError):
            return None
        estimates.append(hand_eye_difference(solution.T_flange_sensor, fold.T_flange_sensor))
        held = [f for f, g in zip(kept, group, strict=True) if g == k]
        T_held = (
            np.stack([f.T_base_flange for f in held])
            if flange_poses is None
            else flange_poses(fold, held)
        )
        for f, T_base_flange in zip(held, T_held, strict=True):
            fit: SampleFit = f.record()
            d = fold.section.surface_distances(fit, T_base_flange @ fold.T_flange_sensor)
            held_rms.append(float(np.sqrt(np.mean(d**2))))
            offsets.append(float(np.mean(d)))
            tilts.append(tilt(fit.points[:, 0], d))
            levers.append(float(np.median(np.linalg.norm(fit.points, axis=1))))
            poses.append(f.T_base_flange)
            indices.append(f.index)
            squares += float(np.sum(d**2))
            count += d.size
    theta = np.array(estimates)
    sigma_jk = np.sqrt((folds - 1) / folds * np.sum((theta - theta.mean(axis=0)) ** 2, axis=0))
    ratio = float(np.sqrt(np.mean((sigma_jk / sigma_model) ** 2)))
    correlation = neighbour_correlation(np.stack([offsets, tilts], axis=1), np.stack(poses))
    region = region_jackknife(solved[folds + 2 :], solution, sigma_model)
    sigma_region = None if region is None else region.sigma
    regions = 0 if region is None else region.regions
    region_ratio = None if region is None else region.ratio
    offset_rms = float(np.sqrt(np.mean(np.square(offsets))))
    lever = float(np.median(levers))
    systematic = correlation > neighbour_limit(len(offsets)) or (
        region_ratio is not None and region_ratio > region_limit(regions - 1)
    )
    sigma = (
        honest_sigma(sigma_model, sigma_region, regions, offset_rms, lever)
        if systematic
        else sigma_model.copy()
    )
    split = _halves(solved[folds], solved[folds + 1])
    halves = None
    if split is not None:
        difference, combined = split
        halves = difference / (combined * sigma / sigma_model)
        # Halves that disagree while neither statistic saw a systematic error mark it too,
        # but widen the 1σ by their excess only (below): the region 1σ and the shared-error
        # prior stand for an error those statistics saw. With independent noise the halves
        # cross the limit now and then, and the prior would widen the 1σ some 50 times.
        systematic = systematic or float(np.max(halves)) > HALVES_LIMIT_SIGMAS
        if float(np.max(halves)) > HALVES_LIMIT_SIGMAS:
            sigma = sigma * float(np.max(halves)) / HALVES_LIMIT_SIGMAS
    clusters = pose_clusters(np.stack([f.T_base_flange for f in kept]))
    check = SelfCheck(
        folds=folds,
        accuracy_in_use_m=float(np.sqrt(squares / max(count, 1))),
        held_out_rms_m=np.array(held_rms),
        indices=indices,
        sigma_jackknife=sigma_jk,
        sigma_model=sigma_model,
        dispersion_ratio=ratio,
        regions=regions,
        sigma_region=sigma_region,
        region_ratio=region_ratio,
        neighbour_correlation=correlation,
        offset_rms_m=offset_rms,
        lever_m=lever,
        halves_sigmas=halves,
        halves_model_sigmas=None if split is None else split[0] / split[1],
        pose_clusters=clusters,
        systematic=systematic,
        sigma_honest=sigma,
    )
    check.warnings = _warnings(check, solution)
    return check


def solve_subsets(
    kept: list[Any],
    folds: int,
    solve: Callable[[list[Any]], TargetSolution],
    workers: int = 1,
) -> list[TargetSolution | CalibrationError]:
    """The solves of the self-check, each a solution or the CalibrationError it raised: every
    fold's training features (all but every ``folds``-th from k, for each fold k), then the
    even and the odd features, then the features without each region of the workspace
    (:func:`region_subsets`, ``folds`` regions). They are independent; with ``workers`` 2 a
    forked child takes half of them (:func:`~linelaser_calib.core.forked.map_forked`; same
    outcomes as one process)."""
    group = np.arange(len(kept)) % folds
    subsets = [[f for f, g in zip(kept, group, strict=True) if g != k] for k in range(folds)]
    return map_forked(
        solve, [*subsets, kept[0::2], kept[1::2], *region_subsets(kept, folds)], workers
    )


def _halves(
    a: TargetSolution | CalibrationError, b: TargetSolution | CalibrationError
) -> tuple[FloatArray, FloatArray] | None:
    """|θ_even − θ_odd| (6,) and the halves' combined model 1σ √(σ_even² + σ_odd²) (6,) of the
    even (a) and odd (b) solves, or None when they could not be solved apart."""
    if isinstance(a, CalibrationError) or isinstance(b, CalibrationError):
        return None
    sigma_a, sigma_b = _sigma(a), _sigma(b)
    if sigma_a is None or sigma_b is None:
        return None
    difference = hand_eye_difference(a.T_flange_sensor, b.T_flange_sensor)
    return np.abs(difference), np.sqrt(sigma_a**2 + sigma_b**2)


def _warnings(check: SelfCheck, solution: TargetSolution) -> list[str]:
    """The self-check's warnings in plain words (mm, degrees)."""
    out = []
    if check.systematic:
        factor_t = float(np.max(check.sigma_honest[3:] / check.sigma_model[3:]))
        factor_r = float(np.max(check.sigma_honest[:3] / check.sigma_model[:3]))
        evidence = [f"the held-out profiles are off by {check.offset_rms_m * 1e3:.3f} mm RMS"]
        if check.neighbour_correlation > neighbour_limit(len(check.indices)):
            evidence.append(
                "neighbouring poses are off alike (correlation "
                f"{check.neighbour_correlation:.2f} of their held-out offsets)"
            )
        if check.region_ratio is not None and check.region_ratio > region_limit(check.regions - 1):
            evidence.append(
                f"the hand-eye moves {check.region_ratio:.1f} times more when one region of "
                "the workspace is left out than the noise model predicts"
            )
        if (
            check.halves_model_sigmas is not None
            and np.max(check.halves_model_sigmas) > HALVES_LIMIT_SIGMAS
        ):
            evidence.append(
                "the even and odd halves differ by up to "
                f"{float(np.max(check.halves_model_sigmas)):.1f} combined sigma of the noise "
                "model"
            )
        if check.halves_sigmas is not None and np.max(check.halves_sigmas) > HALVES_LIMIT_SIGMAS:
            evidence.append(
                "and by "
                f"{float(np.max(check.halves_sigmas)):.1f} combined sigma of the widened 1 sigma "
                "(widened further to cover them)"
            )
        out.append(
            "the robot's pose error looks systematic (pose-dependent, e.g. kinematic "
            "parameters that differ from the nominal ones), not independent per pose: "
            + ", ".join(evidence)
            + ". The per-pose corrections absorb part of that error and part of it goes into "
            "the hand-eye, so the hand-eye is off by about the robot's absolute error, not by "
            "its repeatability; the 1 sigma was widened "
            f"{factor_t:.1f}x (translation) and {factor_r:.1f}x (rotation) to "
            f"{', '.join(f'{v * 1e3:.3f}' for v in check.sigma_honest[3:])} mm and "
            f"{', '.join(f'{np.degrees(v):.4f}' for v in check.sigma_honest[:3])} deg. "
            f"Scans mapped with it will be off by about {check.accuracy_in_use_m * 1e3:.3f} mm "
            "RMS (cross-validated); flange poses from a kinematically calibrated robot model "
            "remove the systematic part"
        )
    if check.pose_clusters <= FEW_CLUSTERS:
        out.append(
            f"the {len(solution.samples_used)} poses fall into only {check.pose_clusters} "
            f"clusters (poses within {CLUSTER_RADIUS_M * 1e3:.0f} mm and "
            f"{np.degrees(CLUSTER_ANGLE_RAD):.0f} deg of each other): the result rests on "
            "a few independent views, and a robot error shared within a cluster counts once "
            "per cluster, not once per pose; add poses between the clusters"
        )
    return out
