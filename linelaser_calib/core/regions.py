"""Regions of the workspace, and the accuracy a user meets scanning elsewhere in the cell.

A real arm errs by region: poses near each other share most of their error (the kinematic
parameters that differ from the nominal ones act alike over a small part of the workspace).
A user calibrates once and scans parts elsewhere; the error met there is that of poses whose
neighbours the calibration never saw. Cross-validation that interleaves poses leaves a
neighbour of every held-out pose in the training set, which shares its error and hides it.

Regions
-------
The poses are grouped twice, by one pair of scales (:data:`CLUSTER_RADIUS_M`,
:data:`CLUSTER_ANGLE_RAD`):

- :func:`pose_clusters` counts the clusters of poses linked by small steps (how many
  independent views the recording holds);
- :func:`region_groups` splits the poses into a given number of regions by k-means on position
  and flange direction.

:func:`workspace_regions` takes as many regions as there are clusters, at most the
self-check's folds: k-means never splits one tight cluster into "regions" that share their
error. With fewer than :data:`MIN_REGIONS` there is no held-out region whose neighbours are
all out of the fit, and no accuracy in use is claimed.

Region-blocked cross-validation
-------------------------------
Each region is left out in turn; the rest are solved; the held-out region's profile points
are mapped into the base frame with their *recorded* flange poses (the robot's error at a new
pose is unknown to the user) and that solve's hand-eye, and their distances to that solve's
fitted target (:meth:`~linelaser_calib.core.targets.base.ResultSection.surface_distances`,
any target) are taken. That target is itself off at the held-out points (the user's part is
where it is, not where a fit puts it); how far it moves there when the region joins the fit
is added in quadrature. The RMS over all held-out points is the **accuracy in use**
(:class:`BlockedAccuracy`).

The model chosen by it
----------------------
Where the robot's error looks systematic (:mod:`.selfcheck`), two models are cross-validated
alike: the default one (per-pose robot error as nuisance with the stated prior σ_t, σ_r) and
a plain fit (the same solve with that prior
:data:`PLAIN_PRIOR_SCALE` times tighter, so that the poses are taken nearly as recorded).
:func:`choose_model` keeps the per-pose model unless the plain one's held-out mean square is
lower region by region beyond chance: a one-sided paired t-test on the regions' mean-square
differences at :data:`CHOICE_CONFIDENCE`.

All lengths in m and angles in rad; text in mm and degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import cdist
from scipy.special import stdtrit

from .errors import CalibrationError
from .geometry import FloatArray
from .targets.base import TargetSolution

#: Fewest regions for a region-blocked accuracy (and a region jackknife).
MIN_REGIONS = 3
#: One-sided confidence at which the plain model must beat the per-pose one on the held-out
#: regions to be chosen (:func:`choose_model`).
CHOICE_CONFIDENCE = 0.95
#: The plain fit's prior on the per-pose robot error, as a fraction of the stated one.
PLAIN_PRIOR_SCALE = 0.01
#: Name of the default model: the robot's per-pose error as nuisance with the stated prior.
PER_POSE = "per_pose"
#: Name of the plain model (:data:`PLAIN_PRIOR_SCALE`).
PLAIN = "plain"

#: ``flange_poses(solution, held)``: the flange poses (K, 4, 4) a solution gives held-out
#: features (a joint kinematic calibration's corrected forward kinematics).
FlangePoses = Callable[[TargetSolution, list[Any]], FloatArray]

#: Pose clusters: poses closer than this (m) ...
CLUSTER_RADIUS_M = 0.05
#: ... and this (rad) belong to one cluster.
CLUSTER_ANGLE_RAD = float(np.deg2rad(8.0))
#: A linked group of poses counts once per neighbourhood of this many times the limits above
#: that it takes to cover it (a continuous sweep is one linked group).
CLUSTER_SPAN = 2.0
#: Poses per block of the pairwise pose comparisons (:func:`pose_clusters`,
#: :func:`nearest_poses`): a block against every pose stays about a MB per array however long
#: the recording (an (M, M) array of 20,000 profiles' poses would be 3.2 GB; blocks of 256
#: made the self-check's neighbour test the run's peak on 1,600 profiles, 3 MB above the
#: subset solves).
DISTANCE_BLOCK = 64

#: Most Lloyd iterations of :func:`region_groups`.
LLOYD_ITERATIONS = 50


def _linked(
    T_a: FloatArray, T_b: FloatArray, radius_m: float, angle_rad: float
) -> NDArray[np.bool_]:
    """(A, B) whether poses (A, 4, 4) and (B, 4, 4) lie within ``radius_m`` of each other
    and their flange z axes within ``angle_rad``."""
    cosine = np.clip(T_a[:, :3, 2] @ T_b[:, :3, 2].T, -1.0, 1.0)
    near = cdist(T_a[:, :3, 3], T_b[:, :3, 3]) < radius_m
    return np.asarray(near & (cosine > np.cos(angle_rad)))


def _blocks(M: int) -> list[slice]:
    """Consecutive blocks of :data:`DISTANCE_BLOCK` poses out of M."""
    return [slice(start, min(start + DISTANCE_BLOCK, M)) for start in range(0, M, DISTANCE_BLOCK)]


def pose_clusters(T_base_flange: FloatArray) -> int:
    """Number of clusters of poses (M, 4, 4): groups linked by steps within
    :data:`CLUSTER_RADIUS_M` and :data:`CLUSTER_ANGLE_RAD` (single linkage), each counted once
    per neighbourhood of :data:`CLUSTER_SPAN` times those limits that it takes to cover it
    (greedily, around the first pose not yet covered).

    A tight group counts once however many poses it holds; a continuous sweep, which steps
    link into one group across the whole workspace, counts by its extent. The links are
    found a block of poses at a time (:data:`DISTANCE_BLOCK`): no (M, M) array."""
    T = T_base_flange
    M = len(T)
    first, second = [], []
    for rows in _blocks(M):
        i, j = np.nonzero(_linked(T[rows], T, CLUSTER_RADIUS_M, CLUSTER_ANGLE_RAD))
        i += rows.start
        first.append(i[j > i])
        second.append(j[j > i])
    i, j = np.concatenate(first), np.concatenate(second)
    links = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(M, M))
    _, label = connected_components(links, directed=False)
    radius, angle = CLUSTER_SPAN * CLUSTER_RADIUS_M, CLUSTER_SPAN * CLUSTER_ANGLE_RAD
    count = 0
    for group in np.unique(label):
        members = T[label == group]
        covered = np.zeros(len(members), dtype=bool)
        while not np.all(covered):
            centre = members[[int(np.argmin(covered))]]
            covered |= _linked(centre, members, radius, angle)[0]
            count += 1
    return count


def pose_distances(T_a: FloatArray, T_b: FloatArray) -> FloatArray:
    """(A, B) distances between poses (A, 4, 4) and (B, 4, 4): position step over
    :data:`CLUSTER_RADIUS_M` plus the angle between the flange z axes over
    :data:`CLUSTER_ANGLE_RAD`."""
    angle = np.arccos(np.clip(T_a[:, :3, 2] @ T_b[:, :3, 2].T, -1.0, 1.0))
    step = cdist(T_a[:, :3, 3], T_b[:, :3, 3])  # without the (A, B, 3) differences
    return np.asarray(step / CLUSTER_RADIUS_M + angle / CLUSTER_ANGLE_RAD)


def nearest_poses(T_base_flange: FloatArray, k: int) -> NDArray[np.intp]:
    """(M, k) indices of each pose's k nearest other poses (M, 4, 4) by
    :func:`pose_distances`, nearest first; a block of :data:`DISTANCE_BLOCK` poses at a time
    (no (M, M) array)."""
    M = len(T_base_flange)
    nearest = np.empty((M, k), dtype=np.intp)
    for rows in _blocks(M):
        D = pose_distances(T_base_flange[rows], T_base_flange)
        D[np.arange(rows.stop - rows.start), np.arange(rows.start, rows.stop)] = np.inf
        nearest[rows] = np.argsort(D, axis=1)[:, :k]
    return nearest


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


def workspace_regions(T_base_flange: FloatArray, most: int) -> tuple[NDArray[np.int64] | None, int]:
    """Region labels (M,) of the poses (M, 4, 4) and their number of clusters.

    As many regions (:func:`region_groups`) as :func:`pose_clusters` finds, at most ``most``;
    the labels are None when that is fewer than :data:`MIN_REGIONS`.
    """
    clusters = pose_clusters(T_base_flange)
    groups = min(most, clusters)
    if groups < MIN_REGIONS:
        return None, clusters
    return region_groups(T_base_flange, groups), clusters


def held_out_distances(
    solution: TargetSolution, held: Sequence[Any], flange_poses: FlangePoses | None = None
) -> list[FloatArray]:
    """Distances (K_j,) of each held-out feature's points from ``solution``'s fitted target,
    m, mapped with its hand-eye and the recorded flange poses (or ``flange_poses``)."""
    T_held = (
        np.stack([f.T_base_flange for f in held])
        if flange_poses is None
        else flange_poses(solution, list(held))
    )
    return [
        solution.section.surface_distances(f.record(), T_base_flange @ solution.T_flange_sensor)
        for f, T_base_flange in zip(held, T_held, strict=True)
    ]


@dataclass(frozen=True)
class BlockedAccuracy:
    """The region-blocked cross-validation of one model (:func:`blocked_accuracy`).

    Attributes
    ----------
    rms_m : float
        The accuracy in use, m: √(mean over the held-out points of d² + Δ²), d a point's
        distance from the target fitted without its region and Δ how far that target moves
        at the point when the region joins the fit.
    region_rms_m : ndarray, shape (G,)
        The same per region, m; NaN where the rest could not be solved.
    target_move_m : float
        RMS of Δ over the held-out points, m.
    """

    rms_m: float
    region_rms_m: FloatArray
    target_move_m: float

    @property
    def regions(self) -> int:
        """Regions held out and solved without."""
        return int(np.sum(np.isfinite(self.region_rms_m)))


def blocked_accuracy(
    solves: Sequence[TargetSolution | CalibrationError],
    held_sets: Sequence[Sequence[Any]],
    full: TargetSolution,
    flange_poses: FlangePoses | None = None,
) -> BlockedAccuracy | None:
    """The held-out RMS of each region (``held_sets[g]``) under the solve without it
    (``solves[g]``), and over all; None when fewer than :data:`MIN_REGIONS` were solved.

    A point's distance d from the target fitted without its region misses that target's own
    error there, which a user's scans meet as well (the true part is not the fitted one). Its
    estimate is Δ, how far the target moves at the point when the region joins the fit
    (``full``, the solve of all regions, against the one without); d² + Δ² is averaged.
    """
    squares = moves = 0.0
    count = 0
    region_rms = np.full(len(held_sets), np.nan)
    for g, (solve, held) in enumerate(zip(solves, held_sets, strict=True)):
        if isinstance(solve, CalibrationError):
            continue
        T_held = (
            np.stack([f.T_base_flange for f in held])
            if flange_poses is None
            else flange_poses(solve, list(held))
        )
        d, delta = [], []
        for f, T_base_flange in zip(held, T_held, strict=True):
            fit, T_base_sensor = f.record(), T_base_flange @ solve.T_flange_sensor
            d.append(solve.section.surface_distances(fit, T_base_sensor))
            delta.append(full.section.surface_distances(fit, T_base_sensor) - d[-1])
        d2 = np.concatenate(d) ** 2
        m2 = np.concatenate(delta) ** 2
        region_rms[g] = float(np.sqrt(np.mean(d2 + m2)))
        squares += float(np.sum(d2 + m2))
        moves += float(np.sum(m2))
        count += d2.size
    if int(np.sum(np.isfinite(region_rms))) < MIN_REGIONS:
        return None
    return BlockedAccuracy(
        rms_m=float(np.sqrt(squares / count)),
        region_rms_m=region_rms,
        target_move_m=float(np.sqrt(moves / count)),
    )


@dataclass(frozen=True)
class ModelChoice:
    """Which model the region-blocked accuracy chose (:func:`choose_model`).

    Attributes
    ----------
    chosen : str
        :data:`PER_POSE` or :data:`PLAIN`.
    accuracy_m : dict of str to float
        Each cross-validated model's accuracy in use (:attr:`BlockedAccuracy.rms_m`), m.
    """

    chosen: str
    accuracy_m: dict[str, float]


def choose_model(per_pose: BlockedAccuracy, plain: BlockedAccuracy | None) -> ModelChoice:
    """The per-pose model, unless the plain one's held-out mean square is lower beyond chance.

    With d_g the per-pose minus the plain mean square of region g (the regions both solved),
    the plain model is chosen when mean(d) exceeds the one-sided Student-t quantile at
    :data:`CHOICE_CONFIDENCE` (G − 1 degrees of freedom) times its standard error.
    """
    if plain is None:
        return ModelChoice(PER_POSE, {PER_POSE: per_pose.rms_m})
    accuracy = {PER_POSE: per_pose.rms_m, PLAIN: plain.rms_m}
    both = np.isfinite(per_pose.region_rms_m) & np.isfinite(plain.region_rms_m)
    d = per_pose.region_rms_m[both] ** 2 - plain.region_rms_m[both] ** 2
    if d.size < MIN_REGIONS:
        return ModelChoice(PER_POSE, accuracy)
    margin = stdtrit(d.size - 1, CHOICE_CONFIDENCE) * float(np.std(d, ddof=1)) / np.sqrt(d.size)
    return ModelChoice(PLAIN if float(np.mean(d)) > margin else PER_POSE, accuracy)
