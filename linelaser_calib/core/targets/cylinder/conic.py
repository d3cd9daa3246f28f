"""Conic algebra in the sensor x-z plane: matrices, centres, ellipse geometry, distances,
an arc's extent on a conic, and the geometric (Sampson-distance) refinement of a conic.

Conic convention (cylinder paper eq. 4), in the points' units (m)::

    Q(x, z) = A x^2 + B x z + C z^2 + D x + E z + F = 0

The RANSAC fits that produce conics are in :mod:`.ellipse`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg.lapack import dgesv

from ...model_check import effective_count, robust_scale_m
from ...types import BoolArray, FloatArray

#: An F smaller than this times the conic's size at the points counts as ~0 (see
#: :func:`normalise_conic`): the ellipse then passes within ~1e-9 of the origin.
F_ZERO_TOLERANCE = 1e-9


def conic_matrix(conic: ArrayLike) -> FloatArray:
    """Symmetric 3 x 3 matrix of a conic, so that Q(x, z) = [x z 1] M [x z 1]^T.

    Parameters
    ----------
    conic : array-like, shape (..., 6)
        (A, B, C, D, E, F).

    Returns
    -------
    M : ndarray, shape (..., 3, 3)
    """
    k = np.asarray(conic, dtype=np.float64)
    half = k / 2
    M = np.empty((*k.shape[:-1], 3, 3))
    M[..., 0, 0], M[..., 1, 1], M[..., 2, 2] = k[..., 0], k[..., 2], k[..., 5]
    M[..., 0, 1] = M[..., 1, 0] = half[..., 1]
    M[..., 0, 2] = M[..., 2, 0] = half[..., 3]
    M[..., 1, 2] = M[..., 2, 1] = half[..., 4]
    return M


def conic_from_matrix(M: ArrayLike) -> FloatArray:
    """Inverse of :func:`conic_matrix`: (A, B, C, D, E, F), shape (..., 6)."""
    M = np.asarray(M, dtype=np.float64)
    return np.stack(
        [
            M[..., 0, 0],
            2 * M[..., 0, 1],
            M[..., 1, 1],
            2 * M[..., 0, 2],
            2 * M[..., 1, 2],
            M[..., 2, 2],
        ],
        axis=-1,
    )


def centre_from_conic(conic: ArrayLike) -> FloatArray:
    """Centre of a central conic by the paper's eq. 5.

    ``x_c = (B E - 2 C D) / (4 A C - B^2)``, ``z_c = (B D - 2 A E) / (4 A C - B^2)``.
    Numerator and denominator are both quadratic in the coefficients, so the formula holds
    for any scaling of the conic, not only for F = 1. It is Cramer's rule on grad Q = 0
    (:func:`centre_from_gradient`).

    Parameters
    ----------
    conic : array-like, shape (..., 6)

    Returns
    -------
    centre_xz : ndarray, shape (..., 2)
        NaN/Inf where 4AC - B^2 = 0 (a parabola has no centre).
    """
    a, b, c, d, e, _ = np.moveaxis(np.asarray(conic, dtype=np.float64), -1, 0)
    det = 4 * a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([(b * e - 2 * c * d) / det, (b * d - 2 * a * e) / det], axis=-1)


def centre_from_gradient(conic: ArrayLike) -> FloatArray:
    """Centre of a central conic as the point where grad Q = 0.

    Solves ``[[2A, B], [B, 2C]] [x, z]^T = -[D, E]^T``; the general form of eq. 5.

    Parameters
    ----------
    conic : array-like, shape (6,)

    Returns
    -------
    centre_xz : ndarray, shape (2,)
    """
    a, b, c, d, e, _ = np.asarray(conic, dtype=np.float64)
    return np.asarray(np.linalg.solve([[2 * a, b], [b, 2 * c]], [-d, -e]), dtype=np.float64)


@dataclass(frozen=True)
class EllipseGeometry:
    """Geometric form of ellipses (batched: leading shape ``...``).

    Attributes
    ----------
    valid : ndarray of bool, shape (...)
        True where the conic is a real, non-degenerate ellipse.
    centre : ndarray, shape (..., 2)
    semi_axes : ndarray, shape (..., 2)
        Semi-major, semi-minor.
    major_axis : ndarray, shape (..., 2)
        Unit direction of the major axis.
    """

    valid: BoolArray
    centre: FloatArray
    semi_axes: FloatArray
    major_axis: FloatArray


def ellipse_geometry(conic: ArrayLike) -> EllipseGeometry:
    """Centre, semi-axes and orientation of conics; flags those that are not ellipses.

    A conic is a real ellipse when 4AC - B^2 > 0 and Q at the centre has the sign opposite
    to A + C (otherwise it is empty or a point).

    Parameters
    ----------
    conic : array-like, shape (..., 6)

    Returns
    -------
    EllipseGeometry
        Entries of invalid conics are NaN.
    """
    k = np.asarray(conic, dtype=np.float64)
    a, b, c, d, e, f = (k[..., i] for i in range(6))
    det = 4 * a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        centre_x, centre_z = (b * e - 2 * c * d) / det, (b * d - 2 * a * e) / det  # eq. 5
        q_centre = f + 0.5 * (d * centre_x + e * centre_z)
        half_trace = 0.5 * (a + c)
        root = np.hypot(0.5 * (a - c), 0.5 * b)
        # Eigenvalues of [[A, B/2], [B/2, C]]; for an ellipse both share the sign of A + C.
        sign = np.sign(half_trace)
        lam_small, lam_large = half_trace - sign * root, half_trace + sign * root
        semi_major = np.sqrt(-q_centre / lam_small)
        semi_minor = np.sqrt(-q_centre / lam_large)
        # Eigenvector of lam_small: (B/2, lam_small - A), or (lam_small - C, B/2).
        use_v2 = np.hypot(lam_small - c, 0.5 * b) > np.hypot(0.5 * b, lam_small - a)
        axis_x = np.where(use_v2, lam_small - c, 0.5 * b)
        axis_z = np.where(use_v2, 0.5 * b, lam_small - a)
        length = np.hypot(axis_x, axis_z)
        axis_x = np.where(length > 0, axis_x / length, 1.0)
        axis_z = np.where(length > 0, axis_z / length, 0.0)
    valid = np.asarray((det > 0) & (q_centre * half_trace < 0) & np.isfinite(semi_major))
    # One array for the three pairs, NaN where invalid: a third of the calls of three.
    pairs = np.stack([centre_x, centre_z, semi_major, semi_minor, axis_x, axis_z], axis=-1)
    pairs[~valid] = np.nan
    return EllipseGeometry(
        valid=valid, centre=pairs[..., 0:2], semi_axes=pairs[..., 2:4], major_axis=pairs[..., 4:6]
    )


def value_and_gradient_sq(
    conic: FloatArray, points_xz: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Q and |grad Q|^2 of conics (K, 6) or (6,) at points (N, 2); shapes (K, N) or (N,)."""
    x, z = points_xz[:, 0], points_xz[:, 1]
    ones = np.ones_like(x)
    q = conic @ np.stack([x * x, x * z, z * z, x, z, ones])
    linear = np.stack([x, z, ones])
    a, b, c, d, e = (conic[..., i, None] for i in range(5))
    gx = np.concatenate([2 * a, b, d], axis=-1) @ linear
    gz = np.concatenate([b, 2 * c, e], axis=-1) @ linear
    return np.asarray(q, dtype=np.float64), np.asarray(gx * gx + gz * gz, dtype=np.float64)


def sampson_distance(conic: ArrayLike, points_xz: ArrayLike) -> FloatArray:
    """Signed Sampson distance Q / |grad Q| of points to conics.

    It is the first-order approximation of the geometric (orthogonal) distance, in the
    points' units.

    Parameters
    ----------
    conic : array-like, shape (6,) or (K, 6)
    points_xz : array-like, shape (N, 2)

    Returns
    -------
    distance : ndarray, shape (N,) or (K, N)
    """
    q, gradient_sq = value_and_gradient_sq(
        np.asarray(conic, dtype=np.float64), np.asarray(points_xz, dtype=np.float64)
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(q / np.sqrt(gradient_sq), dtype=np.float64)


def normalise_conic(conic: ArrayLike, length_scale_m: float) -> FloatArray:
    """Scale a conic so that F = 1, or to unit norm with A + C > 0 when F is ~0.

    F counts as ~0 when ``|F| <= F_ZERO_TOLERANCE * (|A| + |B| + |C|) * L^2`` with L the
    length scale of the data: the conic then passes within about 1e-9 L of the origin,
    which never happens for a profiler, whose origin is its own optical centre.

    Parameters
    ----------
    conic : array-like, shape (6,)
    length_scale_m : float
        Typical distance of the points from the origin, m.

    Returns
    -------
    conic : ndarray, shape (6,)
    """
    k = np.asarray(conic, dtype=np.float64)
    quadratic_size = float(np.sum(np.abs(k[:3]))) * length_scale_m**2
    if abs(k[5]) > F_ZERO_TOLERANCE * quadratic_size:
        return np.asarray(k / k[5], dtype=np.float64)
    k = k / np.linalg.norm(k)
    return np.asarray(k if k[0] + k[2] > 0 else -k, dtype=np.float64)


# ------------------------------------------------------------------ geometric refinement


#: Levenberg-Marquardt iterations of the geometric refinement, and its stopping rule on the
#: relative decrease of the cost.
LM_MAX_ITERATIONS = 50


LM_RELATIVE_TOLERANCE = 1e-10


#: ... and on the step length, in normalised units (the points' RMS spread is 1).
LM_STEP_TOLERANCE = 1e-12


def design_rows(u: FloatArray) -> FloatArray:
    """Rows (x^2, xz, z^2, x, z, 1) of points (N, 2): Q = design @ conic, shape (N, 6)."""
    x, z = u[:, 0], u[:, 1]
    return np.column_stack([x * x, x * z, z * z, x, z, np.ones_like(x)])


def sampson_rows(u: FloatArray) -> FloatArray:
    """The rows that make Q and grad Q = (gx, gz) linear in the conic at points (N, 2):
    ``rows @ conic`` gives Q, gx and gz, shape (3, N, 6) (:func:`design_rows`, then
    (2x, z, 0, 1, 0, 0) and (0, x, 2z, 0, 1, 0))."""
    x, z = u[:, 0], u[:, 1]
    zero, one = np.zeros_like(x), np.ones_like(x)
    return np.stack(
        [
            design_rows(u),
            np.column_stack([2 * x, z, zero, one, zero, zero]),
            np.column_stack([zero, x, 2 * z, zero, one, zero]),
        ]
    )


def sampson_jacobian(conic: FloatArray, rows: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Sampson distances r = Q / |grad Q| (N,) and their derivative (N, 6) by the conic.

    ``rows`` is :func:`sampson_rows` of the points. With g = grad Q, dr/dk = design / |g| -
    Q / |g|^3 (gx dgx/dk + gz dgz/dk), the derivatives being the rows' second and third
    blocks.
    """
    q, gx, gz = rows @ conic
    norm_sq = gx * gx + gz * gz
    norm = np.sqrt(norm_sq)
    along = (q / norm_sq)[:, None] * (gx[:, None] * rows[1] + gz[:, None] * rows[2])
    return q / norm, (rows[0] - along) / norm[:, None]


class GeometricFit(NamedTuple):
    """A conic refined by :func:`refine_geometric`: the conic (6,), and where it is the
    optimum (not the start handed back), its Sampson distances (N,) and their Jacobian (N, 6)
    at the points, which later steps use again (the inliers' distances, the axes' 1σ)."""

    conic: FloatArray
    residual: FloatArray | None
    jacobian: FloatArray | None


def refine_geometric(
    conic_u: FloatArray, u: FloatArray, rows: FloatArray | None = None
) -> GeometricFit:
    """Least-squares Sampson-distance fit (Levenberg-Marquardt) starting from a conic.

    Minimising the sum of squared Sampson distances approximates the geometric
    (orthogonal-distance) fit; unlike the direct fit it is not biased on short arcs
    (measured: median centre error 131 um instead of 951 um on 60 deg arcs, R = 20 mm,
    5 um noise). The conic's 6 coefficients are the parameters: the Sampson distance is
    invariant to their scale, so the damping fixes that free direction and every step is
    renormalised. If the optimum is not an ellipse the start is returned. ``rows``, the
    points' :func:`sampson_rows` when the caller holds them, saves forming them again.
    """
    conic = conic_u / np.linalg.norm(conic_u)
    rows = sampson_rows(u) if rows is None else rows
    residual, jacobian = sampson_jacobian(conic, rows)
    cost = float(residual @ residual)
    damping = 1e-6
    diagonal = np.diag_indices(6)
    for _ in range(LM_MAX_ITERATIONS):
        hessian = jacobian.T @ jacobian
        scaled = hessian.copy()
        scaled[diagonal] += damping * hessian[diagonal] + 1e-12 * np.trace(hessian)
        # LAPACK's solver itself: numpy.linalg.solve's checks cost ten times the 6 x 6 solve.
        *_, step, info = dgesv(scaled, -jacobian.T @ residual)
        if info != 0:
            raise np.linalg.LinAlgError("singular normal equations in the conic refinement")
        if math.sqrt(step @ step) <= LM_STEP_TOLERANCE:
            break
        trial = conic + step
        trial /= math.sqrt(trial @ trial)
        trial_residual, trial_jacobian = sampson_jacobian(trial, rows)
        trial_cost = float(trial_residual @ trial_residual)
        if trial_cost < cost:
            converged = cost - trial_cost <= LM_RELATIVE_TOLERANCE * cost
            conic, residual, jacobian, cost = trial, trial_residual, trial_jacobian, trial_cost
            damping = max(damping / 10, 1e-12)
            if converged:
                break
        else:
            damping *= 10
            if damping > 1e8:
                break
    if is_ellipse(conic):
        return GeometricFit(conic, residual, jacobian)
    return GeometricFit(conic_u, None, None)


#: Step of the semi-axes' numerical gradient by the unit conic (:func:`semi_axis_sigmas`).
AXIS_GRADIENT_STEP = 1e-7


def semi_axis_sigmas(conic: FloatArray, residual: FloatArray, jacobian: FloatArray) -> FloatArray:
    """Standard errors (2,) of the semi-axes (major, minor) of a unit ellipse (6,) fitted to
    points whose Sampson distances (N,) and their Jacobian (N, 6) are ``residual`` and
    ``jacobian`` (:class:`GeometricFit`), in the points' units; zeros where not finite.

    The conic's covariance is s² (JᵀJ)⁺ with J the Sampson distances' Jacobian and s their
    robust scale, inflated by N / n_eff for the smooth shape error that makes neighbouring
    residuals alike (:func:`~linelaser_calib.core.model_check.effective_count`); it is
    carried to the semi-axes by their central-difference gradient. A partial arc leaves its
    axes loosely fixed: a 20 deg arc of a 12.5 mm radius with 20 um of shape error allows
    semi-minor axes several mm apart.
    """
    scale = robust_scale_m(residual)
    scale_sq = scale**2 * len(residual) / effective_count(residual, scale)
    covariance = scale_sq * np.linalg.pinv(jacobian.T @ jacobian)
    steps = AXIS_GRADIENT_STEP * np.eye(6)
    axes = ellipse_geometry(np.concatenate([conic + steps, conic - steps])).semi_axes
    gradient = (axes[:6] - axes[6:]).T / (2.0 * AXIS_GRADIENT_STEP)
    sigma = np.sqrt(np.maximum(np.einsum("ik,kl,il->i", gradient, covariance, gradient), 0.0))
    return np.asarray(sigma if np.all(np.isfinite(sigma)) else np.zeros(2), dtype=np.float64)


def is_ellipse(conic: FloatArray) -> bool:
    """:attr:`EllipseGeometry.valid` of one conic (6,), in scalar arithmetic (the same
    formulas as :func:`ellipse_geometry`, without its arrays' set-up, which costs more than
    a Sampson refinement's step)."""
    a, b, c, d, e, f = (float(k) for k in conic)
    det = 4 * a * c - b * b
    if not det > 0.0:
        return False
    q_centre = f + 0.5 * (d * ((b * e - 2 * c * d) / det) + e * ((b * d - 2 * a * e) / det))
    half_trace = 0.5 * (a + c)
    if not q_centre * half_trace < 0.0:
        return False
    lam_small = half_trace - math.copysign(math.hypot(0.5 * (a - c), 0.5 * b), half_trace)
    if lam_small == 0.0:
        return False
    semi_major_sq = -q_centre / lam_small
    return math.isfinite(semi_major_sq) and not semi_major_sq < 0.0


def sampson_from_rows(conic: FloatArray, rows: FloatArray) -> FloatArray:
    """Signed Sampson distances (N,) of the points whose :func:`sampson_rows` are ``rows``
    from a conic (6,): :func:`sampson_distance` for points whose rows are at hand."""
    q, gx, gz = rows @ conic
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(q / np.sqrt(gx * gx + gz * gz), dtype=np.float64)


def arc_coverage(geometry: EllipseGeometry, points_xz: FloatArray) -> float:
    """Angular extent of points on an ellipse, in its parametric angle, rad.

    Each point gets the parametric angle t of x = a cos t, z = b sin t in the ellipse's
    axes; the coverage is 2 pi minus the largest gap between consecutive angles.
    """
    (a, b), axis = geometry.semi_axes, geometry.major_axis
    rel = points_xz - geometry.centre
    along = rel @ axis
    across = rel @ np.array([-axis[1], axis[0]])
    t = np.sort(np.arctan2(across / b, along / a))
    gaps = np.diff(np.concatenate([t, [t[0] + 2 * math.pi]]))
    return float(2 * math.pi - gaps.max())


def turning_angle(conic: FloatArray, points_xz: FloatArray) -> float:
    """How far the normal of a conic (6,) turns over points on it (N, 2), m, rad: 2 pi minus
    the largest gap between the normals' directions (for a circle, the arc's angle)."""
    a, b, c, d, e, _ = conic
    x, z = points_xz[:, 0], points_xz[:, 1]
    angles = np.sort(np.arctan2(b * x + 2 * c * z + e, 2 * a * x + b * z + d))
    gaps = np.diff(np.concatenate([angles, [angles[0] + 2 * math.pi]]))
    return float(2 * math.pi - gaps.max())
