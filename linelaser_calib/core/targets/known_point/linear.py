"""Closed-form hand-eye (and point) from the linear known-point model, projected onto SO(3).

p = R_i (x_i a1 + z_i a3 + t_X) + t_i is linear in (a1, a3, t_X) and, when p is not taught,
in p (a1, a3 the first and third columns of R_X).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ...errors import DegenerateError
from ...geometry import FloatArray, project_to_so3, transform_from_rotation_translation
from ...seam_grid import corners_3d

#: Relative singular value below which the closed form's system counts as rank-deficient.
RANK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class HandEyePrior:
    """A Gaussian prior on the hand-eye around an initial one.

    The deviation from the initial hand-eye is δ = [Log(R0ᵀR) (rad, sensor axes), t − t0 (m,
    flange axes)].

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        The initial hand-eye (R0, t0).
    sigma_rotation_rad : float
        Per axis, rad.
    sigma_translation_m : float
        Per axis, m.
    pinned : ndarray, shape (k, 6)
        Rows r whose r·δ (m) is held at 0 (1σ ``PIN_SIGMA_M``): the directions the views
        cannot determine keep the initial value exactly instead of drifting with noise within
        the loose σ. Their information is left out of the reported covariance.
    """

    T_flange_sensor: FloatArray
    sigma_rotation_rad: float
    sigma_translation_m: float
    pinned: FloatArray = field(default_factory=lambda: np.zeros((0, 6)))


def _linear_rows(
    s: FloatArray, T: FloatArray, point: FloatArray | None
) -> tuple[FloatArray, FloatArray]:
    """Stacked system A u = b (3M rows) of the known-point equation; u = [a1, a3, t_X(, p)]."""
    M = len(s)
    R_i, t_i = T[:, :3, :3], T[:, :3, 3]
    blocks = [R_i * s[:, 0, None, None], R_i * s[:, 2, None, None], R_i]
    if point is None:
        blocks.append(np.broadcast_to(-np.eye(3), (M, 3, 3)))
        rhs = -t_i
    else:
        rhs = point - t_i
    return np.concatenate(blocks, axis=2).reshape(3 * M, -1), rhs.reshape(-1)


def _least_squares(
    A: FloatArray, b: FloatArray, prior_rows: FloatArray, prior_rhs: FloatArray
) -> FloatArray:
    """Solve the stacked system with column scaling; raise DegenerateError if rank-deficient."""
    A_all = np.vstack([A, prior_rows])
    b_all = np.concatenate([b, prior_rhs])
    scale = np.linalg.norm(A_all, axis=0)
    scale = np.where(scale > 0.0, scale, 1.0)
    solution, _, _, singular = np.linalg.lstsq(A_all / scale, b_all, rcond=None)
    if len(singular) < A_all.shape[1] or singular[-1] < RANK_TOLERANCE * singular[0]:
        raise DegenerateError(
            "the views do not determine the hand-eye in closed form (the linear system is "
            "rank-deficient): give an initial hand-eye, or add views that tilt the flange and "
            "move the weld point along the laser line"
        )
    return np.asarray(solution / scale)


def solve_linear(
    corners_xz: ArrayLike,
    T_base_flange: ArrayLike,
    point_base: ArrayLike | None,
    prior: HandEyePrior | None = None,
    sigma_point_m: float = 5e-5,
) -> tuple[FloatArray, FloatArray]:
    """Closed-form hand-eye (and point) from the linear model, projected onto SO(3).

    Parameters
    ----------
    corners_xz : array-like, shape (M, 2)
        Corners in the sensor x-z plane, m.
    T_base_flange : array-like, shape (M, 4, 4)
    point_base : array-like, shape (3,), or None
        The taught point, m; None estimates it.
    prior : HandEyePrior, optional
        Ties each unknown to the initial hand-eye (ridge rows weighted against
        ``sigma_point_m``); needed when the views leave directions unobservable.
    sigma_point_m : float
        1σ of a reconstructed point, m (weights the data rows against the prior rows).

    Returns
    -------
    T_flange_sensor : ndarray, shape (4, 4)
    point : ndarray, shape (3,)
        The estimated point, or the taught one.

    Raises
    ------
    DegenerateError
        Without a prior, when the views do not determine every unknown (at least 3 views
        with corners not on one line for a taught point, and tilted flanges otherwise).
    """
    s = corners_3d(np.asarray(corners_xz, dtype=np.float64))
    T = np.asarray(T_base_flange, dtype=np.float64)
    p = None if point_base is None else np.asarray(point_base, dtype=np.float64)
    A, b = _linear_rows(s, T, p)
    A, b = A / sigma_point_m, b / sigma_point_m
    n_unknown = A.shape[1]
    if prior is None:
        rows, rhs = np.zeros((0, n_unknown)), np.zeros(0)
    else:
        R0, t0 = prior.T_flange_sensor[:3, :3], prior.T_flange_sensor[:3, 3]
        weights = np.repeat(
            [1.0 / prior.sigma_rotation_rad] * 2 + [1.0 / prior.sigma_translation_m], 3
        )
        u0 = np.concatenate([R0[:, 0], R0[:, 2], t0])
        rows = np.hstack([np.diag(weights), np.zeros((9, n_unknown - 9))])
        rhs = weights * u0
    u = _least_squares(A, b, rows, rhs)
    a1, a3 = u[:3], u[3:6]
    R = project_to_so3(np.column_stack([a1, np.cross(a3, a1), a3]))

    # Translation (and point) again with the rotation fixed: R_i t_X (− p) = (p) − R_i R s_i − t_i.
    R_i, t_i = T[:, :3, :3], T[:, :3, 3]
    known = np.einsum("mij,mj->mi", R_i, s @ R.T) + t_i
    blocks = [R_i]
    if p is None:
        blocks.append(np.broadcast_to(-np.eye(3), R_i.shape))
        rhs_t = -known
    else:
        rhs_t = p - known
    A_t = np.concatenate(blocks, axis=2).reshape(3 * len(s), -1) / sigma_point_m
    b_t = rhs_t.reshape(-1) / sigma_point_m
    if prior is None:
        rows_t, prior_rhs_t = np.zeros((0, A_t.shape[1])), np.zeros(0)
    else:
        w = 1.0 / prior.sigma_translation_m
        rows_t = np.hstack([w * np.eye(3), np.zeros((3, A_t.shape[1] - 3))])
        prior_rhs_t = w * prior.T_flange_sensor[:3, 3]
    v = _least_squares(A_t, b_t, rows_t, prior_rhs_t)
    point = v[3:6] if p is None else p
    return transform_from_rotation_translation(R, v[:3]), np.asarray(point, dtype=np.float64)
