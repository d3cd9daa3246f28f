"""Hand-eye from one known point seen from many poses (the weld-seam paper, and better).

A weld-seam point p (taught in the base frame with the tool tip, or unknown) is scanned from
M flange poses; each profile is a V whose corner (:mod:`linelaser_calib.core.corner`) is p in
the sensor frame, s_i = (x_i, 0, z_i). With the hand-eye X = (R_X, t_X) (``T_flange_sensor``)
and the reported flange poses (R_i, t_i) (``T_base_flange``)::

    p = R_i (R_X s_i + t_X) + t_i = R_i (x_i a1 + z_i a3 + t_X) + t_i,

where a1, a3 are R_X's first and third columns (y = 0 drops the second, as in the cylinder
paper). This is linear in (a1, a3, t_X) and, when p is not taught, in p.

Methods
-------
``paper`` (:func:`paper_correction`, weld-seam paper eq. 11-16, ``papers.md`` §B)
    Start from an initial hand-eye and the taught point. Reconstruct p_i through every view.
    The scatter per axis is K_X = sign(X̄ − X_R) Σ|X_n − X̄| (eq. 14 as printed sums signed
    deviations, which is identically zero; the sum of absolute deviations is the evident
    intent), and ΔR = √(K_X² + K_Y² + K_Z²) (eq. 15). A two-step grid search over the hand-eye
    rotation vector minimises ΔR with the translation held, then the translation is shifted
    by the mean offset d = mean(p_i) − p (eq. 16).

    *Grid sizes.* The text says: step each component from r − Δ to r + Δ by Δ/20, "8000
    combinations", then ±Δ/20 by Δ/100. These disagree: ±Δ by Δ/20 is 41 values per axis
    (68 921 combinations), 8000 = 20³ would be 20 values. The experiment (§3) states the
    numbers it ran, ±0.4 rad by 0.02 (41 per axis) and then ±0.02 by 0.005 (9 per axis;
    Δ/100 would be 0.004), so those are the defaults (:attr:`KnownPointConfig.grid_coarse`,
    ``grid_fine``); ``GridStep(0.4, 20)`` is the "8000" reading. Every candidate of a step
    is evaluated in one vectorised numpy expression (candidates × views).

    *Mapping to this package.* The paper corrects the rotation vector and translation of
    L_C (camera to calibration board) inside M_C = P_C⁻¹ C_C L_C with P_C, C_C fixed; moving
    L_C's rotation with its translation held keeps M_C's translation. Here the grid moves the
    hand-eye's own rotation vector, r = rotvec(R_X) + δ, with t_X held, the same search up to
    a fixed rotation of the grid axes. The translation step is the least-squares shift
    t_X ← t_X − mean_i R_iᵀ (p_i − p), which with the paper's constant orientation is exactly
    the base-frame offset d expressed in the flange frame, −Rᵀd.

``default`` (:func:`solve_linear` then :func:`refine_known_point`)
    1. Closed form: linear least squares in (a1, a3, t_X[, p]), then R_X = the SVD
       projection of [a1, a3 × a1, a3] onto SO(3) and t_X (and p) solved again with R_X
       fixed; exact on noise-free data whenever the views determine everything. With an
       initial hand-eye, prior rows (ridge) tie each unknown to it with the loose σ of the
       configuration, so the system stays solvable when the views leave directions
       undetermined (the paper's pattern); a1 and a3 then take their initial parts where the
       views are blind, and the projection leaves the start up to ~0.3 mm off, which step 2
       removes.
    2. Maximum likelihood, as in :mod:`linelaser_calib.core.refine`: per-view flange-pose
       nuisance δ_i = (ω_i, τ_i) in the flange frame, true pose T_i·D(δ_i), with Gaussian
       priors σ_r, σ_t; the corner measured with the covariance of its line fits (floored)
       in x-z and ``aim_sigma_m`` along y (how far the laser plane may miss the point); a
       prior on the hand-eye from the initial one (``initial_sigma_*``, loose); p fixed when
       taught (or with ``point_sigma_m``), else estimated. Levenberg-Marquardt with the
       nuisance eliminated per view (Schur complement, the refinement's block solver).
       Views whose residual is implausible (χ², 3 dof) are dropped and the solve repeated.

Observability (:func:`analyse_known_point`)
-------------------------------------------
The data-only information of the hand-eye (nuisance and point marginalised, initial-guess
prior left out) is eigen-analysed in lever-scaled units, as the cylinder refinement does:

- With one flange orientation for all views (the paper's eq. 6) the rotation is still
  determined if the weld point is seen at points of the laser plane that do not lie on one
  line. Stepping in z alone moves the point through the sensor along one line (for a sensor
  looking down, nearly its depth axis z); a rotation of the sensor about that line leaves
  every reconstructed point where it was. That one rotation, a roll of the laser plane about
  the path of the point, is unobservable; the two rotations across the line and the three
  translations are determined (p taught).
- With p unknown and one orientation, a shift of the sensor and the same shift of p look
  alike: the three translations are unobservable too.
- Tilting the flange between views, or moving the sensor sideways along the laser line,
  determines everything.

Unobservable directions keep the initial hand-eye's value and are named in the warnings:
after the solve with the loose prior, the default method solves again with those directions
pinned to the initial value (:attr:`HandEyePrior.pinned`), because even a direction the
views do not determine picks up a noise-driven pull that the loose prior would let move it
by a few tenths of a degree. The reported covariance keeps the loose prior's σ there.
Without an initial hand-eye they raise DegenerateError.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from .corner import CornerConfig, CornerFit, fit_corner
from .errors import DegenerateError, InputError, ProfileRejected, SolverError
from .geometry import (
    check_transform,
    project_to_so3,
    rotvec_from_matrix,
    transform_from_rotation_translation,
)
from .observability import Direction, poor_directions, scaled_eigen
from .profile import CleaningConfig, clean_profile
from .refine import (
    INITIAL_DAMPING,
    MAX_DAMPING,
    _exp_so3,
    _Normal,
    _right_jacobian,
    _schur_information,
    _solve,
)
from .types import FloatArray, Rejection, Sample

#: Accepted values of the ``method`` argument.
METHODS = ("paper", "default")
#: Flange orientations spanning less than this count as one orientation, rad.
SAME_ORIENTATION_RAD = math.radians(2.0)
#: Corner points whose second principal spread is below this share of the first lie on a line.
COLLINEAR_RATIO = 0.05
#: A rotation direction within this angle of the corners' line is "about that line", rad.
LINE_ALIGNED_RAD = math.radians(15.0)
#: A direction with at least this share of its (scaled) length in rotation is a rotation.
ROTATION_SHARE = 0.5
#: Candidates evaluated at once in the grid search (memory: candidates × views × 3 floats).
GRID_CHUNK = 20000
#: 1σ with which a pinned hand-eye direction keeps its initial value, m (rotations times the
#: lever): tight against the data, loose enough for a well-conditioned solve.
PIN_SIGMA_M = 1e-6
#: Relative singular value below which the closed form's system counts as rank-deficient.
RANK_TOLERANCE = 1e-9


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


@dataclass(frozen=True)
class KnownPointConfig:
    """Settings of the known-point calibration (SI units).

    Attributes
    ----------
    cleaning : CleaningConfig
        Profile cleaning before the corner fit.
    corner : CornerConfig
    robot_sigma_t_m : float
        1σ per axis of the flange position error, m. Default 0.05 mm (the paper's PR1400,
        ±0.05 mm repeatability).
    robot_sigma_r_rad : float
        1σ per axis of the flange orientation error, rad. Default 0.005 deg.
    corner_sigma_floor_m : float
        Smallest 1σ of a corner in x and z, m: the line fits' covariance ignores flank
        roughness and weld-bead shape. Default 5 µm.
    aim_sigma_m : float
        1σ of the laser plane's miss of the point along the sensor's y, m: how exactly each
        view was aimed at the taught point. Default 20 µm.
    initial_sigma_rotation_rad : float
        Loose prior of the hand-eye rotation around the initial one, per axis, rad. Default
        5 deg (a bumped mount moves 1-2 deg). It decides only what the views cannot.
    initial_sigma_translation_m : float
        Same for the translation, m. Default 10 mm.
    point_sigma_m : float
        1σ per axis of the taught point, m; 0 (default) takes it as exact (the paper does).
    grid_coarse, grid_fine : GridStep
        The paper's two grid steps. Defaults: ±0.4 rad in 41 values per axis (step 0.02),
        then ±0.02 rad in 9 (step 0.005), as in its experiment (see the module docstring).
    min_samples : int
        Fewest views with a corner. Default 6.
    max_iterations : int
        Levenberg-Marquardt iterations. Default 50.
    tolerance : float
        Stop when an accepted step lowers the cost by less than this fraction. Default 1e-12.
    outlier_probability : float
        A view whose normalised residual (χ², 3 dof) has a smaller upper-tail probability
        is an outlier. Default 1e-4.
    max_outlier_fraction : float
        Largest share of views dropped as outliers. Default 0.2.
    weak_sigma_m, unobservable_sigma_m : float
        A hand-eye direction whose data-only 1σ (m; rotations times the lever, the median
        distance of the corners from the sensor origin) exceeds these is weak (warning) or
        unobservable (taken from the initial hand-eye). Defaults 0.2 mm and 1 mm.
    """

    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    corner: CornerConfig = field(default_factory=CornerConfig)
    robot_sigma_t_m: float = 5e-5
    robot_sigma_r_rad: float = math.radians(0.005)
    corner_sigma_floor_m: float = 5e-6
    aim_sigma_m: float = 2e-5
    initial_sigma_rotation_rad: float = math.radians(5.0)
    initial_sigma_translation_m: float = 0.01
    point_sigma_m: float = 0.0
    grid_coarse: GridStep = field(default_factory=lambda: GridStep(0.4, 41))
    grid_fine: GridStep = field(default_factory=lambda: GridStep(0.02, 9))
    min_samples: int = 6
    max_iterations: int = 50
    tolerance: float = 1e-12
    outlier_probability: float = 1e-4
    max_outlier_fraction: float = 0.2
    weak_sigma_m: float = 2e-4
    unobservable_sigma_m: float = 1e-3

    def __post_init__(self) -> None:
        positive = (
            "robot_sigma_t_m",
            "robot_sigma_r_rad",
            "corner_sigma_floor_m",
            "aim_sigma_m",
            "initial_sigma_rotation_rad",
            "initial_sigma_translation_m",
            "tolerance",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(
                    f"KnownPointConfig.{name} must be positive and finite, got {value}"
                )
        if not (math.isfinite(self.point_sigma_m) and self.point_sigma_m >= 0.0):
            raise InputError(
                f"KnownPointConfig.point_sigma_m must be >= 0, got {self.point_sigma_m}"
            )
        if self.min_samples < 3 or self.max_iterations < 1:
            raise InputError("KnownPointConfig.min_samples must be >= 3 and max_iterations >= 1")
        if not 0.0 < self.outlier_probability < 1.0:
            raise InputError("KnownPointConfig.outlier_probability must be in (0, 1)")
        if not 0.0 <= self.max_outlier_fraction < 1.0:
            raise InputError("KnownPointConfig.max_outlier_fraction must be in [0, 1)")
        if not 0.0 < self.weak_sigma_m < self.unobservable_sigma_m:
            raise InputError(
                "KnownPointConfig needs 0 < weak_sigma_m < unobservable_sigma_m, got "
                f"{self.weak_sigma_m} m and {self.unobservable_sigma_m} m"
            )


# --------------------------------------------------------------------------------------
# Shared geometry


def _skews(v: FloatArray) -> FloatArray:
    """Skew matrices (M, 3, 3) of vectors (M, 3): ``_skews(v)[i] @ u == cross(v[i], u)``."""
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def _corners_3d(corners_xz: FloatArray) -> FloatArray:
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
    s = _corners_3d(np.asarray(corners_xz, dtype=np.float64))
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
    K = np.sign(mean - np.asarray(point_base)) * np.abs(p - mean[..., None, :]).sum(axis=-2)
    return np.asarray(np.linalg.norm(K, axis=-1))


# --------------------------------------------------------------------------------------
# The paper's correction


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
        R = Rotation.from_rotvec(rotvecs).as_matrix()  # (K, 3, 3)
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
    config: KnownPointConfig | None = None,
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
    config : KnownPointConfig, optional
        Only the grid steps are used.
    free_direction : array-like, shape (3,), optional
        Unit direction of the reference line, base frame; None for a point.
    """
    cfg = KnownPointConfig() if config is None else config
    across = np.eye(3)
    if free_direction is not None:
        d = np.asarray(free_direction, dtype=np.float64)
        across = across - np.outer(d, d) / float(d @ d)
    s = _corners_3d(np.asarray(corners_xz, dtype=np.float64))
    T = np.asarray(T_base_flange, dtype=np.float64)
    X0 = np.asarray(T_flange_sensor_initial, dtype=np.float64)
    p = np.asarray(point_base, dtype=np.float64)
    t_fs = X0[:3, 3].copy()
    r0 = rotvec_from_matrix(X0[:3, :3])
    start = float(scatter_delta_r(weld_points_base(corners_xz, T, X0) @ across, p @ across))
    r1, score1, edge = _grid_best(r0, cfg.grid_coarse, s, T, t_fs, p, across)
    r2, score2, _ = _grid_best(r1, cfg.grid_fine, s, T, t_fs, p, across)
    R = Rotation.from_rotvec(r2).as_matrix()
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


# --------------------------------------------------------------------------------------
# Closed form


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
    s = _corners_3d(np.asarray(corners_xz, dtype=np.float64))
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


# --------------------------------------------------------------------------------------
# Maximum likelihood


@dataclass(frozen=True)
class _Views:
    """The measurements: corners (M, 3), their whitening (M, 3, 3) and the flange poses."""

    s: FloatArray
    W: FloatArray
    R: FloatArray
    t: FloatArray


@dataclass(frozen=True)
class _Setup:
    """What is estimated and which priors apply."""

    estimate_point: bool
    point_prior: tuple[FloatArray, float] | None
    hand_eye_prior: HandEyePrior | None
    config: KnownPointConfig

    @property
    def n_global(self) -> int:
        return 9 if self.estimate_point else 6


@dataclass(frozen=True)
class _State:
    R_fs: FloatArray
    t_fs: FloatArray
    point: FloatArray
    omega: FloatArray  # (M, 3) rad, flange frame
    tau: FloatArray  # (M, 3) m, flange frame


def _whitening(covariance_xz: FloatArray, config: KnownPointConfig) -> FloatArray:
    """Whitening matrices (M, 3, 3) of the corners: x-z from the fits (floored), y the aim."""
    M = len(covariance_xz)
    cov = np.zeros((M, 3, 3))
    cov[:, 0, 0], cov[:, 0, 2] = covariance_xz[:, 0, 0], covariance_xz[:, 0, 1]
    cov[:, 2, 0], cov[:, 2, 2] = covariance_xz[:, 1, 0], covariance_xz[:, 1, 1]
    cov[:, 0, 0] += config.corner_sigma_floor_m**2
    cov[:, 2, 2] += config.corner_sigma_floor_m**2
    cov[:, 1, 1] = config.aim_sigma_m**2
    return np.asarray(np.linalg.inv(np.linalg.cholesky(cov)))


def _predict(views: _Views, state: _State) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted corners s (M, 3), the point in the true flange frame h (M, 3), Exp(ω) (M, 3, 3)."""
    E = _exp_so3(state.omega)
    g = np.einsum("mji,mj->mi", views.R, state.point - views.t) - state.tau
    h = np.einsum("mji,mj->mi", E, g)
    return np.asarray((h - state.t_fs) @ state.R_fs), h, E


class _Priors(NamedTuple):
    """The global priors at one state."""

    residuals: FloatArray  # (rows,) normalised
    jacobian: FloatArray  # (rows, G)
    hand_eye_info: FloatArray  # (G, G) of the hand-eye prior, pinned rows included
    pinned_info: FloatArray  # (G, G) of the pinned rows alone


def _global_priors(setup: _Setup, state: _State) -> _Priors:
    """Hand-eye (with pinned directions) and point priors, normalised."""
    G = setup.n_global
    residuals, jacobians = [np.zeros(0)], [np.zeros((0, G))]
    hand_eye_info, pinned_info = np.zeros((G, G)), np.zeros((G, G))
    if setup.hand_eye_prior is not None:
        he = setup.hand_eye_prior
        phi = rotvec_from_matrix(he.T_flange_sensor[:3, :3].T @ state.R_fs)
        delta = np.concatenate([phi, state.t_fs - he.T_flange_sensor[:3, 3]])
        rows = np.vstack(
            [
                np.diag([1.0 / he.sigma_rotation_rad] * 3 + [1.0 / he.sigma_translation_m] * 3),
                he.pinned / PIN_SIGMA_M,
            ]
        )
        local = np.eye(6)  # d delta / d (θ, ρ)
        local[:3, :3] = np.linalg.inv(_right_jacobian(phi[None])[0])
        J = np.zeros((len(rows), G))
        J[:, :6] = rows @ local
        residuals.append(rows @ delta)
        jacobians.append(J)
        hand_eye_info = J.T @ J
        pinned_info = J[6:].T @ J[6:]
    if setup.point_prior is not None:
        point0, sigma = setup.point_prior
        J = np.zeros((3, G))
        J[:, 6:] = np.eye(3) / sigma
        residuals.append((state.point - point0) / sigma)
        jacobians.append(J)
    return _Priors(np.concatenate(residuals), np.vstack(jacobians), hand_eye_info, pinned_info)


def _residuals(views: _Views, setup: _Setup, state: _State) -> tuple[FloatArray, FloatArray]:
    """Normalised corner residuals (M, 3) and pose-correction priors (M, 6)."""
    s, _, _ = _predict(views, state)
    r = np.einsum("mij,mj->mi", views.W, s - views.s)
    cfg = setup.config
    prior = np.hstack([state.omega / cfg.robot_sigma_r_rad, state.tau / cfg.robot_sigma_t_m])
    return np.asarray(r), prior


def _cost(views: _Views, setup: _Setup, state: _State) -> float:
    r, prior = _residuals(views, setup, state)
    global_prior = _global_priors(setup, state).residuals
    return 0.5 * float(np.sum(r**2) + np.sum(prior**2) + np.sum(global_prior**2))


def _normal_equations(views: _Views, setup: _Setup, state: _State) -> tuple[_Normal, _Priors]:
    """Normal equations (block form) and the global priors they include."""
    cfg = setup.config
    s, h, E = _predict(views, state)
    r, prior = _residuals(views, setup, state)
    M = len(s)
    RT = state.R_fs.T
    RTE = RT @ np.transpose(E, (0, 2, 1))  # R_fsᵀ Exp(ω)ᵀ
    global_blocks = [_skews(s), np.broadcast_to(-RT, (M, 3, 3))]
    if setup.estimate_point:
        global_blocks.append(RTE @ np.transpose(views.R, (0, 2, 1)))
    J_g = views.W @ np.concatenate(global_blocks, axis=2)
    J_omega = RT @ _skews(h) @ _right_jacobian(state.omega)
    J_l = views.W @ np.concatenate([J_omega, -RTE], axis=2)

    priors = _global_priors(setup, state)
    A = np.einsum("mki,mkj->ij", J_g, J_g) + priors.jacobian.T @ priors.jacobian
    g_global = np.einsum("mki,mk->i", J_g, r) + priors.jacobian.T @ priors.residuals
    prior_info = np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)
    normal = _Normal(
        A=A,
        B=np.einsum("mki,mkj->mij", J_g, J_l),
        C_data=np.einsum("mki,mkj->mij", J_l, J_l),
        prior_precision=prior_info**2,
        g_global=g_global,
        g_local=np.einsum("mki,mk->mi", J_l, r) + prior * prior_info,
    )
    return normal, priors


def _data_information(
    normal: _Normal, hand_eye_info: FloatArray, estimate_point: bool
) -> FloatArray:
    """Hand-eye information (6, 6) from the views alone: the hand-eye prior removed, the pose
    corrections and the point marginalised."""
    data = _schur_information(replace(normal, A=normal.A - hand_eye_info))
    if estimate_point:
        data = data[:6, :6] - data[:6, 6:] @ np.linalg.pinv(data[6:, 6:]) @ data[6:, :6]
    return np.asarray(0.5 * (data + data.T))


def _retract(state: _State, step_global: FloatArray, step_local: FloatArray) -> _State:
    point = state.point + step_global[6:9] if len(step_global) == 9 else state.point
    return _State(
        R_fs=state.R_fs @ _exp_so3(step_global[None, :3])[0],
        t_fs=state.t_fs + step_global[3:6],
        point=point,
        omega=state.omega + step_local[:, :3],
        tau=state.tau + step_local[:, 3:],
    )


def _levenberg_marquardt(
    views: _Views, setup: _Setup, state: _State
) -> tuple[_State, list[float], int, bool]:
    """Minimise the cost; returns the state, cost history, linearisations, converged."""
    cfg = setup.config
    cost = _cost(views, setup, state)
    history = [cost]
    damping = INITIAL_DAMPING
    normal: _Normal | None = None
    iterations, converged = 0, False
    while iterations < cfg.max_iterations:
        if normal is None:
            normal, _ = _normal_equations(views, setup, state)
            iterations += 1
        step_global, step_local = _solve(normal, damping)
        candidate = _retract(state, step_global, step_local)
        new_cost = _cost(views, setup, candidate)
        if new_cost < cost:
            decrease = cost - new_cost
            state, cost, normal = candidate, new_cost, None
            history.append(cost)
            damping = max(damping / 3.0, 1e-15)
            if decrease <= cfg.tolerance * max(cost, 1e-300):
                converged = True
                break
        else:
            damping *= 4.0
            if damping > MAX_DAMPING:
                converged = True
                break
    return state, history, iterations, converged


@dataclass(frozen=True)
class KnownPointRefinement:
    """Outcome of :func:`refine_known_point` (per-view arrays follow the input order).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    point_base : ndarray, shape (3,)
        Estimated (or the given) weld point, m.
    covariance : ndarray, shape (G, G)
        Posterior covariance of ``[θ (rad, sensor axes; R = R̂·Exp(θ)), ρ (m, flange frame)
        (, point (m, base frame))]``, pose corrections marginalised, priors included (pinned
        directions count with the prior's loose σ only).
    information_data : ndarray, shape (6, 6)
        Information of the hand-eye from the views alone (hand-eye prior left out, point
        marginalised), in the units of ``covariance``.
    pose_corrections : ndarray, shape (M, 6)
        ``[ω (rad), τ (m)]`` per view, flange frame: true pose = T_base_flange · D(δ).
    view_chi2 : ndarray, shape (M,)
        Normalised squared residual of each view (corner and pose correction), ≈ χ²(3).
    cost_history : list of float
    iterations : int
    converged : bool
    """

    T_flange_sensor: FloatArray
    point_base: FloatArray
    covariance: FloatArray
    information_data: FloatArray
    pose_corrections: FloatArray
    view_chi2: FloatArray
    cost_history: list[float]
    iterations: int
    converged: bool


def _check_inputs(
    corners_xz: ArrayLike, T_base_flange: ArrayLike, min_samples: int
) -> tuple[FloatArray, FloatArray]:
    c = np.asarray(corners_xz, dtype=np.float64)
    T = np.asarray(T_base_flange, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2 or not np.all(np.isfinite(c)):
        raise InputError(f"corners must be a finite (M, 2) array of (x, z) in m, got {c.shape}")
    if T.shape != (len(c), 4, 4):
        raise InputError(
            f"T_base_flange must have shape ({len(c)}, 4, 4), one pose per corner, got {T.shape}"
        )
    for j, Tj in enumerate(T):
        try:
            check_transform(Tj, tolerance=1e-4)
        except ValueError as exc:
            raise InputError(f"T_base_flange[{j}] is not a rigid transform: {exc}") from exc
    if len(c) < min_samples:
        raise DegenerateError(
            f"{len(c)} views with a weld-seam corner, but at least {min_samples} are needed: "
            "scan the taught point from more flange poses (10-20 are typical)"
        )
    return c, T


def refine_known_point(
    corners_xz: ArrayLike,
    corner_covariances: ArrayLike,
    T_base_flange: ArrayLike,
    T_flange_sensor0: ArrayLike,
    point0: ArrayLike,
    estimate_point: bool,
    prior: HandEyePrior | None,
    config: KnownPointConfig | None = None,
) -> KnownPointRefinement:
    """Maximum-likelihood hand-eye (and point) with per-view flange-pose nuisance.

    Parameters
    ----------
    corners_xz : array-like, shape (M, 2)
        Corners in the sensor x-z plane, m.
    corner_covariances : array-like, shape (M, 2, 2)
        Their covariances from the line fits, m² (floored by ``corner_sigma_floor_m``).
    T_base_flange : array-like, shape (M, 4, 4)
        Reported flange poses.
    T_flange_sensor0 : array-like, shape (4, 4)
        Start value (e.g. from :func:`solve_linear`).
    point0 : array-like, shape (3,)
        Start value of the point, or the taught point, m.
    estimate_point : bool
        Estimate the point (free if ``config.point_sigma_m`` is 0 and the point was not
        taught; the caller passes the taught point as ``point0`` with ``point_sigma_m`` > 0
        for a prior on it) or hold it fixed at ``point0``.
    prior : HandEyePrior or None
        Prior on the hand-eye (its information is left out of ``information_data``).
    config : KnownPointConfig, optional

    Raises
    ------
    InputError, DegenerateError, SolverError
    """
    cfg = KnownPointConfig() if config is None else config
    c, T = _check_inputs(corners_xz, T_base_flange, cfg.min_samples)
    covariance_xz = np.asarray(corner_covariances, dtype=np.float64)
    if covariance_xz.shape != (len(c), 2, 2):
        raise InputError(f"corner_covariances must have shape ({len(c)}, 2, 2)")
    try:
        X0 = check_transform(T_flange_sensor0, tolerance=1e-4)
    except ValueError as exc:
        raise InputError(f"the start hand-eye is not a rigid transform: {exc}") from exc
    p0 = np.asarray(point0, dtype=np.float64)
    point_prior = (
        (p0.copy(), cfg.point_sigma_m) if estimate_point and cfg.point_sigma_m > 0 else None
    )
    setup = _Setup(estimate_point, point_prior, prior, cfg)
    views = _Views(_corners_3d(c), _whitening(covariance_xz, cfg), T[:, :3, :3], T[:, :3, 3])
    M = len(c)
    state = _State(
        X0[:3, :3].copy(), X0[:3, 3].copy(), p0.copy(), np.zeros((M, 3)), np.zeros((M, 3))
    )
    state, history, iterations, converged = _levenberg_marquardt(views, setup, state)
    if not (np.all(np.isfinite(state.R_fs)) and np.isfinite(history[-1])):
        raise SolverError("the known-point refinement produced non-finite values")
    normal, priors = _normal_equations(views, setup, state)
    covariance = np.linalg.inv(_schur_information(replace(normal, A=normal.A - priors.pinned_info)))
    r, pose_prior = _residuals(views, setup, state)
    return KnownPointRefinement(
        T_flange_sensor=transform_from_rotation_translation(state.R_fs, state.t_fs),
        point_base=state.point.copy(),
        covariance=covariance,
        information_data=_data_information(normal, priors.hand_eye_info, estimate_point),
        pose_corrections=np.hstack([state.omega, state.tau]),
        view_chi2=np.sum(r**2, axis=1) + np.sum(pose_prior**2, axis=1),
        cost_history=history,
        iterations=iterations,
        converged=converged,
    )


# --------------------------------------------------------------------------------------
# Observability in plain words


@dataclass(frozen=True)
class KnownPointObservability:
    """What the views determine of the hand-eye (see the module docstring).

    Attributes
    ----------
    sigma_m : ndarray, shape (6,)
        1σ from the views alone per eigen-direction of the information, m (rotations times
        the lever), largest first.
    lever_m : float
        Median distance of the corners from the sensor origin, m.
    directions : list of Direction
        Unobservable ones first, then weak ones.
    orientation_spread_rad : float
        Largest angle between a flange orientation and their mean, rad.
    corner_spread_m : ndarray, shape (2,)
        Standard deviations of the corners along their two principal directions in the
        laser plane, m.
    point_estimated : bool
    """

    sigma_m: FloatArray
    lever_m: float
    directions: list[Direction]
    orientation_spread_rad: float
    corner_spread_m: FloatArray
    point_estimated: bool

    @property
    def unobservable(self) -> list[Direction]:
        """Directions the views cannot determine."""
        return [d for d in self.directions if d.status == "unobservable"]

    def statement(self) -> str:
        """The pose pattern and what it determines, in plain words (mm, deg)."""
        spread = math.degrees(self.orientation_spread_rad)
        if self.orientation_spread_rad < SAME_ORIENTATION_RAD:
            text = f"All views share one flange orientation (spread {spread:.2f} deg)"
        else:
            text = f"The flange orientations span ±{spread:.1f} deg"
        major, minor = self.corner_spread_m * 1e3
        if minor < COLLINEAR_RATIO * major:
            text += (
                f"; the weld point was seen along one line of the laser plane (spread "
                f"{major:.1f} mm along it, {minor:.2f} mm across, 1 sigma)"
            )
        else:
            text += f"; the weld point was seen over {major:.1f} x {minor:.1f} mm (1 sigma)"
        missing = self.unobservable
        if not missing:
            worst = float(np.max(self.sigma_m)) * 1e3
            return (
                text + f". The views determine the whole hand-eye (worst direction 1 sigma "
                f"{worst:.3f} mm at a {self.lever_m * 1e3:.0f} mm lever)."
            )
        texts = [d.description for d in missing if _is_rotation(d.vector)]
        shifts = [d.description for d in missing if not _is_rotation(d.vector)]
        if self.point_estimated and len(shifts) > 1:
            same = self.orientation_spread_rad < SAME_ORIENTATION_RAD
            shifts = [
                f"the translation of the sensor in "
                f"{'all three directions' if len(shifts) == 3 else 'two directions'} together "
                "with the same shift of the weld point cannot be determined from these views and "
                f"keeps the initial hand-eye's value: {_shift_reason(same)}, so the two look "
                "alike in every view. To determine it, give the taught point, or tilt the flange "
                "between views by 20 deg or more about two different axes"
            ]
        items = " ".join(f"({k + 1}) {text}." for k, text in enumerate(texts + shifts))
        return (
            text + f". The views determine {6 - len(missing)} of the 6 hand-eye directions; "
            f"not determined: {items}"
        )


def _is_rotation(vector: FloatArray) -> bool:
    """A scaled direction (6,) is mostly a rotation."""
    return float(vector[:3] @ vector[:3]) >= ROTATION_SHARE


def _shift_reason(same_orientation: bool) -> str:
    return (
        "all views share one flange orientation"
        if same_orientation
        else "the flange rotates too little between views"
    )


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def _sign_free_angle(a: FloatArray, b: FloatArray) -> float:
    return math.acos(min(1.0, abs(float(a @ b))))


def _describe(
    vector: FloatArray,
    observability_inputs: tuple[float, FloatArray, FloatArray, bool, bool, bool],
    status: str,
    sigma_m: float,
) -> str:
    lever, R_fs, line, collinear, same_orientation, point_estimated = observability_inputs
    verdict = (
        "cannot be determined from these views and keeps the initial hand-eye's value"
        if status == "unobservable"
        else f"is only weakly determined (1 sigma {sigma_m * 1e3:.3f} mm)"
    )
    if _is_rotation(vector):
        theta = vector[:3] / lever
        axis = theta / np.linalg.norm(theta)
        where = ""
        if not point_estimated:
            through = np.cross(theta, R_fs.T @ vector[3:]) / float(theta @ theta)
            where = f" through {_fmt(through * 1e3)} mm"
        if collinear and _sign_free_angle(axis, line) < LINE_ALIGNED_RAD:
            return (
                f"a rotation of the sensor about the line along which the weld point moved "
                f"through the laser plane (direction {_fmt(axis)}{where}, sensor frame) {verdict}: "
                "the point was seen along this one line only"
                + (", from one flange orientation" if same_orientation else "")
                + ", so turning the sensor about it moves no reconstructed point. To determine "
                "it, also move the sensor sideways along the laser line between views (the "
                "point at different x, over 20 mm or more) or tilt the flange by 10-20 deg"
            )
        return (
            f"a rotation of the sensor about {_fmt(axis)}{where} (sensor frame) {verdict}. To "
            "determine it, tilt the flange between views about different axes by 10-20 deg "
            "and see the point at different places along the laser line"
        )
    direction = vector[3:] / np.linalg.norm(vector[3:])
    if point_estimated:
        return (
            f"a translation of the sensor along {_fmt(direction)} (flange frame) together with "
            f"the same shift of the weld point {verdict}: {_shift_reason(same_orientation)}, so "
            "the two look alike in every "
            "view. To determine it, give the taught point, or tilt the flange between views by "
            f"20 deg or more about axes perpendicular to {_fmt(direction)} (flange frame)"
        )
    return (
        f"a translation of the sensor along {_fmt(direction)} (flange frame) {verdict}. To "
        "determine it, tilt the flange between views by 20 deg or more"
    )


def analyse_known_point(
    information_data: ArrayLike,
    corners_xz: ArrayLike,
    T_base_flange: ArrayLike,
    T_flange_sensor: ArrayLike,
    point_estimated: bool,
    config: KnownPointConfig | None = None,
) -> KnownPointObservability:
    """Which hand-eye directions the views determine, in plain words.

    Parameters
    ----------
    information_data : array-like, shape (6, 6)
        Data-only information of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.
    corners_xz : array-like, shape (M, 2)
    T_base_flange : array-like, shape (M, 4, 4)
    T_flange_sensor : array-like, shape (4, 4)
        The estimate the information was formed at.
    point_estimated : bool
    config : KnownPointConfig, optional
        The weak and unobservable thresholds.
    """
    cfg = KnownPointConfig() if config is None else config
    c = np.asarray(corners_xz, dtype=np.float64)
    T = np.asarray(T_base_flange, dtype=np.float64)
    X = np.asarray(T_flange_sensor, dtype=np.float64)
    lever = float(np.median(np.linalg.norm(c, axis=1)))
    _, eigenvectors, sigma = scaled_eigen(np.asarray(information_data, dtype=np.float64), lever)

    R = T[:, :3, :3]
    R_mean = project_to_so3(np.sum(R, axis=0))
    spread = float(np.max(np.linalg.norm(rotvec_from_matrix(R @ R_mean.T), axis=-1)))
    centred = c - c.mean(axis=0)
    _, singular, Vt = np.linalg.svd(centred, full_matrices=False)
    corner_spread = singular / math.sqrt(max(len(c) - 1, 1))
    line = np.array([Vt[0, 0], 0.0, Vt[0, 1]])
    collinear = bool(corner_spread[1] < COLLINEAR_RATIO * corner_spread[0])
    inputs = (lever, X[:3, :3], line, collinear, spread < SAME_ORIENTATION_RAD, point_estimated)

    directions = [
        Direction(d.vector, d.sigma_m, d.status, _describe(d.vector, inputs, d.status, d.sigma_m))
        for d in poor_directions(eigenvectors, sigma, cfg.weak_sigma_m, cfg.unobservable_sigma_m)
    ]
    return KnownPointObservability(
        sigma_m=np.asarray(np.sort(sigma)[::-1], dtype=np.float64),
        lever_m=lever,
        directions=directions,
        orientation_spread_rad=spread,
        corner_spread_m=corner_spread,
        point_estimated=point_estimated,
    )


# --------------------------------------------------------------------------------------
# From samples to a result


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
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    corner_xz: FloatArray
    covariance_xz: FloatArray
    points: FloatArray


@dataclass
class KnownPointResult:
    """Outcome of :func:`calibrate_known_point`.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    point_base : ndarray, shape (3,)
        The weld point in the base frame, m: estimated, or the taught one.
    point_estimated : bool
    method : str
        ``paper`` or ``default``.
    samples_used : list of int
        Profile indices in the final solve.
    samples_rejected : list of Rejection
        Stages ``cleaning``, ``corner`` and ``outlier``.
    sample_residuals_m : dict of int to float
        Per used sample, the distance between the weld point reconstructed through it (its
        recorded pose, the estimated hand-eye) and ``point_base``, m.
    rms_residual_m : float
        RMS of those distances, m.
    uncertainty_translation_m, uncertainty_rotation_rad : ndarray, shape (3,), or None
        1σ of the hand-eye translation (m, flange axes) and rotation (rad, small angles about
        the sensor axes), priors included; None for ``paper``.
    uncertainty_point_m : ndarray, shape (3,), or None
        1σ of an estimated point, m.
    observability : KnownPointObservability
    warnings : list of str
        The observability statement when a direction is weak or undetermined, and others.
    history : dict of str to list of float
        ``paper_delta_r_m`` (ΔR at the start and after each grid step, m) or
        ``refine_cost`` (the maximum-likelihood cost per accepted step).
    corners : list of CornerSample
        The samples in the final solve.
    """

    T_flange_sensor: FloatArray
    point_base: FloatArray
    point_estimated: bool
    method: str
    samples_used: list[int]
    samples_rejected: list[Rejection]
    sample_residuals_m: dict[int, float]
    rms_residual_m: float
    uncertainty_translation_m: FloatArray | None
    uncertainty_rotation_rad: FloatArray | None
    uncertainty_point_m: FloatArray | None
    observability: KnownPointObservability
    warnings: list[str]
    history: dict[str, list[float]]
    corners: list[CornerSample]


def extract_corner(
    sample: Sample, config: KnownPointConfig, rng: np.random.Generator
) -> CornerSample | Rejection:
    """Clean one sample's profile and fit its V corner; a rejection says why it failed.

    Parameters
    ----------
    sample : Sample
        Profile (sensor frame, m) paired with its flange pose.
    config : KnownPointConfig
        Its ``cleaning`` and ``corner`` settings apply.
    rng : numpy.random.Generator
        For the RANSAC line fits.

    Returns
    -------
    CornerSample or Rejection
        A rejection has stage ``cleaning`` or ``corner``.
    """
    try:
        cleaned = clean_profile(sample.points, config.cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    try:
        fit: CornerFit = fit_corner(cleaned.points_xz, config.corner, rng)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "corner", str(exc))
    return CornerSample(
        sample.index,
        sample.stamp_ns,
        np.asarray(sample.T_base_flange, dtype=np.float64),
        fit.corner_xz,
        fit.covariance_xz,
        cleaned.points[fit.inliers.any(axis=0)],
    )


def extract_corners(
    samples: list[Sample], config: KnownPointConfig, rng: np.random.Generator
) -> tuple[list[CornerSample], list[Rejection]]:
    """:func:`extract_corner` of every sample: the corners and the rejections."""
    corners: list[CornerSample] = []
    rejections: list[Rejection] = []
    for sample in samples:
        outcome = extract_corner(sample, config, rng)
        if isinstance(outcome, Rejection):
            rejections.append(outcome)
        else:
            corners.append(outcome)
    return corners, rejections


def _digest(rejections: list[Rejection]) -> str:
    counts: dict[str, int] = {}
    for r in rejections:
        key = f"{r.stage}: {r.reason.split(':')[0]}"
        counts[key] = counts.get(key, 0) + 1
    top = sorted(counts.items(), key=lambda kv: -kv[1])[:4]
    return "Rejected: " + "; ".join(f"{n} x {k}" for k, n in top) + ". " if top else ""


def _paper_information(
    corners: FloatArray, T: FloatArray, X: FloatArray, point: FloatArray, config: KnownPointConfig
) -> FloatArray:
    """Data-only hand-eye information at a given hand-eye (point taught), for the diagnosis."""
    covariance = np.zeros((len(corners), 2, 2))
    views = _Views(_corners_3d(corners), _whitening(covariance, config), T[:, :3, :3], T[:, :3, 3])
    state = _State(
        X[:3, :3], X[:3, 3], point, np.zeros((len(corners), 3)), np.zeros((len(corners), 3))
    )
    normal, priors = _normal_equations(views, _Setup(False, None, None, config), state)
    return _data_information(normal, priors.hand_eye_info, False)


def _observability_warnings(observability: KnownPointObservability, method: str) -> list[str]:
    if not observability.directions:
        return []
    text = observability.statement()
    weak = [d for d in observability.directions if d.status == "weak"]
    if weak:
        text += " Weakly determined: " + " ".join(
            f"({k + 1}) {d.description}." for k, d in enumerate(weak)
        )
    if method == "paper" and observability.unobservable:
        text += (
            " The paper's grid search sees no change of the scatter along the undetermined "
            "directions, so its choice there is arbitrary within the grid."
        )
    return [text]


def calibrate_known_point(
    samples: list[Sample],
    T_flange_sensor_initial: ArrayLike | None,
    point_base: ArrayLike | None,
    config: KnownPointConfig,
    method: str,
    rng: np.random.Generator,
) -> KnownPointResult:
    """Correct (or find) the hand-eye from views of one weld-seam point.

    Parameters
    ----------
    samples : list of Sample
        Profiles of the V joint paired with their flange poses (sensor frame, m).
    T_flange_sensor_initial : array-like, shape (4, 4), or None
        The old hand-eye. Required for ``paper``; for ``default`` it is the start and a loose
        prior (``initial_sigma_*``) that decides only what the views cannot.
    point_base : array-like, shape (3,), or None
        The taught weld point in the base frame, m. Required for ``paper``; None estimates it
        (``default``).
    config : KnownPointConfig
    method : str
        ``default`` (closed form + maximum likelihood) or ``paper`` (grid search + shift).
    rng : numpy.random.Generator
        For the RANSAC corner fits.

    Returns
    -------
    KnownPointResult

    Raises
    ------
    InputError
        Malformed input, or ``paper`` without an initial hand-eye or a taught point.
    DegenerateError
        Too few corners, or (without an initial hand-eye) views that leave a direction
        undetermined; the message names the views to add.
    SolverError
    """
    if method not in METHODS:
        raise InputError(f"method must be one of {METHODS}, got {method!r}")
    X0: FloatArray | None = None
    if T_flange_sensor_initial is not None:
        try:
            X0 = check_transform(T_flange_sensor_initial, tolerance=1e-4)
        except ValueError as exc:
            raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc
    taught: FloatArray | None = None
    if point_base is not None:
        taught = np.asarray(point_base, dtype=np.float64)
        if taught.shape != (3,) or not np.all(np.isfinite(taught)):
            raise InputError(f"the weld point must be 3 finite numbers in m, got {point_base}")
    paper_inputs: tuple[FloatArray, FloatArray] | None = None
    if method == "paper":
        if X0 is None or taught is None:
            raise InputError(
                "the paper's method corrects an existing hand-eye against a taught point: give "
                "both the initial hand-eye and the weld point (x, y, z in m, base frame)"
            )
        paper_inputs = (X0, taught)
    corner_samples, rejections = extract_corners(samples, config, rng)
    if len(corner_samples) < config.min_samples:
        raise DegenerateError(
            f"only {len(corner_samples)} of {len(samples)} profiles show a weld-seam corner, "
            f"and at least {config.min_samples} are needed. "
            + _digest(rejections)
            + "Aim the laser line across the seam through the taught point, both flanks in view."
        )
    if paper_inputs is not None:
        return _paper_result(corner_samples, rejections, *paper_inputs, config)
    return _default_result(corner_samples, rejections, X0, taught, config)


def _stack(corners: list[CornerSample]) -> tuple[FloatArray, FloatArray, FloatArray]:
    return (
        np.array([c.corner_xz for c in corners]),
        np.array([c.covariance_xz for c in corners]),
        np.array([c.T_base_flange for c in corners]),
    )


def _residuals_m(
    corners: list[CornerSample], X: FloatArray, point: FloatArray
) -> tuple[dict[int, float], float]:
    c, _, T = _stack(corners)
    d = np.linalg.norm(weld_points_base(c, T, X) - point, axis=1)
    return {s.index: float(v) for s, v in zip(corners, d, strict=True)}, float(
        np.sqrt(np.mean(d**2))
    )


def _paper_result(
    corners: list[CornerSample],
    rejections: list[Rejection],
    X0: FloatArray,
    point: FloatArray,
    config: KnownPointConfig,
) -> KnownPointResult:
    c, _, T = _stack(corners)
    corrected = paper_correction(c, T, X0, point, config)
    X = corrected.T_flange_sensor
    observability = analyse_known_point(
        _paper_information(c, T, X, point, config), c, T, X, False, config
    )
    warnings = _observability_warnings(observability, "paper")
    if corrected.on_grid_edge:
        warnings.append(
            "the coarse grid's best rotation lies on its edge "
            f"(±{config.grid_coarse.half_width_rad:.2f} rad): the initial hand-eye may be "
            "further off than the search range; widen grid_coarse"
        )
    residuals, rms = _residuals_m(corners, X, point)
    return KnownPointResult(
        T_flange_sensor=X,
        point_base=point.copy(),
        point_estimated=False,
        method="paper",
        samples_used=[s.index for s in corners],
        samples_rejected=sorted(rejections, key=lambda r: r.index),
        sample_residuals_m=residuals,
        rms_residual_m=rms,
        uncertainty_translation_m=None,
        uncertainty_rotation_rad=None,
        uncertainty_point_m=None,
        observability=observability,
        warnings=warnings,
        history={"paper_delta_r_m": [float(v) for v in corrected.delta_r_m]},
        corners=corners,
    )


def _default_result(
    corners: list[CornerSample],
    rejections: list[Rejection],
    X0: FloatArray | None,
    taught: FloatArray | None,
    config: KnownPointConfig,
) -> KnownPointResult:
    prior = (
        None
        if X0 is None
        else HandEyePrior(X0, config.initial_sigma_rotation_rad, config.initial_sigma_translation_m)
    )
    estimate_point = taught is None or config.point_sigma_m > 0.0
    c, cov, T = _stack(corners)
    X, point = solve_linear(c, T, taught, prior, config.robot_sigma_t_m)
    keep = list(range(len(corners)))
    budget = min(
        int(config.max_outlier_fraction * len(corners)),
        len(corners) - config.min_samples,
    )
    limit = float(chi2.isf(config.outlier_probability, 3))
    dropped: list[Rejection] = []
    while True:
        refined = refine_known_point(
            c[keep], cov[keep], T[keep], X, point, estimate_point, prior, config
        )
        X, point = refined.T_flange_sensor, refined.point_base
        order = np.argsort(-refined.view_chi2)
        flagged = [int(j) for j in order if refined.view_chi2[j] > limit]
        room = budget - len(dropped)
        if not flagged or room <= 0:
            break
        for j in flagged[:room]:
            s = corners[keep[j]]
            residual = float(
                np.linalg.norm(weld_points_base(c[[keep[j]]], T[[keep[j]]], X)[0] - point)
            )
            dropped.append(
                Rejection(
                    s.index,
                    s.stamp_ns,
                    "outlier",
                    f"the view's weld point lies {residual * 1e3:.3f} mm from the others' "
                    f"(normalised chi2 {refined.view_chi2[j]:.1f} > {limit:.1f} for 3 dof at "
                    f"the robot's 1 sigma {config.robot_sigma_t_m * 1e3:.3f} mm): wrong "
                    "corner, a miss of the taught point, or motion during the scan",
                )
            )
        drop = set(flagged[:room])
        keep = [i for j, i in enumerate(keep) if j not in drop]
    used = [corners[i] for i in keep]
    c_used, cov_used, T_used = _stack(used)
    observability = analyse_known_point(
        refined.information_data, c_used, T_used, X, estimate_point, config
    )
    missing = observability.unobservable
    if missing and prior is None:
        raise DegenerateError(
            "without an initial hand-eye the views must determine everything. "
            + observability.statement()
            + " Give the old hand-eye as the initial one, or add such views."
        )
    if missing and prior is not None:
        # Keep the undetermined directions at the initial value exactly (noise would move
        # them within the loose prior): solve again in the observable subspace.
        scale = np.array([observability.lever_m] * 3 + [1.0] * 3)
        pinned = replace(prior, pinned=np.array([d.vector * scale for d in missing]))
        refined = refine_known_point(
            c_used, cov_used, T_used, X, point, estimate_point, pinned, config
        )
        X, point = refined.T_flange_sensor, refined.point_base
    warnings = _observability_warnings(observability, "default")
    if not refined.converged:
        warnings.append(
            f"the refinement stopped after {refined.iterations} iterations without converging; "
            "the result may be inaccurate"
        )
    residuals, rms = _residuals_m(used, X, point)
    sigma = np.sqrt(np.diag(refined.covariance))
    return KnownPointResult(
        T_flange_sensor=X,
        point_base=point,
        point_estimated=estimate_point,
        method="default",
        samples_used=[s.index for s in used],
        samples_rejected=sorted(rejections + dropped, key=lambda r: r.index),
        sample_residuals_m=residuals,
        rms_residual_m=rms,
        uncertainty_translation_m=sigma[3:6],
        uncertainty_rotation_rad=sigma[:3],
        uncertainty_point_m=sigma[6:9] if estimate_point else None,
        observability=observability,
        warnings=warnings,
        history={"refine_cost": list(refined.cost_history)},
        corners=used,
    )
