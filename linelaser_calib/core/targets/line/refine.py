"""Maximum-likelihood hand-eye and seam line from the corners of many views.

Unknowns: the hand-eye (θ, ρ; R_X ← R_X Exp(θ), t_X ← t_X + ρ), the line (4, see
:mod:`.model`) and each view's flange-pose correction δ_i = (ω_i, τ_i) with Gaussian priors
σ_r, σ_t per axis (the robot's pose error, as in the cylinder's refinement). Each corner is
measured in the laser plane with the covariance of its fit (floored). An optional loose prior
ties the hand-eye to an initial one; it decides only what the views cannot.

Optionally the profiler's scales are estimated too: its along-line (x) and depth (z) scale
errors s = (s_x, s_z), both about the sensor origin, so that a measured corner (x, z) is the
true one (x / (1 + s_x), z / (1 + s_z)) (:func:`~...profile.along_line.measured_to_true`).
A corner is where two straight flanks meet, and a scale of either axis maps straight lines
to straight lines, so the measured corner is the scaled true one exactly. A z scale about
any other depth would be this one plus a shift of the sensor frame along z, which is part of
the hand-eye; about the origin the two are told apart by the corners' spread in depth.

The shared block solver (:mod:`linelaser_calib.core.solver`) minimises it, each view's
correction eliminated (Schur complement). The information of the hand-eye from the views
alone (prior left out, line and corrections marginalised) feeds the observability diagnosis.
Its covariance is the per-view model's; :meth:`LineRefinement.views` gives what
:mod:`...shared_pose` needs for the estimate's covariance where neighbouring views share
their pose error.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...errors import SolverError
from ...geometry import (
    matrix_from_rotvec,
    rotvec_from_matrix,
    transform_from_rotation_translation,
)
from ...profile.along_line import measured_to_true
from ...shared_pose import ViewsLinearised
from ...solver import Linearisation, SolverConfig, solve
from ...solver.lm import Residuals
from ...types import FloatArray
from .config import LineConfig
from .model import N_LINE, Line, LineResiduals, line_residuals, retract_line

#: Global parameters without the scales: hand-eye (6) and line (4).
N_GLOBAL = 6 + N_LINE
#: Profiler axes whose scale may be estimated: along the line (x) and depth (z).
SCALE_AXES = ("x", "z")


class _State(NamedTuple):
    X: FloatArray  # (4, 4)
    R_L: FloatArray  # (3, 3)
    offset: FloatArray  # (2,)
    pose: FloatArray  # (M, 6)
    scales: FloatArray  # (2,) s_x, s_z


def whitening_matrices(covariance_xz: FloatArray, floor_m: float) -> FloatArray:
    """W (M, 2, 2) with Wᵀ W the inverse of each corner covariance plus floor² I."""
    cov = np.asarray(covariance_xz, dtype=np.float64) + np.eye(2) * floor_m**2
    return np.asarray(np.linalg.inv(np.linalg.cholesky(cov)))


@dataclass(frozen=True, eq=False)
class _LineProblem:
    """The corner-on-line problem in the solver's block form."""

    corners_xz: FloatArray  # (M, 2)
    whitening: FloatArray  # (M, 2, 2)
    T_base_flange: FloatArray  # (M, 4, 4)
    prior_centre: FloatArray | None  # (4, 4)
    config: LineConfig
    lever_m: float
    free_scales: tuple[bool, bool]

    @property
    def n_global(self) -> int:
        return N_GLOBAL + sum(self.free_scales)

    @property
    def step_scale(self) -> FloatArray:
        lengths = [self.lever_m] * 3 + [1.0] * 3 + [self.lever_m] * 2 + [1.0] * 2
        return np.array(lengths + [self.lever_m] * sum(self.free_scales))

    @property
    def precision(self) -> FloatArray:
        cfg = self.config
        return np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)

    def _prior(self, X: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Residuals (R,) and Jacobian (R, G) of the loose hand-eye prior."""
        X0 = self.prior_centre
        if X0 is None:
            return np.zeros(0), np.zeros((0, self.n_global))
        cfg = self.config
        weights = np.array(
            [1.0 / cfg.initial_sigma_rotation_rad] * 3 + [1.0 / cfg.initial_sigma_translation_m] * 3
        )
        delta = np.concatenate([rotvec_from_matrix(X0[:3, :3].T @ X[:3, :3]), X[:3, 3] - X0[:3, 3]])
        J = np.zeros((6, self.n_global))
        J[:, :6] = np.diag(weights)
        return weights * delta, J

    def _corners(self, scales: FloatArray) -> FloatArray:
        """The corners (M, 2) with the scale errors removed, m."""
        return measured_to_true(self.corners_xz, float(scales[0]), float(scales[1]))

    def _model(self, state: _State) -> LineResiduals:
        return line_residuals(
            self._corners(state.scales),
            self.whitening,
            self.T_base_flange,
            state.X,
            state.R_L,
            state.offset,
            state.pose,
        )

    def residuals(self, state: _State) -> Residuals:
        return Residuals(
            self._model(state).residuals, state.pose * self.precision, self._prior(state.X)[0]
        )

    def linearise(self, state: _State) -> Linearisation:
        model = self._model(state)
        prior, J_prior = self._prior(state.X)
        # The residual is the whitened in-plane offset of the true corner (x / (1 + s_x),
        # z / (1 + s_z)), so d residual / d s_a = W[:, :, a] · (−true_a / (1 + s_a)).
        true = self._corners(state.scales)
        J_scales = [
            self.whitening[:, :, [a]] * (-true[:, a] / (1.0 + state.scales[a]))[:, None, None]
            for a in range(2)
            if self.free_scales[a]
        ]
        return Linearisation(
            residuals=Residuals(model.residuals, state.pose * self.precision, prior),
            J_global=np.concatenate([model.hand_eye, model.line, *J_scales], axis=2),
            J_local=model.pose,
            pose_prior_sqrt_information=self.precision,
            global_prior_jacobian=J_prior,
        )

    def retract(self, state: _State, step_global: FloatArray, step_local: FloatArray) -> _State:
        X = state.X.copy()
        X[:3, :3] = X[:3, :3] @ matrix_from_rotvec(step_global[:3])
        X[:3, 3] += step_global[3:6]
        R_L, offset = retract_line(state.R_L, state.offset, step_global[6:N_GLOBAL])
        scales = state.scales.copy()
        scales[np.flatnonzero(self.free_scales)] += step_global[N_GLOBAL:]
        return _State(X, R_L, offset, state.pose + step_local, scales)


@dataclass(frozen=True)
class LineRefinement:
    """Outcome of :func:`refine_line` (per-view arrays follow the input order).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    line : Line
        The seam line in the base frame.
    covariance : ndarray, shape (10 + F, 10 + F)
        Of ``[θ (rad, sensor axes), ρ (m, flange), line delta (rad, rad, m, m)]`` and the F
        estimated scale errors (x before z), pose corrections marginalised, priors included.
    information_data : ndarray, shape (6, 6)
        Hand-eye information from the views alone (prior left out, line and scales
        marginalised).
    scales : ndarray, shape (2,)
        The scale errors (s_x, s_z) of the profiler's x and z axes; 0 where held.
    scale_sigmas : tuple of (float or None)
        1σ of each scale error; None where it was held.
    pose_corrections : ndarray, shape (M, 6)
    offsets_xz : ndarray, shape (M, 2)
        Each corner's in-plane offset (true, scale errors removed) from the line's crossing
        of its laser plane, m.
    view_chi2 : ndarray, shape (M,)
        Normalised squared residual of each view (corner and pose correction), ≈ χ²(2).
    cost_history : list of float
    iterations : int
    converged : bool
    problem : _LineProblem
        The problem solved (for :meth:`views`).
    """

    T_flange_sensor: FloatArray
    line: Line
    covariance: FloatArray
    information_data: FloatArray
    scales: FloatArray
    scale_sigmas: tuple[float | None, float | None]
    pose_corrections: FloatArray
    offsets_xz: FloatArray
    view_chi2: FloatArray
    cost_history: list[float]
    iterations: int
    converged: bool
    problem: _LineProblem

    def views(self) -> ViewsLinearised:
        """The views linearised at the solution with every pose correction at zero, for
        :func:`~...shared_pose.shared_pose_error` (its covariance in the order of
        :attr:`covariance`)."""
        problem = self.problem
        R_L, offset = self.line.frame()
        pose = np.zeros((len(problem.corners_xz), 6))
        state = _State(self.T_flange_sensor, R_L, offset, pose, self.scales)
        return ViewsLinearised.from_linearisation(problem.linearise(state), problem.T_base_flange)


def refine_line(
    corners_xz: FloatArray,
    covariances_xz: FloatArray,
    T_base_flange: FloatArray,
    T_flange_sensor0: FloatArray,
    line0: Line,
    T_flange_sensor_prior: FloatArray | None,
    config: LineConfig,
    free_scales: tuple[bool, bool] = (False, False),
) -> LineRefinement:
    """Maximum-likelihood hand-eye and line (see the module docstring).

    Parameters
    ----------
    corners_xz : ndarray, shape (M, 2)
        Corners (x, z) in the sensor frame, m.
    covariances_xz : ndarray, shape (M, 2, 2)
        Their covariances, m² (floored by ``config.corner_sigma_floor_m``).
    T_base_flange : ndarray, shape (M, 4, 4)
        Reported flange poses.
    T_flange_sensor0 : ndarray, shape (4, 4)
        Start hand-eye.
    line0 : Line
        Start line.
    T_flange_sensor_prior : ndarray, shape (4, 4), or None
        Centre of the loose hand-eye prior; None for none.
    config : LineConfig
    free_scales : (bool, bool)
        Whether the x and the z scale errors are estimated (held at 0 otherwise).

    Raises
    ------
    SolverError
        Non-finite values.
    """
    c = np.asarray(corners_xz, dtype=np.float64)
    problem = _LineProblem(
        c,
        whitening_matrices(covariances_xz, config.corner_sigma_floor_m),
        np.asarray(T_base_flange, dtype=np.float64),
        None if T_flange_sensor_prior is None else np.asarray(T_flange_sensor_prior),
        config,
        float(np.median(np.hypot(c[:, 0], c[:, 1]))),
        free_scales,
    )
    R_L, offset = line0.frame()
    start = _State(
        np.asarray(T_flange_sensor0, dtype=np.float64),
        R_L,
        offset,
        np.zeros((len(c), 6)),
        np.zeros(2),
    )
    solution = solve(
        problem,
        start,
        SolverConfig(max_iterations=config.max_iterations, tolerance=config.tolerance),
    )
    state = solution.state
    if not (np.all(np.isfinite(state.X)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the line refinement produced non-finite values")
    _, J_prior = problem._prior(state.X)
    information = solution.information
    data = solution.normal.schur_information(remove=J_prior.T @ J_prior)
    data_hand_eye = data[:6, :6] - data[:6, 6:] @ np.linalg.pinv(data[6:, 6:]) @ data[6:, :6]
    model = problem._model(state)
    r = solution.residuals
    covariance = np.asarray(np.linalg.pinv(information, hermitian=True))
    sigmas = iter(np.sqrt(np.diag(covariance)[N_GLOBAL:]))
    return LineRefinement(
        T_flange_sensor=transform_from_rotation_translation(state.X[:3, :3], state.X[:3, 3]),
        line=Line.from_frame(state.R_L, state.offset),
        covariance=covariance,
        information_data=np.asarray(0.5 * (data_hand_eye + data_hand_eye.T)),
        scales=state.scales.copy(),
        scale_sigmas=(
            float(next(sigmas)) if free_scales[0] else None,
            float(next(sigmas)) if free_scales[1] else None,
        ),
        pose_corrections=state.pose.copy(),
        offsets_xz=model.offsets_xz,
        view_chi2=np.sum(r.points**2, axis=1) + np.sum(r.pose_prior**2, axis=1),
        cost_history=solution.cost_history,
        iterations=solution.iterations,
        converged=solution.converged,
        problem=problem,
    )
