"""The cylinder's arc in a cluttered profile: pick it among the curved segments and fit it.

:func:`~linelaser_calib.core.profile.segmentation.segment_profile` sets the planes of the scene
aside and measures the noise; :func:`fit_arc_in_scene` then

1. scales the RANSAC inlier threshold to the measured noise: at least
   ``ARC_NOISE_SIGMAS`` sigmas, never below the configured threshold (which suits a
   5-10 um profiler);
2. fits an ellipse (:func:`~.ellipse.fit_ellipse_ransac`) to each
   curved candidate with enough points, its share rule applied to the candidate's own
   points rather than to the whole profile, and keeps the fit with the most inliers;
3. polishes the ellipse on the arc without its grazing-angle ends, the inliers seen at
   more than ``grazing_angle_rad`` between the ray from the sensor origin and the ellipse
   normal, and measures how far outside that ellipse the ends sit. A camera's laser spot smears
   along a steep surface and its centroid leaves the surface: the ends then pull the
   radius and the centre. Whether they do is decided over the whole recording
   (:func:`grazing_ends_biased`), and the trimmed fits are used only then.

If no candidate gives an ellipse, the rejection of the largest candidate is raised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from ...errors import ProfileRejected
from ...model_check import median
from ...profile.cleaning import MAD_TO_SIGMA
from ...profile.segmentation import (
    IntArray,
    SegmentationConfig,
    SegmentedProfile,
    segment_profile,
)
from ...types import BoolArray, FloatArray
from .conic import centre_from_conic, sampson_distance
from .ellipse import EllipseConfig, EllipseFit, fit_ellipse_ransac, refine_conic

#: RANSAC inlier threshold in measured noise sigmas (a hypothesis from five noisy points
#: must still collect the whole arc).
ARC_NOISE_SIGMAS = 10.0
#: Most points (evenly spread) of the polish without the grazing ends: the test's precision
#: rests on the few grazing points, not on these.
MAX_POLISH_POINTS = 200
#: Standard errors of the median grazing-end shift that count as a bias, the smallest
#: shift that does (noise sigmas), and the fewest profiles the test pools.
GRAZING_BIAS_SIGMAS, GRAZING_MIN_SHIFT_SIGMAS, MIN_GRAZING_PROFILES = 3.0, 0.5, 5


@dataclass(frozen=True)
class ArcConfig:
    """Parameters of :func:`fit_arc_in_scene` (SI units).

    Attributes
    ----------
    segmentation : SegmentationConfig
    grazing_angle_rad : float
        Inliers seen at a larger angle between ray and surface normal are the arc's
        grazing ends (tested for bias, see the module docstring), rad. pi/2 disables it.
    min_grazing_points : int
        Fewest grazing points for the bias test.
    """

    segmentation: SegmentationConfig = field(default_factory=SegmentationConfig)
    grazing_angle_rad: float = math.radians(65.0)
    min_grazing_points: int = 6

    def __post_init__(self) -> None:
        if not 0.0 < self.grazing_angle_rad <= math.pi / 2:
            raise ValueError(
                f"grazing_angle_rad must be in (0, pi/2], got {self.grazing_angle_rad}"
            )


@dataclass(frozen=True)
class ArcFit:
    """The arc found in a profile.

    Attributes
    ----------
    points_xz : ndarray, shape (M, 2)
        The candidate segment the ellipse was fitted to, m; ``ellipse.inliers`` is a mask
        over these rows.
    rows : ndarray of int, shape (M,)
        Their rows in the input points.
    ellipse : EllipseFit
    ellipse_config : EllipseConfig
        The ellipse parameters used, inlier threshold scaled to the noise.
    grazing : ndarray of bool, shape (M,)
        The inliers seen at more than ``grazing_angle_rad`` from the surface normal (all
        False when fewer than ``min_grazing_points``).
    noise_sigma_m : float
        The profile's measured noise (its segmentation's), m.
    grazing_shift_sigmas : float
        Mean outward distance of the grazing inliers from the ellipse through the other
        inliers, less the median of the others', in noise sigmas (NaN when not measured).
    """

    points_xz: FloatArray
    rows: IntArray
    ellipse: EllipseFit
    ellipse_config: EllipseConfig
    grazing: BoolArray
    noise_sigma_m: float
    grazing_shift_sigmas: float = math.nan


def incidence_cosines(conic: FloatArray, points_xz: FloatArray) -> FloatArray:
    """|cos| of the angle between the ray to each point and the conic's normal there, (M,)."""
    a, b, c, d, e, _ = conic
    x, z = points_xz[:, 0], points_xz[:, 1]
    gx, gz = 2 * a * x + b * z + d, b * x + 2 * c * z + e
    norm = np.hypot(gx, gz) * np.hypot(x, z)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.where(norm > 0.0, np.abs(gx * x + gz * z) / norm, 1.0))


def outward_distance(conic: FloatArray, points_xz: FloatArray) -> FloatArray:
    """Sampson distance of points from an ellipse, positive outside it, m, shape (M,)."""

    def value(q: FloatArray) -> FloatArray:
        a, b, c, d, e, f = conic
        x, z = q[:, 0], q[:, 1]
        return np.asarray(a * x * x + b * x * z + c * z * z + d * x + e * z + f)

    inside = np.sign(value(centre_from_conic(conic)[None, :]))[0]
    distance = np.abs(sampson_distance(conic, points_xz))
    return np.asarray(-inside * np.sign(value(points_xz)) * distance)


def _grazing_shift(
    fit: EllipseFit, points_xz: FloatArray, sigma_m: float, config: ArcConfig
) -> tuple[BoolArray, float]:
    """The grazing inliers, and how far outside the ellipse through the others they sit."""
    grazing = np.zeros(len(points_xz), dtype=np.bool_)
    inlier_rows = np.flatnonzero(fit.inliers)
    cosines = incidence_cosines(fit.conic, points_xz[inlier_rows])
    grazing[inlier_rows[cosines < math.cos(config.grazing_angle_rad)]] = True
    if grazing.sum() < config.min_grazing_points:
        return np.zeros_like(grazing), math.nan
    rest = fit.inliers & ~grazing
    rows = np.flatnonzero(rest)
    sampled = rows[:: max(1, len(rows) // MAX_POLISH_POINTS)]
    try:
        front = refine_conic(fit.conic, points_xz[sampled])
    except ProfileRejected:
        return grazing, math.nan
    outward = outward_distance(front, points_xz[inlier_rows])
    at_grazing = grazing[inlier_rows]
    ends = float(np.mean(outward[at_grazing]))
    others = median(outward[~at_grazing])
    return grazing, (ends - others) / sigma_m


def without_grazing_ends(
    points_xz: FloatArray,
    grazing: BoolArray,
    ellipse_config: EllipseConfig,
    noise_sigma_m: float,
    radius_m: float | None,
) -> EllipseFit | None:
    """An arc's ellipse fitted again without its grazing inliers (None if that fails): the
    arc's ``points_xz``, ``grazing``, ``ellipse_config`` and ``noise_sigma_m``
    (:class:`ArcFit`).

    Its ``inliers`` mask covers the arc's rows, the grazing ones False.
    """
    if not grazing.any():
        return None
    keep = ~grazing
    try:
        fit = fit_ellipse_ransac(
            points_xz[keep],
            ellipse_config,
            np.random.default_rng(len(points_xz)),
            radius_m,
            noise_sigma_m,
        )
    except ProfileRejected:
        return None
    inliers = np.zeros(len(points_xz), dtype=np.bool_)
    inliers[np.flatnonzero(keep)[fit.inliers]] = True
    return replace(fit, inliers=inliers)


def fit_arc_in_scene(
    points_xz: ArrayLike,
    ellipse_config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None = None,
    config: ArcConfig | None = None,
    segmented: SegmentedProfile | None = None,
) -> ArcFit:
    """Find and fit the cylinder's elliptical arc in a cluttered profile.

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Cleaned profile points (x, z) in the sensor frame, m.
    ellipse_config : EllipseConfig
    rng : numpy.random.Generator
    radius_m : float or None
        Cylinder radius, m, when known (bounds the ellipse's semi-minor axis).
    config : ArcConfig, optional
    segmented : SegmentedProfile, optional
        The points' segmentation by ``config.segmentation`` where the caller holds it
        (:func:`~linelaser_calib.core.profile.segmentation.segment_profiles`, done for many
        profiles at once).

    Returns
    -------
    ArcFit
        With its grazing ends and how far they sit off the rest; whether they are biased
        is decided over the recording (:func:`grazing_ends_biased`), and the trimmed
        ellipse (:func:`without_grazing_ends`) used only then.

    Raises
    ------
    ProfileRejected
        No curved segment holds a plausible ellipse; the message of the largest one's fit.
    """
    config = config or ArcConfig()
    p = np.asarray(points_xz, dtype=np.float64)
    if segmented is None:
        segmented = segment_profile(p, config.segmentation)
    sigma = segmented.noise.sigma_m
    threshold = max(ellipse_config.inlier_threshold_m, ARC_NOISE_SIGMAS * sigma)
    scaled = replace(ellipse_config, inlier_threshold_m=threshold)
    candidates = [s for s in segmented.curves() if len(s.indices) >= scaled.min_inliers]
    if not candidates:
        raise ProfileRejected(
            f"no curved piece of at least {scaled.min_inliers} points beside the "
            f"{len(segmented.lines())} straight piece(s) set aside as planes (tables, walls): "
            f"measured noise {sigma * 1e6:.0f} um; the laser line may miss the cylinder"
        )
    best: tuple[EllipseFit, IntArray] | None = None
    first_error: ProfileRejected | None = None
    for segment in candidates:  # most points first
        if best is not None and len(segment.indices) <= best[0].inliers.sum():
            break  # no smaller candidate can hold more inliers
        try:
            fit = fit_ellipse_ransac(p[segment.indices], scaled, rng, radius_m, sigma)
        except ProfileRejected as exc:
            first_error = first_error or exc
            continue
        if best is None or fit.inliers.sum() > best[0].inliers.sum():
            best = (fit, segment.indices)
    if best is None:
        assert first_error is not None
        raise first_error
    fit, rows = best
    grazing, shift = _grazing_shift(fit, p[rows], sigma, config)
    return ArcFit(p[rows], rows, fit, scaled, grazing, sigma, shift)


def circle_radius(points_xz: FloatArray) -> float:
    """Radius of the least-squares circle through points (N >= 3, 2) of an arc, m (Kasa's
    algebraic fit: x^2 + z^2 + D x + E z + F = 0 solved linearly)."""
    x, z = points_xz[:, 0], points_xz[:, 1]
    design = np.column_stack([x, z, np.ones_like(x)])
    (d, e, f), *_ = np.linalg.lstsq(design, -(x * x + z * z), rcond=None)
    return float(math.sqrt(max(0.25 * (d * d + e * e) - f, 0.0)))


def circle_centre(points_xz: FloatArray, radius_m: float) -> FloatArray:
    """Centre (2,) of the circle of radius ``radius_m`` (m) nearest to points (N >= 3, 2) of
    an arc in the least-squares sense, m, on the arc's concave side.

    A short arc leaves an ellipse's five numbers loose but fixes a circle of known radius:
    its centre stands in for the ellipse centre in a solve on the centres (a cylinder's cut
    is a circle stretched by 1 / sin of the cut angle, so the stand-in errs by up to that
    stretch of the radius, within what the refinement on the points corrects).
    """
    x, z = points_xz[:, 0], points_xz[:, 1]
    design = np.column_stack([x, z, np.ones_like(x)])
    (d, e, _), *_ = np.linalg.lstsq(design, -(x * x + z * z), rcond=None)
    middle = points_xz.mean(axis=0)
    inward = np.array([-0.5 * d, -0.5 * e]) - middle
    start = middle + radius_m * inward / max(float(np.linalg.norm(inward)), 1e-300)
    fit = least_squares(lambda c: np.hypot(x - c[0], z - c[1]) - radius_m, start)
    return np.asarray(fit.x, dtype=np.float64)


def grazing_ends_biased(shifts_sigmas: ArrayLike) -> float | None:
    """Whether the arcs' grazing ends sit off the rest of the arcs, over a recording.

    One profile has only a few grazing points, and the ellipse through the rest of its arc
    extrapolates with an error of its own, so the test pools the profiles: the median
    shift (in noise sigmas) must differ from zero by more than ``GRAZING_BIAS_SIGMAS``
    standard errors of a median and by more than ``GRAZING_MIN_SHIFT_SIGMAS``.

    Parameters
    ----------
    shifts_sigmas : array-like, shape (K,)
        :attr:`ArcFit.grazing_shift_sigmas` of the profiles (NaN entries are ignored).

    Returns
    -------
    float or None
        The median shift in sigmas when the ends are biased, else None.
    """
    shifts = np.asarray(shifts_sigmas, dtype=np.float64)
    shifts = shifts[np.isfinite(shifts)]
    if len(shifts) < MIN_GRAZING_PROFILES:
        return None
    median = float(np.median(shifts))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(shifts - median)))
    error = math.sqrt(math.pi / 2.0) * spread / math.sqrt(len(shifts))
    if abs(median) <= max(GRAZING_BIAS_SIGMAS * error, GRAZING_MIN_SHIFT_SIGMAS):
        return None
    return median


#: Standard errors by which the profiles' radius must differ from a given one to contradict
#: it, and the smallest relative difference reported (a few tenths of a percent are within
#: the ellipse fits' bias on short arcs).
RADIUS_MISMATCH_SIGMAS, RADIUS_MISMATCH_RELATIVE = 3.0, 0.003


def radius_mismatch(semi_minor_axes_m: ArrayLike, radius_m: float | None) -> str | None:
    """A warning when the profiles contradict a given cylinder radius, else None.

    Parameters
    ----------
    semi_minor_axes_m : array-like, shape (K,)
        Semi-minor axes of the fitted ellipses, m (a cylinder cut's is its radius).
    radius_m : float or None
        The radius the user gave, m (None: nothing to check).

    Returns
    -------
    str or None
        Both numbers, the median with its standard error (1.4826 MAD / sqrt(K)), and what
        else than the radius could explain the gap: the sensor's along-line scale.
    """
    axes = np.asarray(semi_minor_axes_m, dtype=np.float64)
    if radius_m is None or len(axes) < 2:
        return None
    measured = float(np.median(axes))
    error = 1.4826 * float(np.median(np.abs(axes - measured))) / math.sqrt(len(axes))
    # The median's standard error is sqrt(pi / 2) times the mean's.
    error *= math.sqrt(math.pi / 2.0)
    gap = measured - radius_m
    if abs(gap) <= max(RADIUS_MISMATCH_SIGMAS * error, RADIUS_MISMATCH_RELATIVE * radius_m):
        return None
    return (
        f"the profiles fit a radius of {measured * 1e3:.2f} ± {error * 1e3:.2f} mm (median "
        f"semi-minor axis of {len(axes)} ellipses, 1 sigma) against the given "
        f"{radius_m * 1e3:.2f} mm, {100.0 * gap / radius_m:+.1f}%: either the cylinder is "
        f"not the given size (measure it, or omit the radius to estimate it), or the "
        f"sensor's along-line (x) scale is off by about {100.0 * gap / radius_m:+.1f}%, "
        "which stretches every profile across the line; the calibration used the given "
        "radius"
    )


def trimming_note(trimmed: ArrayLike, shift_sigmas: float, config: ArcConfig) -> str:
    """The note on the grazing-angle points trimmed from the profiles.

    Parameters
    ----------
    trimmed : array-like of int, shape (K,)
        Points trimmed from each profile's arc.
    shift_sigmas : float
        Median shift of the grazing ends (:func:`grazing_ends_biased`), noise sigmas.
    config : ArcConfig
    """
    counts = np.asarray(trimmed, dtype=np.intp)
    side = "outside" if shift_sigmas > 0.0 else "inside"
    return (
        f"trimmed the grazing-angle ends of {int(np.count_nonzero(counts))} of {len(counts)} "
        f"arcs ({int(counts.sum())} points seen at more than "
        f"{math.degrees(config.grazing_angle_rad):.0f} deg from the surface normal): they sit "
        f"a median {abs(shift_sigmas):.1f} noise sigmas {side} the ellipse through the rest "
        "of the arc and would bias the radius and the centre (a laser spot smeared along a "
        "steep surface)"
    )
