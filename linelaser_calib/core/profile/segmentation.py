"""Segmentation of one laser profile into straight and curved pieces, and its noise level.

A real profile shows more than the target: a table, a background wall, fixtures. This
module cuts the scan line into pieces and says which are straight (the trace of a plane)
so that a target's fitter can look for its feature (a cylinder's elliptical arc, a
sphere's circle, a seam's V corner) among the rest, wherever it lies and however small its
share of the profile. Pure numpy.

Steps of :func:`segment_profile`, on points in scan-line order (sorted by ray angle,
:func:`~linelaser_calib.core.profile.cleaning.scan_order`):

1. **Noise.** :func:`estimate_noise` measures the sensor noise from the data: the
   distance of each point from the chord through its two neighbours is, on a smooth curve,
   noise plus a curvature term k s^2 / 2 (k curvature, s spacing) that is negligible at
   profiler spacings; for independent noise of sigma normal to the curve its spread is
   sqrt(3/2) sigma. sigma = 1.4826 * median(|distance|) / sqrt(3/2). When the depths are
   quantised (a camera's sub-pixel step, detected as a common step of the depth
   differences), the noise is at least step / sqrt(12), the spread of rounding.
2. **Gaps.** The scan line is split where consecutive points are farther apart than
   ``gap_spacings`` times the median spacing (and at least ``min_gap_m``): a depth jump
   from the target to the background, a shadow, missing returns.
3. **Straight pieces.** In each gap-free piece, RANSAC looks for the longest run of
   consecutive points within ``line_band_sigmas`` noise sigmas of a line (one stray point
   is bridged). A run at least ``min_line_length_m`` long with ``min_line_points`` points
   is a straight segment; it is set aside and the search goes on in what is left on either
   side (so a plane that runs into the target's arc with no gap, at a corner, is split off
   there). A curve of radius R stays within a band of half-width b of a line for a chord of
   only sqrt(8 R b): about 6 mm for R = 12.5 mm and b = 0.2 mm, 15 mm for R = 50 mm and
   b = 0.6 mm, below the default ``min_line_length_m`` of 20 mm, so the arcs of the targets
   this package calibrates are never mistaken for planes.
4. **Curved pieces.** What is left of each gap-free piece, in runs of at least
   ``min_segment_points`` points, are the candidates for the target's feature.

Each target's fitter picks its feature from the result: the cylinder fits an ellipse to
each curved segment (:mod:`~..targets.cylinder.arc`); a sphere's circle is found the
same way; a seam's V corner is where two adjacent straight segments meet (their line fits
are in the result). The noise estimate scales every target's inlier thresholds.

The RANSAC draws of step 3 come from a generator seeded by the number of points, so the
result is deterministic and does not consume the caller's random stream.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..types import FloatArray
from .cleaning import MAD_TO_SIGMA, profile_medians, scan_order

IntArray = NDArray[np.intp]

#: Spread of a point's distance to its neighbours' chord, in noise sigmas: sqrt(1 + 1/4 + 1/4).
CHORD_SPREAD = math.sqrt(1.5)
#: Smallest noise the thresholds use, m (noise-free simulations).
MIN_NOISE_M = 1e-6
#: Share of the depth differences that must be whole multiples of a step for the depths to
#: count as quantised, and the tolerance of "whole", in steps.
QUANTISED_SHARE, QUANTUM_TOLERANCE = 0.9, 0.05
#: Differences (in steps) up to which the quantisation test looks.
QUANTUM_MAX_STEPS = 50


class SegmentKind(str, Enum):
    """What a segment looks like."""

    LINE = "line"
    CURVE = "curve"


@dataclass(frozen=True)
class SegmentationConfig:
    """Profile segmentation parameters (SI units; see the module docstring).

    Attributes
    ----------
    gap_spacings : float
        A gap is wider than this many median point spacings ...
    min_gap_m : float
        ... and at least this, m.
    line_band_sigmas : float
        Half-width of a line's inlier band, in noise sigmas.
    min_line_length_m : float
        Shortest straight run set aside as a plane, m (end to end).
    min_line_points : int
        Fewest points of a straight run.
    min_segment_points : int
        Fewest points of a curved candidate segment.
    line_hypotheses : int
        RANSAC line hypotheses per search. A hypothesis joins two points a few line
        lengths apart in the scan order, so it lies on a plane as often as the plane's
        share of the piece: 48 miss a plane of 15 % share once in 2500 searches.
    max_lines : int
        Most straight segments taken out of one profile.
    """

    gap_spacings: float = 20.0
    min_gap_m: float = 2e-3
    line_band_sigmas: float = 4.0
    min_line_length_m: float = 0.02
    min_line_points: int = 20
    min_segment_points: int = 10
    line_hypotheses: int = 48
    max_lines: int = 8

    def __post_init__(self) -> None:
        if not (self.gap_spacings > 0.0 and self.min_gap_m > 0.0):
            raise ValueError("gap_spacings and min_gap_m must be > 0")
        if not (self.line_band_sigmas > 0.0 and self.min_line_length_m > 0.0):
            raise ValueError("line_band_sigmas and min_line_length_m must be > 0")
        if min(self.min_line_points, self.min_segment_points, self.line_hypotheses) < 2:
            raise ValueError("min_line_points, min_segment_points, line_hypotheses must be >= 2")
        if self.max_lines < 0:
            raise ValueError(f"max_lines must be >= 0, got {self.max_lines}")


@dataclass(frozen=True)
class NoiseEstimate:
    """The noise of one profile.

    Attributes
    ----------
    sigma_m : float
        Point noise normal to the surface, 1σ, m (at least ``MIN_NOISE_M``).
    depth_quantum_m : float
        Step of the depths, m; 0 when they are not quantised.
    """

    sigma_m: float
    depth_quantum_m: float


@dataclass(frozen=True)
class Segment:
    """A piece of the scan line.

    Attributes
    ----------
    indices : ndarray of int, shape (M,)
        Rows of the input points, in scan-line order.
    kind : SegmentKind
    line_point, line_direction : ndarray, shape (2,), or None
        For a line: a point (x, z) on it, m, and its unit direction.
    rms_m : float
        RMS distance of the points from the line (lines), NaN for curves, m.
    """

    indices: IntArray
    kind: SegmentKind
    line_point: FloatArray | None = None
    line_direction: FloatArray | None = None
    rms_m: float = math.nan


@dataclass(frozen=True)
class SegmentedProfile:
    """The result of :func:`segment_profile`.

    Attributes
    ----------
    segments : tuple of Segment
        In scan-line order.
    noise : NoiseEstimate
    """

    segments: tuple[Segment, ...]
    noise: NoiseEstimate

    def curves(self) -> list[Segment]:
        """The curved segments (candidates for a target's feature), most points first."""
        found = [s for s in self.segments if s.kind is SegmentKind.CURVE]
        return sorted(found, key=lambda s: -len(s.indices))

    def lines(self) -> list[Segment]:
        """The straight segments (planes), in scan-line order."""
        return [s for s in self.segments if s.kind is SegmentKind.LINE]


def _check_xz(points_xz: ArrayLike) -> FloatArray:
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
        raise InputError(f"profile points must be finite with shape (N, 2), got {p.shape}")
    return p


def depth_quanta(z: FloatArray, owner: IntArray, count: int) -> FloatArray:
    """The step of each profile's quantised depths, m, or 0 where they are not quantised,
    shape (count,), for ``count`` profiles' depths ``z`` (N,) stacked in turn (``owner``
    (N,) the profile of each).

    A profile's candidate step is the smallest non-zero difference between its sorted
    depths; they are quantised when ``QUANTISED_SHARE`` of the differences up to
    ``QUANTUM_MAX_STEPS`` steps are whole multiples of it.
    """
    order = np.lexsort((z, owner))
    diff, own = np.diff(z[order]), owner[order][1:]
    positive = (owner[order][:-1] == own) & (diff > 1e-12)
    step = np.full(count, math.inf)
    np.minimum.at(step, own[positive], diff[positive])
    small = positive & (diff <= QUANTUM_MAX_STEPS * step[own])
    multiples = diff[small] / step[own[small]]
    whole = np.abs(multiples - np.round(multiples)) <= QUANTUM_TOLERANCE
    tested = np.bincount(own[small], minlength=count)
    share = np.bincount(own[small], weights=whole, minlength=count) / np.maximum(tested, 1)
    enough = np.bincount(own[positive], minlength=count) >= 10
    return np.asarray(np.where(enough & (share >= QUANTISED_SHARE), step, 0.0), dtype=np.float64)


def estimate_noise(points_xz: ArrayLike) -> NoiseEstimate:
    """Robust point noise of a profile from its neighbour chords (see the module docstring).

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Points (x, z) in scan-line order, m; N >= 3.

    Returns
    -------
    NoiseEstimate
    """
    p = _check_xz(points_xz)
    return _noises(p, np.zeros(len(p), dtype=np.intp), 1)[0]


def _noises(p: FloatArray, owner: IntArray, count: int) -> list[NoiseEstimate]:
    """:func:`estimate_noise` of ``count`` profiles' points (N, 2) stacked in turn, each in
    scan-line order (``owner`` (N,) the profile of each)."""
    quantum = depth_quanta(p[:, 1], owner, count)
    floor = np.maximum(MIN_NOISE_M, quantum / math.sqrt(12.0))
    a, b, c = p[:-2], p[1:-1], p[2:]
    chord = c - a
    length = np.hypot(chord[:, 0], chord[:, 1])
    cross = chord[:, 0] * (b - a)[:, 1] - chord[:, 1] * (b - a)[:, 0]
    ok = (owner[:-2] == owner[2:]) & (length > 0.0)
    distance = np.abs(cross[ok]) / length[ok]
    sigma = MAD_TO_SIGMA * profile_medians(distance, owner[:-2][ok], count) / CHORD_SPREAD
    sigma = np.where(np.isnan(sigma), floor, np.maximum(sigma, floor))
    return [NoiseEstimate(s, q) for s, q in zip(sigma.tolist(), quantum.tolist(), strict=True)]


def _gap_cuts(p: FloatArray, owner: IntArray, count: int, config: SegmentationConfig) -> IntArray:
    """Where ``count`` profiles' points (N, 2) stacked in turn, each in scan-line order
    (``owner`` (N,) the profile of each), are split at gaps: the positions (in the stack)
    that start a piece after a gap, ascending."""
    step = np.hypot(*np.diff(p, axis=0).T)
    within = owner[1:] == owner[:-1]
    spacing = profile_medians(step[within], owner[1:][within], count)
    limit = np.maximum(config.min_gap_m, config.gap_spacings * spacing)
    return np.asarray(np.flatnonzero(within & (step > limit[owner[1:]])) + 1, dtype=np.intp)


def _longest_runs(mask: NDArray[np.bool_]) -> tuple[IntArray, IntArray]:
    """Start and end (exclusive) of the longest run of True in each row of (H, M), the
    first where runs tie (0, 0 for a row without True)."""
    h, m = mask.shape
    position = np.arange(1, m + 1)
    # The length of the run of True ending at each entry: its position less the last False's.
    last_false = np.maximum.accumulate(np.where(mask, 0, position), axis=1)
    length = position - last_false
    end = np.argmax(length, axis=1)
    longest = length[np.arange(h), end]
    end = np.where(longest > 0, end + 1, 0)
    return np.asarray(end - longest, dtype=np.intp), np.asarray(end, dtype=np.intp)


def _bridge(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Fill single False entries between two True ones along the last axis."""
    out = mask.copy()
    out[..., 1:-1] |= mask[..., :-2] & mask[..., 2:]
    return out


def _line_fit(p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Total least squares line through points (M, 2): centroid and unit direction."""
    centre = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - centre, full_matrices=False)
    return centre, vt[0]


def _line_axis(p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`_line_fit`'s line up to its direction's sign (the principal axis of the 2 x 2
    scatter in closed form, a tenth of an SVD's cost): for distances from it."""
    centre = p.mean(axis=0)
    q = p - centre
    sxx, sxz, szz = float(q[:, 0] @ q[:, 0]), float(q[:, 0] @ q[:, 1]), float(q[:, 1] @ q[:, 1])
    angle = 0.5 * math.atan2(2.0 * sxz, sxx - szz)
    return centre, np.array([math.cos(angle), math.sin(angle)])


def _line_distance(p: FloatArray, centre: FloatArray, direction: FloatArray) -> FloatArray:
    d = p - centre
    return np.asarray(np.abs(d[..., 0] * direction[1] - d[..., 1] * direction[0]))


def _find_line(
    p: FloatArray, band_m: float, config: SegmentationConfig, rng: np.random.Generator
) -> tuple[int, int, FloatArray, FloatArray] | None:
    """The longest straight run of consecutive points (start, end, centre, direction)."""
    m = len(p)
    if m < config.min_line_points:
        return None
    first = rng.integers(0, m, config.line_hypotheses)
    offset = rng.integers(config.min_line_points // 2, config.min_line_points * 4, len(first))
    second = np.clip(first + offset, 0, m - 1)
    good = second > first
    a, b = p[first[good]], p[second[good]]
    direction = b - a
    length = np.hypot(direction[:, 0], direction[:, 1])
    keep = length > 0.0
    a, direction = a[keep], direction[keep] / length[keep, None]
    if not len(a):
        return None
    normal = np.column_stack([direction[:, 1], -direction[:, 0]])
    distance = np.abs(normal @ p.T - np.sum(normal * a, axis=1)[:, None])
    start, end = _longest_runs(_bridge(distance <= band_m))
    best = int(np.argmax(end - start))
    lo, hi = int(start[best]), int(end[best])
    if hi - lo < config.min_line_points:
        return None
    for _ in range(3):  # refit on the run, grow or shrink the run around its middle
        centre, unit = _line_axis(p[lo:hi])
        inside = _bridge(_line_distance(p, centre, unit) <= band_m)
        middle = (lo + hi) // 2
        if not inside[middle]:
            break
        outside = np.flatnonzero(~inside)
        lo = int(outside[outside < middle].max()) + 1 if np.any(outside < middle) else 0
        hi = int(outside[outside > middle].min()) if np.any(outside > middle) else m
    span = float(np.hypot(*(p[hi - 1] - p[lo])))
    if hi - lo < config.min_line_points or span < config.min_line_length_m:
        return None
    centre, unit = _line_fit(p[lo:hi])
    return lo, hi, centre, unit


def segment_profile(
    points_xz: ArrayLike, config: SegmentationConfig | None = None
) -> SegmentedProfile:
    """Cut a profile into straight and curved segments and estimate its noise.

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Profile points (x, z) in the sensor frame, m, any order (they are put in scan
        order).
    config : SegmentationConfig, optional

    Returns
    -------
    SegmentedProfile
        Segment indices refer to rows of ``points_xz``.
    """
    (segmented,) = segment_profiles([points_xz], config)
    return segmented


def segment_profiles(
    profiles: Sequence[ArrayLike], config: SegmentationConfig | None = None
) -> list[SegmentedProfile]:
    """:func:`segment_profile` of each profile (N_i, 2), the same segments and noise: the
    scan order, the noise and the gaps of all of them at once, then each one's planes."""
    config = config or SegmentationConfig()
    arrays = [_check_xz(points_xz) for points_xz in profiles]
    sizes = [len(p) for p in arrays]
    owner = np.repeat(np.arange(len(arrays)), sizes)
    stacked = np.concatenate(arrays) if arrays else np.zeros((0, 2))
    order = scan_order(stacked, owner)  # the profiles stay in turn
    p = stacked[order]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.intp)
    noises = _noises(p, owner, len(arrays))
    cuts = _gap_cuts(p, owner, len(arrays), config)
    bounds = np.searchsorted(cuts, starts)
    return [
        _segments(p[lo:hi], order[lo:hi] - lo, noise, cuts[bounds[k] : bounds[k + 1]] - lo, config)
        for k, (lo, hi, noise) in enumerate(zip(starts[:-1], starts[1:], noises, strict=True))
    ]


def _segments(
    p: FloatArray, order: IntArray, noise: NoiseEstimate, cuts: IntArray, config: SegmentationConfig
) -> SegmentedProfile:
    """One profile's segments: its points ``p`` in scan-line order (their rows ``order``),
    its noise, the positions that start a piece after a gap."""
    band = config.line_band_sigmas * noise.sigma_m
    rng = np.random.default_rng(len(p))
    segments: list[tuple[int, Segment]] = []
    lines_left = config.max_lines
    stack = [piece for piece in np.split(np.arange(len(p)), cuts) if len(piece)]
    while stack:
        piece = stack.pop()
        found = _find_line(p[piece], band, config, rng) if lines_left > 0 else None
        if found is None:
            if len(piece) >= config.min_segment_points:
                segments.append((int(piece[0]), Segment(order[piece], SegmentKind.CURVE)))
            continue
        lo, hi, centre, unit = found
        lines_left -= 1
        run = piece[lo:hi]
        rms = float(np.sqrt(np.mean(_line_distance(p[run], centre, unit) ** 2)))
        segments.append((int(run[0]), Segment(order[run], SegmentKind.LINE, centre, unit, rms)))
        stack.extend(rest for rest in (piece[:lo], piece[hi:]) if len(rest))
    segments.sort(key=lambda item: item[0])
    return SegmentedProfile(tuple(s for _, s in segments), noise)
