"""Maximum-likelihood hand-eye (and point) from the corners of one point, through the shared
block solver (:mod:`linelaser_calib.core.solver`).

Per view i: the corner s_i (sensor frame, y = 0) measured with the covariance of its line fits
(floored) in x-z and ``aim_sigma_m`` along y (how far the laser plane may miss the point); the
flange-pose nuisance δ_i = (ω_i, τ_i) in the flange frame, true pose T_i·D(δ_i), with Gaussian
priors σ_r, σ_t; a prior on the hand-eye from the initial one (loose, plus pinned directions);
the point p fixed when taught (or with ``point_sigma_m``), else estimated. The predicted corner
is R_Xᵀ (Exp(ω)ᵀ (R_iᵀ (p − t_i) − τ) − t_X). Optionally the profiler's x and z scale errors
are estimated too: a scale of either axis maps the flanks' straight lines to straight lines,
so the measured corner is the scaled true one and is compared with the prediction with the
scales removed (:func:`~...profile.along_line.measured_to_true`, as the line target's). Global
step: θ (3, sensor axes), ρ (3, flange axes), when estimated the point (3, base frame), and
when estimated the scale errors (2, x then z). Its covariance is the per-view model's;
:meth:`KnownPointRefinement.views` gives what :mod:`...shared_pose` needs for the estimate's
covariance where neighbouring views share their pose error.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ...errors import DegenerateError, InputError, SolverError
from ...geometry import (
    FloatArray,
    check_transform,
    exp_so3,
    right_jacobian_so3,
    rotvec_from_matrix,
    skews,
    transform_from_rotation_translation,
)
from ...profile.along_line import measured_to_true
from ...seam_grid import corners_3d
from ...shared_pose import ViewsLinearised
from ...solver import Linearisation, Residuals, SolverConfig, normal_equations, solve
from .config import KnownPointConfig
from .linear import HandEyePrior

#: 1σ with which a pinned hand-eye direction keeps its initial value, m (rotations times the
#: lever): tight against the data, loose enough for a well-conditioned solve.
PIN_SIGMA_M = 1e-6


@dataclass(frozen=True)
class KnownPointState:
    """Current estimate: hand-eye (R_fs, t_fs m), point (3,) m, pose corrections ω, τ (M, 3)
    (rad, m; flange frame), the profiler's x and z scale errors (2,) (0 where held)."""

    R_fs: FloatArray
    t_fs: FloatArray
    point: FloatArray
    omega: FloatArray
    tau: FloatArray
    scales: FloatArray = field(default_factory=lambda: np.zeros(2))


class _Priors(NamedTuple):
    """The global priors at one state."""

    residuals: FloatArray  # (rows,) normalised
    jacobian: FloatArray  # (rows, G)
    hand_eye_info: FloatArray  # (G, G) of the hand-eye prior, pinned rows included
    pinned_info: FloatArray  # (G, G) of the pinned rows alone


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


@dataclass(frozen=True)
class KnownPointProblem:
    """The views in the shared solver's block form (a
    :class:`~linelaser_calib.core.solver.BlockProblem`).

    Attributes
    ----------
    s : ndarray, shape (M, 3)
        Corners in the sensor frame (y = 0), m.
    W : ndarray, shape (M, 3, 3)
        Their whitening matrices.
    R, t : ndarray, shape (M, 3, 3) and (M, 3)
        Recorded flange poses.
    estimate_point : bool
    point_prior : (ndarray (3,), float) or None
        Prior on an estimated point: its value and 1σ, m.
    hand_eye_prior : HandEyePrior or None
    config : KnownPointConfig
    free_scales : (bool, bool)
        Whether the profiler's x and the z scale errors are estimated (held at 0 otherwise).
    """

    s: FloatArray
    W: FloatArray
    R: FloatArray
    t: FloatArray
    estimate_point: bool
    point_prior: tuple[FloatArray, float] | None
    hand_eye_prior: HandEyePrior | None
    config: KnownPointConfig
    lever_m: float = field(default=1.0)
    free_scales: tuple[bool, bool] = (False, False)

    @property
    def n_global(self) -> int:
        return 6 + (3 if self.estimate_point else 0) + sum(self.free_scales)

    @property
    def step_scale(self) -> FloatArray:
        """Rotations and scale errors times the lever (the corners' median distance),
        lengths as they are."""
        scale = np.ones(self.n_global)
        scale[:3] = self.lever_m
        scale[6 + (3 if self.estimate_point else 0) :] = self.lever_m
        return scale

    def _corners(self, scales: FloatArray) -> FloatArray:
        """The measured corners (M, 3) with the scale errors removed, m."""
        return measured_to_true(self.s, float(scales[0]), float(scales[1]))

    def _predict(self, state: KnownPointState) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Predicted corners (M, 3), the point in the true flange frame h (M, 3), Exp(ω)."""
        E = exp_so3(state.omega)
        g = np.einsum("mji,mj->mi", self.R, state.point - self.t) - state.tau
        h = np.einsum("mji,mj->mi", E, g)
        return np.asarray((h - state.t_fs) @ state.R_fs), h, E

    def _sqrt_information(self) -> FloatArray:
        cfg = self.config
        return np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)

    def priors(self, state: KnownPointState) -> _Priors:
        """Hand-eye (with pinned directions), point and scale priors, normalised."""
        G = self.n_global
        residuals, jacobians = [np.zeros(0)], [np.zeros((0, G))]
        hand_eye_info, pinned_info = np.zeros((G, G)), np.zeros((G, G))
        if self.hand_eye_prior is not None:
            he = self.hand_eye_prior
            phi = rotvec_from_matrix(he.T_flange_sensor[:3, :3].T @ state.R_fs)
            delta = np.concatenate([phi, state.t_fs - he.T_flange_sensor[:3, 3]])
            rows = np.vstack(
                [
                    np.diag([1.0 / he.sigma_rotation_rad] * 3 + [1.0 / he.sigma_translation_m] * 3),
                    he.pinned / PIN_SIGMA_M,
                ]
            )
            local = np.eye(6)  # d delta / d (θ, ρ)
            local[:3, :3] = np.linalg.inv(right_jacobian_so3(phi[None])[0])
            J = np.zeros((len(rows), G))
            J[:, :6] = rows @ local
            residuals.append(rows @ delta)
            jacobians.append(J)
            hand_eye_info = J.T @ J
            pinned_info = J[6:].T @ J[6:]
        if self.point_prior is not None:
            point0, sigma = self.point_prior
            J = np.zeros((3, G))
            J[:, 6:9] = np.eye(3) / sigma
            residuals.append((state.point - point0) / sigma)
            jacobians.append(J)
        free = np.flatnonzero(self.free_scales)
        if len(free):
            J = np.zeros((len(free), G))
            J[:, G - len(free) :] = np.eye(len(free)) / self.config.scale_prior_sigma
            residuals.append(state.scales[free] / self.config.scale_prior_sigma)
            jacobians.append(J)
        return _Priors(np.concatenate(residuals), np.vstack(jacobians), hand_eye_info, pinned_info)

    def residuals(self, state: KnownPointState) -> Residuals:
        """Whitened corner residuals (M, 3), pose priors (M, 6), global priors."""
        predicted, _, _ = self._predict(state)
        return self._residuals(state, predicted, self.priors(state))

    def _residuals(
        self, state: KnownPointState, predicted: FloatArray, priors: _Priors
    ) -> Residuals:
        r = np.einsum("mij,mj->mi", self.W, predicted - self._corners(state.scales))
        cfg = self.config
        prior = np.hstack([state.omega / cfg.robot_sigma_r_rad, state.tau / cfg.robot_sigma_t_m])
        return Residuals(np.asarray(r), prior, priors.residuals)

    def linearise(self, state: KnownPointState) -> Linearisation:
        """Residuals and their analytic Jacobians."""
        predicted, h, E = self._predict(state)
        priors = self.priors(state)
        M = len(predicted)
        RT = state.R_fs.T
        RTE = RT @ np.transpose(E, (0, 2, 1))  # R_fsᵀ Exp(ω)ᵀ
        global_blocks = [skews(predicted), np.broadcast_to(-RT, (M, 3, 3))]
        if self.estimate_point:
            global_blocks.append(RTE @ np.transpose(self.R, (0, 2, 1)))
        J_global = self.W @ np.concatenate(global_blocks, axis=2)
        free = [a for a, f in enumerate(self.free_scales) if f]
        if free:
            true = self._corners(state.scales)[:, [0, 2]] / (1.0 + state.scales)
            columns = self.W[:, :, [0, 2]] * true[:, None, :]
            J_global = np.concatenate([J_global, columns[:, :, free]], axis=2)
        J_omega = RT @ skews(h) @ right_jacobian_so3(state.omega)
        return Linearisation(
            residuals=self._residuals(state, predicted, priors),
            J_global=J_global,
            J_local=self.W @ np.concatenate([J_omega, -RTE], axis=2),
            pose_prior_sqrt_information=self._sqrt_information(),
            global_prior_jacobian=priors.jacobian,
        )

    def retract(
        self, state: KnownPointState, step_global: FloatArray, step_local: FloatArray
    ) -> KnownPointState:
        """Apply increments: R ← R·Exp(θ), t ← t + ρ, p, scale errors, ω, τ additively."""
        point = state.point + step_global[6:9] if self.estimate_point else state.point
        scales = state.scales.copy()
        scales[np.flatnonzero(self.free_scales)] += step_global[
            6 + (3 if self.estimate_point else 0) :
        ]
        return KnownPointState(
            R_fs=state.R_fs @ exp_so3(step_global[None, :3])[0],
            t_fs=state.t_fs + step_global[3:6],
            point=point,
            omega=state.omega + step_local[:, :3],
            tau=state.tau + step_local[:, 3:],
            scales=scales,
        )


def data_information(information: FloatArray) -> FloatArray:
    """Hand-eye information (6, 6) with the point and scale errors (if estimated)
    marginalised."""
    data = information
    if len(data) > 6:
        data = data[:6, :6] - data[:6, 6:] @ np.linalg.pinv(data[6:, 6:]) @ data[6:, :6]
    return np.asarray(0.5 * (data + data.T))


def build_problem(
    corners_xz: FloatArray,
    covariance_xz: FloatArray,
    T: FloatArray,
    estimate_point: bool,
    point_prior: tuple[FloatArray, float] | None,
    prior: HandEyePrior | None,
    config: KnownPointConfig,
    free_scales: tuple[bool, bool] = (False, False),
) -> KnownPointProblem:
    """The problem of checked corners (M, 2), covariances (M, 2, 2) and poses (M, 4, 4)."""
    return KnownPointProblem(
        s=corners_3d(corners_xz),
        W=_whitening(covariance_xz, config),
        R=T[:, :3, :3],
        t=T[:, :3, 3],
        estimate_point=estimate_point,
        point_prior=point_prior,
        hand_eye_prior=prior,
        config=config,
        lever_m=float(np.median(np.linalg.norm(corners_xz, axis=1))),
        free_scales=free_scales,
    )


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
    problem : KnownPointProblem
        The problem solved (for :meth:`views`).
    scales : ndarray, shape (2,)
        The profiler's x and z scale errors; 0 where held (``problem.free_scales``).
    scale_sigmas : (float or None, float or None)
        1σ of each scale error; None where it was held.
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
    problem: KnownPointProblem
    scales: FloatArray = field(default_factory=lambda: np.zeros(2))
    scale_sigmas: tuple[float | None, float | None] = (None, None)

    def views(self) -> ViewsLinearised:
        """The views linearised at the solution with every pose correction at zero, for
        :func:`~...shared_pose.shared_pose_error` (its covariance in the order of
        :attr:`covariance`); pinned directions count with the loose prior only, as there."""
        problem = self.problem
        prior = problem.hand_eye_prior
        if prior is not None:
            problem = replace(problem, hand_eye_prior=replace(prior, pinned=np.zeros((0, 6))))
        M = len(problem.s)
        X, zero = self.T_flange_sensor, np.zeros((M, 3))
        state = KnownPointState(X[:3, :3], X[:3, 3], self.point_base, zero, zero, self.scales)
        T = np.tile(np.eye(4), (M, 1, 1))
        T[:, :3, :3], T[:, :3, 3] = problem.R, problem.t
        return ViewsLinearised.from_linearisation(problem.linearise(state), T)


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
    free_scales: tuple[bool, bool] = (False, False),
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
    free_scales : (bool, bool)
        Estimate the profiler's x and the z scale error (after the point in ``covariance``).

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
    problem = build_problem(
        c, covariance_xz, T, estimate_point, point_prior, prior, cfg, free_scales
    )
    M = len(c)
    state = KnownPointState(
        X0[:3, :3].copy(), X0[:3, 3].copy(), p0.copy(), np.zeros((M, 3)), np.zeros((M, 3))
    )
    solver = SolverConfig(max_iterations=cfg.max_iterations, tolerance=cfg.tolerance)
    solution = solve(problem, state, solver)
    state = solution.state
    if not (np.all(np.isfinite(state.R_fs)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the known-point refinement produced non-finite values")
    priors = problem.priors(state)
    normal = solution.normal
    covariance = np.linalg.inv(normal.schur_information(remove=priors.pinned_info))
    r, pose_prior = solution.residuals.points, solution.residuals.pose_prior
    return KnownPointRefinement(
        T_flange_sensor=transform_from_rotation_translation(state.R_fs, state.t_fs),
        point_base=state.point.copy(),
        covariance=covariance,
        information_data=data_information(normal.schur_information(remove=priors.hand_eye_info)),
        pose_corrections=np.hstack([state.omega, state.tau]),
        view_chi2=np.sum(r**2, axis=1) + np.sum(pose_prior**2, axis=1),
        cost_history=solution.cost_history,
        iterations=solution.iterations,
        converged=solution.converged,
        problem=problem,
        scales=state.scales.copy(),
        scale_sigmas=_scale_sigmas(covariance, free_scales),
    )


def _scale_sigmas(
    covariance: FloatArray, free_scales: tuple[bool, bool]
) -> tuple[float | None, float | None]:
    """1σ of the estimated scale errors, the last rows of ``covariance``; None where held."""
    sigmas = iter(np.sqrt(np.diag(covariance))[len(covariance) - sum(free_scales) :])
    x, z = (float(next(sigmas)) if free else None for free in free_scales)
    return x, z


def paper_information(
    corners_xz: FloatArray,
    T: FloatArray,
    X: FloatArray,
    point: FloatArray,
    config: KnownPointConfig,
) -> FloatArray:
    """Data-only hand-eye information (6, 6) at a given hand-eye, point taught (for the
    diagnosis of the paper's method, which has no covariance of its own)."""
    problem = build_problem(
        corners_xz, np.zeros((len(corners_xz), 2, 2)), T, False, None, None, config
    )
    M = len(corners_xz)
    state = KnownPointState(X[:3, :3], X[:3, 3], point, np.zeros((M, 3)), np.zeros((M, 3)))
    normal = normal_equations(problem.linearise(state), SolverConfig())
    return data_information(normal.schur_information())
