"""Maximum likelihood on every profile point of a sphere, with the robot's pose error.

Model
-----
Sample j has profile points q_jk (sensor frame, m) and a reported flange pose T_j =
(R_j, t_j). The robot's pose error is a per-sample nuisance δ_j = (ω_j, τ_j) in the flange
frame (right perturbation, as for the cylinder): the true flange pose is T_j · D(δ_j),
D(δ) = [[Exp(ω), τ], [0, 1]]. A point maps into the base frame as

    x_jk = R_j (Exp(ω_j) s_jk + τ_j) + t_j,   s_jk = R_X q_jk + t_X,

and its residual is its distance from the sphere (centre c, radius R), measured in the
laser plane, where the profiler measures and errs:

    e_jk = w_j (‖x_jk − c‖ − R) / σ_s,   w_j = R / r_j,   r_j = √(R² − d_j²),

d_j the distance of c from sample j's laser plane and r_j the radius of the plane's section
of the sphere. An in-plane deviation δ moves a point only δ r_j / R off the sphere, so the
plain distance would rate a plane that cuts the ball far from its centre as a better fit,
and a larger radius as better on every profile that is not an exact circle (noise, or the
tens of µm of a real profiler's shape error): on the RobCalibrator scans the free radius
came out 41.2 mm for a 40 mm ball with the robot's σ at 1 mm (102 mm unweighted). r_j is
kept above :data:`MIN_SECTION_SHARE` R.

The profiler may read x along its line as (1 + s) times the true one: with
``estimate_scale`` the points are taken as q = (x / (1 + s), y, z) and s is estimated with
the rest (∂e/∂s = −w_j nᵀ R_j E_j R_X e_x q_x / (1 + s) / σ_s; the weight does not depend
on the points).

under the Huber loss (quadratic within ``loss_scale``, linear beyond) against spikes, plus
the Gaussian priors ω_j / σ_r and τ_j / σ_t per sample. Minimising ½ Σ loss is the joint
maximum a-posteriori estimate of the hand-eye, the sphere and the pose corrections.

Parameters and Jacobians
------------------------
The hand-eye is R_X = R̂·Exp(θ) (θ about the sensor axes), t_X = t̂ + ρ (ρ in the flange
frame); the centre and the radius are additive; so are ω_j and τ_j. With n = (x − c)/‖x − c‖
and J_r the right Jacobian of Exp:

- ∂e/∂θ = nᵀ R_j Exp(ω_j) (−R_X [q]ₓ J_r(θ)),  ∂e/∂ρ = nᵀ R_j Exp(ω_j);
- ∂e/∂c = −nᵀ,  ∂e/∂R = −1;
- ∂e/∂ω_j = nᵀ R_j (−Exp(ω_j) [s]ₓ J_r(ω_j)),  ∂e/∂τ_j = nᵀ R_j

(all times w_j / σ_s), plus the weight's own derivative times ‖x − c‖ − R: with
d_j = ν_jᵀ(c − o_j) (ν_j = R_j E_j R_X e_y the plane's normal, o_j the sensor origin),
∂w = (R d / r³) ∂d − (d² / r³) ∂R, and ∂d/∂θ = −(p × e_y)ᵀ (p the centre in the sensor
frame), ∂d/∂ρ = −(R_X e_y)ᵀ, ∂d/∂c = ν_jᵀ, ∂d/∂ω_j = ((R_X e_y) × (E_jᵀ R_jᵀ u_j))ᵀ J_r(ω_j)
(u_j = c − t_j − R_j τ_j), ∂d/∂τ_j = −ν_jᵀ R_j.
A point depends on the 9 or 10 global numbers and its sample's 6:
:func:`point_residuals` returns the residuals with these two Jacobian blocks.

Solver and covariance
---------------------
:class:`SphereProblem` states the problem in the shared solver's block form and
:func:`~linelaser_calib.core.solver.solve` minimises it (block-sparse Levenberg-Marquardt,
Schur complement over the samples). The covariance of the global numbers is the inverse of
their information with every pose correction marginalised, formed with the sensor's and the
robot's noise levels re-estimated from the residuals
(:func:`~linelaser_calib.core.solver.variance_factors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linelaser_calib.core.errors import InputError, SolverError
from linelaser_calib.core.geometry import (
    matrix_from_rotvec,
    right_jacobian_so3,
    transform_from_rotation_translation,
)
from linelaser_calib.core.profile.along_line import measured_to_true
from linelaser_calib.core.shared_pose import ViewsLinearised
from linelaser_calib.core.solver import (
    Linearisation,
    SolverConfig,
    robust_costs,
    sample_dispersion,
    solve,
    variance_factors,
    widen_covariance,
)
from linelaser_calib.core.solver.lm import Residuals
from linelaser_calib.core.types import BoolArray, FloatArray

IntArray = NDArray[np.int64]

#: Numbers per sample: the pose correction ω (3), τ (3).
N_LOCAL = 6
#: The section radius r_j in the in-plane weight R / r_j is at least this share of R.
MIN_SECTION_SHARE = 0.05


@dataclass(frozen=True)
class SphereState:
    """The unknowns of the refinement.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    centre_m : ndarray, shape (3,)
        Sphere centre, base frame, m.
    radius_m : float
    corrections : ndarray, shape (K, 6)
        Per-sample pose corrections [ω (rad), τ (m)], flange frame.
    scale : float
        The sensor's along-line scale error s (x reads (1 + s) times the true one; 0 unless
        estimated).
    """

    T_flange_sensor: FloatArray
    centre_m: FloatArray
    radius_m: float
    corrections: FloatArray
    scale: float = 0.0


def point_residuals(
    state: SphereState,
    T_base_flange: FloatArray,
    points: FloatArray,
    valid: BoolArray,
    sensor_sigma_m: float,
    *,
    jacobians: bool = True,
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """Point-to-sphere residuals and their Jacobian blocks, at ``state`` (θ = 0).

    The points are held per sample, padded (row j holds sample j's points), so that every
    product is a batched 3 × 3 one per sample.

    Parameters
    ----------
    state : SphereState
    T_base_flange : ndarray, shape (K, 4, 4)
    points : ndarray, shape (K, M, 3)
        Sensor-frame points of every sample as measured, m, padded (the state's along-line
        scale error is removed from them).
    valid : ndarray of bool, shape (K, M)
        The slots that hold a point (the others give zero residuals and Jacobians).
    sensor_sigma_m : float
    jacobians : bool
        Also the Jacobians (otherwise None for both).

    Returns
    -------
    residuals : ndarray, shape (K, M)
        w_j (‖x − c‖ − R) / σ_s (see the module docstring).
    J_global : ndarray, shape (K, M, 11), or None
        Against [θ (3), ρ (3), c (3), R, s].
    J_local : ndarray, shape (K, M, 6), or None
        Against the own sample's [ω (3), τ (3)].
    """
    X = state.T_flange_sensor
    points = measured_to_true(points, state.scale)
    omega, tau = state.corrections[:, :3], state.corrections[:, 3:]
    E = np.stack([matrix_from_rotvec(w) for w in omega]) if len(omega) else np.zeros((0, 3, 3))
    Rj = T_base_flange[:, :3, :3]
    RE = Rj @ E
    s = points @ X[:3, :3].T + X[:3, 3]
    # Per sample: x = R_j E_j s + (R_j τ_j + t_j).
    offset = np.einsum("kij,kj->ki", Rj, tau) + T_base_flange[:, :3, 3]
    d = s @ RE.transpose(0, 2, 1) + (offset - state.centre_m)[:, None, :]
    dist = np.linalg.norm(d, axis=2)
    # The centre's distance from each laser plane (normal: the sensor y axis in the base
    # frame; the sensor origin lies in the plane), and the section's radius.
    normal = RE @ X[:3, 1]
    origin = RE @ X[:3, 3] + offset
    off_plane = np.einsum("ki,ki->k", normal, state.centre_m - origin)
    section_sq = np.maximum(
        state.radius_m**2 - off_plane**2, (MIN_SECTION_SHARE * state.radius_m) ** 2
    )
    section = np.sqrt(section_sq)
    weight = valid * (state.radius_m / section)[:, None] / sensor_sigma_m
    residuals = (dist - state.radius_m) * weight
    if not jacobians:
        return residuals, None, None
    # The weight's derivative per sample (zero where the section radius is at its floor).
    R = state.radius_m
    free = section_sq > (MIN_SECTION_SHARE * R) ** 2
    by_d = np.where(free, R * off_plane / section**3, 0.0)
    y_axis = X[:3, 1]
    centre_sensor = np.einsum("kji,kj->ki", RE @ X[:3, :3], state.centre_m - origin)
    u = state.centre_m - T_base_flange[:, :3, 3] - np.einsum("kij,kj->ki", Rj, tau)
    turned = np.einsum("kji,kj->ki", RE, u)
    weight_global = np.empty((len(omega), 10))
    weight_global[:, :3] = -by_d[:, None] * np.cross(centre_sensor, X[:3, :3].T @ y_axis)
    weight_global[:, 3:6] = -by_d[:, None] * y_axis
    weight_global[:, 6:9] = by_d[:, None] * normal
    weight_global[:, 9] = np.where(free, -(off_plane**2) / section**3, 0.0)
    weight_local = np.empty((len(omega), N_LOCAL))
    weight_local[:, :3] = by_d[:, None] * np.einsum(
        "ki,kij->kj", np.cross(y_axis, turned), right_jacobian_so3(omega)
    )
    weight_local[:, 3:] = -by_d[:, None] * np.einsum("ki,kij->kj", normal, Rj)
    misfit = ((dist - state.radius_m) * valid / sensor_sigma_m)[..., None]
    n = d / np.maximum(dist, 1e-300)[..., None]
    nR = n @ Rj
    nRE = n @ RE
    w = weight[..., None]
    J_global = np.empty((*valid.shape, 11))
    # θ at 0 (J_r = I): −nᵀ R_j E_j R_X [q]ₓ, and aᵀ[q]ₓ = (a × q)ᵀ.
    J_global[..., :3] = -np.cross(nRE @ X[:3, :3], points) * w
    J_global[..., 3:6] = nRE * w
    J_global[..., 6:9] = -n * w
    J_global[..., 9] = -weight
    J_global[..., :10] += misfit * weight_global[:, None, :]
    # s: the true x is the measured one over 1 + s (the weight does not depend on it).
    J_global[..., 10] = -(nRE @ X[:3, 0]) * points[..., 0] / (1.0 + state.scale) * weight
    J_local = np.empty((*valid.shape, N_LOCAL))
    J_local[..., :3] = -(np.cross(nRE, s) @ right_jacobian_so3(omega)) * w
    J_local[..., 3:] = nR * w
    J_local += misfit * weight_local[:, None, :]
    return residuals, J_global, J_local


@dataclass(frozen=True)
class SphereRefineConfig:
    """Settings of the sphere refinement.

    Attributes
    ----------
    sensor_sigma_m, robot_sigma_t_m, robot_sigma_r_rad : float
        Prior noise levels (1σ): the profiler's point noise (m), and the robot's pose error
        per axis (m, rad).
    loss_scale : float
        Where the Huber loss turns linear, in σ. Default 3.
    estimate_radius : bool
        Estimate the sphere radius (otherwise it is held at the start value).
    estimate_scale : bool
        Estimate the sensor's along-line scale error s with the hand-eye (otherwise it is
        held at the start value, 0).
    max_points_per_profile : int
        Profiles with more points are subsampled evenly (0 keeps all). Default 300.
    max_iterations : int
        Linearisations. Default 50.
    estimate_variance_factors : bool
        Re-estimate both noise levels from the residuals for the covariance. Default True.
    variance_rounds : int
        With ``estimate_variance_factors``, solve again this many times with the noise
        levels re-estimated (so that stated levels far from the real ones weight the points
        and the pose priors as the data say); the robot's are only ever lowered. Default 2.
    widen_by_dispersion : bool
        Widen the 1σ of a parameter where the profiles scatter the estimate more than the
        noise model says (:func:`~linelaser_calib.core.solver.sample_dispersion`): the
        points of a real profile err alike along the line, not independently as this
        refinement weighs them. Default True.
    """

    sensor_sigma_m: float = 5e-6
    robot_sigma_t_m: float = 1e-4
    robot_sigma_r_rad: float = float(np.deg2rad(0.01))
    loss_scale: float = 3.0
    estimate_radius: bool = True
    estimate_scale: bool = False
    max_points_per_profile: int = 300
    max_iterations: int = 50
    estimate_variance_factors: bool = True
    variance_rounds: int = 2
    widen_by_dispersion: bool = True

    def __post_init__(self) -> None:
        for name in ("sensor_sigma_m", "robot_sigma_t_m", "robot_sigma_r_rad", "loss_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"SphereRefineConfig.{name} must be positive, got {value}")
        if self.max_points_per_profile < 0 or self.max_iterations < 1:
            raise InputError(
                "SphereRefineConfig.max_points_per_profile must be >= 0 and max_iterations >= 1"
            )


def subsample(points: FloatArray, most: int) -> FloatArray:
    """At most ``most`` points (0: all), evenly spaced in scan order."""
    if most <= 0 or len(points) <= most:
        return points
    return points[np.round(np.linspace(0, len(points) - 1, most)).astype(np.int64)]


class SphereProblem:
    """The refinement in the shared solver's block form (a ``BlockProblem``).

    Global parameters [θ (3), ρ (3), c (3)], R when estimated and the along-line scale s
    when estimated; the points of sample j are row j of a (M, K) array, padded with zeros.
    """

    def __init__(
        self,
        T_base_flange: FloatArray,
        points: list[FloatArray],
        config: SphereRefineConfig,
        lever_m: float,
    ) -> None:
        self.T_base_flange = T_base_flange
        self.config = config
        used = [subsample(p, config.max_points_per_profile) for p in points]
        self.counts = np.array([len(p) for p in used])
        self.sample = np.repeat(np.arange(len(used)), self.counts)
        self.slot = np.concatenate([np.arange(n) for n in self.counts])
        self.valid = np.zeros((len(used), int(self.counts.max())), dtype=bool)
        self.valid[self.sample, self.slot] = True
        self.points = np.zeros((*self.valid.shape, 3))
        self.points[self.valid] = np.concatenate(used)
        self._columns = list(range(9))
        self.radius_index: int | None = None
        self.scale_index: int | None = None
        if config.estimate_radius:
            self.radius_index = len(self._columns)
            self._columns.append(9)
        if config.estimate_scale:
            self.scale_index = len(self._columns)
            self._columns.append(10)
        self._G = len(self._columns)
        # The scale moves a point by its x: weighed like a rotation, by the lever.
        self._scale = np.array(
            [lever_m] * 3 + [1.0] * 6 + [lever_m if c == 10 else 1.0 for c in self._columns[9:]]
        )
        self.sqrt_prior = np.array(
            [1.0 / config.robot_sigma_r_rad] * 3 + [1.0 / config.robot_sigma_t_m] * 3
        )

    @property
    def n_global(self) -> int:
        """9, plus the radius and the scale when estimated."""
        return self._G

    @property
    def step_scale(self) -> FloatArray:
        """Lever for the rotation, 1 for lengths."""
        return self._scale

    @property
    def n_points(self) -> int:
        """Point residuals (padding excluded)."""
        return len(self.sample)

    def residuals(self, state: SphereState) -> Residuals:
        """Normalised in-plane residuals and pose priors."""
        r, _, _ = point_residuals(
            state,
            self.T_base_flange,
            self.points,
            self.valid,
            self.config.sensor_sigma_m,
            jacobians=False,
        )
        return Residuals(r, state.corrections * self.sqrt_prior)

    def linearise(self, state: SphereState) -> Linearisation:
        """Residuals and Jacobians (see the module docstring)."""
        r, Jg, Jl = point_residuals(
            state, self.T_base_flange, self.points, self.valid, self.config.sensor_sigma_m
        )
        assert Jg is not None and Jl is not None
        return Linearisation(
            residuals=Residuals(r, state.corrections * self.sqrt_prior),
            J_global=Jg[..., self._columns],
            J_local=Jl,
            pose_prior_sqrt_information=self.sqrt_prior,
        )

    def retract(
        self, state: SphereState, step_global: FloatArray, step_local: FloatArray
    ) -> SphereState:
        """R_X ← R_X·Exp(θ), t_X ← t_X + ρ; c, R, s and the corrections additively."""
        X = state.T_flange_sensor
        r, s = self.radius_index, self.scale_index
        return SphereState(
            transform_from_rotation_translation(
                X[:3, :3] @ matrix_from_rotvec(step_global[:3]), X[:3, 3] + step_global[3:6]
            ),
            state.centre_m + step_global[6:9],
            state.radius_m + (0.0 if r is None else float(step_global[r])),
            state.corrections + step_local,
            state.scale + (0.0 if s is None else float(step_global[s])),
        )


@dataclass(frozen=True)
class SphereRefinement:
    """Outcome of :func:`refine_sphere`.

    Attributes
    ----------
    state : SphereState
        The estimate.
    covariance : ndarray, shape (G, G)
        Of the global numbers [θ (rad, sensor axes), ρ (m, flange axes), c (m), R (m, when
        estimated), s (when estimated)], pose corrections marginalised, with the
        re-estimated noise levels.
    residuals_m : ndarray, shape (N,)
        Distances of the points used from the sphere, in the laser plane, m.
    sample : ndarray of int, shape (N,)
        Sample of each point.
    sensor_sigma_m, robot_sigma_t_m, robot_sigma_r_rad : float
        The noise levels the covariance was formed with (re-estimated when configured).
    cost_history : list of float
    converged : bool
    sample_dispersion : ndarray, shape (G,), or None
        Observed over expected profile-to-profile scatter of each global number
        (:func:`~linelaser_calib.core.solver.sample_dispersion`); the covariance is widened
        by it where it exceeds 1. None when not checked.
    model_covariance : ndarray, shape (G, G), or None
        The covariance before that widening: what the noise model and the poses give (the
        question whether the poses suffice); None when it equals ``covariance``.
    scale_index : int or None
        Where the along-line scale is among the global numbers, when estimated.
    problem : SphereProblem or None
        The problem as solved last, with its solver's settings and the variance factors the
        covariance was formed with, for :meth:`views`.
    """

    state: SphereState
    covariance: FloatArray
    residuals_m: FloatArray
    sample: IntArray
    sensor_sigma_m: float
    robot_sigma_t_m: float
    robot_sigma_r_rad: float
    cost_history: list[float]
    converged: bool
    sample_dispersion: FloatArray | None = None
    model_covariance: FloatArray | None = None
    scale_index: int | None = None
    problem: SphereProblem | None = None
    solver: SolverConfig = field(default_factory=SolverConfig)
    variance_factors: tuple[float, float] = (1.0, 1.0)

    def views(self) -> ViewsLinearised | None:
        """The views at the solution for :func:`~...shared_pose.shared_pose_error`
        (:meth:`~...shared_pose.ViewsLinearised.from_points`; its covariance in the order of
        :attr:`covariance`), None without the problem."""
        problem = self.problem
        if problem is None:
            return None
        return ViewsLinearised.from_points(
            problem,
            self.state,
            self.state.corrections,
            self.solver,
            problem.valid,
            problem.T_base_flange,
            self.variance_factors,
        )

    @property
    def rms_m(self) -> float:
        """RMS distance from the sphere in the laser plane, m."""
        return float(np.sqrt(np.mean(self.residuals_m**2)))

    def sample_rms_m(self) -> FloatArray:
        """RMS distance from the sphere in the laser plane of each sample (K,), m."""
        sums = np.bincount(self.sample, weights=self.residuals_m**2)
        return np.asarray(np.sqrt(sums / np.bincount(self.sample)))


def refine_sphere(
    T_base_flange: ArrayLike,
    points: list[FloatArray],
    start: SphereState,
    config: SphereRefineConfig,
) -> SphereRefinement:
    """Maximum-likelihood hand-eye, sphere and pose corrections from every point.

    Parameters
    ----------
    T_base_flange : array-like, shape (K, 4, 4)
        Reported flange poses.
    points : list of ndarray, shape (N_j, 3)
        Each sample's inlier points, sensor frame, m, in scan order.
    start : SphereState
        Start (e.g. the fixed-point solve, no corrections); its radius is held when the
        config does not estimate it.
    config : SphereRefineConfig

    Raises
    ------
    SolverError
        When the solve produces non-finite numbers.
    """
    T = np.asarray(T_base_flange, dtype=np.float64)
    lever = float(np.linalg.norm(start.T_flange_sensor[:3, 3])) + start.radius_m
    clouds = [np.asarray(p, dtype=np.float64) for p in points]
    solver_config = SolverConfig(
        loss="huber", loss_scale=config.loss_scale, max_iterations=config.max_iterations
    )
    state, sensor, robot = start, 1.0, 1.0
    for round_ in range(config.variance_rounds + 1):
        if round_:
            # Tighten, never loosen, the robot's prior: a weakly determined radius would
            # otherwise trade against ever larger pose corrections.
            config = replace(
                config,
                sensor_sigma_m=config.sensor_sigma_m * math.sqrt(sensor),
                robot_sigma_t_m=config.robot_sigma_t_m * math.sqrt(min(robot, 1.0)),
                robot_sigma_r_rad=config.robot_sigma_r_rad * math.sqrt(min(robot, 1.0)),
            )
        problem = SphereProblem(T, clouds, config, lever)
        solution = solve(problem, state, solver_config)
        state = solution.state
        if not (np.all(np.isfinite(state.T_flange_sensor)) and np.isfinite(state.radius_m)):
            raise SolverError("the sphere refinement diverged (non-finite estimate)")
        if not config.estimate_variance_factors:
            break
        sensor, robot = variance_factors(
            solution.normal,
            float(np.sum(robust_costs(solution.residuals.points, solver_config))),
            float(np.sum(solution.residuals.pose_prior**2)),
            problem.n_points,
            problem.n_global,
        )
    information = solution.normal.schur_information(sensor, robot)
    dispersion = sample_dispersion(solution, sensor, robot) if config.widen_by_dispersion else None
    residuals = solution.residuals.points[problem.sample, problem.slot] * config.sensor_sigma_m
    covariance = np.linalg.pinv(information)
    return SphereRefinement(
        state=state,
        covariance=widen_covariance(covariance, dispersion),
        sample_dispersion=dispersion,
        model_covariance=None if dispersion is None else covariance,
        residuals_m=np.asarray(residuals),
        sample=problem.sample,
        sensor_sigma_m=config.sensor_sigma_m * math.sqrt(sensor),
        robot_sigma_t_m=config.robot_sigma_t_m * math.sqrt(robot),
        robot_sigma_r_rad=config.robot_sigma_r_rad * math.sqrt(robot),
        cost_history=solution.cost_history,
        converged=solution.converged,
        scale_index=problem.scale_index,
        problem=problem,
        solver=solver_config,
        variance_factors=(sensor, robot),
    )
