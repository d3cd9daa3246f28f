"""The corner of a V-shaped profile: a weld seam seen by the laser line (weld-seam paper §2.3).

The laser plane cuts a V-groove or fillet joint (two planes meeting along the seam) in two
straight segments; the seam point is where their lines meet. :func:`fit_corner` finds it in the
sensor x-z plane:

1. RANSAC line (MSAC score, a batch of two-point hypotheses at once) on all points: the
   larger flank. Then the same on the points it left: the other flank.
2. Refinement: each line is refitted by total least squares on its inliers, every point is
   re-assigned to the nearer line if it lies within a threshold that shrinks towards a few
   sigma of the measured line noise, and this repeats until the assignment settles.
3. The corner is the intersection of the two lines; its covariance follows from the line
   fits (each line's offset and angle errors, first order), see :func:`_corner_covariance`.

A profile without a clear V raises :class:`~linelaser_calib.core.errors.ProfileRejected`
saying which test failed: too few points; no second line; the lines nearly parallel (a flat
profile); the lines meeting far from their points; or a line lying on both sides of the
corner (not a V, e.g. a step or a cross).

Whether a profile is a V at all is not judged by its lines' residual against the point
noise (a real profiler leaves tens of µm of smooth shape error on a flank over a few µm of
local noise):

- per profile (:func:`extract_corner_sample`), the two lines meet rival shapes fitted to the
  same points, a line (a plane) and an arc (a cylinder or sphere), by the information
  criterion (:mod:`.corner_shape`); a profile without a corner that a rival fits clearly
  better is rejected naming it, and one with a corner keeps the comparison;
- per recording (:func:`check_corner_recording`), a profile whose lines leave far more than
  the recording's other profiles is set aside, with the recording's scale; so is a profile
  that a rival fits clearly better by a margin far above the recording's other profiles'
  (a real profiler's shape error lets an arc beat a V on many a single profile, so the
  margin is judged against the recording's own). No profile decides the target: where
  most profiles fit a rival better (the targets' ``model_doubt``) or too few show a corner,
  the whole recording's full models do (:mod:`linelaser_calib.core.targets.rivals`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ProfileRejected
from ..model_check import Comparison, recording_outliers, recording_scale, shape_doubt
from ..types import BoolArray, FloatArray, Rejection, Sample, SampleFit
from .cleaning import MAD_TO_SIGMA, CleaningConfig, clean_profile
from .corner_shape import (
    NOT_A_V,
    compare_corner,
    compare_without_corner,
    corner_rival_rejection,
)

#: Rounds of "refit, re-assign" after RANSAC.
MAX_REFIT_ROUNDS = 10
#: Smallest noise-adapted inlier threshold, m.
MIN_NOISE_THRESHOLD_M = 1e-6
#: Smallest tolerance of a corner's opening about the recording's median, rad: the laser
#: plane's tilt against the seam changes the flanks' angle in the profile by tens of degrees.
MIN_OPENING_SPREAD_RAD = math.radians(30.0)
#: Fewest cleaned points of a profile without a corner that are weighed against the rivals
#: (a line pair needs 8).
MIN_RIVAL_POINTS = 8


class FlatProfile(ProfileRejected):
    """A profile whose two lines are one: no second line, or the lines nearly parallel."""


@dataclass(frozen=True)
class CornerConfig:
    """Two-line corner fit parameters (SI units).

    Attributes
    ----------
    inlier_threshold_m : float
        Largest distance of a RANSAC inlier from its line, m. Default 0.1 mm: 10-20 σ of a
        5-10 µm profiler, far below a flank's extent.
    noise_threshold_sigmas : float
        After RANSAC the threshold shrinks to this many times each line's measured RMS noise
        (never above ``inlier_threshold_m``). Default 4.
    hypotheses : int
        RANSAC hypotheses per line. Default 300: with a flank holding 30 % of the points, a
        clean pair is drawn with probability 1 − (1 − 0.09)^300 > 0.999999.
    min_line_points : int
        Fewest inliers of each line. Default 10.
    min_flank_length_m : float
        Shortest extent of a flank's inliers along its line, m. Default 1 mm.
    max_flank_sigma_m : float
        A flank is usable when its line fit pins the line at the corner to this 1σ, m
        (from the line's points, their extent and its residual: ``_flank_sigma``), however
        few its points are next to the other flank's. Default 30 µm: the robot's error.
    max_lines : int
        Most straight lines looked for in one profile (two flanks and, beside them, a
        floor or a wall; a long flank bent by the profiler's shape error may take two).
        Default 4.
    min_bend_rad : float
        Smallest angle between the two lines, rad: below it the profile is flat, not a V.
        Default 10 deg.
    max_corner_gap_m : float
        Largest distance from the corner to the nearest inlier of each line, m: the lines
        must meet near their points, not far outside them (a gap at the corner is fine as
        long as each flank still pins its line there, ``max_flank_sigma_m``). Default 10 mm.
    max_wrong_side_fraction : float
        Largest share of a line's inliers lying on the far side of the corner (beyond a
        noise margin): a V has each flank on one side. Default 0.05.
    profile_outlier_sigmas : float
        A profile whose lines leave an RMS residual this many robust spreads above the
        median of the recording's profiles is set aside (:func:`check_corner_recording`).
        Default 6.
    """

    inlier_threshold_m: float = 1e-4
    noise_threshold_sigmas: float = 4.0
    hypotheses: int = 300
    min_line_points: int = 10
    min_flank_length_m: float = 1e-3
    max_flank_sigma_m: float = 3e-5
    max_lines: int = 4
    min_bend_rad: float = math.radians(10.0)
    max_corner_gap_m: float = 1e-2
    max_wrong_side_fraction: float = 0.05
    profile_outlier_sigmas: float = 6.0

    def __post_init__(self) -> None:
        for name in (
            "inlier_threshold_m",
            "noise_threshold_sigmas",
            "max_corner_gap_m",
            "profile_outlier_sigmas",
            "min_flank_length_m",
            "max_flank_sigma_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"CornerConfig.{name} must be positive and finite, got {value}")
        if self.hypotheses < 1 or self.min_line_points < 2 or self.max_lines < 2:
            raise InputError(
                "CornerConfig.hypotheses must be >= 1, min_line_points >= 2 and max_lines >= 2"
            )
        if not 0.0 < self.min_bend_rad < math.pi / 2:
            raise InputError("CornerConfig.min_bend_rad must be in (0, pi/2) rad")
        if not 0.0 <= self.max_wrong_side_fraction < 0.5:
            raise InputError("CornerConfig.max_wrong_side_fraction must be in [0, 0.5)")


@dataclass(frozen=True)
class CornerFit:
    """The corner of a V profile in the sensor x-z plane.

    Attributes
    ----------
    corner_xz : ndarray, shape (2,)
        Intersection (x, z) of the two lines, m.
    covariance_xz : ndarray, shape (2, 2)
        Its first-order covariance from the line fits, m².
    normals : ndarray, shape (2, 2)
        Unit normal (n_x, n_z) of each line; line k is ``normals[k] · q = offsets[k]``.
    offsets : ndarray, shape (2,)
        m.
    inliers : ndarray of bool, shape (2, N)
        Points of each line (disjoint).
    bend_rad : float
        Angle between the two lines, rad (0: parallel; π/2: perpendicular).
    rms_m : ndarray, shape (2,)
        RMS distance of each line's inliers from it, m.
    opening_rad : float
        Angle between the flanks, from the corner along their points, rad: positive for a
        ridge (the flanks run away from the sensor), negative for a groove.
    alternatives : tuple of CornerFit
        The corners of other pairs of lines in the profile that make a usable V (a floor or
        wall beside a flank), most points first.
    """

    corner_xz: FloatArray
    covariance_xz: FloatArray
    normals: FloatArray
    offsets: FloatArray
    inliers: BoolArray
    bend_rad: float
    rms_m: FloatArray
    opening_rad: float = math.nan
    alternatives: tuple[CornerFit, ...] = ()

    @property
    def sigma_m(self) -> float:
        """RMS 1σ of the corner, sqrt(trace(covariance) / 2), m."""
        return float(np.sqrt(0.5 * np.trace(self.covariance_xz)))

    def residuals_m(self, points_xz: FloatArray) -> FloatArray:
        """Signed distance of each inlier of the points (N, 2) the fit was made on from its
        line, in the points' order (K,), m."""
        inside = self.inliers.any(axis=0)
        line = np.argmax(self.inliers[:, inside], axis=0)
        q = points_xz[inside]
        return np.asarray(np.einsum("ij,ij->i", q, self.normals[line]) - self.offsets[line])


@dataclass(frozen=True)
class _Line:
    normal: FloatArray  # (2,) unit
    offset: float  # normal · q = offset
    centroid: FloatArray  # (2,)
    rms: float
    spread_sq: float  # Σ (along-line coordinate − mean)² of the inliers, m²
    count: int

    @property
    def direction(self) -> FloatArray:
        return np.array([-self.normal[1], self.normal[0]])


def _fit_line(points: FloatArray) -> _Line:
    """Total least squares line through points (K, 2), K >= 2."""
    centroid = points.mean(axis=0)
    centred = points - centroid
    _, s, Vt = np.linalg.svd(centred, full_matrices=False)
    normal = Vt[1]
    dof = max(len(points) - 2, 1)
    return _Line(
        normal=normal,
        offset=float(normal @ centroid),
        centroid=centroid,
        rms=float(s[1] / np.sqrt(dof)) if len(s) > 1 else 0.0,
        spread_sq=float(s[0] ** 2),
        count=len(points),
    )


def _ransac_line(
    points: FloatArray, threshold: float, hypotheses: int, rng: np.random.Generator
) -> BoolArray:
    """Inlier mask (K,) of the best two-point line hypothesis by MSAC cost."""
    n = len(points)
    first = rng.integers(0, n, hypotheses)
    second = (first + rng.integers(1, n, hypotheses)) % n
    d = points[second] - points[first]
    normals = np.column_stack([-d[:, 1], d[:, 0]])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    offsets = np.einsum("hi,hi->h", normals, points[first])
    distance = np.abs(points @ normals.T - offsets)  # (K, H)
    cost = np.minimum(distance, threshold) ** 2
    best = int(np.argmin(cost.sum(axis=0)))
    return np.asarray(distance[:, best] < threshold)


def _intersection(a: _Line, b: _Line) -> FloatArray:
    N = np.vstack([a.normal, b.normal])
    return np.asarray(np.linalg.solve(N, [a.offset, b.offset]))


def _flank_variance(line: _Line, corner: FloatArray) -> float:
    """Variance of the line's offset at the corner, m² (see :func:`_corner_covariance`)."""
    u = float(line.direction @ (corner - line.centroid))
    sigma_sq = line.rms**2
    return sigma_sq / line.count + u * u * sigma_sq / max(line.spread_sq, 1e-300)


def _corner_covariance(lines: tuple[_Line, _Line], corner: FloatArray) -> FloatArray:
    """First-order covariance (2, 2) of the intersection from the two line fits.

    Line k, parametrised at its centroid m_k by its angle φ_k and offset d_k (n_k·(q − m_k)
    = d_k), has var(d_k) = σ_k²/K_k and var(φ_k) = σ_k²/S_k (S_k: the inliers' spread along
    the line). Differentiating n_k·(q − m_k) = d_k at the corner q gives
    n_k·dq = dd_k − dφ_k · u_k with u_k the corner's position along the line from m_k; the
    two rows are independent, so cov(q) = N⁻¹ diag(var_k) N⁻ᵀ.
    """
    N = np.vstack([line.normal for line in lines])
    variances = [_flank_variance(line, corner) for line in lines]
    N_inv = np.linalg.inv(N)
    return np.asarray(N_inv @ np.diag(variances) @ N_inv.T)


def _check_points(points_xz: ArrayLike) -> FloatArray:
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"profile points must have shape (N, 2) (x, z), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise InputError("profile points contain NaN or Inf: clean the profile first")
    return p


def _find_lines(p: FloatArray, config: CornerConfig, rng: np.random.Generator) -> list[BoolArray]:
    """Up to ``max_lines`` lines by RANSAC, each on the points the earlier ones left, then
    refitted: each point goes to the nearer line within a threshold that shrinks towards a
    few sigma of that line's residual, until the assignment settles. Most points first."""
    n = len(p)
    remaining = np.arange(n)
    masks: list[BoolArray] = []
    while len(masks) < config.max_lines and len(remaining) >= config.min_line_points:
        inside = _ransac_line(p[remaining], config.inlier_threshold_m, config.hypotheses, rng)
        if int(inside.sum()) < config.min_line_points:
            break
        mask = np.zeros(n, dtype=np.bool_)
        mask[remaining[inside]] = True
        masks.append(mask)
        remaining = remaining[~inside]
    for _ in range(MAX_REFIT_ROUNDS):
        if len(masks) < 2 or min(int(m.sum()) for m in masks) < 2:
            break
        lines = [_fit_line(p[m]) for m in masks]
        distance = np.abs(
            p @ np.vstack([line.normal for line in lines]).T
            - np.array([line.offset for line in lines])
        )
        threshold = np.array(
            [
                min(
                    config.inlier_threshold_m,
                    max(config.noise_threshold_sigmas * line.rms, MIN_NOISE_THRESHOLD_M),
                )
                for line in lines
            ]
        )
        nearer = np.argmin(distance, axis=1)
        new = [(nearer == k) & (distance[:, k] < threshold[k]) for k in range(len(lines))]
        if all(np.array_equal(a, b) for a, b in zip(new, masks, strict=True)):
            break
        masks = new
    return sorted(masks, key=lambda m: -int(m.sum()))


def _pair_corner(
    p: FloatArray, masks: tuple[BoolArray, BoolArray], config: CornerConfig
) -> CornerFit | ProfileRejected:
    """The corner of two lines' points, or why they make no usable V."""
    lines = (_fit_line(p[masks[0]]), _fit_line(p[masks[1]]))
    bend = math.acos(min(1.0, abs(float(lines[0].direction @ lines[1].direction))))
    if bend < config.min_bend_rad:
        return FlatProfile(
            f"the two lines differ in direction by only {math.degrees(bend):.1f} deg (at least "
            f"{math.degrees(config.min_bend_rad):.1f} deg needed): the profile is flat, not a V"
        )
    corner = _intersection(*lines)
    away = []
    for k, line in enumerate(lines):
        along = (p[masks[k]] - corner) @ line.direction
        gap = float(np.min(np.abs(along)))
        if gap > config.max_corner_gap_m:
            return ProfileRejected(
                f"the lines meet {gap * 1e3:.2f} mm from the nearest point of line {k + 1} "
                f"(at most {config.max_corner_gap_m * 1e3:.2f} mm): the profile is not a V "
                "around its corner (a gap, or part of the joint out of view)"
            )
        margin = config.noise_threshold_sigmas * max(line.rms, MIN_NOISE_THRESHOLD_M)
        positive = int(np.sum(along > margin))
        negative = int(np.sum(along < -margin))
        wrong = min(positive, negative) / len(along)
        if wrong > config.max_wrong_side_fraction:
            return ProfileRejected(
                f"{wrong:.0%} of line {k + 1}'s points lie beyond the corner (at most "
                f"{config.max_wrong_side_fraction:.0%}): the lines cross instead of meeting "
                "in a V"
            )
        extent = float(np.ptp(along))
        sigma = math.sqrt(_flank_variance(line, corner))
        if extent < config.min_flank_length_m or sigma > config.max_flank_sigma_m:
            return ProfileRejected(
                f"line {k + 1}'s {line.count} points over {extent * 1e3:.2f} mm pin it at the "
                f"corner to {sigma * 1e6:.1f} um (at least {config.min_flank_length_m * 1e3:.1f}"
                f" mm and at most {config.max_flank_sigma_m * 1e6:.0f} um needed): the flank is "
                "too short or too rough to determine its line"
            )
        away.append(line.direction * math.copysign(1.0, float(np.median(along))))
    interior = math.acos(float(np.clip(away[0] @ away[1], -1.0, 1.0)))
    # Seen from the sensor (at the origin), a ridge's flanks run away from it, a groove's
    # towards it.
    convex = float((away[0] + away[1]) @ corner) >= 0.0
    return CornerFit(
        corner_xz=corner,
        covariance_xz=_corner_covariance(lines, corner),
        normals=np.vstack([line.normal for line in lines]),
        offsets=np.array([line.offset for line in lines]),
        inliers=np.vstack(masks),
        bend_rad=bend,
        rms_m=np.array([line.rms for line in lines]),
        opening_rad=interior if convex else -interior,
    )


def fit_corner(points_xz: ArrayLike, config: CornerConfig, rng: np.random.Generator) -> CornerFit:
    """Fit the lines of a V profile and intersect them (see the module docstring).

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Cleaned profile points (x, z) in the sensor frame, m, finite.
    config : CornerConfig
    rng : numpy.random.Generator
        For the RANSAC hypotheses.

    Returns
    -------
    CornerFit
        The corner of the two lines holding the most points among the pairs that make a
        usable V; the other such pairs' corners are its ``alternatives``.

    Raises
    ------
    InputError
        Malformed points.
    ProfileRejected
        The profile shows no clear V; the message says which test failed, with numbers (for
        the pair of the two largest lines).
    """
    p = _check_points(points_xz)
    n = len(p)
    need = config.min_line_points
    if n < 2 * need:
        raise ProfileRejected(
            f"only {n} points, fewer than the {2 * need} two lines of a V need: aim the laser "
            "line across the seam with both flanks in view"
        )
    masks = _find_lines(p, config, rng)
    if len(masks) < 2:
        held = int(masks[0].sum()) if masks else 0
        raise FlatProfile(
            f"one straight line holds {held} of {n} points and the {n - held} left hold no "
            f"second line of at least {need} points: the profile is flat, not a V; aim the "
            "laser line across the seam"
        )
    counts = [int(m.sum()) for m in masks]
    if counts[1] < need:
        raise ProfileRejected(
            f"the two largest lines hold {counts[0]} and {counts[1]} points, fewer than the "
            f"{need} each needs: the profile has no clear second flank"
        )
    masks = [m for m in masks if int(m.sum()) >= need]
    outcomes = [
        _pair_corner(p, (masks[a], masks[b]), config) for a, b in combinations(range(len(masks)), 2)
    ]
    fits = sorted(
        (o for o in outcomes if isinstance(o, CornerFit)), key=lambda f: -int(f.inliers.sum())
    )
    if not fits:
        first = outcomes[0]
        assert isinstance(first, ProfileRejected)  # no pair made a corner
        raise first
    return replace(fits[0], alternatives=tuple(fits[1:]))


@dataclass(frozen=True)
class CornerSample:
    """A sample whose profile gave a weld-seam corner.

    Attributes
    ----------
    index : int
        Profile index in the input stream.
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
        Flange pose as paired (recorded).
    corner_xz : ndarray, shape (2,)
        Corner in the sensor x-z plane, m.
    covariance_xz : ndarray, shape (2, 2)
        From the line fits, m².
    points : ndarray, shape (K, 3)
        The two lines' inlier points, sensor frame, m.
    rms_m : float or None
        RMS distance of those points from their lines, m; None for a corner given as
        feature points (no profile to fit).
    opening_rad : float
        :attr:`CornerFit.opening_rad` (NaN for feature points).
    alternatives : tuple of CornerSample
        The profile's other usable corners (:attr:`CornerFit.alternatives`); the recording
        chooses among them (:func:`check_corner_recording`).
    shape : Comparison or None
        The corner's two lines against the rival shapes on this profile
        (:func:`~.corner_shape.compare_corner`); None for feature points.
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    corner_xz: FloatArray
    covariance_xz: FloatArray
    points: FloatArray
    rms_m: float | None = None
    opening_rad: float = math.nan
    alternatives: tuple[CornerSample, ...] = ()
    shape: Comparison | None = None

    @property
    def rival(self) -> Comparison | None:
        """The comparison when a rival shape fits this one profile clearly better, else None."""
        return self.shape if self.shape is not None and self.shape.rival_wins else None

    def record(self) -> SampleFit:
        """The plain record kept in the result (the V corner as the feature point)."""
        return SampleFit(self.index, self.stamp_ns, self.T_base_flange, self.points, self.corner_xz)


def extract_corner_sample(
    sample: Sample, cleaning: CleaningConfig, corner: CornerConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """Clean one sample's profile, fit its V corner and weigh it against the rival shapes;
    a rejection says why it failed (a
    :class:`~linelaser_calib.core.model_check.RivalRejection` when no corner was found and
    a rival fits clearly better). A corner keeps its comparison (:attr:`CornerSample.shape`),
    also where a rival fits this one profile better: the recording judges it
    (:func:`check_corner_recording`).

    Shared by the targets that see a V (the known point, the straight seam).

    Parameters
    ----------
    sample : Sample
        Profile (sensor frame, m) paired with its flange pose.
    cleaning : CleaningConfig
    corner : CornerConfig
    rng : numpy.random.Generator
        For the RANSAC line fits.

    Returns
    -------
    CornerSample or Rejection
        A rejection has stage ``cleaning`` or ``corner``.
    """
    try:
        cleaned = clean_profile(sample.points, cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    xz = cleaned.points_xz
    try:
        fit = fit_corner(xz, corner, rng)
    except ProfileRejected as exc:
        flat = isinstance(exc, FlatProfile)
        rival = compare_without_corner(xz, flat) if len(xz) >= MIN_RIVAL_POINTS else None
        if rival is not None:
            return corner_rival_rejection(sample.index, sample.stamp_ns, *rival)
        return Rejection(sample.index, sample.stamp_ns, "corner", str(exc))
    comparison = compare_corner(xz[fit.inliers.any(axis=0)], fit.residuals_m(xz))

    def sample_of(corner_fit: CornerFit) -> CornerSample:
        residuals = corner_fit.residuals_m(xz)
        return CornerSample(
            sample.index,
            sample.stamp_ns,
            np.asarray(sample.T_base_flange, dtype=np.float64),
            corner_fit.corner_xz,
            corner_fit.covariance_xz,
            cleaned.points[corner_fit.inliers.any(axis=0)],
            float(np.sqrt(np.mean(residuals**2))),
            corner_fit.opening_rad,
            shape=comparison,
        )

    return replace(
        sample_of(fit), alternatives=tuple(sample_of(other) for other in fit.alternatives)
    )


def _consistent_corners(
    corners: list[CornerSample], sigmas: float
) -> tuple[list[CornerSample], dict[int, str]]:
    """Each corner with alternatives replaced by the one whose opening (flank angle and
    ridge or groove) is nearest the recording's median, taken over the profiles with one
    usable corner (over every profile's first when fewer than three have one), of those that
    no rival shape fits better (of all when fewer than three are such); and the positions of
    the corners whose opening still lies more than ``sigmas`` robust spreads of those same
    profiles' (at least
    :data:`MIN_OPENING_SPREAD_RAD`) from it, with the reason (another corner of the part,
    e.g. where a flank meets the floor)."""
    finite = np.array([math.isfinite(c.opening_rad) for c in corners], dtype=np.bool_)
    undoubted = finite & np.array([c.rival is None for c in corners], dtype=np.bool_)
    if undoubted.sum() >= 3:
        finite = undoubted
    reference = finite & np.array([not c.alternatives for c in corners], dtype=np.bool_)
    if reference.sum() < 3:
        reference = finite
    if reference.sum() < 3:
        return corners, {}
    typical = float(
        np.median([c.opening_rad for c, r in zip(corners, reference, strict=True) if r])
    )
    chosen = [
        min(
            (replace(c, alternatives=()), *c.alternatives),
            key=lambda option: abs(option.opening_rad - typical),
        )
        for c in corners
    ]
    off = np.array([abs(c.opening_rad - typical) for c in chosen])
    spread = MAD_TO_SIGMA * float(np.median(off[reference]))
    limit = max(sigmas * spread, MIN_OPENING_SPREAD_RAD)
    aside = {
        k: f"its flanks meet at {_angle_text(c.opening_rad)} where the recording's corners "
        f"meet at {_angle_text(typical)} (at most {math.degrees(limit):.1f} deg apart, "
        f"{sigmas:g} times their spread): another corner of the part (a flank meeting a floor "
        "or a wall), or a flank out of view"
        for k, c in enumerate(chosen)
        if off[k] > limit
    }
    return chosen, aside


def corner_doubt(corners: list[CornerSample]) -> str | None:
    """Why the profiles' own shapes put a V target in doubt: at least half of its corners'
    profiles fit a rival shape clearly better than a V (:attr:`CornerSample.rival`); None
    otherwise. The whole recording decides then (:mod:`~linelaser_calib.core.targets.rivals`)."""
    return shape_doubt([(c.index, c.rival) for c in corners], "V")


def corners_shown(corners: list[CornerSample]) -> tuple[int, str]:
    """How many corners no rival shape fits better one by one (what a refusal for too few
    corners counts as showing the V, :class:`~linelaser_calib.core.errors.TooFewFeatures`),
    and the words to put after "show a seam corner" saying so ("" when none is doubted)."""
    doubted = [c for c in corners if c.rival is not None]
    if not doubted:
        return len(corners), ""
    example = doubted[0]
    assert example.rival is not None
    return len(corners) - len(doubted), (
        f" that no rival shape fits better ({len(doubted)} more show a corner that a rival "
        f"fits better one by one; profile {example.index}: {example.rival.describe()})"
    )


def _rival_outliers(corners: list[CornerSample], sigmas: float) -> dict[int, str]:
    """The positions of the corners that a rival shape fits clearly better by a margin (BIC
    per effective point) more than ``sigmas`` robust spreads above the median of the
    recording's corners, with the reason (none for fewer than 3 compared corners)."""
    compared = [(k, c.shape) for k, c in enumerate(corners) if c.shape is not None]
    if len(compared) < 3:
        return {}
    margins = [shape.delta_bic / max(shape.n_effective, 1.0) for _, shape in compared]
    scale = recording_scale(margins)
    limit = scale.limit_m(sigmas)
    return {
        k: f"{NOT_A_V}: {shape.describe()}; that margin, {margin:.2f} per effective point, "
        f"lies {scale.sigmas_above(margin):.0f} robust spreads above the median "
        f"{scale.median_m:.2f} of this recording's {len(compared)} corners (spread "
        f"{scale.spread_m:.2f}; limit {limit:.2f} at {sigmas:g} spreads)"
        for (k, shape), margin in zip(compared, margins, strict=True)
        if shape.rival_wins and margin > limit
    }


def _angle_text(opening_rad: float) -> str:
    """An opening in words: degrees and ridge or groove."""
    kind = "a ridge" if opening_rad >= 0.0 else "a groove"
    return f"{math.degrees(abs(opening_rad)):.1f} deg ({kind})"


def check_corner_recording(
    corners: list[CornerSample], rejections: list[Rejection], sigmas: float
) -> tuple[list[CornerSample], list[Rejection]]:
    """The recording's corners without the outliers among them, and the rejections with
    theirs added (stage ``corner``).

    A corner whose lines leave an RMS residual ``sigmas`` robust spreads above the median of
    the recording's profiles is set aside
    (:func:`~linelaser_calib.core.model_check.recording_outliers`; corners given as feature
    points are not judged), each corner's spread counting the sampling spread of an RMS over
    its effective points (:attr:`~linelaser_calib.core.model_check.Comparison.n_effective`),
    as the sphere's circles do; so is one that a rival shape fits clearly better by a margin
    ``sigmas`` robust spreads above the recording's median (:func:`_rival_outliers`).

    Parameters
    ----------
    corners : list of CornerSample
    rejections : list of Rejection
        The profiles' rejections (:func:`extract_corner_sample`).
    sigmas : float
    """
    corners, aside = _consistent_corners(corners, sigmas)
    aside.update({k: why for k, why in _rival_outliers(corners, sigmas).items() if k not in aside})
    fitted = [(k, c.rms_m, c) for k, c in enumerate(corners) if c.rms_m is not None]
    outliers = recording_outliers(
        [rms for _, rms, _ in fitted],
        sigmas,
        "line pair",
        [len(c.points) if c.shape is None else c.shape.n_effective for _, _, c in fitted],
    )
    aside.update({fitted[j][0]: reason for j, reason in outliers if fitted[j][0] not in aside})
    rejections = rejections + [
        Rejection(corners[k].index, corners[k].stamp_ns, "corner", reason)
        for k, reason in aside.items()
    ]
    return [c for k, c in enumerate(corners) if k not in aside], rejections
