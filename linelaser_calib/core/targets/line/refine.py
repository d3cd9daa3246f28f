"""Maximum-likelihood hand-eye and seam line from the corners of many views.

Unknowns: the hand-eye (θ, ρ; R_X ← R_X Exp(θ), t_X ← t_X + ρ), the line (4, see
:mod:`.model`) and each view's flange-pose correction δ_i = (ω_i, τ_i) with Gaussian priors
σ_r, σ_t per axis (the robot's pose error, as in the cylinder's refinement). Each corner is
measured in the laser plane with the covariance of its fit (floored). An optional loose prior
ties the hand-eye to an initial one; it decides only what the views cannot.

The shared block solver (:mod:`linelaser_calib.core.solver`) minimises it, each view's
correction eliminated (Schur complement). The information of the hand-eye from the views
alone (prior left out, line and corrections marginalised) feeds the observability diagnosis.
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
from ...solver import Linearisation, SolverConfig, solve
from ...solver.lm import Residuals
from ...types import FloatArray
from .config import LineConfig
from .model import N_LINE, Line, LineResiduals, line_residuals, retract_line

#: Global parameters: hand-eye (6) and line (4).
N_GLOBAL = 6 + N_LINE


class _State(NamedTuple):
    X: FloatArray  # (4, 4)
    R_L: FloatArray  # (3, 3)
    offset: FloatArray  # (2,)
    pose: FloatArray  # (M, 6)


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

    @property
    def n_global(self) -> int:
        return N_GLOBAL

    @property
    def step_scale(self) -> FloatArray:
        return np.array([self.lever_m] * 3 + [1.0] * 3 + [self.lever_m] * 2 + [1.0] * 2)

    @property
    def precision(self) -> FloatArray:
        cfg = self.config
        return np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)

    def _prior(self, X: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Residuals (R,) and Jacobian (R, N_GLOBAL) of the loose hand-eye prior."""
        X0 = self.prior_centre
        if X0 is None:
            return np.zeros(0), np.zeros((0, N_GLOBAL))
        cfg = self.config
        weights = np.array(
            [1.0 / cfg.initial_sigma_rotation_rad] * 3 + [1.0 / cfg.initial_sigma_translation_m] * 3
        )
        delta = np.concatenate([rotvec_from_matrix(X0[:3, :3].T @ X[:3, :3]), X[:3, 3] - X0[:3, 3]])
        J = np.zeros((6, N_GLOBAL))
        J[:, :6] = np.diag(weights)
        return weights * delta, J

    def _model(self, state: _State) -> LineResiduals:
        return line_residuals(
            self.corners_xz,
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
        return Linearisation(
            residuals=Residuals(model.residuals, state.pose * self.precision, prior),
            J_global=np.concatenate([model.hand_eye, model.line], axis=2),
            J_local=model.pose,
            pose_prior_sqrt_information=self.precision,
            global_prior_jacobian=J_prior,
        )

    def retract(self, state: _State, step_global: FloatArray, step_local: FloatArray) -> _State:
        X = state.X.copy()
        X[:3, :3] = X[:3, :3] @ matrix_from_rotvec(step_global[:3])
        X[:3, 3] += step_global[3:6]
        R_L, offset = retract_line(state.R_L, state.offset, step_global[6:])
        return _State(X, R_L, offset, state.pose + step_local)


@dataclass(frozen=True)
class LineRefinement:
    """Outcome of :func:`refine_line` (per-view arrays follow the input order).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    line : Line
        The seam line in the base frame.
    covariance : ndarray, shape (10, 10)
        Of ``[θ (rad, sensor axes), ρ (m, flange), line delta (rad, rad, m, m)]``, pose
        corrections marginalised, priors included.
    information_data : ndarray, shape (6, 6)
        Hand-eye information from the views alone (prior left out, line marginalised).
    pose_corrections : ndarray, shape (M, 6)
    offsets_xz : ndarray, shape (M, 2)
        Each corner's in-plane offset from the line's crossing of its laser plane, m.
    view_chi2 : ndarray, shape (M,)
        Normalised squared residual of each view (corner and pose correction), ≈ χ²(2).
    cost_history : list of float
    iterations : int
    converged : bool
    """

    T_flange_sensor: FloatArray
    line: Line
    covariance: FloatArray
    information_data: FloatArray
    pose_corrections: FloatArray
    offsets_xz: FloatArray
    view_chi2: FloatArray
    cost_history: list[float]
    iterations: int
    converged: bool


def refine_line(
    corners_xz: FloatArray,
    covariances_xz: FloatArray,
    T_base_flange: FloatArray,
    T_flange_sensor0: FloatArray,
    line0: Line,
    T_flange_sensor_prior: FloatArray | None,
    config: LineConfig,
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
    )
    R_L, offset = line0.frame()
    start = _State(
        np.asarray(T_flange_sensor0, dtype=np.float64), R_L, offset, np.zeros((len(c), 6))
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
    return LineRefinement(
        T_flange_sensor=transform_from_rotation_translation(state.X[:3, :3], state.X[:3, 3]),
        line=Line.from_frame(state.R_L, state.offset),
        covariance=np.asarray(np.linalg.pinv(information)),
        information_data=np.asarray(0.5 * (data_hand_eye + data_hand_eye.T)),
        pose_corrections=state.pose.copy(),
        offsets_xz=model.offsets_xz,
        view_chi2=np.sum(r.points**2, axis=1) + np.sum(r.pose_prior**2, axis=1),
        cost_history=solution.cost_history,
        iterations=solution.iterations,
        converged=solution.converged,
    )
