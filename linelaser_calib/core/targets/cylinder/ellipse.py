"""Ellipse fitting of one laser profile in the sensor x-z plane (cylinder paper §3.1).

The laser plane cuts the cylinder's side in an ellipse whose semi-minor axis is the
cylinder radius R and whose semi-major axis is R / sin(angle between plane and axis). Its
centre lies on the cylinder axis; that centre is what the paper's cost (eq. 6-12) uses.

Conic convention (paper eq. 4), in metres::

    Q(x, z) = A x^2 + B x z + C z^2 + D x + E z + F = 0

Steps of :func:`fit_ellipse_ransac`:

1. Coordinates are normalised (centred on the points' mean, scaled to unit RMS radius) so
   that every linear system is well conditioned; results are mapped back to metres.
2. RANSAC with MSAC scoring. A hypothesis is the conic through 5 points (null space of a
   5 x 6 system; a batch of hypotheses at once). The 5 points are spread over a random
   window of the scan line, so that samples fall inside the arc even when a table or
   background fills most of the profile. Hypotheses that are not real ellipses, or whose
   size and shape are implausible for a cylinder cut, are dropped before scoring. Each new
   best is locally optimised by a direct fit on its inliers, and the number of hypotheses
   adapts to the share of all-inlier samples. An arc whose direct fit on all its points
   explains each within the profile's measured noise, as most clean arcs' does, needs no
   search: that fit is the start RANSAC would give it (:func:`_whole_arc`).
3. The distance of a point to a conic is the Sampson distance |Q| / |grad Q|, the
   first-order geometric distance, in metres.
4. The best hypothesis is refitted on its inliers: direct least squares
   (:func:`fit_ellipse_direct`, after Fitzgibbon et al. 1999 in the numerically stable form
   of Halir & Flusser 1998), then Levenberg-Marquardt on the Sampson distances, which
   removes the direct fit's bias on short arcs. Inliers are recomputed, with a threshold
   that shrinks towards a few sigma of the measured noise, and the refit repeated until
   they settle.
5. The centre follows eq. 5; the arc coverage is measured in the ellipse's parametric angle.

A profile that gives no trustworthy ellipse raises
:class:`~linelaser_calib.core.errors.ProfileRejected` with the reason and the numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from ...errors import InputError, ProfileRejected
from ...model_check import median
from ...profile.cleaning import MAD_TO_SIGMA
from ...types import BoolArray, FloatArray
from .conic import (
    EllipseGeometry,
    arc_coverage,
    conic_from_matrix,
    conic_matrix,
    design_rows,
    ellipse_geometry,
    normalise_conic,
    refine_geometric,
    sampson_distance,
    sampson_from_rows,
    sampson_jacobian,
    sampson_rows,
    semi_axis_sigmas,
    turning_angle,
)
from .hypotheses import (
    SAMPLE_SIZE,
    IntArray,
    minimal_conics,
    msac_costs,
    required_iterations,
    window_samples,
)


@dataclass(frozen=True)
class EllipseFit:
    """A RANSAC ellipse fitted to one profile in the sensor x-z plane.

    Attributes
    ----------
    centre_xz : ndarray, shape (2,)
        Ellipse centre (x_c, z_c) in the sensor frame, m (paper eq. 5).
    conic : ndarray, shape (6,)
        (A, B, C, D, E, F) of A x^2 + B xz + C z^2 + D x + E z + F = 0, in m units,
        scaled so that F = 1 when F is not ~0 (paper eq. 4).
    semi_axes : ndarray, shape (2,)
        Semi-major and semi-minor axis lengths, m.
    inliers : ndarray of bool, shape (N,)
        Inlier mask over the cleaned points handed to the fit.
    coverage_rad : float
        Angular extent of the inlier arc in the ellipse's parametric angle, rad.
    rms_m : float
        RMS algebraic-to-geometric residual of the inliers, m.
    short : bool
        A short arc (:func:`fit_ellipse_ransac`): its points are a cut of the cylinder, but
        they do not fix the ellipse, so its centre and semi-axes are not measurements.
    """

    centre_xz: FloatArray
    conic: FloatArray
    semi_axes: FloatArray
    inliers: BoolArray
    coverage_rad: float
    rms_m: float
    short: bool = False


#: Rounds of "refit on the inliers, recompute the inliers" after RANSAC.
MAX_REFIT_ROUNDS = 10


#: Floor of the noise-adapted inlier threshold, m (see ``noise_threshold_sigmas``).
MIN_NOISE_THRESHOLD_M = 1e-6


#: Standard errors of a fitted ellipse's semi-axes (:func:`.conic.semi_axis_sigmas`) by
#: which the plausibility bounds widen (:func:`_plausible`).
AXIS_SLACK_SIGMAS = 3.0


#: Semi-axis bounds of a short arc's ellipse (:func:`fit_ellipse_ransac`), m: any ellipse.
ANY_SEMI_AXIS_M = (1e-6, 1e3)


@dataclass(frozen=True)
class EllipseConfig:
    """RANSAC ellipse parameters (SI units).

    Attributes
    ----------
    inlier_threshold_m : float
        Largest Sampson distance of an inlier, m. The default 0.1 mm is 10-20 sigma of a
        5-10 um profiler, so that a hypothesis from 5 noisy points still collects the whole
        arc (its error grows away from the sampled points), yet it is far below the
        millimetre size of reflection spikes and of the step to a table behind the cylinder.
        For a noisier sensor use about 5 times its sigma.
    max_iterations : int
        Upper bound on RANSAC hypotheses.
    local_optimisations : int
        Hypotheses of each batch, best MSAC score first, that are locally optimised (a
        direct fit on their inliers) before they compete for the best. A hypothesis from
        five points of a short window is often poor away from them and scores worse than
        a wrong ellipse through part of the arc and a table behind it, though its local
        optimum is the right ellipse. The default 4 (1 is plain LO-RANSAC) removed every
        such wrong fit in 8500 profiles of random table scenes (bench/accuracy.py scenes;
        6 remained with 1), at ~5 % of the fit time (the fits are batched).
    confidence : float
        Probability of drawing at least one all-inlier sample; sets the adaptive number of
        hypotheses from the best inlier fraction so far.
    batch_size : int
        Hypotheses generated and scored together (vectorised).
    min_inliers : int
        Fewest inliers of an accepted ellipse.
    min_inlier_fraction : float
        Smallest accepted fraction of inliers among the points handed in.
    min_arc_coverage_rad : float
        Smallest accepted angular extent of the inlier arc, rad (parametric angle). The
        centre error grows fast on short arcs: for R = 20 mm, a 60 deg cut (axis ratio
        1.15), 800 points and 5 um noise, the median error is about 200 um at 60 deg,
        50 um at 90 deg, 10 um at 120 deg and 2 um at 180 deg. The default is 60 deg.
    min_semi_axis_m, max_semi_axis_m : float
        Plausible range of both semi-axes, m. The defaults (2 mm, 0.25 m) cover the
        20-100 mm cylinders of the method at any axis ratio up to 5 and exclude the
        needle-thin and the huge flat ellipses that hug a straight table edge.
    max_axis_ratio : float
        Largest semi-major / semi-minor ratio, 1 / sin(angle between laser plane and axis).
        The default 5 allows planes down to 11.5 deg from the axis (the paper's long-axis
        profiles reach a ratio of 3.9).
    radius_tolerance : float
        When the cylinder radius R is given, the semi-minor axis must be within
        ``radius_tolerance * R`` of R and the semi-major axis at least
        ``(1 - radius_tolerance) * R``. Relative, dimensionless.
    min_short_arc_turn_rad : float
        An arc whose ellipse is too short (``min_arc_coverage_rad``), or implausible with
        its tangent turning by less than ``min_arc_coverage_rad``, is kept as a short arc
        when its tangent turns by at least this much from one end to the other, rad (0
        refuses short arcs). Its
        centre and semi-axes are left unused; its points still constrain the surface in the
        joint fit of all profiles. The default 15 deg is a 13 mm wide arc of a 100 mm shaft,
        and 25 times the turn of a profiler's 40 mm line bowed by 50 um, so that a plane's
        profile stays a line.
    noise_threshold_sigmas : float
        After RANSAC, the inlier threshold shrinks to this many robust sigmas of the
        inliers' distances (1.4826 * median), never below 1 um nor above
        ``inlier_threshold_m``, so that table or background points that merely pass within
        0.1 mm of the ellipse where they meet the arc do not bend the fit. 0 keeps
        ``inlier_threshold_m``.
    """

    inlier_threshold_m: float = 1e-4
    max_iterations: int = 1000
    local_optimisations: int = 4
    confidence: float = 0.999
    batch_size: int = 64
    min_inliers: int = 20
    min_inlier_fraction: float = 0.1
    min_arc_coverage_rad: float = math.radians(60.0)
    min_semi_axis_m: float = 2e-3
    max_semi_axis_m: float = 0.25
    max_axis_ratio: float = 5.0
    radius_tolerance: float = 0.1
    min_short_arc_turn_rad: float = math.radians(15.0)
    noise_threshold_sigmas: float = 4.0

    def __post_init__(self) -> None:
        if not self.inlier_threshold_m > 0.0:
            raise ValueError(f"inlier_threshold_m must be > 0 m, got {self.inlier_threshold_m}")
        if self.max_iterations < 1 or self.batch_size < 1 or self.local_optimisations < 1:
            raise ValueError("max_iterations, batch_size and local_optimisations must be >= 1")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if self.min_inliers < SAMPLE_SIZE + 1:
            raise ValueError(f"min_inliers must be >= {SAMPLE_SIZE + 1}, got {self.min_inliers}")
        if not 0.0 <= self.min_inlier_fraction <= 1.0:
            raise ValueError(
                f"min_inlier_fraction must be in [0, 1], got {self.min_inlier_fraction}"
            )
        if not 0.0 <= self.min_arc_coverage_rad <= 2.0 * math.pi:
            raise ValueError(
                f"min_arc_coverage_rad must be in [0, 2 pi], got {self.min_arc_coverage_rad}"
            )
        if not 0.0 < self.min_semi_axis_m < self.max_semi_axis_m:
            raise ValueError(
                "need 0 < min_semi_axis_m < max_semi_axis_m, got "
                f"{self.min_semi_axis_m} and {self.max_semi_axis_m}"
            )
        if not self.max_axis_ratio >= 1.0:
            raise ValueError(f"max_axis_ratio must be >= 1, got {self.max_axis_ratio}")
        if not 0.0 <= self.min_short_arc_turn_rad <= math.pi:
            raise ValueError(
                f"min_short_arc_turn_rad must be in [0, pi], got {self.min_short_arc_turn_rad}"
            )
        if not 0.0 < self.radius_tolerance < 1.0:
            raise ValueError(f"radius_tolerance must be in (0, 1), got {self.radius_tolerance}")
        if not self.noise_threshold_sigmas >= 0.0:
            raise ValueError(
                f"noise_threshold_sigmas must be >= 0, got {self.noise_threshold_sigmas}"
            )


# ----------------------------------------------------------------------------- the fits


@dataclass(frozen=True)
class _Normalisation:
    """Similarity u = (p - mean) / scale that conditions the fits (scale in m)."""

    mean: FloatArray
    scale: float

    @classmethod
    def of(cls, points_xz: FloatArray) -> _Normalisation:
        mean = points_xz.mean(axis=0)
        scale = float(np.sqrt(np.mean(np.sum((points_xz - mean) ** 2, axis=1))))
        return cls(mean, scale)

    def apply(self, points_xz: FloatArray) -> FloatArray:
        return np.asarray((points_xz - self.mean) / self.scale, dtype=np.float64)

    def conic_to_metres(self, conic_u: FloatArray) -> FloatArray:
        """Conic in normalised coordinates -> the same conic in metres (arbitrary scale)."""
        s, (mx, mz) = self.scale, self.mean
        H = np.array([[1 / s, 0, -mx / s], [0, 1 / s, -mz / s], [0, 0, 1]])
        return conic_from_matrix(H.T @ conic_matrix(conic_u) @ H)


def _direct_fit_normalised(u: FloatArray) -> FloatArray | None:
    """Direct least-squares ellipse on normalised points; None if the points admit none.

    See :func:`_direct_fits_normalised`, of which this is the one-fit case.
    """
    conics, ok = _direct_fits_normalised(u, np.ones((1, len(u))))
    return conics[0] if ok[0] else None


def _direct_fits_normalised(u: FloatArray, masks: FloatArray) -> tuple[FloatArray, BoolArray]:
    """Direct least-squares ellipses on subsets of normalised points, in one batch.

    Each fit minimises the algebraic distance sum Q(u_i)^2 over its subset subject to
    4AC - B^2 = 1. The problem is split into the quadratic part a1 = (A, B, C) and the
    linear part a2 = (D, E, F): a2 = T a1 with T = -S3^-1 S2^T eliminates the linear part,
    leaving the 3 x 3 eigenproblem C1^-1 (S1 + S2 T) a1 = mu a1, whose single eigenvector
    with 4AC - B^2 > 0 is the ellipse.

    Parameters
    ----------
    u : ndarray, shape (N, 2)
        Normalised points.
    masks : ndarray, shape (K, N)
        1 for the points of each subset, 0 for the others.

    Returns
    -------
    conics : ndarray, shape (K, 6)
        Unit-norm conics in normalised coordinates (meaningless where not ``ok``).
    ok : ndarray of bool, shape (K,)
        False where the subset admits no ellipse (collinear, degenerate).
    """
    design = design_rows(u)  # (N, 6): the quadratic part's columns, then the linear part's
    scatter = (masks[:, :, None] * design).transpose(0, 2, 1) @ design  # (K, 6, 6)
    S1, S2, S3 = scatter[:, :3, :3], scatter[:, :3, 3:], scatter[:, 3:, 3:]
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = np.asarray(np.linalg.cond(S3) <= 1e12, dtype=np.bool_)
    S3 = np.where(ok[:, None, None], S3, np.eye(3))
    T = -np.linalg.solve(S3, S2.transpose(0, 2, 1))
    M = S1 + S2 @ T
    # Left-multiply by the inverse of C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]].
    reduced = np.stack([M[:, 2] / 2, -M[:, 1], M[:, 0] / 2], axis=1)
    _, vectors = np.linalg.eig(reduced)
    vectors = np.real(vectors)
    constraint = 4 * vectors[:, 0] * vectors[:, 2] - vectors[:, 1] ** 2  # (K, 3)
    ok &= np.any(constraint > 0, axis=1)
    choice = np.argmax(constraint, axis=1)
    a1 = vectors[np.arange(len(vectors)), :, choice]  # (K, 3)
    conics = np.concatenate([a1, np.einsum("kij,kj->ki", T, a1)], axis=1)
    conics /= np.linalg.norm(conics, axis=1, keepdims=True)
    return np.asarray(conics, dtype=np.float64), ok


def fit_ellipse_direct(points_xz: ArrayLike) -> FloatArray:
    """Direct least-squares ellipse through points (Fitzgibbon / Halir-Flusser).

    The fit is done in normalised coordinates and mapped back, so it is exact for points on
    an ellipse and well conditioned at any offset from the origin. It minimises the
    algebraic distance, which biases the ellipse on short noisy arcs;
    :func:`fit_ellipse_ransac` refines it geometrically.

    Parameters
    ----------
    points_xz : array-like, shape (N, 2), N >= 6
        Points in the sensor x-z plane, m.

    Returns
    -------
    conic : ndarray, shape (6,)
        (A, B, C, D, E, F), normalised by :func:`.conic.normalise_conic`.

    Raises
    ------
    InputError
        Wrong shape or non-finite points.
    ProfileRejected
        Fewer than 6 points, or points that admit no ellipse (collinear, degenerate).
    """
    p = _check_points(points_xz, SAMPLE_SIZE + 1)
    norm = _Normalisation.of(p)
    conic_u = _direct_fit_normalised(norm.apply(p)) if norm.scale > 0.0 else None
    if conic_u is None:
        raise ProfileRejected(
            f"no ellipse fits the {len(p)} points (they are collinear or coincide)"
        )
    return normalise_conic(norm.conic_to_metres(conic_u), _length_scale(p))


def _check_points(points_xz: ArrayLike, min_count: int) -> FloatArray:
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"points_xz must have shape (N, 2), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise InputError("points_xz contains NaN or Inf: clean the profile first")
    if len(p) < min_count:
        raise ProfileRejected(f"only {len(p)} points, an ellipse fit needs at least {min_count}")
    return p


def _length_scale(points_xz: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.sum(points_xz**2, axis=1))))


def refine_conic(conic: ArrayLike, points_xz: ArrayLike) -> FloatArray:
    """Sampson-distance least squares ellipse through points, from a start conic.

    The geometric polish of :func:`fit_ellipse_ransac` on its own: for a subset of a
    fitted arc's inliers, without a new RANSAC.

    Parameters
    ----------
    conic : array-like, shape (6,)
        Start conic (A, B, C, D, E, F) in metres.
    points_xz : array-like, shape (N, 2), N >= 6
        Points in the sensor x-z plane, m.

    Returns
    -------
    conic : ndarray, shape (6,)
        Normalised by :func:`.conic.normalise_conic`; the start if the optimum is no ellipse.
    """
    p = _check_points(points_xz, SAMPLE_SIZE + 1)
    norm = _Normalisation.of(p)
    (mx, mz), s = norm.mean, norm.scale
    to_metres = np.array([[s, 0.0, mx], [0.0, s, mz], [0.0, 0.0, 1.0]])
    start = conic_from_matrix(to_metres.T @ conic_matrix(conic) @ to_metres)
    refined = refine_geometric(start, norm.apply(p)).conic
    return normalise_conic(norm.conic_to_metres(refined), _length_scale(p))


# --------------------------------------------------------------------------------- RANSAC


def _plausible(
    geometry: EllipseGeometry,
    scale_m: float,
    config: EllipseConfig,
    radius_m: float | None,
    slack_m: tuple[float, float] = (0.0, 0.0),
) -> BoolArray:
    """Ellipses whose size and shape fit a cylinder cut; ``scale_m`` maps lengths to m.

    ``slack_m`` (semi-major, semi-minor, m) widens every bound by that much of each axis:
    the axes' uncertainty (:func:`.conic.semi_axis_sigmas`), so that a short arc whose axes
    the points hardly fix is judged by what they allow, not by its best-fitting values.
    """
    major, minor = geometry.semi_axes[..., 0] * scale_m, geometry.semi_axes[..., 1] * scale_m
    major_low, minor_high = major - slack_m[0], minor + slack_m[1]
    with np.errstate(invalid="ignore"):
        ok = geometry.valid & (minor_high >= config.min_semi_axis_m)
        ok &= (major_low <= config.max_semi_axis_m) & (
            major_low <= config.max_axis_ratio * minor_high
        )
        if radius_m is not None:
            tolerance = config.radius_tolerance * radius_m
            ok &= np.abs(minor - radius_m) <= tolerance + slack_m[1]
            ok &= major + slack_m[0] >= radius_m - tolerance
    return np.asarray(ok, dtype=np.bool_)


def _ransac(
    u: FloatArray,
    norm: _Normalisation,
    config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None,
) -> FloatArray | None:
    """Best plausible ellipse by MSAC on normalised points; None if none is plausible.

    MSAC scores a hypothesis by sum(min(d^2, t^2)) over the points (d the Sampson
    distance, t the inlier threshold), which prefers tight fits among equal inlier counts.
    The ``config.local_optimisations`` best hypotheses of each batch are locally optimised
    (LO-RANSAC): the direct fit on a hypothesis's inliers replaces it when that scores
    better. The number of hypotheses adapts to the best hypothesis: the chance that one
    sample gives a usable hypothesis is estimated as the share of the samples drawn so far
    that are all inliers of the best and gave a plausible ellipse (valid for any sampler).
    Counting plausible hypotheses only matters when the best is a wrong ellipse that hugs a
    straight table line: windows on the line are all its inliers but give degenerate
    conics, and counting them would stop the search before the arc is found.
    """
    threshold_sq = (config.inlier_threshold_m / norm.scale) ** 2
    order = np.argsort(u[:, 0], kind="stable")
    best_cost = math.inf
    best: FloatArray | None = None
    useful: list[IntArray] = []  # samples whose hypothesis was plausible
    drawn = 0
    needed = float(config.max_iterations)
    while drawn < min(needed, config.max_iterations):
        samples = window_samples(order, config.batch_size, rng)
        drawn += config.batch_size
        distinct = np.all(np.diff(np.sort(samples, axis=1), axis=1) > 0, axis=1)
        conics = minimal_conics(u, samples[distinct])
        plausible = _plausible(ellipse_geometry(conics), norm.scale, config, radius_m)
        conics = conics[plausible]
        useful.append(samples[distinct][plausible])
        if len(conics) == 0:
            continue
        d2 = msac_costs(conics, u, threshold_sq)
        top = np.argsort(d2.sum(axis=1))[: config.local_optimisations]
        conics, d2 = conics[top], d2[top]
        inlier_masks = d2 < threshold_sq
        refits, ok = _direct_fits_normalised(u, inlier_masks.astype(np.float64))
        ok &= inlier_masks.sum(axis=1) > SAMPLE_SIZE
        ok &= _plausible(ellipse_geometry(refits), norm.scale, config, radius_m)
        refit_d2 = msac_costs(refits, u, threshold_sq)
        better = ok & (refit_d2.sum(axis=1) < d2.sum(axis=1))
        conics[better], d2[better] = refits[better], refit_d2[better]
        costs = d2.sum(axis=1)
        i = int(np.argmin(costs))
        if costs[i] >= best_cost:
            continue
        best_cost, best, best_d2 = float(costs[i]), conics[i], d2[i]
        inliers = best_d2 < threshold_sq
        all_inlier = sum(int(np.all(inliers[s], axis=1).sum()) for s in useful)
        needed = required_iterations(all_inlier / drawn, config.confidence)
    return best


def fit_ellipse_ransac(
    points_xz: ArrayLike,
    config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None = None,
    noise_sigma_m: float | None = None,
) -> EllipseFit:
    """Robust ellipse fit of one profile (paper eq. 4) and its centre (eq. 5).

    RANSAC finds the arc among outliers; the best hypothesis is refitted on its inliers
    (direct fit, then Levenberg-Marquardt on the Sampson distances) until the inlier set
    settles, the inlier threshold shrinking towards ``config.noise_threshold_sigmas``
    robust sigmas. The centre is taken from the final conic by eq. 5.

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Cleaned profile points (x, z) in the sensor frame, m.
    config : EllipseConfig
    rng : numpy.random.Generator
        Source of the random samples; the result is deterministic given its state.
    radius_m : float or None
        Cylinder radius, m, when known: hypotheses must then have a semi-minor axis within
        ``config.radius_tolerance`` of it (when none has, the search runs again without),
        and the result's semi-minor axis must lie within that tolerance plus its
        uncertainty of it.
    noise_sigma_m : float or None
        The profile's point noise, 1σ, m, when measured
        (:func:`~linelaser_calib.core.profile.segmentation.estimate_noise`): an arc whose
        direct fit explains every point within ``config.noise_threshold_sigmas`` of it starts
        the refits without RANSAC (the start RANSAC gives such an arc, found without its
        hypotheses; :func:`_whole_arc`). None: RANSAC always searches.

    Returns
    -------
    EllipseFit
        ``inliers`` is a mask over ``points_xz``; ``rms_m`` is the RMS Sampson distance of
        the inliers, m; ``coverage_rad`` is in the ellipse's parametric angle. A plausible
        ellipse whose arc is shorter than ``config.min_arc_coverage_rad`` is returned as a
        short arc (``short``) when its tangent turns by ``config.min_short_arc_turn_rad``
        or more: its points are a cut of the cylinder, only its centre is unreliable. (How
        far the tangent turns does not measure the coverage: about the ends of the major
        axis it turns faster than the parametric angle, and a thinned arc covering 58.4 deg
        whose tangent turned by 83 deg was rejected whole.) An arc with no plausible
        ellipse is fitted again with any ellipse and no radius, and returned as a short
        arc when its tangent turns by ``config.min_short_arc_turn_rad`` or more and by
        less than ``config.min_arc_coverage_rad`` (a longer arc fixes its ellipse: the
        first rejection stands). So is an arc turning by that much whose plausible ellipse has a
        semi-minor axis uncertain by more than ``config.radius_tolerance``
        (:data:`AXIS_SLACK_SIGMAS` standard errors): a wrong small ellipse through a short
        noisy arc can pass the coverage and the size bounds.

    Raises
    ------
    InputError
        Wrong shape, non-finite points or a non-positive radius.
    ProfileRejected
        Too few points or inliers, or no plausible ellipse and no short arc; the message
        gives the numbers.
    """
    p = _check_points(points_xz, config.min_inliers)
    if radius_m is not None and not (math.isfinite(radius_m) and radius_m > 0.0):
        raise InputError(f"radius_m must be a positive length in m, got {radius_m}")
    norm = _Normalisation.of(p)
    if not norm.scale > 0.0:
        raise ProfileRejected(f"all {len(p)} points coincide: no ellipse can be fitted")
    try:
        fit = _fit(p, norm, config, rng, radius_m, noise_sigma_m)
    except _TooShortForItsCentre as exc:
        if config.min_short_arc_turn_rad <= 0.0:
            raise
        return _short_arc(exc.fit, p, config, str(exc))
    except _NoPlausibleArc as exc:
        if config.min_short_arc_turn_rad <= 0.0:
            raise
        try:
            fit = _fit(p, norm, _any_ellipse(config), rng, None, noise_sigma_m)
        except ProfileRejected:
            raise exc from None
        if turning_angle(fit.conic, p[fit.inliers]) >= config.min_arc_coverage_rad:
            raise  # a long arc: its points fix the ellipse, which is no cylinder's
        return _short_arc(fit, p, config, str(exc))
    if not fit.short or config.min_short_arc_turn_rad <= 0.0:
        return replace(fit, short=False)
    turn = turning_angle(fit.conic, p[fit.inliers])
    if turn >= config.min_arc_coverage_rad:
        return replace(fit, short=False)
    if turn < config.min_short_arc_turn_rad:
        raise ProfileRejected(
            f"the arc's tangent turns by only {math.degrees(turn):.1f} deg, and its "
            f"ellipse's semi-minor axis is uncertain ({fit.semi_axes[1] * 1e3:.2f} mm ± more "
            f"than {100.0 * config.radius_tolerance / AXIS_SLACK_SIGMAS:.1f}%, 1 sigma): it "
            f"is not a short arc ({math.degrees(config.min_short_arc_turn_rad):.1f} deg)"
        )
    return fit


def _short_arc(fit: EllipseFit, p: FloatArray, config: EllipseConfig, why: str) -> EllipseFit:
    """``fit`` as a short arc, or :class:`ProfileRejected` (``why`` and the turn) where its
    tangent turns by less than ``config.min_short_arc_turn_rad``."""
    turn = turning_angle(fit.conic, p[fit.inliers])
    if turn < config.min_short_arc_turn_rad:
        raise ProfileRejected(
            f"{why}; nor is it a short arc: its tangent turns by {math.degrees(turn):.1f} deg, "
            f"below the {math.degrees(config.min_short_arc_turn_rad):.1f} deg of a short arc"
        )
    return replace(fit, short=True)


class _NoPlausibleArc(ProfileRejected):
    """No plausible ellipse, or an arc too short for its centre (a short arc may remain)."""


class _TooShortForItsCentre(_NoPlausibleArc):
    """A plausible cylinder cut (``fit``) whose arc covers less than its centre needs."""

    def __init__(self, message: str, fit: EllipseFit) -> None:
        super().__init__(message)
        self.fit = fit


def _any_ellipse(config: EllipseConfig) -> EllipseConfig:
    """``config`` taking any real ellipse of any arc: a short arc's fit, whose points leave
    the size and the shape free (:func:`fit_ellipse_ransac`)."""
    return replace(
        config,
        min_semi_axis_m=ANY_SEMI_AXIS_M[0],
        max_semi_axis_m=ANY_SEMI_AXIS_M[1],
        max_axis_ratio=math.inf,
        min_arc_coverage_rad=0.0,
    )


def _fit(
    p: FloatArray,
    norm: _Normalisation,
    config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None,
    noise_sigma_m: float | None,
) -> EllipseFit:
    """:func:`fit_ellipse_ransac` without the short arcs: :class:`_NoPlausibleArc` when no
    plausible ellipse or too short an arc is found; ``short`` marks a fit whose semi-minor
    axis is uncertain by more than ``config.radius_tolerance`` (:data:`AXIS_SLACK_SIGMAS`
    standard errors)."""
    u = norm.apply(p)
    rows = sampson_rows(u)
    threshold_u = config.inlier_threshold_m / norm.scale
    start = _whole_arc(u, rows, norm, config, radius_m, noise_sigma_m)
    if start is not None:
        conic_u, inliers = start, np.ones(len(u), dtype=np.bool_)
    else:
        conic_u, inliers = _ransac_start(u, norm, config, rng, radius_m)
    refined_on = np.zeros(0, dtype=np.bool_)  # the inliers of the last refit: none yet
    for _ in range(MAX_REFIT_ROUNDS):
        if not np.array_equal(inliers, refined_on):
            # Only new inliers are refitted: on the same ones the optimum stays where it is.
            refined, refined_on = refine_geometric(conic_u, u[inliers], rows[:, inliers]), inliers
            conic_u = refined.conic
            distance = np.abs(sampson_from_rows(conic_u, rows))
            spread_u = median(distance[inliers]) if config.noise_threshold_sigmas > 0.0 else 0.0
        settled = True
        if config.noise_threshold_sigmas > 0.0:
            sigma_m = MAD_TO_SIGMA * spread_u * norm.scale
            target_u = max(config.noise_threshold_sigmas * sigma_m, MIN_NOISE_THRESHOLD_M)
            target_u /= norm.scale
            # Halve at most per round, so that a start bent by outliers can straighten.
            threshold_u = min(threshold_u, max(target_u, threshold_u / 2))
            settled = threshold_u <= target_u
        new_inliers = distance < threshold_u
        if new_inliers.sum() <= SAMPLE_SIZE:
            break
        if settled and np.array_equal(new_inliers, inliers):
            break
        inliers = new_inliers

    count = int(inliers.sum())
    if count < max(config.min_inliers, config.min_inlier_fraction * len(p)):
        raise ProfileRejected(
            f"only {count} of {len(p)} points ({100.0 * count / len(p):.0f}%) lie within "
            f"{config.inlier_threshold_m * 1e6:.0f} um of the best ellipse; at least "
            f"{config.min_inliers} and {100.0 * config.min_inlier_fraction:.0f}% are needed"
        )
    geometry_u = ellipse_geometry(conic_u)
    slack = (0.0, 0.0)
    if geometry_u.valid:  # the last refit's Jacobian where it was on these inliers
        unit = conic_u / np.linalg.norm(conic_u)
        residual, jacobian = refined.residual, refined.jacobian
        if residual is None or jacobian is None or not np.array_equal(inliers, refined_on):
            residual, jacobian = sampson_jacobian(unit, rows[:, inliers])
        major, minor = AXIS_SLACK_SIGMAS * semi_axis_sigmas(unit, residual, jacobian) * norm.scale
        slack = (float(major), float(minor))
    if not _plausible(geometry_u, norm.scale, config, radius_m, slack):
        major, minor = geometry_u.semi_axes * norm.scale * 1e3
        sigma_major, sigma_minor = np.asarray(slack) * 1e3 / AXIS_SLACK_SIGMAS
        raise _NoPlausibleArc(
            f"the refitted ellipse (semi-axes {major:.2f} ± {sigma_major:.2f} mm and "
            f"{minor:.2f} ± {sigma_minor:.2f} mm, 1 sigma) is not a plausible cylinder "
            f"cut{_near_radius(radius_m)}"
        )
    geometry = EllipseGeometry(
        valid=geometry_u.valid,
        centre=norm.mean + norm.scale * geometry_u.centre,
        semi_axes=geometry_u.semi_axes * norm.scale,
        major_axis=geometry_u.major_axis,
    )
    coverage = arc_coverage(geometry, p[inliers])
    rms = float(np.sqrt(np.mean(distance[inliers] ** 2))) * norm.scale
    uncertain = slack[1] > config.radius_tolerance * geometry.semi_axes[1]
    fit = EllipseFit(
        centre_xz=np.asarray(geometry.centre, dtype=np.float64),
        conic=normalise_conic(norm.conic_to_metres(conic_u), _length_scale(p)),
        semi_axes=np.asarray(geometry.semi_axes, dtype=np.float64),
        inliers=inliers,
        coverage_rad=coverage,
        rms_m=rms,
        short=bool(uncertain),
    )
    if coverage < config.min_arc_coverage_rad:
        raise _TooShortForItsCentre(
            f"the ellipse arc covers only {math.degrees(coverage):.1f} deg, below the "
            f"{math.degrees(config.min_arc_coverage_rad):.1f} deg needed for a reliable "
            "centre; aim the laser line across more of the cylinder",
            fit,
        )
    return fit


def _near_radius(radius_m: float | None) -> str:
    """ " with semi-minor axis near R mm" for a given radius, for the rejections' messages."""
    return "" if radius_m is None else f" with semi-minor axis near {radius_m * 1e3:.2f} mm"


def _whole_arc(
    u: FloatArray,
    rows: FloatArray,
    norm: _Normalisation,
    config: EllipseConfig,
    radius_m: float | None,
    noise_sigma_m: float | None,
) -> FloatArray | None:
    """The direct fit of all the points (normalised; ``rows`` their
    :func:`.conic.sampson_rows`) when it explains each of them within
    the profile's noise, else None: RANSAC must then search.

    It is the start RANSAC itself gives a clean arc (its best hypothesis then holds every
    point, and its local optimisation is this fit), found without drawing a hypothesis. A
    point counts as explained within ``config.noise_threshold_sigmas`` times the measured
    point noise ``noise_sigma_m`` (m; the rule the refits' inliers end with, with the noise
    measured from neighbouring points rather than from the fit's own residuals, which shape
    error, clutter or smeared grazing ends pulling the fit would inflate), and within the
    inlier threshold; the ellipse must be plausible as RANSAC's hypotheses must. None when
    no noise is given or ``config.noise_threshold_sigmas`` is 0.
    """
    if noise_sigma_m is None or config.noise_threshold_sigmas <= 0.0:
        return None
    limit_m = min(config.noise_threshold_sigmas * noise_sigma_m, config.inlier_threshold_m)
    conic_u = _direct_fit_normalised(u)
    if (
        conic_u is None
        or float(np.max(np.abs(sampson_from_rows(conic_u, rows)))) > limit_m / norm.scale
    ):
        return None
    return conic_u if _plausible(ellipse_geometry(conic_u), norm.scale, config, radius_m) else None


def _ransac_start(
    u: FloatArray,
    norm: _Normalisation,
    config: EllipseConfig,
    rng: np.random.Generator,
    radius_m: float | None,
) -> tuple[FloatArray, BoolArray]:
    """RANSAC's ellipse (normalised) refitted directly on its inliers, and those inliers;
    :class:`_NoPlausibleArc` when no hypothesis is a plausible ellipse."""
    conic_u = _ransac(u, norm, config, rng, radius_m)
    if conic_u is None and radius_m is not None:
        # No hypothesis from five points has a semi-minor axis near the radius: on a short
        # arc they scatter widely; the refitted ellipse is judged with its axes' uncertainty.
        conic_u = _ransac(u, norm, config, rng, None)
    if conic_u is None:
        raise _NoPlausibleArc(
            f"no plausible ellipse{_near_radius(radius_m)} among {config.max_iterations} "
            f"RANSAC hypotheses on {len(u)} points (semi-axes "
            f"{config.min_semi_axis_m * 1e3:.1f}-{config.max_semi_axis_m * 1e3:.0f} mm, axis "
            f"ratio <= {config.max_axis_ratio:.1f}); the profile may not show the cylinder, or "
            "the radius is wrong"
        )
    inliers = np.abs(sampson_distance(conic_u, u)) < config.inlier_threshold_m / norm.scale
    direct = _direct_fit_normalised(u[inliers]) if inliers.sum() > SAMPLE_SIZE else None
    return (conic_u if direct is None else direct), inliers
