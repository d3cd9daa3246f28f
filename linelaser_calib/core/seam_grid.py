"""The weld-seam paper's correction: a two-step grid search on the hand-eye rotation vector
that minimises the scatter ΔR of the point reconstructed through every view (eq. 11-16), then
a translation shift by the mean offset. See :mod:`.targets.known_point.target` for the
reading of the equations.

Shared by the targets whose feature is one seam corner per profile: the known point (a taught
point) and the straight line (the seam's line, along which the points may slide).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError
from .geometry import (
    FloatArray,
    exp_so3,
    matrix_from_rotvec,
    rotvec_from_matrix,
    transform_from_rotation_translation,
)


@dataclass(frozen=True)
class GridStep:
    """One step of the paper's grid search on the rotation vector.

    Attributes
    ----------
    half_width_rad : float
        Each component is searched over ± this around the centre, rad.
    points_per_axis : int
        Evenly spaced values per component, ends included (step = 2·half_width/(points−1)).
    """

    half_width_rad: float
    points_per_axis: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.half_width_rad) and self.half_width_rad > 0.0):
            raise InputError(f"GridStep.half_width_rad must be > 0 rad, got {self.half_width_rad}")
        if self.points_per_axis < 2:
            raise InputError(f"GridStep.points_per_axis must be >= 2, got {self.points_per_axis}")

    @property
    def step_rad(self) -> float:
        """Spacing of the grid values, rad."""
        return 2.0 * self.half_width_rad / (self.points_per_axis - 1)

    def offsets(self) -> FloatArray:
        """All candidate offsets, shape (points_per_axis³, 3), rad."""
        g = np.linspace(-self.half_width_rad, self.half_width_rad, self.points_per_axis)
        return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)


#: The paper's two grid steps: ±0.4 rad in 41 values per axis (step 0.02 rad), then ±0.02 rad
#: in 9 values (step 0.005 rad); see :mod:`.targets.known_point.target` for the reading.
PAPER_GRID_COARSE = GridStep(0.4, 41)
PAPER_GRID_FINE = GridStep(0.02, 9)

#: Candidates evaluated at once in the grid search (memory: candidates × views × 3 floats).
GRID_CHUNK = 20000


def corners_3d(corners_xz: FloatArray) -> FloatArray:
    """(M, 2) corners (x, z) to sensor-frame points (M, 3) with y = 0."""
    return np.column_stack([corners_xz[:, 0], np.zeros(len(corners_xz)), corners_xz[:, 1]])


def weld_points_base(
    corners_xz: ArrayLike, T_base_flange: ArrayLike, T_flange_sensor: ArrayLike
) -> FloatArray:
    """The weld point reconstructed through each view, p_i = T_i · X · (x_i, 0, z_i).

    Parameters
    ----------
    corners_xz : array-like, shape (M, 2)
        Corners in the sensor x-z plane, m.
    T_base_flange : array-like, shape (M, 4, 4)
    T_flange_sensor : array-like, shape (4, 4)

    Returns
    -------
    ndarray, shape (M, 3)
        Base frame, m.
    """
    s = corners_3d(np.asarray(corners_xz, dtype=np.float64))
    T = np.asarray(T_base_flange, dtype=np.float64)
    X = np.asarray(T_flange_sensor, dtype=np.float64)
    flange = s @ X[:3, :3].T + X[:3, 3]
    return np.asarray(np.einsum("mij,mj->mi", T[:, :3, :3], flange) + T[:, :3, 3])


def scatter_delta_r(points_base: ArrayLike, point_base: ArrayLike) -> FloatArray:
    """The paper's scatter ΔR (eq. 14-15) of reconstructed points, vectorised over candidates.

    K_axis = sign(mean − taught) · Σ_n |X_n − mean| per axis (the |·| reading of eq. 14, see
    the module docstring) and ΔR = |K|.

    Parameters
    ----------
    points_base : array-like, shape (..., M, 3)
        Reconstructed points of M views (per candidate), m.
    point_base : array-like, shape (3,)
        The taught point, m (it only sets the signs, which ΔR squares away).

    Returns
    -------
    ndarray, shape (...)
        ΔR, m (a sum over views, so it grows with M).
    """
    p = np.asarray(points_base, dtype=np.float64)
    mean = p.mean(axis=-2)
    # The sign of an axis where the mean sits exactly on the taught point is +1, not 0: a
    # zero would drop that axis's scatter. For a line the reference point is the mean of the
    # initial hand-eye's points, so a candidate equal to that hand-eye to the last bit scored
    # an axis short and won the grid (bags/line: 1.83 instead of 0.71 deg).
    sign = np.where(mean - np.asarray(point_base) < 0.0, -1.0, 1.0)
    K = sign * np.abs(p - mean[..., None, :]).sum(axis=-2)
    return np.asarray(np.linalg.norm(K, axis=-1))


@dataclass(frozen=True)
class PaperCorrection:
    """Outcome of :func:`paper_correction`.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    rotvec_rad : ndarray, shape (3,)
        Final rotation vector of the hand-eye, rad.
    delta_r_m : ndarray, shape (3,)
        ΔR at the initial hand-eye, after the coarse and after the fine step, m.
    offset_m : ndarray, shape (3,)
        Mean offset d = mean(p_i) − p before the translation shift (eq. 16), base frame, m.
    on_grid_edge : bool
        The coarse optimum lies on the edge of the grid (the search range was too small).
    """

    T_flange_sensor: FloatArray
    rotvec_rad: FloatArray
    delta_r_m: FloatArray
    offset_m: FloatArray
    on_grid_edge: bool


def _grid_best(
    centre: FloatArray,
    step: GridStep,
    s: FloatArray,
    T_base_flange: FloatArray,
    t_fs: FloatArray,
    point: FloatArray,
    across: FloatArray,
) -> tuple[FloatArray, float, bool]:
    """Best rotation vector of one grid step, its ΔR and whether it is on the grid's edge.

    ``across`` (3, 3) projects the reconstructed points before the scatter (the identity for
    a point; see :func:`paper_correction`)."""
    offsets = step.offsets()
    R_i, t_i = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    base = np.einsum("mij,j->mi", R_i, t_fs) + t_i  # (M, 3): where the sensor origin is
    scores = np.empty(len(offsets))
    for start in range(0, len(offsets), GRID_CHUNK):
        rotvecs = centre + offsets[start : start + GRID_CHUNK]
        R = exp_so3(rotvecs)  # (K, 3, 3)
        in_flange = np.einsum("kab,mb->kma", R, s)
        points = np.einsum("mab,kmb->kma", R_i, in_flange) + base
        scores[start : start + GRID_CHUNK] = scatter_delta_r(points @ across, point @ across)
    best = int(np.argmin(scores))
    edge = bool(np.any(np.abs(offsets[best]) >= step.half_width_rad * (1.0 - 1e-12)))
    return np.asarray(centre + offsets[best]), float(scores[best]), edge


def paper_correction(
    corners_xz: ArrayLike,
    T_base_flange: ArrayLike,
    T_flange_sensor_initial: ArrayLike,
    point_base: ArrayLike,
    grid_coarse: GridStep = PAPER_GRID_COARSE,
    grid_fine: GridStep = PAPER_GRID_FINE,
    free_direction: ArrayLike | None = None,
) -> PaperCorrection:
    """The weld-seam paper's two-step grid search and translation shift (eq. 11-16).

    With ``free_direction`` the reference is a line (a straight seam, no point taught)
    through ``point_base`` along it: the reconstructed points may slide along the line, so
    only their parts across it enter the scatter and the mean offset.

    Parameters
    ----------
    corners_xz : array-like, shape (M, 2)
        Corners in the sensor x-z plane, m.
    T_base_flange : array-like, shape (M, 4, 4)
        Reported flange poses.
    T_flange_sensor_initial : array-like, shape (4, 4)
        The old hand-eye to correct.
    point_base : array-like, shape (3,)
        The taught point (X_R, Y_R, Z_R), m.
    grid_coarse, grid_fine : GridStep
        The two steps of the search (default: the paper's).
    free_direction : array-like, shape (3,), optional
        Unit direction of the reference line, base frame; None for a point.
    """
    across = np.eye(3)
    if free_direction is not None:
        d = np.asarray(free_direction, dtype=np.float64)
        across = across - np.outer(d, d) / float(d @ d)
    s = corners_3d(np.asarray(corners_xz, dtype=np.float64))
    T = np.asarray(T_base_flange, dtype=np.float64)
    X0 = np.asarray(T_flange_sensor_initial, dtype=np.float64)
    p = np.asarray(point_base, dtype=np.float64)
    t_fs = X0[:3, 3].copy()
    r0 = rotvec_from_matrix(X0[:3, :3])
    start = float(scatter_delta_r(weld_points_base(corners_xz, T, X0) @ across, p @ across))
    r1, score1, edge = _grid_best(r0, grid_coarse, s, T, t_fs, p, across)
    r2, score2, _ = _grid_best(r1, grid_fine, s, T, t_fs, p, across)
    R = matrix_from_rotvec(r2)
    rotated = transform_from_rotation_translation(R, t_fs)
    offsets = (weld_points_base(corners_xz, T, rotated) - p) @ across
    shift = -np.mean(np.einsum("mji,mj->mi", T[:, :3, :3], offsets), axis=0)
    return PaperCorrection(
        T_flange_sensor=transform_from_rotation_translation(R, t_fs + shift),
        rotvec_rad=r2,
        delta_r_m=np.array([start, score1, score2]),
        offset_m=offsets.mean(axis=0),
        on_grid_edge=edge,
    )
