"""Circle fitting of one laser profile of a sphere, in the sensor x-z plane.

The laser plane (sensor y = 0) cuts a sphere of radius R in a circle of radius r ≤ R whose
centre is the foot of the sphere centre on the plane. :func:`fit_circle_ransac` finds that
circle in a profile that may also hold spikes, a table or a holder:

1. RANSAC: a hypothesis is the circle through three points drawn from a random window of
   the scan line (so that samples fall inside the arc even when background fills most of the
   profile); it is scored by its inliers within a first, coarse threshold.
2. The best hypothesis is refitted on its inliers: algebraic (Kåsa) least squares, then
   Gauss-Newton on the geometric distances |p − centre| − r, which removes the algebraic
   fit's bias on short arcs.
3. The noise is measured from the refit's residuals (1.4826 · MAD) and the inlier threshold
   shrinks to ``inlier_sigmas`` times it (never below ``min_threshold_m``); refit and
   threshold repeat until the inliers settle. The threshold thus follows the profiler's own
   noise, whatever it is.

Whether the circle is the right model for the profile is judged apart, against rival
shapes and the recording's other profiles (:mod:`.shape`).

A profile that gives no trustworthy circle raises
:class:`~linelaser_calib.core.errors.ProfileRejected` with the reason and the numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.errors import InputError, ProfileRejected
from linelaser_calib.core.profile.cleaning import MAD_TO_SIGMA
from linelaser_calib.core.types import BoolArray, FloatArray

#: Rounds of "refit on the inliers, recompute the threshold and the inliers".
MAX_REFIT_ROUNDS = 8
#: Gauss-Newton iterations of the geometric refit.
GEOMETRIC_ITERATIONS = 20
#: How every rejection for the profile's shape begins (the target counts them to tell a
#: wrong target from a few bad profiles).
NOT_A_CIRCLE = "not a circular arc"


@dataclass(frozen=True)
class CircleConfig:
    """Settings of the per-profile circle fit.

    Attributes
    ----------
    iterations : int
        RANSAC hypotheses. Default 300.
    coarse_threshold_m : float
        Inlier distance of the RANSAC scoring, m. Default 0.3 mm: wide enough for any
        profiler's noise, narrow enough to leave out spikes and a background.
    inlier_sigmas : float
        Final inlier threshold in units of the measured noise. Default 4.
    min_threshold_m : float
        Floor of the final threshold, m. Default 2 µm.
    min_points : int
        Fewest inliers. Default 30.
    min_inlier_fraction : float
        Fewest inliers as a share of the profile's points. Default 0.3.
    min_arc_rad : float
        Shortest accepted arc, seen from the circle centre, rad. Default 10 deg.
    window_fraction : float
        Width of the window the three sample points are drawn from, as a share of the
        profile's points. Default 0.5.
    """

    iterations: int = 300
    coarse_threshold_m: float = 3e-4
    inlier_sigmas: float = 4.0
    min_threshold_m: float = 2e-6
    min_points: int = 30
    min_inlier_fraction: float = 0.3
    min_arc_rad: float = math.radians(10.0)
    window_fraction: float = 0.5

    def __post_init__(self) -> None:
        positive = {
            "coarse_threshold_m": self.coarse_threshold_m,
            "inlier_sigmas": self.inlier_sigmas,
            "min_threshold_m": self.min_threshold_m,
            "min_arc_rad": self.min_arc_rad,
            "window_fraction": self.window_fraction,
        }
        for name, value in positive.items():
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"CircleConfig.{name} must be positive, got {value}")
        if self.iterations < 1 or self.min_points < 3:
            raise InputError("CircleConfig.iterations must be >= 1 and min_points >= 3")
        if not 0.0 <= self.min_inlier_fraction <= 1.0:
            raise InputError("CircleConfig.min_inlier_fraction must be in [0, 1]")


@dataclass(frozen=True)
class CircleFit:
    """A circle fitted to one profile in the sensor x-z plane.

    Attributes
    ----------
    centre_xz : ndarray, shape (2,)
        Circle centre (x, z) in the sensor frame, m.
    radius_m : float
        Circle radius r, m.
    inliers : ndarray of bool, shape (N,)
        Inlier mask over the points handed to the fit.
    rms_m : float
        RMS geometric residual of the inliers, m.
    arc_rad : float
        Angle the inlier arc spans, seen from the centre, rad.
    """

    centre_xz: FloatArray
    radius_m: float
    inliers: BoolArray
    rms_m: float
    arc_rad: float


def circle_residuals(points_xz: FloatArray, centre_xz: FloatArray, radius_m: float) -> FloatArray:
    """Signed geometric distances (N,) of points (N, 2) from a circle, m (outside positive)."""
    return np.asarray(np.linalg.norm(points_xz - centre_xz, axis=1) - radius_m)


def fit_circle_algebraic(points_xz: ArrayLike) -> tuple[FloatArray, float]:
    """Kåsa least-squares circle through points (N ≥ 3, 2), m; centred for conditioning.

    Returns the centre (2,) and the radius, m. Raises ``ValueError`` for collinear points.
    """
    p = np.asarray(points_xz, dtype=np.float64)
    mean = p.mean(axis=0)
    q = p - mean
    A = np.column_stack([2.0 * q, np.ones(len(q))])
    b = np.sum(q * q, axis=1)
    solution, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    if rank < 3:
        raise ValueError("the points are collinear: no circle passes through them")
    centre = solution[:2]
    radius_sq = float(solution[2] + centre @ centre)
    if radius_sq <= 0.0:
        raise ValueError("the points give no real circle")
    return np.asarray(centre + mean), math.sqrt(radius_sq)


def fit_circle_geometric(
    points_xz: FloatArray, centre_xz: FloatArray, radius_m: float
) -> tuple[FloatArray, float]:
    """Gauss-Newton on the geometric distances from a start circle; returns centre (2,), r."""
    c, r = np.asarray(centre_xz, dtype=np.float64).copy(), float(radius_m)
    for _ in range(GEOMETRIC_ITERATIONS):
        d = points_xz - c
        dist = np.linalg.norm(d, axis=1)
        residual = dist - r
        J = np.column_stack([-d / dist[:, None], -np.ones(len(d))])
        step, *_ = np.linalg.lstsq(J, -residual, rcond=None)
        c, r = c + step[:2], r + float(step[2])
        if float(np.max(np.abs(step))) < 1e-13:
            break
    return c, r


def _arc_span(points_xz: FloatArray, centre_xz: FloatArray) -> float:
    """Angle (rad) spanned by points seen from a centre: 2π minus the largest empty gap."""
    angles = np.sort(np.arctan2(points_xz[:, 1] - centre_xz[1], points_xz[:, 0] - centre_xz[0]))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2.0 * math.pi]))
    return float(2.0 * math.pi - np.max(gaps))


def _hypotheses(
    points_xz: FloatArray, config: CircleConfig, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """Circles through three window-sampled points: centres (H, 2) and radii (H,)."""
    n = len(points_xz)
    window = max(3, int(config.window_fraction * n))
    start = rng.integers(0, n - window + 1, size=config.iterations)
    picks = np.sort(start[:, None] + rng.integers(0, window, size=(config.iterations, 3)), axis=1)
    a, b, c = (points_xz[picks[:, k]] for k in range(3))
    # Circumcentre of each triangle (a, b, c).
    ab, ac = b - a, c - a
    det = 2.0 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
    ok = np.abs(det) > 1e-18
    det = np.where(ok, det, 1.0)
    ab2, ac2 = np.sum(ab * ab, axis=1), np.sum(ac * ac, axis=1)
    ux = (ac[:, 1] * ab2 - ab[:, 1] * ac2) / det
    uz = (ab[:, 0] * ac2 - ac[:, 0] * ab2) / det
    centres = a + np.column_stack([ux, uz])
    radii = np.hypot(ux, uz)
    return centres[ok], radii[ok]


def fit_circle_ransac(
    points_xz: ArrayLike,
    config: CircleConfig,
    rng: np.random.Generator,
    max_radius_m: float | None = None,
) -> CircleFit:
    """Fit a circle to one profile (points in scan order) robustly; see the module docstring.

    Parameters
    ----------
    points_xz : array-like, shape (N, 2)
        Cleaned profile points (x, z) in the sensor frame, m, in scan order.
    config : CircleConfig
    rng : numpy.random.Generator
    max_radius_m : float, optional
        Hypotheses with a larger radius are not considered (the sphere radius, with a margin,
        when it is known), m.

    Raises
    ------
    ProfileRejected
        Too few points, no circle with enough inliers, or an arc too short.
    """
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"profile points must have shape (N, 2), got {p.shape}")
    if len(p) < config.min_points:
        raise ProfileRejected(
            f"only {len(p)} points, a circle fit needs at least {config.min_points}"
        )
    centres, radii = _hypotheses(p, config, rng)
    if max_radius_m is not None:
        keep = radii <= max_radius_m
        centres, radii = centres[keep], radii[keep]
    if len(radii) == 0:
        raise ProfileRejected(f"{NOT_A_CIRCLE}: every three-point circle was degenerate")
    # Score in chunks to bound memory: (H, N) distances.
    best, best_count = 0, -1
    for lo in range(0, len(radii), 64):
        d = np.abs(
            np.linalg.norm(p[None] - centres[lo : lo + 64, None], axis=2)
            - radii[lo : lo + 64, None]
        )
        counts = np.sum(d < config.coarse_threshold_m, axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best, best_count = lo + k, int(counts[k])
    centre, radius = centres[best], float(radii[best])
    threshold = config.coarse_threshold_m
    inliers = np.abs(circle_residuals(p, centre, radius)) < threshold
    for _ in range(MAX_REFIT_ROUNDS):
        if int(inliers.sum()) < config.min_points:
            break
        try:
            centre, radius = fit_circle_algebraic(p[inliers])
        except ValueError as exc:
            raise ProfileRejected(f"{NOT_A_CIRCLE}: {exc}") from None
        centre, radius = fit_circle_geometric(p[inliers], centre, radius)
        residual = circle_residuals(p, centre, radius)
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(residual[inliers])))
        threshold = min(threshold, max(config.inlier_sigmas * sigma, config.min_threshold_m))
        updated = np.abs(residual) < threshold
        if np.array_equal(updated, inliers):
            break
        inliers = updated
    count = int(inliers.sum())
    if count < max(config.min_points, config.min_inlier_fraction * len(p)):
        raise ProfileRejected(
            f"{NOT_A_CIRCLE}: the best circle holds {count} of {len(p)} points (needs "
            f"{max(config.min_points, math.ceil(config.min_inlier_fraction * len(p)))})"
        )
    arc = _arc_span(p[inliers], centre)
    if arc < config.min_arc_rad:
        raise ProfileRejected(
            f"arc too short: {math.degrees(arc):.1f} deg of the circle (radius "
            f"{radius * 1e3:.2f} mm), needs {math.degrees(config.min_arc_rad):.0f} deg"
        )
    residual = circle_residuals(p[inliers], centre, radius)
    return CircleFit(
        centre_xz=np.asarray(centre),
        radius_m=float(radius),
        inliers=inliers,
        rms_m=float(np.sqrt(np.mean(residual**2))),
        arc_rad=arc,
    )
