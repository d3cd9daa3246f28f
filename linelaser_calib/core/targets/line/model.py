"""The straight-line target's model: a seam corner of every profile lies on one 3-D line.

A straight fillet or V seam (or any edge) is scanned from many flange poses. Each profile's
feature point, the corner s_i = (x_i, 0, z_i) in the sensor frame, is where the laser plane
meets the seam. With the hand-eye X = (R_X, t_X) (``T_flange_sensor``) and the flange pose
(R_i, t_i) (``T_base_flange``), the corner in the base frame

    c_i = R_i (R_X s_i + t_X) + t_i

lies on the seam line. No point of the line is known.

Line parametrisation (4 degrees of freedom)
-------------------------------------------
The line is a rotation R_L = [e1 e2 d] (d the direction, e1, e2 across it) and an offset
o ∈ R² such that q = o1 e1 + o2 e2 is its point nearest the base origin. Its retraction is
R_L ← R_L Exp([δ1, δ2, 0]), o ← o + (δ3, δ4): turns about e1 and e2 through the origin and
shifts across the line; a turn about d itself or a shift along it is no change of the line
and is not a parameter.

Residual
--------
The corner's distance from the line across it, r = [e1 e2]ᵀ c_i − o (2 values, base
frame), is zero on the line. Measured in the laser plane, where the corner's noise lives,
the same deviation is u = A_i⁻¹ r with A_i = [e1 e2]ᵀ R_base_sensor [:, (x, z)]: the in-plane
offset (x, z) from the line's intersection with the laser plane to the measured corner
(exactly, because the offset along d is what [e1 e2]ᵀ removes). The whitened residual is
W_i u with W_i the inverse Cholesky factor of the corner's covariance. A_i is singular when
the laser plane contains the seam direction (the corner is then undefined).

The flange pose of each view carries a nuisance correction δ_i = (ω_i, τ_i) in the flange
frame (true pose = T_i · D(δ_i), D = [Exp(ω), τ]) with Gaussian priors, as in the
cylinder's refinement. The Jacobians omit the derivative of A_i⁻¹, which multiplies the
residual (Gauss-Newton's usual second-order term).

Closed form (no initial hand-eye)
---------------------------------
In Plücker coordinates (d, m = q × d) a point c is on the line iff c × d = m. With
y_i = x_i a1 + z_i a3 + t_X (a1, a3 the first and third columns of R_X) this reads

    (R_i y_i) × d + t_i × d − m = 0,

linear in the products a1 dᵀ, a3 dᵀ, t_X dᵀ (27 numbers), d and m: 33 unknowns, homogeneous,
two independent equations per view. The least-squares null vector (of the column-scaled
system) gives them up to scale; |d| = 1 fixes it, then a1 = (a1 dᵀ) d and so on, R_X is the
SVD projection of [a1, a3 × a1, a3] onto SO(3), and the translation and the line are solved
again with the rotation fixed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ...errors import DegenerateError, InputError
from ...geometry import (
    exp_so3,
    matrix_from_rotvec,
    orthonormal_basis,
    project_to_so3,
    right_jacobian_so3,
    rotvec_from_matrix,
    skews,
    transform_from_rotation_translation,
)
from ...observability import SAME_ORIENTATION_RAD
from ...types import FloatArray

#: Parameters of the line (two turns, two shifts).
N_LINE = 4
#: Relative singular value of the closed form's second-smallest singular value below which the
#: views do not determine the line and hand-eye (several null vectors).
NULL_GAP = 1e-6
#: Sines of the angle between the laser plane and the seam below this make a view degenerate.
MIN_CROSSING_SINE = 0.05


@dataclass(frozen=True)
class Line:
    """A 3-D line in the base frame.

    Attributes
    ----------
    point : ndarray, shape (3,)
        Its point nearest the base origin, m.
    direction : ndarray, shape (3,)
        Unit direction (the sign is arbitrary).
    """

    point: FloatArray
    direction: FloatArray

    @classmethod
    def through(cls, point: ArrayLike, direction: ArrayLike) -> Line:
        """The line through any ``point`` (m) along ``direction`` (normalised here)."""
        d = np.asarray(direction, dtype=np.float64)
        norm = float(np.linalg.norm(d))
        if not np.isfinite(norm) or norm < 1e-12:
            raise InputError(f"a line direction must be a non-zero vector, got {d.tolist()}")
        d = d / norm
        p = np.asarray(point, dtype=np.float64)
        return cls(np.asarray(p - (p @ d) * d), d)

    def frame(self) -> tuple[FloatArray, FloatArray]:
        """The parametrisation (R_L (3, 3) with columns e1, e2, d; offset o (2,), m)."""
        e1, e2 = orthonormal_basis(self.direction)
        R = np.column_stack([e1, e2, self.direction])
        return R, np.array([self.point @ e1, self.point @ e2])

    @classmethod
    def from_frame(cls, R_L: FloatArray, offset: FloatArray) -> Line:
        """The line of a parametrisation (see :meth:`frame`)."""
        return cls(np.asarray(R_L[:, :2] @ offset), np.asarray(R_L[:, 2].copy()))

    def distances(self, points: ArrayLike) -> FloatArray:
        """Distance (N,) of points (N, 3) from the line, m."""
        w = np.asarray(points, dtype=np.float64) - self.point
        return np.asarray(np.linalg.norm(w - np.outer(w @ self.direction, self.direction), axis=1))


def retract_line(
    R_L: FloatArray, offset: FloatArray, delta: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Move a line parametrisation by ``delta`` (4,): turns about e1, e2 (rad), shifts (m)."""
    turn = matrix_from_rotvec([delta[0], delta[1], 0.0])
    return np.asarray(R_L @ turn), np.asarray(offset + delta[2:4])


def line_from_points(points: ArrayLike) -> Line:
    """The total-least-squares line through points (N, 3), N >= 2, m."""
    p = np.asarray(points, dtype=np.float64)
    centre = p.mean(axis=0)
    _, _, Vt = np.linalg.svd(p - centre, full_matrices=False)
    return Line.through(centre, Vt[0])


class LineResiduals(NamedTuple):
    """Whitened residuals and Jacobians of M views.

    Attributes
    ----------
    residuals : ndarray, shape (M, 2)
        W_i u_i: the in-plane offset of each measured corner from where the line crosses the
        view's laser plane, whitened (dimensionless).
    offsets_xz : ndarray, shape (M, 2)
        The same offsets u_i before whitening, sensor x and z, m.
    hand_eye : ndarray, shape (M, 2, 6)
        d residual / d [θ (rad, sensor axes; R_X ← R_X Exp(θ)), ρ (m, flange; t_X ← t_X + ρ)].
    line : ndarray, shape (M, 2, 4)
        d residual / d line delta (see :func:`retract_line`).
    pose : ndarray, shape (M, 2, 6)
        d residual / d [ω (rad), τ (m)] of each view's flange-pose correction (flange frame).
    crossing_sine : ndarray, shape (M,)
        |sin| of the angle between each laser plane and the line (0: the plane contains it).
    """

    residuals: FloatArray
    offsets_xz: FloatArray
    hand_eye: FloatArray
    line: FloatArray
    pose: FloatArray
    crossing_sine: FloatArray


def line_residuals(
    corners_xz: FloatArray,
    whitening: FloatArray,
    T_base_flange: FloatArray,
    T_flange_sensor: FloatArray,
    R_L: FloatArray,
    offset: FloatArray,
    pose_corrections: FloatArray,
) -> LineResiduals:
    """Residuals and Jacobians of the corner-on-line model (see the module docstring).

    Parameters
    ----------
    corners_xz : ndarray, shape (M, 2)
        Measured corners (x, z) in the sensor frame, m.
    whitening : ndarray, shape (M, 2, 2)
        W_i with W_iᵀ W_i the inverse covariance of corner i (1/m).
    T_base_flange : ndarray, shape (M, 4, 4)
        Reported flange poses.
    T_flange_sensor : ndarray, shape (4, 4)
    R_L, offset : ndarray, shapes (3, 3) and (2,)
        The line (see :meth:`Line.frame`).
    pose_corrections : ndarray, shape (M, 6)
        [ω (rad), τ (m)] per view, flange frame.

    Returns
    -------
    LineResiduals
    """
    M = len(corners_xz)
    s = np.column_stack([corners_xz[:, 0], np.zeros(M), corners_xz[:, 1]])
    R_X, t_X = T_flange_sensor[:3, :3], T_flange_sensor[:3, 3]
    R_i, t_i = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    omega, tau = pose_corrections[:, :3], pose_corrections[:, 3:]
    E = exp_so3(omega)
    f = s @ R_X.T + t_X  # (M, 3) corner in the flange frame
    RE = R_i @ E
    c = np.einsum("mij,mj->mi", RE, f) + np.einsum("mij,mj->mi", R_i, tau) + t_i
    P = R_L[:, :2].T  # (2, 3)
    r = c @ P.T - offset
    R_bs = RE @ R_X
    A = np.einsum("ij,mjk->mik", P, R_bs[:, :, [0, 2]])
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    # |det A| = |sin| of the angle between the laser plane and the line (unit vectors).
    crossing = np.abs(det)
    safe = np.where(crossing > 1e-12, det, 1e-12)
    A_inv = (
        np.stack(
            [
                np.stack([A[:, 1, 1], -A[:, 0, 1]], axis=1),
                np.stack([-A[:, 1, 0], A[:, 0, 0]], axis=1),
            ],
            axis=1,
        )
        / safe[:, None, None]
    )
    u = np.einsum("mij,mj->mi", A_inv, r)
    G = whitening @ A_inv  # (M, 2, 2): d residual / d r
    GP = G @ P  # (M, 2, 3): d residual / d c
    J_theta = -GP @ R_bs @ skews(s)
    J_rho = GP @ RE
    J_omega = -GP @ RE @ skews(f) @ right_jacobian_so3(omega)
    J_tau = GP @ R_i
    c_line = c @ R_L  # (M, 3) in line coordinates
    basis = np.eye(3)
    dr_dturn = np.stack([np.cross(basis[k], c_line)[:, :2] for k in range(2)], axis=1)
    J_line = np.concatenate([G @ dr_dturn, -G], axis=2)
    return LineResiduals(
        residuals=np.einsum("mij,mj->mi", whitening, u),
        offsets_xz=u,
        hand_eye=np.concatenate([J_theta, J_rho], axis=2),
        line=J_line,
        pose=np.concatenate([J_omega, J_tau], axis=2),
        crossing_sine=crossing,
    )


def _cross_matrices(R: FloatArray) -> FloatArray:
    """C (M, 3, 9) with C[m] @ vec(v dᵀ) == cross(R[m] @ v, d) for any v, d (row-major vec)."""
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    # (R v) × d, component l: ε_lmn R_mp v_p d_n.
    return np.asarray(np.einsum("lmn,kmp->klpn", eps, R).reshape(len(R), 3, 9))


def solve_line_linear(corners_xz: ArrayLike, T_base_flange: ArrayLike) -> tuple[FloatArray, Line]:
    """Closed-form hand-eye and line from the Plücker constraint (see the module docstring).

    Parameters
    ----------
    corners_xz : array-like, shape (M, 2)
        Corners (x, z) in the sensor frame, m; M >= 17.
    T_base_flange : array-like, shape (M, 4, 4)

    Returns
    -------
    T_flange_sensor : ndarray, shape (4, 4)
    line : Line

    Raises
    ------
    DegenerateError
        When the views do not determine the solution (too few, or the flange orientation
        varies too little).
    """
    c = np.asarray(corners_xz, dtype=np.float64)
    T = np.asarray(T_base_flange, dtype=np.float64)
    M = len(c)
    if M < 17:
        raise DegenerateError(
            f"the closed-form line solve needs at least 17 views with a corner, got {M}"
        )
    R_i, t_i = T[:, :3, :3], T[:, :3, 3]
    C = _cross_matrices(R_i)
    blocks = [
        C * c[:, 0, None, None],
        C * c[:, 1, None, None],
        C,
        skews(t_i),
        np.broadcast_to(-np.eye(3), (M, 3, 3)),
    ]
    A = np.concatenate(blocks, axis=2).reshape(3 * M, 33)
    scale = np.linalg.norm(A, axis=0)
    scale = np.where(scale > 0.0, scale, 1.0)
    _, singular, Vt = np.linalg.svd(A / scale, full_matrices=False)
    if singular[-2] < NULL_GAP * singular[0]:
        R_mean = project_to_so3(np.sum(R_i, axis=0))
        spread = float(np.max(np.linalg.norm(rotvec_from_matrix(R_i @ R_mean.T), axis=-1)))
        why = (
            f"all views share one flange orientation (spread {np.degrees(spread):.2f} deg), so "
            "the sensor's translations cannot be told from a shift of the line"
            if spread < SAME_ORIENTATION_RAD
            else f"the flange orientations span only ±{np.degrees(spread):.1f} deg"
        )
        raise DegenerateError(
            f"the views do not determine the hand-eye and the line in closed form: {why}. Tilt "
            "the flange between views about two different axes by 10-20 deg, turn the laser "
            "plane about the viewing axis and sweep the seam across the laser line, or give an "
            "initial hand-eye"
        )
    w = Vt[-1] / scale
    d = w[27:30]
    norm = float(np.linalg.norm(d))
    w, d = w / norm, d / norm
    D = w[:27].reshape(3, 3, 3)  # D[k] = v_k dᵀ, v = a1, a3, t
    a1, a3, t = D[0] @ d, D[1] @ d, D[2] @ d
    R = project_to_so3(np.column_stack([a1, np.cross(a3, a1), a3]))
    X = transform_from_rotation_translation(R, t)
    return _translation_and_line(c, T, X)


def _translation_and_line(
    corners_xz: FloatArray, T_base_flange: FloatArray, X: FloatArray
) -> tuple[FloatArray, Line]:
    """With the rotation fixed, the translation and the line by alternating least squares.

    The corners c_i = R_i t + k_i (k_i known) must lie on a line: for a fixed line direction
    this is linear in (t, q); the direction is updated from the corners' principal axis.
    """
    s = np.column_stack([corners_xz[:, 0], np.zeros(len(corners_xz)), corners_xz[:, 1]])
    R_i, t_i = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    k = np.einsum("mij,mj->mi", R_i, s @ X[:3, :3].T) + t_i
    t = X[:3, 3].copy()
    line = line_from_points(k + np.einsum("mij,j->mi", R_i, t))
    for _ in range(20):
        e1, e2 = orthonormal_basis(line.direction)
        P = np.vstack([e1, e2])
        # P (R_i t + k_i) − o = 0 for all i: unknowns t (3) and o (2).
        A = np.concatenate(
            [np.einsum("ij,mjk->mik", P, R_i), np.broadcast_to(-np.eye(2), (len(k), 2, 2))],
            axis=2,
        ).reshape(-1, 5)
        b = -(k @ P.T).reshape(-1)
        solution = np.linalg.lstsq(A, b, rcond=None)[0]
        t_new = solution[:3]
        line = line_from_points(k + np.einsum("mij,j->mi", R_i, t_new))
        moved = float(np.linalg.norm(t_new - t))
        t = t_new
        if moved < 1e-9:
            break
    return transform_from_rotation_translation(X[:3, :3], t), line
