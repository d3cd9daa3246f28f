"""The cylinder's arc in a cluttered profile: pick it among the curved segments and fit it.

:func:`~linelaser_calib.core.segmentation.segment_profile` sets the planes of the scene
aside and measures the noise; :func:`fit_arc_in_scene` then

1. scales the RANSAC inlier threshold to the measured noise: at least
   ``ARC_NOISE_SIGMAS`` sigmas, never below the configured threshold (which suits a
   5-10 um profiler);
2. fits an ellipse (:func:`~linelaser_calib.core.ellipse.fit_ellipse_ransac`) to each
   curved candidate with enough points, its share rule applied to the candidate's own
   points rather than to the whole profile, and keeps the fit with the most inliers;
3. trims the arc's grazing-angle ends where they bias the fit: the inliers seen at more
   than ``grazing_angle_rad`` between the ray from the sensor origin and the ellipse
   normal are dropped, and the ellipse fitted again, when their mean signed distance from
   the ellipse through the rest of the arc (a direct fit) differs from that of the rest by
   more than ``GRAZING_BIAS_SIGMAS`` standard errors (and half a noise sigma). A camera's laser spot smears along a steep surface, and its
   centroid moves: the ends then pull the radius and the centre. The result says so.

If no candidate gives an ellipse, the rejection of the largest candidate is raised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from .ellipse import EllipseConfig, fit_ellipse_direct, fit_ellipse_ransac, sampson_distance
from .errors import ProfileRejected
from .segmentation import IntArray, SegmentationConfig, SegmentedProfile, segment_profile
from .types import BoolArray, EllipseFit, FloatArray

#: RANSAC inlier threshold in measured noise sigmas (a hypothesis from five noisy points
#: must still collect the whole arc).
ARC_NOISE_SIGMAS = 10.0
#: Standard errors of the grazing ends' mean residual that count as a bias.
GRAZING_BIAS_SIGMAS = 3.0


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
        The candidate segment the ellipse was fitted to (grazing ends removed if trimmed),
        m; ``ellipse.inliers`` is a mask over these rows.
    rows : ndarray of int, shape (M,)
        Their rows in the input points.
    ellipse : EllipseFit
    segmented : SegmentedProfile
        The segmentation (noise estimate, straight segments set aside).
    trimmed : int
        Grazing-angle points dropped because they biased the fit.
    """

    points_xz: FloatArray
    rows: IntArray
    ellipse: EllipseFit
    segmented: SegmentedProfile
    trimmed: int


def incidence_cosines(conic: FloatArray, points_xz: FloatArray) -> FloatArray:
    """|cos| of the angle between the ray to each point and the conic's normal there, (M,)."""
    a, b, c, d, e, _ = conic
    x, z = points_xz[:, 0], points_xz[:, 1]
    gx, gz = 2 * a * x + b * z + d, b * x + 2 * c * z + e
    norm = np.hypot(gx, gz) * np.hypot(x, z)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.where(norm > 0.0, np.abs(gx * x + gz * z) / norm, 1.0))


def _signed_distance(conic: FloatArray, points_xz: FloatArray) -> FloatArray:
    """Sampson distance with the sign of the conic value (m), shape (M,)."""
    a, b, c, d, e, f = conic
    x, z = points_xz[:, 0], points_xz[:, 1]
    value = a * x * x + b * x * z + c * z * z + d * x + e * z + f
    return np.asarray(np.sign(value) * np.abs(sampson_distance(conic, points_xz)))


def _grazing_biased(
    fit: EllipseFit, points_xz: FloatArray, sigma_m: float, config: ArcConfig
) -> BoolArray | None:
    """Mask of the inliers to drop as biased grazing ends, or None to keep them all."""
    inliers = points_xz[fit.inliers]
    grazing = incidence_cosines(fit.conic, inliers) < math.cos(config.grazing_angle_rad)
    if grazing.sum() < config.min_grazing_points:
        return None
    try:
        front = fit_ellipse_direct(inliers[~grazing])
    except ProfileRejected:
        return None
    ends = _signed_distance(front, inliers[grazing])
    shift = abs(float(np.mean(ends)) - float(np.median(_signed_distance(front, inliers[~grazing]))))
    error = sigma_m / math.sqrt(float(grazing.sum()))
    if shift <= max(GRAZING_BIAS_SIGMAS * error, 0.5 * sigma_m):
        return None
    drop = np.zeros(len(points_xz), dtype=np.bool_)
    drop[np.flatnonzero(fit.inliers)[grazing]] = True
    return drop


def fit_arc_in_scene(
    points_xz: ArrayLike,
    ellipse_config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None = None,
    config: ArcConfig | None = None,
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

    Raises
    ------
    ProfileRejected
        No curved segment holds a plausible ellipse; the message of the largest one's fit.
    """
    config = config or ArcConfig()
    p = np.asarray(points_xz, dtype=np.float64)
    segmented = segment_profile(p, config.segmentation)
    sigma = segmented.noise.sigma_m
    threshold = max(ellipse_config.inlier_threshold_m, ARC_NOISE_SIGMAS * sigma)
    scaled = replace(ellipse_config, inlier_threshold_m=threshold)
    candidates = [s for s in segmented.curves() if len(s.indices) >= scaled.min_inliers]
    if not candidates:
        raise ProfileRejected(
            f"no curved piece of at least {scaled.min_inliers} points in the profile "
            f"({len(segmented.lines())} straight pieces set aside as planes, noise "
            f"{sigma * 1e6:.0f} um); the laser line may miss the cylinder"
        )
    best: tuple[EllipseFit, IntArray] | None = None
    first_error: ProfileRejected | None = None
    for segment in candidates:
        try:
            fit = fit_ellipse_ransac(p[segment.indices], scaled, rng, radius_m)
        except ProfileRejected as exc:
            first_error = first_error or exc
            continue
        if best is None or fit.inliers.sum() > best[0].inliers.sum():
            best = (fit, segment.indices)
    if best is None:
        assert first_error is not None
        raise first_error
    fit, rows = best
    drop = _grazing_biased(fit, p[rows], sigma, config)
    if drop is not None:
        try:
            trimmed_fit = fit_ellipse_ransac(p[rows[~drop]], scaled, rng, radius_m)
        except ProfileRejected:
            drop = None
        else:
            fit, rows = trimmed_fit, rows[~drop]
    return ArcFit(
        points_xz=p[rows],
        rows=rows,
        ellipse=fit,
        segmented=segmented,
        trimmed=0 if drop is None else int(drop.sum()),
    )


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


def trimming_note(trimmed: ArrayLike, config: ArcConfig) -> str | None:
    """A note on the grazing-angle points trimmed from the profiles, or None if none were.

    Parameters
    ----------
    trimmed : array-like of int, shape (K,)
        Points trimmed from each profile's arc.
    config : ArcConfig
    """
    counts = np.asarray(trimmed, dtype=np.intp)
    if not counts.any():
        return None
    return (
        f"trimmed the grazing-angle ends of {int(np.count_nonzero(counts))} of {len(counts)} "
        f"arcs ({int(counts.sum())} points seen at more than "
        f"{math.degrees(config.grazing_angle_rad):.0f} deg from the surface normal), because "
        "they sat off the ellipse through the rest of the arc and biased its fit (a laser "
        "spot smeared along a steep surface)"
    )
