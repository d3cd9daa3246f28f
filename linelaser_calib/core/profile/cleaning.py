"""Cleaning of one laser profile before the ellipse fit (cylinder paper §3.1, step 1).

The paper filters each profile statistically before its RANSAC ellipse fit. Here the
cleaning is, in order:

1. Drop invalid returns: NaN or +-Inf in any coordinate (REP 117).
2. Check that the points lie in the laser plane y = 0. A typical |y| above
   ``max_abs_y_m`` means the cloud is probably not in the sensor frame; this is reported
   (or the profile rejected, if so configured), never silently fixed.
3. Range gate: keep ``min_depth_m <= z <= max_depth_m`` and ``|x| <= max_abs_x_m``.
4. Sort the points in scan order (:func:`scan_order`: by ray angle, or by x when the
   frame's origin is not at the emitter) and split them into segments: points up to
   ``MAX_BRIDGED_POINTS + 1`` apart in this order are linked when they are at most
   ``max_gap_m`` apart in the x-z plane, so a few stray points do not split the arc.
   Segments of fewer than ``min_segment_points`` points are dropped: this removes isolated
   reflection spikes and small clusters, and separates the arc from a table or background
   behind it. Optionally only the largest segment is kept.
5. Spike filter, robust and independent of the shape (it works on the steep flanks of the
   arc as on its top). For each point, lines are drawn through pairs of its neighbours in
   the segment, ``spike_half_window`` on each side, taking only pairs that straddle the
   point (one neighbour before, one after), or at a segment's two ends the pairs of its
   nearest neighbours on the one side. The point's residual is the median of its
   perpendicular distances to those lines: near zero on any smooth curve (the curvature
   term is about k s^2 / 2 for spacing s and curvature k), large for a spike, and not
   disturbed by one spike among the neighbours (the median ignores the pairs that contain
   it; a good point next to a run of spikes may go). The noise scale is
   sigma = 1.4826 * median(residuals) over the profile; a point is a spike when its
   residual exceeds ``max(spike_factor * sigma, spike_floor_m)`` and also
   ``spike_spacing_factor`` times the local point spacing (sparse flank points have a
   larger curvature term and are kept unless clearly off the curve).

The RANSAC ellipse fit that follows removes whatever outliers remain (a table plane that
touches the arc, small spikes); cleaning only has to make its job easy and must never cut
into the arc.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.cluster.hierarchy import DisjointSet

from ..errors import InputError, ProfileRejected
from ..types import BoolArray, FloatArray

IntArray = NDArray[np.intp]

#: Consecutive stray points (spikes) that a segment bridges over, see :func:`segment_labels`.
MAX_BRIDGED_POINTS = 3
#: 1 / Phi^-1(3/4): turns a median absolute deviation into a Gaussian sigma.
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class CleaningConfig:
    """Profile cleaning parameters (SI units).

    Attributes
    ----------
    min_points : int
        Fewest points left after cleaning; fewer raise ProfileRejected.
    max_abs_y_m : float
        Largest typical |y| (90th percentile) of a cloud in the sensor frame, m. The laser
        plane is y = 0; drivers report y = 0 or within microns.
    reject_off_plane : bool
        Reject a profile whose |y| exceeds ``max_abs_y_m`` instead of only warning.
    min_depth_m, max_depth_m : float
        Range gate on the depth z, m. The defaults (-inf, inf) disable it.
    max_abs_x_m : float
        Largest |x| kept (half the line width), m. The default inf disables it.
    max_gap_m : float
        Distance between consecutive points (in scan order) that splits the scan line into
        segments, m. The default 2 mm is well above the point spacing of a profiler on a
        cylinder's steep flanks and below the size of a typical reflection spike or of the
        step from the arc to a table behind it. inf disables the split.
    min_segment_points : int
        Segments with fewer points are dropped (isolated spikes and clusters). Must be at
        least ``2 * spike_half_window + 1`` so that every spike window fits in a segment.
    keep_largest_segment : bool
        Keep only the segment with the most points (e.g. a cylinder before an empty
        background). Off by default: a table can hold more points than the arc.
    spike_half_window : int
        Neighbours on each side used by the spike filter; 0 disables the filter.
    spike_factor : float
        Residual, in robust sigmas of the whole profile, above which a point is a spike.
    spike_floor_m : float
        Smallest spike threshold, m, so that noise-free or very clean data (sigma ~ 0)
        does not turn the curvature term into spikes. 50 um suits profilers of 5-10 um
        noise; RANSAC's inlier threshold handles smaller deviations.
    spike_spacing_factor : float
        Where the points are sparse (the arc's steep flanks, spacing s), a point is a spike
        only if its residual also exceeds this times s: the residual of a smooth curve
        grows as k s^2, and the flank points carry the arc's coverage.
    """

    min_points: int = 30
    max_abs_y_m: float = 1e-3
    reject_off_plane: bool = False
    min_depth_m: float = -math.inf
    max_depth_m: float = math.inf
    max_abs_x_m: float = math.inf
    max_gap_m: float = 2e-3
    min_segment_points: int = 10
    keep_largest_segment: bool = False
    spike_half_window: int = 3
    spike_factor: float = 6.0
    spike_floor_m: float = 50e-6
    spike_spacing_factor: float = 0.5

    def __post_init__(self) -> None:
        if self.min_points < 1:
            raise ValueError(f"min_points must be >= 1, got {self.min_points}")
        if not self.max_abs_y_m > 0.0:
            raise ValueError(f"max_abs_y_m must be > 0 m, got {self.max_abs_y_m}")
        if not self.min_depth_m < self.max_depth_m:
            raise ValueError(
                f"need min_depth_m < max_depth_m, got {self.min_depth_m} and {self.max_depth_m}"
            )
        if not self.max_abs_x_m > 0.0 or not self.max_gap_m > 0.0:
            raise ValueError("max_abs_x_m and max_gap_m must be > 0 m (inf disables them)")
        if self.spike_half_window < 0:
            raise ValueError(f"spike_half_window must be >= 0, got {self.spike_half_window}")
        if self.min_segment_points < 2 * self.spike_half_window + 1:
            raise ValueError(
                f"min_segment_points ({self.min_segment_points}) must be at least "
                f"2 * spike_half_window + 1 = {2 * self.spike_half_window + 1}"
            )
        if not self.spike_factor > 0.0 or not self.spike_floor_m >= 0.0:
            raise ValueError("spike_factor must be > 0 and spike_floor_m >= 0 m")
        if not self.spike_spacing_factor >= 0.0:
            raise ValueError(f"spike_spacing_factor must be >= 0, got {self.spike_spacing_factor}")


@dataclass(frozen=True)
class CleanedProfile:
    """The result of :func:`clean_profile`.

    Attributes
    ----------
    points : ndarray, shape (M, 3)
        Kept points in the sensor frame, m, in input order (``input[mask]``).
    mask : ndarray of bool, shape (N,)
        Which input points were kept.
    counts : dict of str to int
        Points at each stage: ``input``, then removed as ``non_finite``, ``range_gate``,
        ``small_segment``, ``other_segment`` (by ``keep_largest_segment``) and ``spike``,
        and finally ``kept``.
    typical_abs_y_m : float
        90th percentile of |y| over the finite points, m (NaN if there are none).
    spike_threshold_m : float
        Residual above which points were called spikes where the points are dense, m (NaN
        if the filter did not run).
    warnings : tuple of str
        Things the user should know (e.g. the cloud does not look like the sensor frame).
    """

    points: FloatArray
    mask: BoolArray
    counts: dict[str, int] = field(default_factory=dict)
    typical_abs_y_m: float = math.nan
    spike_threshold_m: float = math.nan
    warnings: tuple[str, ...] = ()

    @property
    def points_xz(self) -> FloatArray:
        """Kept points in the laser plane, shape (M, 2): (x, z), m."""
        return np.asarray(self.points[:, [0, 2]], dtype=np.float64)


def scan_order(xz: ArrayLike, owner: IntArray | None = None) -> IntArray:
    """The scan-line order of a profile's points, shape (N,): indices that sort them.

    A profiler's columns are rays from its origin, so the points are sorted by their ray
    angle atan2(x, z) when every depth is positive (the sensor frame at the emitter, z the
    depth); sorting by x alone would interleave a near arc with a far background whose
    rays differ but whose x overlap. A frame whose origin is not at the emitter (some z
    <= 0) is sorted by x.

    ``owner`` (N,), the profile of each point where several profiles are stacked (points of
    one profile together, profiles numbered from 0 in order), orders each profile's points
    by its own rule and keeps the profiles in turn; None: one profile.
    """
    p = np.asarray(xz, dtype=np.float64)
    owner = np.zeros(len(p), dtype=np.intp) if owner is None else owner
    profiles = int(owner[-1]) + 1 if len(owner) else 0
    positive = np.bincount(owner, weights=p[:, 1] <= 0.0, minlength=profiles) == 0
    key = np.where(positive[owner], np.arctan2(p[:, 0], p[:, 1]), p[:, 0])
    return np.asarray(np.lexsort((key, owner)), dtype=np.intp)


def segment_labels(xz: ArrayLike, max_gap_m: float, owner: IntArray | None = None) -> IntArray:
    """Connected pieces of a scan line, bridging up to ``MAX_BRIDGED_POINTS`` stray points.

    Points i and i + k (k = 1 .. MAX_BRIDGED_POINTS + 1) of the scan order are linked when
    they are at most ``max_gap_m`` apart in the x-z plane; the pieces are the connected
    components. A spike between two arc points is its own piece and does not split the
    arc.

    Parameters
    ----------
    xz : array-like, shape (N, 2)
        Points in scan-line order (:func:`scan_order`), m.
    max_gap_m : float
    owner : ndarray of int, shape (N,), optional
        The profile of each point where several profiles are stacked (:func:`scan_order`):
        points of different profiles are never linked.

    Returns
    -------
    labels : ndarray of int, shape (N,)
        Piece of each point, numbered in order of first appearance.
    """
    p = np.asarray(xz, dtype=np.float64)
    n = len(p)
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    linked = [
        np.linalg.norm(p[k:] - p[:-k], axis=1) <= max_gap_m
        for k in range(1, MAX_BRIDGED_POINTS + 2)
    ]
    if owner is not None:
        linked = [near & (owner[k:] == owner[:-k]) for k, near in enumerate(linked, start=1)]
    # Runs of consecutive linked points are connected; the longer links join runs (a spike
    # is a run of its own, bridged over). A profile has few runs, so they are joined in
    # scipy's disjoint set rather than a sparse graph, whose set-up costs more than the
    # whole of the rest on a profile of a few hundred points.
    run = np.concatenate([[0], np.cumsum(~linked[0])])
    runs = DisjointSet(range(int(run[-1]) + 1))
    for k, near in enumerate(linked[1:], start=2):
        i = np.flatnonzero(near)
        a, b = run[i], run[i + k]
        across = a != b
        for x, y in zip(a[across].tolist(), b[across].tolist(), strict=True):
            runs.merge(x, y)
    # Components numbered in order of their first run's appearance.
    number: dict[int, int] = {}
    piece = [number.setdefault(runs[r], len(number)) for r in range(int(run[-1]) + 1)]
    return np.asarray(np.array(piece)[run], dtype=np.intp)


def _runs(labels: IntArray) -> IntArray:
    """Number the runs of equal consecutive labels (0, 0, 1, 1, 1, 2, ...)."""
    change = np.concatenate([[0], (np.diff(labels) != 0).astype(np.intp)])
    return np.asarray(np.cumsum(change), dtype=np.intp)


def spike_residuals(
    xz: ArrayLike, labels: ArrayLike, half_window: int
) -> tuple[FloatArray, FloatArray]:
    """Deviation of each point from its scan-line neighbours, and their spacing.

    Parameters
    ----------
    xz : array-like, shape (N, 2)
        Points in scan-line order (:func:`scan_order`), m.
    labels : array-like of int, shape (N,)
        Segment of each point, non-decreasing; every segment has at least
        ``2 * half_window + 1`` points.
    half_window : int
        Neighbours on each side (w). A point's window is itself and the 2w points nearest
        in the scan order within its segment (shifted inwards at the segment's ends).

    Returns
    -------
    residual : ndarray, shape (N,)
        Median perpendicular distance of the point to the lines through pairs of its
        neighbours, m. Only pairs straddling the point are used, except for a segment's
        first and last point, which use the pairs among their w + 1 nearest neighbours. A
        pair of coincident neighbours counts as the distance to that neighbour.
    spacing : ndarray, shape (N,)
        Smallest distance between consecutive points of the window, m (a spike only
        lengthens the gaps next to it).
    """
    p = np.asarray(xz, dtype=np.float64)
    seg = np.asarray(labels, dtype=np.intp)
    n, w = len(p), half_window
    index = np.arange(n)
    starts = np.searchsorted(seg, seg, side="left")
    ends = np.searchsorted(seg, seg, side="right") - 1
    low = np.clip(index - w, starts, ends - 2 * w)
    x, z = p[:, 0], p[:, 1]
    step = np.hypot(np.diff(x), np.diff(z))
    spacing = np.min(step[low[:, None] + np.arange(2 * w)], axis=1)
    residual = np.empty(n)
    # A point with w neighbours on each side (most of them) uses the w * w pairs that
    # straddle it; the others (near a segment's ends) are treated in general.
    centred = low == index - w
    rows = np.flatnonzero(centred)
    before, after, first, second = _window_pairs(w)
    a, b = rows[:, None] + before, rows[:, None] + after
    residual[rows] = _nanmedian_rows(_pair_distances(x, z, rows, a, b))
    rows = np.flatnonzero(~centred)
    window = low[rows, None] + np.arange(2 * w + 1)
    neighbours = window[window != rows[:, None]].reshape(len(rows), 2 * w)
    distance = _pair_distances(x, z, rows, neighbours[:, first], neighbours[:, second])
    later = neighbours > rows[:, None]
    straddles = later[:, first] != later[:, second]
    # A segment's end point has neighbours on one side only: it uses the pairs among its
    # w + 1 nearest, whose extrapolated curvature term stays close to that of the others.
    near = np.abs(neighbours - rows[:, None]) <= w + 1
    end = ((rows == starts[rows]) | (rows == ends[rows]))[:, None]
    at_end = end & near[:, first] & near[:, second]
    residual[rows] = _nanmedian_rows(np.where(straddles | at_end, distance, np.nan))
    return residual, np.asarray(spacing, dtype=np.float64)


@functools.cache
def _window_pairs(w: int) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """The pairs of a spike window of half-width ``w`` (:func:`spike_residuals`), formed once
    per width: the offsets from the point of each straddling pair's two points (w * w,
    before and after it), and every pair of the 2w neighbours (their positions, first and
    second, ``np.triu_indices``)."""
    before = np.repeat(np.arange(-w, 0), w)
    after = np.tile(np.arange(1, w + 1), w)
    first, second = np.triu_indices(2 * w, k=1)
    return before, after, first, second


def _pair_distances(
    x: FloatArray, z: FloatArray, rows: IntArray, a: IntArray, b: IntArray
) -> FloatArray:
    """Distance of each point ``rows`` (R,) from the lines through its pairs of points
    ``a``, ``b`` (R, K) (the distance to ``a`` where the pair coincides), shape (R, K)."""
    dx, dz = x[b] - x[a], z[b] - z[a]  # direction of the line through the pair
    ox, oz = x[rows, None] - x[a], z[rows, None] - z[a]  # the point relative to its first point
    length = np.hypot(dx, dz)
    cross = np.abs(dx * oz - dz * ox)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.where(length > 0.0, cross / length, np.hypot(ox, oz)))


def _nanmedian_rows(values: FloatArray) -> FloatArray:
    """Median of each row's non-NaN entries, shape (N,) from (N, K); NaN for an all-NaN row.

    ``np.nanmedian`` on many short rows goes through masked arrays and costs ~10x more.
    """
    ordered = np.sort(values, axis=1)  # NaN sorts last
    count = np.sum(~np.isnan(values), axis=1)
    rows = np.arange(len(values))
    low = ordered[rows, np.maximum(count - 1, 0) // 2]
    high = ordered[rows, count // 2 - (count == 0)]
    return np.asarray(np.where(count > 0, 0.5 * (low + high), np.nan), dtype=np.float64)


def clean_profile(points: ArrayLike, config: CleaningConfig) -> CleanedProfile:
    """Clean one profile: invalid points, range gate, segments, spikes (see module doc).

    Parameters
    ----------
    points : array-like, shape (N, 3)
        Profile points in the sensor frame, m; may hold NaN/Inf.
    config : CleaningConfig

    Returns
    -------
    CleanedProfile

    Raises
    ------
    InputError
        ``points`` is not an (N, 3) array.
    ProfileRejected
        Fewer than ``config.min_points`` points remain, or (with ``reject_off_plane``) the
        points are not in the laser plane. The message gives the counts per stage.
    """
    (cleaned,) = clean_profiles([points], config)
    if isinstance(cleaned, ProfileRejected):
        raise cleaned
    return cleaned


#: The stages of :attr:`CleanedProfile.counts` that remove points, in order.
REMOVED = ("non_finite", "range_gate", "small_segment", "other_segment", "spike")


def clean_profiles(
    profiles: Sequence[ArrayLike], config: CleaningConfig
) -> list[CleanedProfile | ProfileRejected]:
    """Clean several profiles at once, each as :func:`clean_profile` would (the same
    points, counts and thresholds): their points are stacked, each stage runs once over
    the stack, and no stage links points of different profiles.

    Parameters
    ----------
    profiles : sequence of array-like, shape (N_i, 3) each
        Profile points in the sensor frame, m; may hold NaN/Inf.
    config : CleaningConfig

    Returns
    -------
    list of CleanedProfile or ProfileRejected
        One per profile, in order: its cleaned points, or the rejection
        :func:`clean_profile` raises.

    Raises
    ------
    InputError
        A profile is not an (N, 3) array.
    """
    arrays = [np.asarray(points, dtype=np.float64) for points in profiles]
    for p in arrays:
        if p.ndim != 2 or p.shape[1] != 3:
            raise InputError(f"profile points must have shape (N, 3), got {p.shape}")
    sizes = [len(p) for p in arrays]
    count = len(arrays)
    p = np.concatenate(arrays) if arrays else np.zeros((0, 3))
    owner = np.repeat(np.arange(count), sizes)

    def per_profile(rows: IntArray) -> IntArray:
        return np.bincount(owner[rows], minlength=count)

    keep = np.all(np.isfinite(p), axis=1)
    gate = keep & (p[:, 2] >= config.min_depth_m) & (p[:, 2] <= config.max_depth_m)
    gate &= np.abs(p[:, 0]) <= config.max_abs_x_m
    idx = np.flatnonzero(gate)
    idx = idx[scan_order(p[idx][:, [0, 2]], owner[idx])]
    labels = segment_labels(p[idx][:, [0, 2]], config.max_gap_m, owner[idx])
    gated = per_profile(idx)
    big = np.bincount(labels, minlength=1)[labels] >= config.min_segment_points
    # Without the stray pieces, each segment is a run of the scan line; a run can still be
    # short where two large pieces interleave.
    runs = _runs(labels[big])
    long_run = np.bincount(runs, minlength=1)[runs] >= config.min_segment_points
    big[big] = long_run
    labels = runs[long_run]
    idx = idx[big]
    segmented = per_profile(idx)
    if config.keep_largest_segment and len(idx):
        # Each profile's segment with the most points (the first of equals).
        sizes_of = np.bincount(labels)
        profile_of = np.zeros(len(sizes_of), dtype=np.intp)
        profile_of[labels] = owner[idx]
        order = np.lexsort((-sizes_of, profile_of))
        firsts = order[np.unique(profile_of[order], return_index=True)[1]]
        largest = np.isin(labels, firsts)
        idx, labels = idx[largest], labels[largest]
    largest_kept = per_profile(idx)

    threshold = np.full(count, math.nan)
    if config.spike_half_window > 0 and len(idx):
        residual, spacing = spike_residuals(p[idx][:, [0, 2]], labels, config.spike_half_window)
        sigma = MAD_TO_SIGMA * profile_medians(residual, owner[idx], count)
        threshold = np.maximum(config.spike_factor * sigma, config.spike_floor_m)
        limit = np.maximum(threshold[owner[idx]], config.spike_spacing_factor * spacing)
        idx = idx[residual <= limit]
    mask = np.zeros(len(p), dtype=np.bool_)
    mask[idx] = True
    kept, finite = per_profile(idx), per_profile(np.flatnonzero(keep))
    stages = np.stack(
        [
            sizes - finite,
            finite - gated,
            gated - segmented,
            segmented - largest_kept,
            largest_kept - kept,
        ],
        axis=1,
    ).tolist()
    splits = np.cumsum(sizes)[:-1]
    return [
        _cleaned(
            arrays[k], finite, m, dict(zip(REMOVED, stages[k], strict=True)), threshold[k], config
        )
        for k, (finite, m) in enumerate(
            zip(np.split(keep, splits), np.split(mask, splits), strict=True)
        )
    ]


def profile_medians(values: FloatArray, owner: IntArray, count: int) -> FloatArray:
    """The median of each of ``count`` profiles' values (N,) stacked in turn (``owner`` (N,)
    the profile of each, non-decreasing), shape (count,); NaN for a profile without values:
    :func:`_nanmedian_rows` of the profiles padded with NaN, equal to ``np.median``."""
    sizes = np.bincount(owner, minlength=count)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    padded = np.full((count, max(1, int(sizes.max(initial=0)))), math.nan)
    padded[owner, np.arange(len(values)) - starts[owner]] = values
    return _nanmedian_rows(padded)


def _cleaned(
    p: FloatArray,
    finite: BoolArray,
    mask: BoolArray,
    removed: dict[str, int],
    spike_threshold_m: float,
    config: CleaningConfig,
) -> CleanedProfile | ProfileRejected:
    """One profile's :class:`CleanedProfile` (its points ``p``, the ``finite`` ones, the kept
    ones ``mask``, the points each stage ``removed``), or its rejection."""
    y = p[finite, 1]
    typical_abs_y = float(np.percentile(np.abs(y), 90)) if len(y) else math.nan
    warnings: list[str] = []
    if typical_abs_y > config.max_abs_y_m:
        message = (
            f"90% of the points have |y| up to {typical_abs_y * 1e3:.2f} mm, above the "
            f"{config.max_abs_y_m * 1e3:.2f} mm expected of the laser plane y = 0: the cloud "
            "may not be in the sensor frame (check the frame_id and the driver's output frame)"
        )
        if config.reject_off_plane:
            return ProfileRejected(message)
        warnings.append(message)
    counts = {"input": len(p), **removed, "kept": int(mask.sum())}
    if counts["kept"] < config.min_points:
        text = ", ".join(f"{counts[k]} {k.replace('_', ' ')}" for k in REMOVED if counts[k])
        return ProfileRejected(
            f"only {counts['kept']} of {counts['input']} points are left after cleaning "
            f"(removed: {text or 'none'}), at least {config.min_points} are needed; "
            "check that the laser line hits the cylinder and the range gate "
            f"(z {config.min_depth_m:g} to {config.max_depth_m:g} m, "
            f"|x| <= {config.max_abs_x_m:g} m)"
        )
    return CleanedProfile(
        points=p[mask],
        mask=mask,
        counts=counts,
        typical_abs_y_m=typical_abs_y,
        spike_threshold_m=spike_threshold_m,
        warnings=tuple(warnings),
    )
