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
    profile leaves the fit. It needs nothing of the noise model, so an error the model does
    not describe (a systematic robot error that per-pose corrections absorb) shows in it. A
    jackknife was chosen over a sandwich estimator because the robust point weights and the
    rejection loop make the scores of the refit differ from those of a linearisation.
Disjoint halves:
    Even and odd samples solved apart; their hand-eye difference in units of the combined
    1σ (√(σ_a² + σ_b²) per axis, each half's own σ).

Systematic robot error
----------------------
Per-pose corrections absorb any robot error, so the fit's residual cannot tell an arm with
independent per-pose noise from one whose error is systematic (pose-dependent: kinematic
parameters that differ from the nominal ones). The held-out samples can: each held-out
profile's mean signed offset from the fitted target is the robot's error at that pose as the
target sees it, and its tilt across the profile (the change of the distances from one end to
the other) shows the rotation part. With independent errors the offsets and tilts of
neighbouring poses (the 3 nearest in position and flange direction) are uncorrelated; with a
systematic error neighbours are off alike. A correlation above :func:`neighbour_limit` (in
either) marks the error as systematic: over 20 seeds of bench/robot_error.py the
independent-noise presets gave -0.45 to 0.37 (one paper seed of 20 crossed), kinematic-error
recordings 0.25 to 0.94 (18 of 20 crossed).

A systematic error common to the poses is not averaged away by more poses: its part that the
hand-eye absorbs is of the order of the held-out offsets, so the 1σ is widened to at least
:data:`SYSTEMATIC_FLOOR` times their RMS (translation) and that over the lever of the profile
points (rotation), to the jackknife 1σ if larger, and further by the halves' excess when they
disagree beyond :data:`HALVES_LIMIT_SIGMAS`. The same widening applies when the jackknife 1σ
exceeds the model's by :data:`SYSTEMATIC_RATIO` or the halves disagree. A warning says so in
words.

All lengths in m and angles in rad; text in mm and degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import CalibrationError
from .forked import map_forked
from .geometry import FloatArray, rotvec_from_matrix
from .targets.base import TargetSolution
from .types import SampleFit

#: Folds of the cross-validation.
DEFAULT_FOLDS = 5
#: Dispersion ratio (jackknife σ over model σ, RMS over the axes) above which the robot's
#: error is taken as systematic. Independent-noise recordings stay below (bench/robot_error.py).
SYSTEMATIC_RATIO = 2.5
#: Nearest poses whose mean held-out offset a sample's is correlated with.
NEIGHBOURS = 3
#: Neighbour correlation of the held-out offsets above which the robot's error is systematic.
NEIGHBOUR_LIMIT = 0.3
#: Multiple of the held-out offsets' RMS the 1σ is widened to when the error is systematic
#: (the hand-eye error reached up to 2 times it over the 20 seeds of bench/robot_error.py).
SYSTEMATIC_FLOOR = 2.0
#: Halves that differ by more than this many combined σ on an axis disagree.
HALVES_LIMIT_SIGMAS = 3.0
#: Pose clusters: poses closer than this (m) ...
CLUSTER_RADIUS_M = 0.05
#: ... and this (rad) belong to one cluster.
CLUSTER_ANGLE_RAD = float(np.deg2rad(8.0))
#: Warn when the poses fall into at most this many clusters.
FEW_CLUSTERS = 6


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
        Grouped jackknife 1σ of the hand-eye: rotation (rad, sensor axes), translation (m,
        flange axes).
    sigma_model : ndarray, shape (6,)
        The solution's own 1σ, same order.
    dispersion_ratio : float
        √(mean (σ_jackknife / σ_model)²).
    neighbour_correlation : float
        Correlation of the held-out offsets of neighbouring poses (:func:`neighbour_correlation`).
    offset_rms_m : float
        RMS of the held-out samples' mean signed offsets, m.
    lever_m : float
        Median distance of the held-out points from the sensor origin, m.
    halves_sigmas : ndarray, shape (6,) or None
        |θ_even − θ_odd| / √(σ_even² + σ_odd²) per axis, None when the halves could not be
        solved apart.
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
    neighbour_correlation: float
    offset_rms_m: float
    lever_m: float
    halves_sigmas: FloatArray | None
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
                "jackknife_sigma": {
                    "rotation_rad": [float(v) for v in self.sigma_jackknife[:3]],
                    "translation_m": [float(v) for v in self.sigma_jackknife[3:]],
                },
                "model_sigma": {
                    "rotation_rad": [float(v) for v in self.sigma_model[:3]],
                    "translation_m": [float(v) for v in self.sigma_model[3:]],
                },
                "dispersion_ratio": float(self.dispersion_ratio),
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
    """Number of groups of poses (M, 4, 4) linked by steps within :data:`CLUSTER_RADIUS_M`
    and :data:`CLUSTER_ANGLE_RAD` (single linkage)."""
    M = len(T_base_flange)
    t = T_base_flange[:, :3, 3]
    z = T_base_flange[:, :3, 2]
    near = (np.linalg.norm(t[:, None] - t[None], axis=2) < CLUSTER_RADIUS_M) & (
        np.clip(z @ z.T, -1.0, 1.0) > np.cos(CLUSTER_ANGLE_RAD)
    )
    label = np.arange(M)
    changed = True
    while changed:
        merged = np.array([label[near[i]].min() for i in range(M)])
        changed = bool(np.any(merged != label))
        label = merged[merged]
    return len(np.unique(label))


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
    halves = _halves(solved[folds], solved[folds + 1])
    T_poses = np.stack([f.T_base_flange for f in kept])
    clusters = pose_clusters(T_poses)
    disagree = halves is not None and float(np.max(halves)) > HALVES_LIMIT_SIGMAS
    systematic = correlation > neighbour_limit(len(offsets)) or ratio > SYSTEMATIC_RATIO or disagree
    offset_rms = float(np.sqrt(np.mean(np.square(offsets))))
    lever = float(np.median(levers))
    sigma = sigma_model.copy()
    if systematic:
        floor = SYSTEMATIC_FLOOR * offset_rms * np.array([1.0 / lever] * 3 + [1.0] * 3)
        sigma = np.maximum.reduce([sigma_model, sigma_jk, floor])
        if halves is not None and disagree:
            sigma = sigma * float(np.max(halves)) / HALVES_LIMIT_SIGMAS
    check = SelfCheck(
        folds=folds,
        accuracy_in_use_m=float(np.sqrt(squares / max(count, 1))),
        held_out_rms_m=np.array(held_rms),
        indices=indices,
        sigma_jackknife=sigma_jk,
        sigma_model=sigma_model,
        dispersion_ratio=ratio,
        neighbour_correlation=correlation,
        offset_rms_m=offset_rms,
        lever_m=lever,
        halves_sigmas=halves,
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
    even and the odd features. They are independent; with ``workers`` 2 a forked child takes
    half of them (:func:`~linelaser_calib.core.forked.map_forked`; same outcomes as one
    process)."""
    group = np.arange(len(kept)) % folds
    subsets = [[f for f, g in zip(kept, group, strict=True) if g != k] for k in range(folds)]
    return map_forked(solve, [*subsets, kept[0::2], kept[1::2]], workers)


def _halves(
    a: TargetSolution | CalibrationError, b: TargetSolution | CalibrationError
) -> FloatArray | None:
    """|θ_even − θ_odd| / combined 1σ per axis (6,) of the even (a) and odd (b) solves, or
    None."""
    if isinstance(a, CalibrationError) or isinstance(b, CalibrationError):
        return None
    sigma_a, sigma_b = _sigma(a), _sigma(b)
    if sigma_a is None or sigma_b is None:
        return None
    difference = hand_eye_difference(a.T_flange_sensor, b.T_flange_sensor)
    return np.asarray(np.abs(difference) / np.sqrt(sigma_a**2 + sigma_b**2))


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
        if check.dispersion_ratio > SYSTEMATIC_RATIO:
            evidence.append(
                f"the hand-eye moves {check.dispersion_ratio:.1f} times more between subsets "
                "of the poses than the noise model predicts"
            )
        if check.halves_sigmas is not None and np.max(check.halves_sigmas) > HALVES_LIMIT_SIGMAS:
            evidence.append(
                "the even and odd halves differ by up to "
                f"{float(np.max(check.halves_sigmas)):.1f} combined sigma"
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
