"""Maximum-likelihood refinement of the hand-eye on every profile point (the default method).

The driver (start, solve, outlier samples and points) and the statistics of the solution.
The problem it solves (the model, its parametrisation and Jacobians) is :mod:`.problem`.

Covariance
----------
The inverse of the Schur-complemented information (robust weights at the solution) is the
covariance of the global numbers with every pose correction marginalised. The hand-eye block
(6×6) is ordered ``[θ_x, θ_y, θ_z, ρ_x, ρ_y, ρ_z]``: θ small rotation angles (rad) about the
sensor frame axes (right perturbation ``R = R̂·Exp(θ)``), ρ translation (m) in the flange
frame.

With ``estimate_variance_factors`` (the default) the two noise levels are re-estimated from
the residuals before the covariance is formed (variance-component estimation): the point
residuals give the sensor's factor s_s² = Σ robust point cost / r_points and the pose
corrections give the robot's factor s_r² = Σ prior residual² / r_prior, where the
redundancies r are the shares of the degrees of freedom that each group of observations
keeps (r_prior = Σ_j (6 − tr(P·C_j⁻¹)), about 4 per sample, since a profile fixes 4 of its
pose's 6 degrees of freedom; r_points = points − globals − r_prior). The covariance then uses
σ_s·s_s and σ_r·s_r, σ_t·s_r (neither σ taken below 0.1 of the configured one). A single
χ²/dof factor would be wrong here: the point χ² is about the sensor, while the hand-eye's
uncertainty is mostly the robot's. On simulated data at the paper's noise the 1σ so formed
holds the true error 71 % of the time per axis (bench/refine_study.py, 100 seeds).

With the along-line scale estimated, the move that its errors-in-variables correction makes
is added to the covariance as a rank-one term (:func:`.problem.errors_in_variables_move`): under a
large smooth shape error that first-order correction is no better than its own size.

Correlated point noise
----------------------
A real profiler's smooth shape error along the line (several µm over a few mm, drawn anew
per profile) does not average out over a profile's points as white noise does. Taking the
points as independent then costs accuracy and overstates it: on the ``cylinder_keyence``
preset the translation error was 0.30 mm RMS (4 seeds), against a Cramér–Rao bound of
0.075 mm for the same points, and 4 times the white-noise twin's. So
:func:`refine_with_outlier_rejection` learns the recording's line noise (white σ, smooth σ
and correlation length, or a depth σ, :mod:`~linelaser_calib.core.profile.noise`) from the
first solve's pooled residuals and solves again with every sample's residuals whitened by it
(generalised least squares); the covariance is then that of the correlated noise
(bench/realistic_sensors.py). A learned length beyond a third of the profiles' extent is
not used (:func:`recording_line_noise`). A per-point variance that grows with the cosine
to the depth axis (depth noise above the lateral one: the smooth part's limit ℓ → 0)
weighs each point by its own variance (a diagonal whitening, the same path).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import chdtri
from scipy.stats import median_abs_deviation

from ...errors import DegenerateError, InputError, SolverError
from ...geometry import FloatArray, exp_so3, transform_from_rotation_translation
from ...observability import Observability, analyse_observability, pose_geometry
from ...profile.along_line import measured_to_true
from ...profile.noise import LineNoise, learn_line_noise, learning_profiles, line_whitening
from ...solver import (
    N_HAND_EYE,
    N_LOCAL,
    BlockNormal,
    Flag,
    RejectionOutcome,
    Solution,
    SolverConfig,
    dispersion_warning,
    normal_equations,
    robust_costs,
    sample_dispersion,
    solve,
    solve_with_rejection,
    variance_factors,
    widen_covariance,
)
from ...types import StoredArray
from ..base import ROBOT_PRIOR_EXCESS
from .config import RefineConfig
from .model import Cylinder
from .problem import (
    CylinderProblem,
    CylinderState,
    build_problem,
    data_centroid,
    errors_in_variables_move,
    initial_state,
    lever_arm_m,
    recentred,
)

#: 1σ of the estimated along-line scale beyond which the poses are said to barely tell a
#: profile stretched along the line from a larger cylinder (0.015 % on ``ur_scancontrol`` and
#: 0.05 % on ``cluttered_camera`` with the radius free).
MAX_SCALE_SIGMA = 0.002


#: Longest correlation length of a learned line noise, as a fraction of the median profile's
#: extent along the line, that the refinement weighs the points by (see
#: :func:`recording_line_noise`); the real-profiler presets learn 0.12-0.2 (3-5 mm on
#: 16-40 mm arcs).
MAX_NOISE_LENGTH_FRACTION = 1.0 / 3.0

#: RMS point residual of the solve weighed by the learned line noise, over that noise's own
#: 1σ (white and smooth parts together), beyond which the learned noise is not used. Where
#: the noise model holds, the residual is at most about its 1σ (the fit leaves the smooth
#: error in the residuals rather than fitting it away as the first solve does: on
#: cylinder_keyence 3.6 µm against 4.3 µm, 1.3 times the first solve's); where the whitened
#: cost lets a misfit of the shape along the line pass (all arcs short) it is many times it.
MAX_NOISE_RESIDUAL_RATIO = 2.0
#: RMS point residual of the solve weighed by the learned line noise, over the first
#: (independent points) solve's, beyond which the learned noise is not used either. The
#: weighed solve leaves the smooth error in its residuals (1.3 times on cylinder_keyence);
#: on arcs of 25 degrees REML, seeing the smooth error only through what 6 pose parameters
#: leave of it, learned 67 µm over 2 mm from 6.6 µm residuals, and the solve so weighed
#: left 89 µm (13 times): a misfit that the learned noise's own 1σ let pass.
MAX_FIRST_RESIDUAL_RATIO = 3.0
#: The first solve of :func:`refine_with_outlier_rejection`, which only starts the reported
#: one, stops where its steps tell that the optimum is within this fraction of each global
#: parameter's 1σ (its noise levels learned from its residuals), as the self-check's subsets
#: do. ``ur_scancontrol``, 1,600 poses: 4 linearisations, not 7 (the last three moved the
#: cost by under 1e-7 of itself).
START_STEP_SIGMAS = 0.01


class DroppedSample(NamedTuple):
    """A sample removed as an outlier: its index in the caller's list and why (µm, mm, deg)."""

    sample_index: int
    reason: str


@dataclass
class RefineResult:
    """Outcome of :func:`refine` or :func:`refine_with_outlier_rejection`.

    Per-sample arrays follow :attr:`used` (indices into the caller's sample list).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    cylinder : Cylinder
        Axis point closest to the base origin, unit direction (sign of the start value), radius.
    radius_estimated : bool
    covariance_hand_eye : ndarray, shape (6, 6)
        Covariance of ``[θ (rad, about sensor x, y, z; R = R̂·Exp(θ)), ρ (m, flange frame;
        t = t̂ + ρ)]``, pose corrections, axis and radius marginalised.
    sigma_rotation_rad : ndarray, shape (3,)
        1σ of θ, rad.
    sigma_translation_m : ndarray, shape (3,)
        1σ of ρ, m.
    sigma_radius_m : float or None
        1σ of the radius, when estimated.
    scale : float
        The sensor's along-line scale error s (dimensionless: the profiler reports x as
        (1 + s) times the true value); 0 when not estimated.
    sigma_scale : float or None
        1σ of ``scale``, when estimated, from the noise model only: with the radius given,
        whatever else stretches every arc (grazing-angle smear) goes into the scale too
        (+0.83 ± 0.02 % for a true +0.5 % on ``cluttered_camera``).
    scale_radius_correlation : float or None
        Correlation coefficient of the scale and the radius, when both are estimated.
    used : list of int
        Indices (into the caller's list) of the samples in the solve.
    dropped : list of DroppedSample
        Samples removed as outliers (by :func:`refine_with_outlier_rejection`).
    sample_rms_m : ndarray, shape (M,)
        RMS point-to-surface residual of each sample, m.
    sample_rms_zscore : ndarray, shape (M,)
        Robust z-score ((value − median) / (1.4826 · MAD)) of each sample's RMS residual as
        the noise model weighs it: ``sample_rms_m`` over σ_s, or with a learned line noise
        the whitened residual's RMS, so that a profile whose smooth shape error happens to
        be large (a draw of the recording's own noise) is no outlier.
    sample_prior_chi2 : ndarray, shape (M,)
        ``|ω/σ_r|² + |τ/σ_t|²`` of each pose correction (≈ χ² with ≤ 6 dof if plausible).
    sample_downweighted : ndarray, shape (M,)
        Share of each sample's points beyond the robust loss scale.
    pose_corrections : ndarray, shape (M, 6)
        ``[ω (rad), τ (m)]`` per sample, flange frame: true pose = T_base_flange · D(δ).
    rms_residual_m : float
        RMS point-to-surface residual over all points, m.
    chi2_dof : float
        (robust point cost + prior cost) · 2 / (points − global parameters).
    sensor_sigma_estimated_m : float
        Sensor σ re-estimated from the point residuals, m (the configured one when
        ``estimate_variance_factors`` is off).
    robot_sigma_scale : float
        Robot σ re-estimated from the pose corrections, as a multiple of the configured
        σ_t and σ_r (1 when ``estimate_variance_factors`` is off).
    cost_history : list of float
        Cost after each accepted step, starting with the initial cost.
    iterations : int
        Linearisations performed.
    converged : bool
    n_points : int
        Points in the solve after subsampling.
    observability : Observability
        Of the pose set for the configured noise levels (the design question "do these
        poses suffice"), whereas the covariance uses the re-estimated ones.
    warnings : list of str
    solved : SolvedProblem or None
        The problem as solved (points trimmed and subsampled) and the state at the solution,
        rows in :attr:`used` order, for :func:`.warm.refine_subset`.
    line_noise : LineNoise or None
        The recording's point noise along the line that weighed the points (generalised
        least squares), when learned; None weighs them as independent.
    sample_dispersion : ndarray, shape (6,), or None
        How much more the hand-eye moves from profile to profile than the noise model
        says, per axis (observed over expected variance,
        :func:`~linelaser_calib.core.solver.sample_dispersion`); the 1σ above is widened by
        its square root where it exceeds 1. None when not checked (too few profiles).
    depth_scale : float
        The sensor's depth scale error s_z about its origin (z reported as (1 + s_z) times
        the true value); 0 when not estimated.
    sigma_depth_scale : float or None
        1σ of ``depth_scale``, when estimated.
    """

    T_flange_sensor: FloatArray
    cylinder: Cylinder
    radius_estimated: bool
    covariance_hand_eye: FloatArray
    sigma_rotation_rad: FloatArray
    sigma_translation_m: FloatArray
    sigma_radius_m: float | None
    scale: float
    sigma_scale: float | None
    scale_radius_correlation: float | None
    used: list[int]
    dropped: list[DroppedSample]
    sample_rms_m: FloatArray
    sample_rms_zscore: FloatArray
    sample_prior_chi2: FloatArray
    sample_downweighted: FloatArray
    pose_corrections: FloatArray
    rms_residual_m: float
    chi2_dof: float
    sensor_sigma_estimated_m: float
    robot_sigma_scale: float
    cost_history: list[float]
    iterations: int
    converged: bool
    n_points: int
    observability: Observability
    warnings: list[str]
    solved: SolvedProblem | None = None
    line_noise: LineNoise | None = None
    sample_dispersion: FloatArray | None = None
    depth_scale: float = 0.0
    sigma_depth_scale: float | None = None

    @property
    def sample_residuals_m(self) -> dict[int, float]:
        """Per-sample RMS residual, m, keyed by the caller's sample index."""
        return {j: float(r) for j, r in zip(self.used, self.sample_rms_m, strict=True)}


@dataclass(frozen=True)
class SolvedProblem:
    """A refinement's problem (its points trimmed and subsampled), its state at the
    solution, the line noise it was weighed by, the sensor and robot variance factors it
    estimated there and its normal equations there (robust weights there): where
    :func:`.warm.refine_subset` starts a solve of some of its samples, whose first
    linearisation is then these equations' rows."""

    problem: CylinderProblem
    state: CylinderState
    noise: LineNoise | None = None
    variance_factors: tuple[float, float] = (1.0, 1.0)
    normal: BlockNormal | None = None


def _marginal_hand_eye(information: FloatArray) -> FloatArray:
    """Information (6, 6) of the hand-eye after eliminating the axis (radius, scale)."""
    h, o = slice(0, N_HAND_EYE), slice(N_HAND_EYE, None)
    S_oo = information[o, o]
    return np.asarray(
        information[h, h] - information[h, o] @ np.linalg.pinv(S_oo) @ information[o, h]
    )


# --------------------------------------------------------------------------------------
# The solve


def _robust_zscore(values: FloatArray) -> FloatArray:
    """(value − median) / (1.4826 · MAD), the MAD floored at 1e-3 of the median."""
    median, mad = float(np.median(values)), float(median_abs_deviation(values, scale="normal"))
    return np.asarray((values - median) / max(mad, 1e-3 * abs(median), 1e-300))


def _observability(
    problem: CylinderProblem, state: CylinderState, information: FloatArray
) -> Observability:
    T = transform_from_rotation_translation(state.R_fs, state.t_fs)
    T_base_flange = np.zeros((problem.n_samples, 4, 4))
    T_base_flange[:, :3, :3] = problem.R_bf
    T_base_flange[:, :3, 3] = problem.t_bf
    T_base_flange[:, 3, 3] = 1.0
    return analyse_observability(
        _marginal_hand_eye(information),
        lever_arm_m(problem),
        pose_geometry(T_base_flange, T, state.point, state.direction),
        problem.config.observability,
    )


def refine(
    samples_points: Sequence[StoredArray],
    T_base_flange: ArrayLike,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
    pose_corrections0: FloatArray | None = None,
    scale0: float = 0.0,
    noise: LineNoise | None = None,
    depth_scale0: float = 0.0,
    observed: bool = False,
    solver: SolverConfig | None = None,
) -> RefineResult:
    """Maximum-likelihood hand-eye, axis and radius from every profile point.

    Parameters
    ----------
    samples_points : list of ndarray, shape (N_j, 3)
        Inlier profile points of each sample in the sensor frame, m.
    T_base_flange : array-like, shape (M, 4, 4)
        Reported flange poses, one per sample (translation in m).
    T_flange_sensor0 : array-like, shape (4, 4)
        Initial hand-eye, e.g. from the paper's solver (about 1 deg / 1 mm off); starts up to
        about 5 deg / 10 mm off converge (measured on simulated data).
    cylinder0 : Cylinder
        Initial axis in the base frame; its radius is the start value when estimated.
    config : RefineConfig, optional
    radius_m : float, optional
        Known radius, m (fixed unless ``config.estimate_radius``); None estimates it.
    pose_corrections0 : ndarray, shape (M, 6), optional
        Start of the pose corrections ``[ω, τ]`` (default zero), e.g. an earlier solve's.
    scale0 : float
        Start of the along-line scale error, when estimated.
    noise : LineNoise, optional
        The points' correlated noise along the line: each sample's residuals are whitened
        with it (generalised least squares; normals taken at the start). None weighs the
        points as independent with σ_s.
    depth_scale0 : float
        Start of the depth scale error, when estimated.
    observed : bool
        The poses passed the observability check at an earlier solve's solution (a re-solve
        of the same samples): not checked before the solve, only at its solution.
    solver : SolverConfig, optional
        The solve's settings (e.g. a looser stop); None: ``config.solver``.

    Returns
    -------
    RefineResult

    Raises
    ------
    InputError
        Malformed input.
    DegenerateError
        Too few samples, or poses that leave a hand-eye direction unobservable; the message
        names the motion to add.
    SolverError
        The solve produced non-finite numbers.
    """
    cfg = RefineConfig() if config is None else config
    estimate_radius = radius_m is None or cfg.estimate_radius
    problem = build_problem(samples_points, T_base_flange, cfg, estimate_radius)
    state = initial_state(
        problem, T_flange_sensor0, cylinder0, cylinder0.radius if radius_m is None else radius_m
    )
    if pose_corrections0 is not None:
        start = np.asarray(pose_corrections0, dtype=np.float64)
        state = replace(state, omega=start[:, :3].copy(), tau=start[:, 3:].copy())
    if problem.estimate_scale:
        state = replace(state, scale=float(scale0))
    if problem.estimate_depth_scale:
        state = replace(state, depth_scale=float(depth_scale0))
    if noise is not None:
        whitening = line_whitening(
            noise,
            problem.x_m,
            problem.depth_cosines(state),
            problem.mask,
            cfg.sensor_sigma_m,
        )
        problem = replace(problem, whitening=whitening)
    problem = problem.with_scale_shares(state)
    if not observed:
        geometric = normal_equations(
            problem.linearise_chunks(state), cfg.solver, np.broadcast_to(1.0, problem.mask.shape)
        ).schur_information()
        _observability(problem, state, geometric).raise_if_unobservable()

    centroid = data_centroid(problem, state)
    problem = replace(problem, centroid=centroid)
    solution = solve(problem, recentred(state, centroid), solver or cfg.solver)
    if not (np.all(np.isfinite(solution.state.R_fs)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the refinement produced non-finite values: check the initial estimate")
    return summarise(problem, solution, noise)


def summarise(
    problem: CylinderProblem, solution: Solution[CylinderState], noise: LineNoise | None = None
) -> RefineResult:
    """Covariance, observability and per-sample statistics at the solution (``noise``: the
    line noise the problem's whitening was formed with)."""
    cfg = problem.config
    state, normal = solution.state, solution.normal
    # First: the lever arm's distances of every point are then not held beside e below.
    observability = _observability(problem, state, normal.schur_information())
    observability.raise_if_unobservable()
    e, prior = solution.residuals.points, solution.residuals.pose_prior
    point_cost = float(np.sum(robust_costs(e, cfg.solver)))
    prior_cost = float(np.sum(prior**2))
    weighed_rms = np.sqrt(np.sum(e**2, axis=1) / problem.counts)
    if problem.whitening is not None:
        e = problem.point_residuals(state)  # per-point statistics on the plain residuals
    n_points = problem.n_measurements
    chi2_dof = (point_cost + prior_cost) / max(n_points - problem.n_global, 1)
    factors = (1.0, 1.0)
    if cfg.estimate_variance_factors:
        factors = variance_factors(normal, point_cost, prior_cost, n_points, problem.n_global)
    covariance = np.linalg.inv(normal.schur_information(*factors))
    dispersion = sample_dispersion(solution, *factors) if cfg.widen_by_dispersion else None
    covariance = widen_covariance(covariance, dispersion)
    shares_move = errors_in_variables_move(problem, normal)
    covariance = covariance + np.outer(shares_move, shares_move)
    sigma = np.sqrt(np.diag(covariance))
    r, s, z = problem.radius_index, problem.scale_index, problem.depth_scale_index

    squares = np.sum((e * cfg.sensor_sigma_m) ** 2, axis=1)
    sample_rms = np.sqrt(squares / problem.counts)
    beyond = np.sum(np.abs(e) > cfg.loss_scale, axis=1)
    cylinder_point = state.point - float(state.point @ state.direction) * state.direction
    warnings = list(observability.warnings)
    scatter = dispersion_warning(dispersion)
    if scatter is not None:
        warnings.append(scatter)
    correlation = (
        None if r is None or s is None else float(covariance[r, s] / (sigma[r] * sigma[s]))
    )
    if s is not None and sigma[s] > MAX_SCALE_SIGMA:
        warnings.append(
            f"the sensor's along-line scale is poorly determined (1 sigma {100.0 * sigma[s]:.2f} "
            "%"
            + ("" if correlation is None else f", correlated {correlation:+.2f} with the radius")
            + "): these profiles barely tell a profile stretched along the line from a larger "
            "cylinder or a shifted hand-eye. Give the measured radius ({setting:radius_m}), or "
            "scan with "
            "the arc at several positions along the laser line"
        )
    history = solution.cost_history
    robot_scale = float(np.sqrt(factors[1]))
    prior_note = ""
    if cfg.estimate_variance_factors and robot_scale > ROBOT_PRIOR_EXCESS:
        prior_note = (
            f"the robot's pose error is about {robot_scale:.1f} times the prior assumed: "
            f"{cfg.robot_sigma_t_m * robot_scale * 1e3:.3f} mm and "
            f"{np.degrees(cfg.robot_sigma_r_rad) * robot_scale:.4f} deg per pose (1 sigma, from "
            f"the pose corrections) against {cfg.robot_sigma_t_m * 1e3:.3f} mm and "
            f"{np.degrees(cfg.robot_sigma_r_rad):.4f} deg "
            "({setting:robot_sigma_t_m}, {setting:robot_sigma_r_rad})"
        )
        warnings.append(
            prior_note + "; the 1 sigma above is formed with the larger error, and the arm is "
            "less accurate than assumed"
        )
    if not solution.converged:
        warnings.append(
            f"the refinement stopped after {solution.iterations} iterations without converging "
            f"(cost {history[-1]:.6g}); the result may be inaccurate"
            + (
                f". A likely reason: {prior_note}; give the larger values with "
                "{setting:robot_sigma_t_m} and {setting:robot_sigma_r_rad}"
                if prior_note
                else ""
            )
        )
    return RefineResult(
        T_flange_sensor=transform_from_rotation_translation(state.R_fs, state.t_fs),
        cylinder=Cylinder(
            point=cylinder_point, direction=state.direction.copy(), radius=state.radius
        ),
        radius_estimated=problem.estimate_radius,
        covariance_hand_eye=covariance[:N_HAND_EYE, :N_HAND_EYE],
        sigma_rotation_rad=sigma[:3],
        sigma_translation_m=sigma[3:6],
        sigma_radius_m=None if r is None else float(sigma[r]),
        scale=state.scale,
        sigma_scale=None if s is None else float(sigma[s]),
        scale_radius_correlation=correlation,
        depth_scale=state.depth_scale,
        sigma_depth_scale=None if z is None else float(sigma[z]),
        used=list(range(problem.n_samples)),
        dropped=[],
        sample_rms_m=sample_rms,
        sample_rms_zscore=_robust_zscore(weighed_rms),
        sample_prior_chi2=np.sum(prior**2, axis=1),
        sample_downweighted=beyond / problem.counts,
        pose_corrections=np.hstack([state.omega, state.tau]),
        rms_residual_m=float(np.sqrt(np.sum(squares) / n_points)),
        chi2_dof=chi2_dof,
        # A point's 1σ about the surface: with a learned line noise its white and smooth
        # parts together (the factor then scales the whitened residuals).
        sensor_sigma_estimated_m=float(np.sqrt(factors[0]))
        * (cfg.sensor_sigma_m if noise is None else noise.point_sigma_m),
        robot_sigma_scale=robot_scale,
        cost_history=history,
        iterations=solution.iterations,
        converged=solution.converged,
        n_points=n_points,
        observability=observability,
        warnings=warnings,
        solved=SolvedProblem(problem, state, noise, factors, normal),
        line_noise=noise,
        sample_dispersion=None if dispersion is None else dispersion[:N_HAND_EYE],
    )


# --------------------------------------------------------------------------------------
# Outlier samples


def _outlier_samples(result: RefineResult, config: RefineConfig) -> list[Flag]:
    """Samples inconsistent with the rest (positions in ``result.used``), with reasons."""
    rms, z_rms = result.sample_rms_m, result.sample_rms_zscore
    prior_chi2 = result.sample_prior_chi2
    z_prior = _robust_zscore(np.sqrt(prior_chi2))
    # P(chi2 > limit) = outlier_prior_probability
    chi2_limit = float(chdtri(N_LOCAL, config.outlier_prior_probability))
    median_rms = float(np.median(rms))
    flagged = []
    for j in range(len(rms)):
        reasons = []
        if (
            z_rms[j] > config.outlier_zscore
            and rms[j] > config.outlier_min_rms_sigma * config.sensor_sigma_m
        ):
            reasons.append(
                f"its points lie {rms[j] * 1e6:.1f} um RMS off the cylinder (median sample "
                f"{median_rms * 1e6:.1f} um, robust z {z_rms[j]:.0f}"
                + ("" if result.line_noise is None else " weighed by the learned line noise")
                + ")"
            )
        if prior_chi2[j] > chi2_limit and z_prior[j] > config.outlier_zscore:
            omega, tau = result.pose_corrections[j, :3], result.pose_corrections[j, 3:]
            reasons.append(
                "fitting them needs a flange pose correction of "
                f"{np.linalg.norm(tau) * 1e3:.2f} mm and {np.rad2deg(np.linalg.norm(omega)):.3f} "
                f"deg (prior chi2 {prior_chi2[j]:.0f} > {chi2_limit:.0f} for the robot's 1 sigma "
                f"of {config.robot_sigma_t_m * 1e3:.3f} mm and "
                f"{np.rad2deg(config.robot_sigma_r_rad):.3f} deg)"
            )
        if reasons:
            reason = (
                "; ".join(reasons)
                + ": the profile does not fit at its recorded flange pose (wrong pairing, motion "
                "during the scan, or not the cylinder)"
            )
            flagged.append(Flag(max(float(z_rms[j]), float(z_prior[j])), j, reason))
    return flagged


def point_residuals_m(
    samples_points: Sequence[StoredArray], T_base_flange: ArrayLike, result: RefineResult
) -> list[FloatArray]:
    """Signed point-to-surface distances at a solution, with its pose corrections.

    Parameters
    ----------
    samples_points : list of ndarray, shape (N_j, 3)
        Sensor-frame points of the samples in ``result.used`` (same order), m.
    T_base_flange : array-like, shape (M, 4, 4)
        Their reported flange poses.
    result : RefineResult

    Returns
    -------
    list of ndarray, shape (N_j,)
        Distance to the axis minus the radius for every point, m.
    """
    T_all = np.asarray(T_base_flange, dtype=np.float64)
    R_fs, t_fs = result.T_flange_sensor[:3, :3], result.T_flange_sensor[:3, 3]
    c, d = result.cylinder.point, result.cylinder.direction
    out = []
    for p, T, delta in zip(samples_points, T_all, result.pose_corrections, strict=True):
        R = T[:3, :3] @ exp_so3(delta[None, :3])[0]
        w = (measured_to_true(p, result.scale, result.depth_scale) @ R_fs.T + t_fs) @ R.T + (
            T[:3, 3] + T[:3, :3] @ delta[3:] - c
        )
        radial = w - np.outer(w @ d, d)
        out.append(np.sqrt(np.sum(radial**2, axis=1)) - result.cylinder.radius)
    return out


def recording_line_noise(result: RefineResult, limit_m: float) -> LineNoise | None:
    """The recording's point noise along the line, learned from a solve's residuals
    (:func:`~linelaser_calib.core.profile.noise.learn_line_noise`), points beyond
    ``limit_m`` left out.

    None (weigh the points as independent and alike) when the solve kept no problem, too
    few profiles, the residuals look white, or the learned correlation length exceeds
    :data:`MAX_NOISE_LENGTH_FRACTION` of the median profile's extent along the line: an
    error that smooth moves a whole profile as its pose would, so the residuals cannot tell
    its size (REML's likelihood is flat along larger σ with longer length), and what they
    show is more likely a systematic misfit (a scale error, a grazing-angle bias on
    ``cluttered_camera``: lengths of 17-30 mm on 25 mm arcs) than noise to weigh by.
    """
    if result.solved is None:
        return None
    problem, state = result.solved.problem, result.solved.state
    residuals = problem.point_residuals(state) * problem.config.sensor_sigma_m
    mask = problem.mask * (np.abs(residuals) <= limit_m)
    try:
        rows = learning_profiles(mask)  # the bases of these few, not of the whole recording
        learned, at = (
            problem.take(rows),
            replace(state, omega=state.omega[rows], tau=state.tau[rows]),
        )
        noise = learn_line_noise(
            residuals[rows],
            learned.x_m,
            learned.depth_cosines(at),
            mask[rows],
            learned.unwhitened_local_jacobian(at),
        )
    except InputError:
        return None
    x = np.where(mask > 0.0, problem.x_m, np.nan)
    extent = float(np.nanmedian(np.nanmax(x, axis=1) - np.nanmin(x, axis=1)))
    if noise.smooth_sigma_m > 0.0:
        return noise if noise.length_m <= MAX_NOISE_LENGTH_FRACTION * extent else None
    return noise if noise.depth_sigma_m > 0.0 else None


def _trim_points(
    samples_points: Sequence[StoredArray],
    T_base_flange: FloatArray,
    result: RefineResult,
    limit_m: float,
) -> tuple[list[StoredArray], int]:
    """Drop points whose residual exceeds ``limit_m``; returns the samples and the count. A
    sample that loses no point is its own array, not a copy (the caller holds the returned
    samples through the solve: 6 MB of copies on a 1,600-profile recording)."""
    residuals = point_residuals_m(samples_points, T_base_flange, result)
    trimmed, removed = [], 0
    for p, r in zip(samples_points, residuals, strict=True):
        keep = np.abs(r) <= limit_m
        dropped = int(np.count_nonzero(~keep))
        removed += dropped
        trimmed.append(np.asarray(p)[keep] if dropped else np.asarray(p))
    return trimmed, removed


def refine_with_outlier_rejection(
    samples_points: Sequence[StoredArray],
    T_base_flange: ArrayLike,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
    screen: bool = True,
) -> RefineResult:
    """:func:`refine`, then drop samples inconsistent with the rest and solve again
    (without ``screen``, a set screened already: no sample dropped).

    After each solve a sample is an outlier when its RMS point residual or its pose
    correction's prior χ² is far (``outlier_zscore`` robust standard deviations) above the
    other samples' and implausible in absolute terms (``outlier_min_rms_sigma`` σ_s, or a χ²
    tail probability below ``outlier_prior_probability``). All outliers of a round are dropped
    (most severe first, at most ``max_outlier_fraction`` of the samples over all rounds, and
    never below ``min_samples``) and the solve is repeated from the last solution until none
    is left (:func:`~linelaser_calib.core.solver.solve_with_rejection`). Outliers left because
    of the cap are reported in the warnings.

    Parameters and exceptions are those of :func:`refine`. The result's ``used`` and
    ``dropped`` give indices into ``samples_points``.
    """
    cfg = RefineConfig() if config is None else config
    T_all = np.asarray(T_base_flange, dtype=np.float64)
    T0, start = T_flange_sensor0, cylinder0
    points = list(samples_points)
    first: RefineResult | None = None
    noise: LineNoise | None = None
    if cfg.point_outlier_sigmas > 0.0 or cfg.learn_line_noise:
        starting = replace(cfg.solver, step_sigmas=START_STEP_SIGMAS, variance_factors=None)
        first = refine(points, T_all, T0, start, cfg, radius_m, solver=starting)
        sigma = max(cfg.sensor_sigma_m, first.sensor_sigma_estimated_m)
        limit = cfg.point_outlier_sigmas * sigma if cfg.point_outlier_sigmas > 0.0 else np.inf
        if cfg.learn_line_noise:
            noise = recording_line_noise(first, limit)
        trimmed, removed = _trim_points(points, T_all, first, limit)
        if removed and all(len(p) >= cfg.min_points_per_profile for p in trimmed):
            points = trimmed
        T0, start = first.T_flange_sensor, first.cylinder
        # Every round solves on from its solution: its problem let go (10 MB of 1,600 profiles).
        first = replace(first, solved=None)

    solved_rows: dict[int, int] = {}  # sample -> its row in the last solve's result

    def solve_subset(keep: list[int], previous: RefineResult | None) -> RefineResult:
        result = _solve_subset(keep, previous, noise)
        solved_rows.clear()
        solved_rows.update((i, row) for row, i in enumerate(keep))
        return result

    def _solve_subset(
        keep: list[int], previous: RefineResult | None, noise: LineNoise | None
    ) -> RefineResult:
        # Weighed by a learned smooth error, the solve keeps more points (the whitening's cost
        # grows with the points times its few tens of basis functions, not their square).
        # A per-point depth σ alone leaves the points independent: as many as white noise
        # (on 6 ur_scancontrol seeds every point moved the error as much with it as without).
        cfg_solve = (
            cfg
            if noise is None or noise.smooth_sigma_m == 0.0
            else replace(cfg, max_points_per_profile=cfg.max_points_per_profile_correlated)
        )
        base = previous or first
        if base is None:
            return refine(
                [points[i] for i in keep], T_all[keep], T0, start, cfg_solve, radius_m, noise=noise
            )
        # From the first solve (near its optimum) or the last round's, pose corrections too.
        rows = keep if previous is None else [solved_rows[i] for i in keep]
        return refine(
            [points[i] for i in keep],
            T_all[keep],
            base.T_flange_sensor,
            base.cylinder,
            cfg_solve,
            radius_m,
            base.pose_corrections[rows],
            base.scale,
            noise,
            base.depth_scale,
            observed=previous is None and len(keep) == len(points),
        )

    def with_rejection() -> RejectionOutcome[RefineResult]:
        return outlier_rounds(len(points), solve_subset, cfg, screen)

    try:
        outcome = with_rejection()
    except (DegenerateError, SolverError):
        if noise is None:
            raise
        outcome = None
    if noise is not None:
        assert first is not None  # the noise is learned from the first solve
        rms = np.inf if outcome is None else outcome.outcome.rms_residual_m
        if (
            rms > MAX_NOISE_RESIDUAL_RATIO * noise.point_sigma_m
            or rms > MAX_FIRST_RESIDUAL_RATIO * first.rms_residual_m
        ):
            # The learned noise explains a misfit, not noise: weigh the points as independent.
            noise = None
            outcome = with_rejection()
    assert outcome is not None
    return screened(outcome, cfg)


def outlier_rounds(
    n_samples: int,
    solve_subset: Callable[[list[int], RefineResult | None], RefineResult],
    config: RefineConfig,
    screen: bool = True,
) -> RejectionOutcome[RefineResult]:
    """:func:`~linelaser_calib.core.solver.solve_with_rejection` of ``n_samples`` samples
    with ``solve_subset`` and the outlier test of :func:`refine_with_outlier_rejection`
    (none without ``screen``)."""
    return solve_with_rejection(
        n_samples,
        solve_subset,
        lambda result, _keep: _outlier_samples(result, config),
        config.max_outlier_fraction,
        config.min_samples,
        screen,
    )


def screened(outcome: RejectionOutcome[RefineResult], config: RefineConfig) -> RefineResult:
    """The last solve of :func:`outlier_rounds` with its ``used`` and ``dropped`` samples
    (indices into the samples screened) and a warning for outliers the cap left in."""
    result = outcome.outcome
    if outcome.left_flagged:
        result.warnings.append(
            f"{len(outcome.left_flagged)} more sample(s) look like outliers but "
            f"max_outlier_fraction {config.max_outlier_fraction:.2f} allows no more drops: "
            + "; ".join(f"sample {i}: {reason}" for i, reason in outcome.left_flagged)
        )
    result.used = outcome.kept
    result.dropped = [DroppedSample(i, reason) for i, reason in outcome.dropped]
    return result
