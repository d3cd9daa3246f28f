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
   the ellipse differs from zero by more than ``GRAZING_BIAS_SIGMAS`` standard errors (and
   half a noise sigma). A camera's laser spot smears along a steep surface, and its
   centroid moves: the ends then pull the radius and the centre. The result says so.

If no candidate gives an ellipse, the rejection of the largest candidate is raised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from .ellipse import EllipseConfig, fit_ellipse_ransac, sampson_distance
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
    residual = _signed_distance(fit.conic, inliers)
    front = residual[~grazing]
    shift = abs(float(np.mean(residual[grazing])) - float(np.median(front)))
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
