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
  criterion (:mod:`.corner_shape`); a profile a rival fits clearly better is rejected naming
  it;
- per recording (:func:`check_corner_recording`), a recording most of whose profiles a
  rival describes better is refused naming the target it points to, and a profile whose
  lines leave far more than the recording's other profiles is set aside, with the
  recording's scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ModelMismatch, ProfileRejected
from ..model_check import recording_outliers
from ..types import BoolArray, FloatArray, Rejection, Sample, SampleFit
from .cleaning import CleaningConfig, clean_profile
from .corner_shape import (
    NOT_A_V,
    compare_corner,
    compare_without_corner,
    corner_rival_rejection,
    corner_rival_verdict,
)

#: Rounds of "refit, re-assign" after RANSAC.
MAX_REFIT_ROUNDS = 10
#: Smallest noise-adapted inlier threshold, m.
MIN_NOISE_THRESHOLD_M = 1e-6
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
    min_line_fraction : float
        Fewest inliers of each line as a share of the profile's points. Default 0.1.
    min_bend_rad : float
        Smallest angle between the two lines, rad: below it the profile is flat, not a V.
        Default 10 deg.
    max_corner_gap_m : float
        Largest distance from the corner to the nearest inlier of each line, m: the lines
        must meet where the points are, not far outside them. Default 3 mm.
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
    min_line_fraction: float = 0.1
    min_bend_rad: float = math.radians(10.0)
    max_corner_gap_m: float = 3e-3
    max_wrong_side_fraction: float = 0.05
    profile_outlier_sigmas: float = 6.0

    def __post_init__(self) -> None:
        for name in (
            "inlier_threshold_m",
            "noise_threshold_sigmas",
            "max_corner_gap_m",
            "profile_outlier_sigmas",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"CornerConfig.{name} must be positive and finite, got {value}")
        if self.hypotheses < 1 or self.min_line_points < 2:
            raise InputError("CornerConfig.hypotheses must be >= 1 and min_line_points >= 2")
        if not 0.0 <= self.min_line_fraction < 0.5:
            raise InputError("CornerConfig.min_line_fraction must be in [0, 0.5)")
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
    """

    corner_xz: FloatArray
    covariance_xz: FloatArray
    normals: FloatArray
    offsets: FloatArray
    inliers: BoolArray
    bend_rad: float
    rms_m: FloatArray

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


def _corner_covariance(lines: tuple[_Line, _Line], corner: FloatArray) -> FloatArray:
    """First-order covariance (2, 2) of the intersection from the two line fits.

    Line k, parametrised at its centroid m_k by its angle φ_k and offset d_k (n_k·(q − m_k)
    = d_k), has var(d_k) = σ_k²/K_k and var(φ_k) = σ_k²/S_k (S_k: the inliers' spread along
    the line). Differentiating n_k·(q − m_k) = d_k at the corner q gives
    n_k·dq = dd_k − dφ_k · u_k with u_k the corner's position along the line from m_k; the
    two rows are independent, so cov(q) = N⁻¹ diag(var_k) N⁻ᵀ.
    """
    N = np.vstack([line.normal for line in lines])
    variances = []
    for line in lines:
        u = float(line.direction @ (corner - line.centroid))
        sigma_sq = line.rms**2
        variances.append(sigma_sq / line.count + u * u * sigma_sq / max(line.spread_sq, 1e-300))
    N_inv = np.linalg.inv(N)
    return np.asarray(N_inv @ np.diag(variances) @ N_inv.T)


def _check_points(points_xz: ArrayLike) -> FloatArray:
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"profile points must have shape (N, 2) (x, z), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise InputError("profile points contain NaN or Inf: clean the profile first")
    return p


def fit_corner(points_xz: ArrayLike, config: CornerConfig, rng: np.random.Generator) -> CornerFit:
    """Fit two lines to a V profile and intersect them (see the module docstring).

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

    Raises
    ------
    InputError
        Malformed points.
    ProfileRejected
        The profile shows no clear V; the message says which test failed, with numbers.
    """
    p = _check_points(points_xz)
    n = len(p)
    need = max(config.min_line_points, math.ceil(config.min_line_fraction * n))
    if n < 2 * need:
        raise ProfileRejected(
            f"only {n} points, fewer than the {2 * need} two lines of a V need: aim the laser "
            "line across the seam with both flanks in view"
        )
    first = _ransac_line(p, config.inlier_threshold_m, config.hypotheses, rng)
    rest = np.flatnonzero(~first)
    if len(rest) < need:
        raise FlatProfile(
            f"one straight line holds {int(first.sum())} of {n} points and only {len(rest)} "
            f"are left for a second (at least {need} needed): the profile is flat, not a V; "
            "aim the laser line across the seam"
        )
    second = np.zeros(n, dtype=np.bool_)
    second[rest] = _ransac_line(p[rest], config.inlier_threshold_m, config.hypotheses, rng)
    masks = np.vstack([first, second])
    for _ in range(MAX_REFIT_ROUNDS):
        if int(masks[0].sum()) < 2 or int(masks[1].sum()) < 2:
            break
        lines = (_fit_line(p[masks[0]]), _fit_line(p[masks[1]]))
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
        new = np.vstack([(nearer == k) & (distance[:, k] < threshold[k]) for k in range(2)])
        if np.array_equal(new, masks):
            break
        masks = new
    counts = masks.sum(axis=1)
    if int(counts.min()) < need:
        raise ProfileRejected(
            f"the two lines hold {counts[0]} and {counts[1]} points, fewer than the {need} "
            "each needs: the profile has no clear second flank"
        )
    lines = (_fit_line(p[masks[0]]), _fit_line(p[masks[1]]))
    bend = math.acos(min(1.0, abs(float(lines[0].direction @ lines[1].direction))))
    if bend < config.min_bend_rad:
        raise FlatProfile(
            f"the two lines differ in direction by only {math.degrees(bend):.1f} deg (at least "
            f"{math.degrees(config.min_bend_rad):.1f} deg needed): the profile is flat, not a V"
        )
    corner = _intersection(*lines)
    for k, line in enumerate(lines):
        along = (p[masks[k]] - corner) @ line.direction
        gap = float(np.min(np.abs(along)))
        if gap > config.max_corner_gap_m:
            raise ProfileRejected(
                f"the lines meet {gap * 1e3:.2f} mm from the nearest point of line {k + 1} "
                f"(at most {config.max_corner_gap_m * 1e3:.2f} mm): the profile is not a V "
                "around its corner (a gap, or part of the joint out of view)"
            )
        margin = config.noise_threshold_sigmas * max(line.rms, MIN_NOISE_THRESHOLD_M)
        positive = int(np.sum(along > margin))
        negative = int(np.sum(along < -margin))
        wrong = min(positive, negative) / len(along)
        if wrong > config.max_wrong_side_fraction:
            raise ProfileRejected(
                f"{wrong:.0%} of line {k + 1}'s points lie beyond the corner (at most "
                f"{config.max_wrong_side_fraction:.0%}): the lines cross instead of meeting "
                "in a V"
            )
    return CornerFit(
        corner_xz=corner,
        covariance_xz=_corner_covariance(lines, corner),
        normals=np.vstack([line.normal for line in lines]),
        offsets=np.array([line.offset for line in lines]),
        inliers=masks,
        bend_rad=bend,
        rms_m=np.array([line.rms for line in lines]),
    )


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
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    corner_xz: FloatArray
    covariance_xz: FloatArray
    points: FloatArray
    rms_m: float | None = None

    def record(self) -> SampleFit:
        """The plain record kept in the result (the V corner as the feature point)."""
        return SampleFit(self.index, self.stamp_ns, self.T_base_flange, self.points, self.corner_xz)


def extract_corner_sample(
    sample: Sample, cleaning: CleaningConfig, corner: CornerConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """Clean one sample's profile, fit its V corner and weigh it against the rival shapes;
    a rejection says why it failed (a
    :class:`~linelaser_calib.core.model_check.RivalRejection` when a rival fits clearly
    better, also when no corner was found).

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
    inside = fit.inliers.any(axis=0)
    residuals = fit.residuals_m(xz)
    comparison = compare_corner(xz[inside], residuals)
    if comparison.rival_wins:
        return corner_rival_rejection(sample.index, sample.stamp_ns, NOT_A_V, comparison)
    return CornerSample(
        sample.index,
        sample.stamp_ns,
        np.asarray(sample.T_base_flange, dtype=np.float64),
        fit.corner_xz,
        fit.covariance_xz,
        cleaned.points[inside],
        float(np.sqrt(np.mean(residuals**2))),
    )


def check_corner_recording(
    title: str, corners: list[CornerSample], rejections: list[Rejection], sigmas: float
) -> tuple[list[CornerSample], list[Rejection]]:
    """The recording's corners without the outliers among them, and the rejections with
    theirs added (stage ``corner``).

    A corner whose lines leave an RMS residual ``sigmas`` robust spreads above the median of
    the recording's profiles is set aside
    (:func:`~linelaser_calib.core.model_check.recording_outliers`; corners given as feature
    points are not judged).

    Parameters
    ----------
    title : str
        The target's model in words ("known point"), for the refusal.
    corners : list of CornerSample
    rejections : list of Rejection
        The profiles' rejections (:func:`extract_corner_sample`).
    sigmas : float

    Raises
    ------
    ModelMismatch
        When a rival shape describes at least as many profiles better as show a corner
        (:func:`~.corner_shape.corner_rival_verdict`: it names what the scans show).
    """
    verdict = corner_rival_verdict(title, rejections, len(corners))
    if verdict is not None:
        raise ModelMismatch(verdict)
    fitted = [(k, c.rms_m) for k, c in enumerate(corners) if c.rms_m is not None]
    outliers = recording_outliers([rms for _, rms in fitted], sigmas, "line pair")
    aside = {fitted[j][0]: reason for j, reason in outliers}
    rejections = rejections + [
        Rejection(corners[k].index, corners[k].stamp_ns, "corner", reason)
        for k, reason in aside.items()
    ]
    return [c for k, c in enumerate(corners) if k not in aside], rejections
