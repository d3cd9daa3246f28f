"""Maximum-likelihood refinement of the hand-eye on every profile point (the default method).

Model
-----
Sample j has profile points p_jk (sensor frame, m) and a reported flange pose T_j =
``T_base_flange[j]``. The robot's pose error is a per-sample nuisance δ_j = (ω_j, τ_j): a
rotation vector ω_j (rad) and a translation τ_j (m), both in the **flange frame** (right
perturbation), so that the true flange pose is

    T_j · D(δ_j),   D(δ) = [[Exp(ω), τ], [0, 1]],

i.e. the flange's true orientation is R_j·Exp(ω_j) (a rotation about the flange origin) and
its true position t_j + R_j·τ_j. For an isotropic robot error this is the same distribution as
an error stated in the base frame, and it keeps rotation and translation errors decoupled
(a base-frame rotation would swing the flange about the robot base). A point maps into the
base frame as

    x_jk = T_j · D(δ_j) · T_flange_sensor · S⁻¹ · p_jk,   S = diag(1 + s, 1, 1),

where s is the sensor's along-line scale error (dimensionless; 0 unless estimated): a
profiler that reports x as (1 + s) times the true value (s = 0.005 reads 0.5 % long)
stretches each arc across the line and shifts its centre by s times its along-line
position.

The cylinder has an axis point c, a unit direction d and a radius R. The residuals are

- per point: (‖(I − d dᵀ)(x_jk − c)‖ − R) / σ_s, under a robust loss (Huber or soft-L1 with
  a scale of ``loss_scale`` σ) against spikes;
- per sample: the Gaussian priors ω_j / σ_r and τ_j / σ_t (no robust loss).

Minimising their sum (``½ Σ loss + ½ Σ prior²``) is the joint maximum a-posteriori estimate of
the hand-eye, axis, radius and pose corrections; in the linearised (Gaussian) model the
hand-eye part equals the maximum-likelihood estimate with the corrections integrated out.

Parametrisation and solver
--------------------------
Every iteration linearises around the current estimate in local coordinates:

- hand-eye: ``R = R̂ · Exp(θ)`` (θ about the **sensor** axes), ``t = t̂ + ρ`` (ρ in the
  **flange** frame);
- axis: ``d = normalise(d̂ + a₁u + a₂v)``, ``c = ĉ + b₁u + b₂v`` with (u, v) ⟂ d̂ (4 numbers,
  no singularity; the point is kept nearest to the data's centroid, which only slides it
  along the axis);
- radius: R = R̂ + r (only when estimated);
- along-line scale: s = ŝ + σ (only when estimated; ``estimate_scale``);
- corrections: ω_j, τ_j additively (exact right Jacobian of Exp).

The Jacobian is analytic and block-sparse: a point depends on the G = 10 to 12 global
numbers and on its sample's 6. The shared block solver
(:mod:`linelaser_calib.core.solver`: Levenberg–Marquardt with Marquardt scaling, Nielsen's
damping update and iteratively re-weighted robust weights) solves the normal equations by a
Schur complement: each sample's 6×6 block is inverted on its own and eliminated, leaving a
G×G system. Cost and time grow linearly with the number of samples.

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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import DegenerateError, InputError, ModelMismatch, SolverError
from ...geometry import (
    FloatArray,
    check_transform,
    exp_so3,
    orthonormal_basis,
    right_jacobian_so3,
    transform_from_rotation_translation,
)
from ...observability import (
    Observability,
    ObservabilityConfig,
    analyse_observability,
    pose_geometry,
)
from ...quantiles import chi2_upper_quantile
from ...robot.joint_calibration import JointOutcome, KinematicSetup, MultiScanProblem, solve_joint
from ...robot.kinematics import forward_kinematics
from ...solver import (
    LOSSES,
    N_HAND_EYE,
    N_LOCAL,
    Flag,
    Linearisation,
    Residuals,
    Solution,
    SolverConfig,
    evaluate_loss,
    normal_equations,
    solve,
    solve_with_rejection,
    variance_factors,
)
from .model import Cylinder

#: Axis parameters (a, b) in the global block, after the hand-eye's 6.
N_AXIS = 4
#: Robot variance factor (as a ratio of 1σ) beyond which the arm is said to be less accurate
#: than the prior (σ_t, σ_r) assumes.
ROBOT_PRIOR_EXCESS = 2.0
#: 1σ of the estimated along-line scale beyond which the poses are said to barely tell a
#: profile stretched along the line from a larger cylinder (0.015 % on ``ur_scancontrol`` and
#: 0.05 % on ``cluttered_camera`` with the radius free).
MAX_SCALE_SIGMA = 0.002


@dataclass(frozen=True)
class RefineConfig:
    """Settings of the maximum-likelihood refinement.

    Attributes
    ----------
    sensor_sigma_m : float
        1σ of a profile point's distance to the surface, m. Default 5 µm: the paper's
        SR6130 (±5 µm) and a scanCONTROL-class profiler at 0.1 m stand-off.
    robot_sigma_t_m : float
        1σ per axis of the flange position error, m. Default 0.1 mm: a UR5 (repeatability
        ±0.1 mm; e-series ±0.03 mm) as in the paper.
    robot_sigma_r_rad : float
        1σ per axis of the flange orientation error, rad. Default 0.01 deg.
    loss : str
        ``huber`` (default: quadratic, hence fully efficient, for the 99.7 % of Gaussian
        residuals inside 3σ, linear beyond), ``soft_l1`` or ``linear`` (least squares).
    loss_scale : float
        Where the robust loss turns from quadratic to linear, in units of σ_s. Default 3.
    max_points_per_profile : int
        Profiles with more points are subsampled evenly along the line (0 keeps all).
        Default 200: at the paper's noise the robot error dominates, and 200 of 800 points
        cost no measurable accuracy (bench/refine_study.py) for a 5× faster solve.
    estimate_radius : bool
        Estimate the radius even when ``radius_m`` is given (it is then the start value).
        Without a ``radius_m`` the radius is always estimated.
    estimate_scale : bool
        Estimate the sensor's along-line scale error s (the profiler reports x as (1 + s)
        times the true value; a point (x, z) is taken as (x / (1 + s), z)) as one more global
        parameter. Default False: s = 0.
    max_iterations : int
        Levenberg–Marquardt iterations (linearisations). Default 50.
    tolerance : float
        Stop when an accepted step lowers the cost by less than this fraction. Default 1e-10.
    step_tolerance_m : float
        Stop when no global parameter moves by more than this, m (rotations times the
        lever). Default 1e-12 m.
    min_samples : int
        Fewest samples accepted. Default 6.
    min_points_per_profile : int
        Fewest points a profile must have. Default 10.
    estimate_variance_factors : bool
        Form the covariance with the sensor and robot noise levels re-estimated from the
        residuals (see the module docstring), not the configured ones. Default True.
    observability : ObservabilityConfig
    outlier_zscore : float
        A sample is an outlier when its RMS residual lies this many robust standard deviations
        (1.4826 · MAD) above the median, or its pose correction's prior χ² does. Default 6.
    outlier_min_rms_sigma : float
        ... and its RMS residual also exceeds this many σ_s (so that clean data, whose RMS
        values all equal σ_s, never loses a sample to a tiny MAD). Default 3.
    outlier_prior_probability : float
        A pose correction whose χ² (6 degrees of freedom) has a smaller upper-tail probability
        than this is implausible for the robot's stated σ. Default 1e-6.
    max_outlier_fraction : float
        :func:`refine_with_outlier_rejection` drops at most this share of the samples.
        Default 0.2.
    point_outlier_sigmas : float
        :func:`refine_with_outlier_rejection` removes points whose residual after the first
        solve exceeds this many sensor σ (the re-estimated one, if larger), then solves
        again: spikes that passed the ellipse RANSAC otherwise bias their sample's pose
        correction. 0 disables. Default 6.
    """

    sensor_sigma_m: float = 5e-6
    robot_sigma_t_m: float = 1e-4
    robot_sigma_r_rad: float = float(np.deg2rad(0.01))
    loss: str = "huber"
    loss_scale: float = 3.0
    max_points_per_profile: int = 200
    estimate_radius: bool = False
    estimate_scale: bool = False
    max_iterations: int = 50
    tolerance: float = 1e-10
    step_tolerance_m: float = 1e-12
    min_samples: int = 6
    min_points_per_profile: int = 10
    estimate_variance_factors: bool = True
    observability: ObservabilityConfig = field(default_factory=ObservabilityConfig)
    outlier_zscore: float = 6.0
    outlier_min_rms_sigma: float = 3.0
    outlier_prior_probability: float = 1e-6
    max_outlier_fraction: float = 0.2
    point_outlier_sigmas: float = 6.0

    def __post_init__(self) -> None:
        positive = {
            "sensor_sigma_m": self.sensor_sigma_m,
            "robot_sigma_t_m": self.robot_sigma_t_m,
            "robot_sigma_r_rad": self.robot_sigma_r_rad,
            "loss_scale": self.loss_scale,
            "tolerance": self.tolerance,
            "step_tolerance_m": self.step_tolerance_m,
            "outlier_zscore": self.outlier_zscore,
        }
        for name, value in positive.items():
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"RefineConfig.{name} must be positive and finite, got {value}")
        if self.loss not in LOSSES:
            raise InputError(f"RefineConfig.loss must be one of {LOSSES}, got {self.loss!r}")
        if self.max_points_per_profile < 0 or self.max_iterations < 1:
            raise InputError(
                "RefineConfig.max_points_per_profile must be >= 0 and max_iterations >= 1, got "
                f"{self.max_points_per_profile} and {self.max_iterations}"
            )
        if self.min_samples < 3 or self.min_points_per_profile < 3:
            raise InputError("RefineConfig.min_samples and min_points_per_profile must be >= 3")
        if not 0.0 <= self.max_outlier_fraction < 1.0:
            raise InputError(
                "RefineConfig.max_outlier_fraction must be in [0, 1), got "
                f"{self.max_outlier_fraction}"
            )
        if not 0.0 < self.outlier_prior_probability < 1.0:
            raise InputError("RefineConfig.outlier_prior_probability must be in (0, 1)")

    @property
    def solver(self) -> SolverConfig:
        """The shared solver's settings."""
        return SolverConfig(
            loss=self.loss,
            loss_scale=self.loss_scale,
            max_iterations=self.max_iterations,
            tolerance=self.tolerance,
            step_tolerance_m=self.step_tolerance_m,
        )


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
        Robust z-score of ``sample_rms_m`` ((value − median) / (1.4826 · MAD)).
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
        rows in :attr:`used` order, for :func:`refine_subset`.
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

    @property
    def sample_residuals_m(self) -> dict[int, float]:
        """Per-sample RMS residual, m, keyed by the caller's sample index."""
        return {j: float(r) for j, r in zip(self.used, self.sample_rms_m, strict=True)}


# --------------------------------------------------------------------------------------
# The problem in the shared solver's block form


@dataclass(frozen=True)
class CylinderState:
    """Current estimate (absolute values, not increments).

    Attributes
    ----------
    R_fs : ndarray, shape (3, 3)
    t_fs : ndarray, shape (3,)
        Hand-eye, m.
    point : ndarray, shape (3,)
        On the axis, base frame, m.
    direction : ndarray, shape (3,)
        Unit axis direction.
    radius : float
        m.
    omega, tau : ndarray, shape (M, 3)
        Pose corrections, rad and m, flange frame.
    scale : float
        The sensor's along-line scale error s (dimensionless).
    """

    R_fs: FloatArray
    t_fs: FloatArray
    point: FloatArray
    direction: FloatArray
    radius: float
    omega: FloatArray
    tau: FloatArray
    scale: float = 0.0


class _Geometry(NamedTuple):
    """Per-point intermediate quantities at one state."""

    p: FloatArray  # (M, K, 3) sensor point with the along-line scale removed, S⁻¹ p
    y: FloatArray  # (M, K, 3) point in the nominal flange frame, R_fs S⁻¹ p + t_fs
    RE: FloatArray  # (M, 3, 3) R_bf·Exp(ω) per sample
    distance: FloatArray  # (M, K) distance to the axis, m
    normal: FloatArray  # (M, K, 3) unit radial direction in the base frame
    along: FloatArray  # (M, K) d · (x − c)


@dataclass(frozen=True)
class CylinderProblem:
    """Validated, subsampled data in a padded (samples × points) layout; a
    :class:`~linelaser_calib.core.solver.BlockProblem`.

    Sample j's points fill ``points[j, :counts[j]]``; the rest repeat its first point and are
    masked out (residual and Jacobian rows zero), so that every per-point operation is a
    batched array operation without gathers. Global step: θ (3), ρ (3), a (2), b (2) and,
    when estimated, the radius and then the along-line scale (see the module docstring).
    With ``centroid`` set, a retraction slides the axis point along the axis to the point
    nearest it (same cylinder).
    """

    points: FloatArray  # (M, K, 3) sensor frame, m
    mask: FloatArray  # (M, K) 1 for a real point, 0 for padding
    counts: np.ndarray  # (M,) real points per sample
    R_bf: FloatArray  # (M, 3, 3)
    t_bf: FloatArray  # (M, 3)
    estimate_radius: bool
    config: RefineConfig
    centroid: FloatArray | None = None
    estimate_scale: bool = False

    @property
    def n_samples(self) -> int:
        return int(self.R_bf.shape[0])

    @property
    def n_global(self) -> int:
        return N_HAND_EYE + N_AXIS + int(self.estimate_radius) + int(self.estimate_scale)

    @property
    def radius_index(self) -> int | None:
        """Position of the radius in the global step, when estimated."""
        return N_HAND_EYE + N_AXIS if self.estimate_radius else None

    @property
    def scale_index(self) -> int | None:
        """Position of the along-line scale in the global step, when estimated."""
        return self.n_global - 1 if self.estimate_scale else None

    @property
    def step_scale(self) -> FloatArray:
        """Rotations and the along-line scale times the lever, lengths as they are."""
        scale = np.ones(self.n_global)
        scale[:3] = _lever(self)
        if self.scale_index is not None:
            scale[self.scale_index] = _lever(self)
        return scale

    def with_flange_poses(self, T_base_flange: FloatArray) -> CylinderProblem:
        """The same problem at other flange poses (M, 4, 4)."""
        return replace(
            self,
            R_bf=np.ascontiguousarray(T_base_flange[:, :3, :3]),
            t_bf=np.ascontiguousarray(T_base_flange[:, :3, 3]),
        )

    def pose_corrections(self, state: CylinderState) -> FloatArray:
        """``[ω (rad), τ (m)]`` (M, 6) of every sample."""
        return np.hstack([state.omega, state.tau])

    def _prior_sqrt_information(self) -> FloatArray:
        cfg = self.config
        return np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)

    def residuals(self, state: CylinderState) -> Residuals:
        """Normalised point residuals (M, K), zero on padding, and pose priors (M, 6)."""
        return self._residuals(state, _geometry(self, state))

    def _residuals(self, state: CylinderState, geo: _Geometry) -> Residuals:
        cfg = self.config
        e = (geo.distance - state.radius) * (self.mask / cfg.sensor_sigma_m)
        prior = np.hstack([state.omega / cfg.robot_sigma_r_rad, state.tau / cfg.robot_sigma_t_m])
        return Residuals(e, prior)

    def linearise(self, state: CylinderState) -> Linearisation:
        """Residuals and their analytic Jacobians.

        ``J_global`` (M, K, G) has the columns θ (3), ρ (3), a (2), b (2) and, when
        estimated, the radius and the along-line scale; ``J_local`` (M, K, 6) the columns
        ω (3), τ (3) of the point's own sample; both zero on padding.
        """
        geo = _geometry(self, state)
        scale = (self.mask / self.config.sensor_sigma_m)[..., None]
        n_base = geo.normal * scale
        n_corrected = n_base @ self.R_bf  # rows R_bfᵀ n: d r / d τ
        n_flange = n_base @ geo.RE  # rows Exp(ω)ᵀ R_bfᵀ n: d r / d ρ
        n_sensor = n_flange @ state.R_fs  # rows R_fsᵀ n_flange
        u, v = orthonormal_basis(state.direction)
        n_uv = n_base @ np.column_stack([u, v])
        columns = [_cross(geo.p, n_sensor), n_flange, -geo.along[..., None] * n_uv, -n_uv]
        if self.estimate_radius:
            columns.append(-scale)
        if self.estimate_scale:
            # d (x / (1 + s)) / d s = −x / (1 + s)² = −(x / (1 + s)) / (1 + s)
            columns.append((-n_sensor[..., 0] * geo.p[..., 0] / (1.0 + state.scale))[..., None])
        J_omega = _cross(geo.y, n_flange) @ right_jacobian_so3(state.omega)
        return Linearisation(
            residuals=self._residuals(state, geo),
            J_global=np.concatenate(columns, axis=2),
            J_local=np.concatenate([J_omega, n_corrected], axis=2),
            pose_prior_sqrt_information=self._prior_sqrt_information(),
        )

    def retract(
        self, state: CylinderState, step_global: FloatArray, step_local: FloatArray
    ) -> CylinderState:
        """Apply increments in the local coordinates of :meth:`linearise`."""
        u, v = orthonormal_basis(state.direction)
        direction = state.direction + step_global[6] * u + step_global[7] * v
        r, s = self.radius_index, self.scale_index
        moved = CylinderState(
            R_fs=state.R_fs @ exp_so3(step_global[None, :3])[0],
            t_fs=state.t_fs + step_global[3:6],
            point=state.point + step_global[8] * u + step_global[9] * v,
            direction=direction / np.linalg.norm(direction),
            radius=state.radius + (0.0 if r is None else float(step_global[r])),
            omega=state.omega + step_local[:, :3],
            tau=state.tau + step_local[:, 3:],
            scale=state.scale + (0.0 if s is None else float(step_global[s])),
        )
        return moved if self.centroid is None else _recentred(moved, self.centroid)


@dataclass(frozen=True)
class SolvedProblem:
    """A refinement's problem (its points trimmed and subsampled) and its state at the
    solution: where :func:`refine_subset` starts a solve of some of its samples."""

    problem: CylinderProblem
    state: CylinderState


def _sample_transforms(
    problem: CylinderProblem, state: CylinderState
) -> tuple[FloatArray, FloatArray]:
    """Per-sample rotation R_bf·Exp(ω) (M, 3, 3) and the base position of the flange-frame
    origin after correction, t_bf + R_bf·τ (M, 3)."""
    RE = problem.R_bf @ exp_so3(state.omega)
    offset = problem.t_bf + np.einsum("mij,mj->mi", problem.R_bf, state.tau)
    return RE, offset


def _geometry(problem: CylinderProblem, state: CylinderState) -> _Geometry:
    """Base-frame points and their relation to the axis."""
    RE, offset = _sample_transforms(problem, state)
    p = measured_to_true(problem.points, state.scale)
    y = p @ state.R_fs.T + state.t_fs
    w = y @ RE.transpose(0, 2, 1) + (offset - state.point)[:, None, :]
    along = w @ state.direction
    radial = w - along[..., None] * state.direction
    distance = np.sqrt(np.sum(radial**2, axis=2))
    normal = radial / np.maximum(distance, 1e-300)[..., None]
    return _Geometry(p, y, RE, distance, normal, along)


def measured_to_true(points: ArrayLike, scale: float) -> FloatArray:
    """Sensor points (..., 3) with the along-line scale error s removed: x → x / (1 + s), m."""
    if scale == 0.0:
        return np.asarray(points, dtype=np.float64)
    p = np.array(points, dtype=np.float64)
    p[..., 0] /= 1.0 + scale
    return p


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross products of (..., 3) arrays (cheaper than numpy.cross on small last axes)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _data_centroid(problem: CylinderProblem, state: CylinderState) -> FloatArray:
    """Mean of the profiles' centroids in the base frame (3,), m."""
    RE, offset = _sample_transforms(problem, state)
    means = np.sum(problem.points * problem.mask[..., None], axis=1) / problem.counts[:, None]
    y = measured_to_true(means, state.scale) @ state.R_fs.T + state.t_fs
    return np.asarray(np.mean(np.einsum("mij,mj->mi", RE, y) + offset, axis=0))


def _recentred(state: CylinderState, centroid: FloatArray) -> CylinderState:
    """Slide the axis point along the axis to the point nearest ``centroid`` (same cylinder)."""
    point = state.point + float((centroid - state.point) @ state.direction) * state.direction
    return replace(state, point=point)


def _marginal_hand_eye(information: FloatArray) -> FloatArray:
    """Information (6, 6) of the hand-eye after eliminating the axis (radius, scale)."""
    h, o = slice(0, N_HAND_EYE), slice(N_HAND_EYE, None)
    S_oo = information[o, o]
    return np.asarray(
        information[h, h] - information[h, o] @ np.linalg.pinv(S_oo) @ information[o, h]
    )


# --------------------------------------------------------------------------------------
# Input handling


def _subsample(points: FloatArray, limit: int) -> FloatArray:
    """At most ``limit`` points (0: all), evenly spaced along the profile order."""
    if limit == 0 or len(points) <= limit:
        return points
    return np.asarray(points[np.round(np.linspace(0, len(points) - 1, limit)).astype(int)])


def build_problem(
    samples_points: list[FloatArray],
    T_base_flange: ArrayLike,
    config: RefineConfig,
    estimate_radius: bool,
) -> CylinderProblem:
    """Validate the input (InputError/DegenerateError with advice) and stack it.

    Parameters are those of :func:`refine`; ``estimate_radius`` adds the radius to the
    global parameters, ``config.estimate_scale`` the along-line scale.
    """
    T_all = np.asarray(T_base_flange, dtype=np.float64)
    M = len(samples_points)
    if T_all.shape != (M, 4, 4):
        raise InputError(
            f"T_base_flange must have shape ({M}, 4, 4), one pose per profile, got {T_all.shape}"
        )
    if config.min_samples > M:
        raise DegenerateError(
            f"{M} samples given, but the refinement needs at least {config.min_samples}: "
            "scan the cylinder from more flange poses (20-50 diverse poses are typical)"
        )
    for j, T in enumerate(T_all):
        try:
            check_transform(T, tolerance=1e-4)
        except ValueError as exc:
            raise InputError(f"T_base_flange[{j}] is not a rigid transform: {exc}") from exc
    stacked: list[FloatArray] = []
    for j, p in enumerate(samples_points):
        q = np.asarray(p, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 3:
            raise InputError(f"profile {j} must be an (N, 3) array of points, got shape {q.shape}")
        if len(q) < config.min_points_per_profile:
            raise InputError(
                f"profile {j} has {len(q)} points, fewer than {config.min_points_per_profile}: "
                "drop it or check the profile cleaning"
            )
        if not np.all(np.isfinite(q)):
            raise InputError(f"profile {j} contains NaN or Inf: clean the profiles first")
        stacked.append(_subsample(q, config.max_points_per_profile))
    counts = np.array([len(q) for q in stacked])
    K = int(counts.max())
    points = np.empty((M, K, 3))
    mask = np.zeros((M, K))
    for j, q in enumerate(stacked):
        points[j, : len(q)] = q
        points[j, len(q) :] = q[0]
        mask[j, : len(q)] = 1.0
    return CylinderProblem(
        points=points,
        mask=mask,
        counts=counts,
        R_bf=np.ascontiguousarray(T_all[:, :3, :3]),
        t_bf=np.ascontiguousarray(T_all[:, :3, 3]),
        estimate_radius=estimate_radius,
        config=config,
        estimate_scale=config.estimate_scale,
    )


def initial_state(
    problem: CylinderProblem, T_flange_sensor0: ArrayLike, cylinder0: Cylinder, radius: float
) -> CylinderState:
    """The start of the solve: the given hand-eye and axis, zero pose corrections.

    Raises
    ------
    InputError
        A start that is not a rigid transform, a degenerate axis or a bad radius.
    """
    try:
        T0 = check_transform(T_flange_sensor0, tolerance=1e-4)
    except ValueError as exc:
        raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc
    d = np.asarray(cylinder0.direction, dtype=np.float64)
    c = np.asarray(cylinder0.point, dtype=np.float64)
    if d.shape != (3,) or c.shape != (3,) or not np.all(np.isfinite(np.concatenate([c, d]))):
        raise InputError("the initial cylinder needs a finite point (3,) and direction (3,)")
    if not np.linalg.norm(d) > 0.0:
        raise InputError("the initial cylinder direction is zero")
    if not (np.isfinite(radius) and radius > 0.0):
        raise InputError(f"the cylinder radius must be a positive length in m, got {radius}")
    M = problem.n_samples
    return CylinderState(
        R_fs=T0[:3, :3].copy(),
        t_fs=T0[:3, 3].copy(),
        point=c,
        direction=d / np.linalg.norm(d),
        radius=float(radius),
        omega=np.zeros((M, 3)),
        tau=np.zeros((M, 3)),
    )


# --------------------------------------------------------------------------------------
# The solve


def _robust_zscore(values: FloatArray) -> FloatArray:
    """(value − median) / (1.4826 · MAD), with the MAD floored at 1e-3 of the median."""
    median = float(np.median(values))
    mad = 1.4826 * float(np.median(np.abs(values - median)))
    return np.asarray((values - median) / max(mad, 1e-3 * abs(median), 1e-300))


def _lever(problem: CylinderProblem) -> float:
    """Median distance of the profile points from the sensor origin, m."""
    lever = problem.config.observability.lever_m
    if lever is not None:
        return lever
    return float(np.median(np.linalg.norm(problem.points, axis=2)[problem.mask > 0.0]))


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
        _lever(problem),
        pose_geometry(T_base_flange, T, state.point, state.direction),
        problem.config.observability,
    )


def refine(
    samples_points: list[FloatArray],
    T_base_flange: ArrayLike,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
    pose_corrections0: FloatArray | None = None,
    scale0: float = 0.0,
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
    geometric = normal_equations(problem.linearise(state), cfg.solver, np.ones_like(problem.mask))
    _observability(problem, state, geometric.schur_information()).raise_if_unobservable()

    centroid = _data_centroid(problem, state)
    problem = replace(problem, centroid=centroid)
    solution = solve(problem, _recentred(state, centroid), cfg.solver)
    if not (np.all(np.isfinite(solution.state.R_fs)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the refinement produced non-finite values: check the initial estimate")
    return _summarise(problem, solution)


#: Step tolerance of :func:`refine_subset`, m: 10 nm, a thousandth of the smallest 1σ this
#: tool reports (a few µm); the full solve's 1e-12 m would cost it one or two more
#: linearisations.
SUBSET_STEP_TOLERANCE_M = 1e-8
#: Cost tolerance of :func:`refine_subset`: it stops when a step lowers the cost by less
#: than this fraction. With some 10⁴ points that step moved the hand-eye by under 1 % of
#: its 1σ, and what is left is smaller again. Where the robust loss slows convergence it
#: saves a few linearisations (cluttered_camera: 9-12 instead of 13-21; the jackknife's
#: statistics move by 1e-3 of themselves).
SUBSET_COST_TOLERANCE = 1e-8


def refine_subset(solved: SolvedProblem, rows: Sequence[int]) -> RefineResult:
    """The refinement of some samples of a solved problem, started at its solution.

    The samples keep their points as solved (trimmed, subsampled) and start at the full
    solution with their own pose corrections; no seed solve, no point trimming and no
    outlier rejection run again (the full solve screened these samples). Leaving samples out
    moves the optimum by about its 1σ, so the solve converges, to
    :data:`SUBSET_STEP_TOLERANCE_M`, in two or three linearisations on clean data (a few more
    where the robust loss down-weights many points) instead of a dozen: the self-check's
    twelve subset solves (leave-some-out, halves, regions) go through here. One Gauss–Newton
    step is not enough: on cluttered data it moves the jackknife's dispersion by 20 %.

    Parameters
    ----------
    solved : SolvedProblem
        :attr:`RefineResult.solved` of the full solve.
    rows : sequence of int
        Positions of the samples in ``solved.problem``.

    Returns
    -------
    RefineResult
        ``used`` indexes ``rows``.

    Raises
    ------
    DegenerateError
        Fewer samples than ``min_samples``, or poses that leave a direction unobservable.
    SolverError
        The solve produced non-finite numbers.
    """
    full, at = solved.problem, solved.state
    keep = np.asarray(rows, dtype=np.intp)
    if len(keep) < full.config.min_samples:
        raise DegenerateError(
            f"{len(keep)} samples given, but the refinement needs at least "
            f"{full.config.min_samples}"
        )
    problem = replace(
        full,
        points=full.points[keep],
        mask=full.mask[keep],
        counts=full.counts[keep],
        R_bf=full.R_bf[keep],
        t_bf=full.t_bf[keep],
    )
    start = replace(at, omega=at.omega[keep], tau=at.tau[keep])
    solution = solve(
        problem,
        start,
        replace(
            full.config.solver,
            step_tolerance_m=SUBSET_STEP_TOLERANCE_M,
            tolerance=SUBSET_COST_TOLERANCE,
        ),
    )
    if not (np.all(np.isfinite(solution.state.R_fs)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the refinement of a subset produced non-finite values")
    return _summarise(problem, solution)


def _summarise(problem: CylinderProblem, solution: Solution[CylinderState]) -> RefineResult:
    """Covariance, observability and per-sample statistics at the solution."""
    cfg = problem.config
    state, normal = solution.state, solution.normal
    e, prior = solution.residuals.points, solution.residuals.pose_prior
    rho, _ = evaluate_loss(e, cfg.solver)
    point_cost, prior_cost = float(np.sum(rho)), float(np.sum(prior**2))
    n_points = int(problem.counts.sum())
    chi2_dof = (point_cost + prior_cost) / max(n_points - problem.n_global, 1)
    factors = (1.0, 1.0)
    if cfg.estimate_variance_factors:
        factors = variance_factors(normal, point_cost, prior_cost, n_points, problem.n_global)
    observability = _observability(problem, state, normal.schur_information())
    observability.raise_if_unobservable()
    covariance = np.linalg.inv(normal.schur_information(*factors))
    sigma = np.sqrt(np.diag(covariance))
    r, s = problem.radius_index, problem.scale_index

    squares = np.sum((e * cfg.sensor_sigma_m) ** 2, axis=1)
    sample_rms = np.sqrt(squares / problem.counts)
    beyond = np.sum(np.abs(e) > cfg.loss_scale, axis=1)
    cylinder_point = state.point - float(state.point @ state.direction) * state.direction
    warnings = list(observability.warnings)
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
        used=list(range(problem.n_samples)),
        dropped=[],
        sample_rms_m=sample_rms,
        sample_rms_zscore=_robust_zscore(sample_rms),
        sample_prior_chi2=np.sum(prior**2, axis=1),
        sample_downweighted=beyond / problem.counts,
        pose_corrections=np.hstack([state.omega, state.tau]),
        rms_residual_m=float(np.sqrt(np.sum(squares) / n_points)),
        chi2_dof=chi2_dof,
        sensor_sigma_estimated_m=cfg.sensor_sigma_m * float(np.sqrt(factors[0])),
        robot_sigma_scale=robot_scale,
        cost_history=history,
        iterations=solution.iterations,
        converged=solution.converged,
        n_points=n_points,
        observability=observability,
        warnings=warnings,
        solved=SolvedProblem(problem, state),
    )


# --------------------------------------------------------------------------------------
# Outlier samples


def _outlier_samples(result: RefineResult, config: RefineConfig) -> list[Flag]:
    """Samples inconsistent with the rest (positions in ``result.used``), with reasons."""
    rms, z_rms = result.sample_rms_m, result.sample_rms_zscore
    prior_chi2 = result.sample_prior_chi2
    z_prior = _robust_zscore(np.sqrt(prior_chi2))
    # P(chi2 > limit) = outlier_prior_probability
    chi2_limit = float(chi2_upper_quantile(N_LOCAL, config.outlier_prior_probability))
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
                f"{median_rms * 1e6:.1f} um, robust z {z_rms[j]:.0f})"
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
    samples_points: list[FloatArray], T_base_flange: ArrayLike, result: RefineResult
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
        w = (measured_to_true(p, result.scale) @ R_fs.T + t_fs) @ R.T + (
            T[:3, 3] + T[:3, :3] @ delta[3:] - c
        )
        radial = w - np.outer(w @ d, d)
        out.append(np.sqrt(np.sum(radial**2, axis=1)) - result.cylinder.radius)
    return out


def _trim_points(
    samples_points: list[FloatArray],
    T_base_flange: FloatArray,
    result: RefineResult,
    limit_m: float,
) -> tuple[list[FloatArray], int]:
    """Drop points whose residual exceeds ``limit_m``; returns the samples and the count."""
    residuals = point_residuals_m(samples_points, T_base_flange, result)
    trimmed, removed = [], 0
    for p, r in zip(samples_points, residuals, strict=True):
        keep = np.abs(r) <= limit_m
        removed += int(np.count_nonzero(~keep))
        trimmed.append(np.asarray(p)[keep])
    return trimmed, removed


def refine_with_outlier_rejection(
    samples_points: list[FloatArray],
    T_base_flange: ArrayLike,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
) -> RefineResult:
    """:func:`refine`, then drop samples inconsistent with the rest and solve again.

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
    trimmed_any = False
    if cfg.point_outlier_sigmas > 0.0:
        first = refine(points, T_all, T0, start, cfg, radius_m)
        sigma = max(cfg.sensor_sigma_m, first.sensor_sigma_estimated_m)
        trimmed, removed = _trim_points(points, T_all, first, cfg.point_outlier_sigmas * sigma)
        if removed and all(len(p) >= cfg.min_points_per_profile for p in trimmed):
            points, trimmed_any = trimmed, True
        T0, start = first.T_flange_sensor, first.cylinder

    def solve_subset(keep: list[int], previous: RefineResult | None) -> RefineResult:
        if previous is None and first is not None:
            if not trimmed_any and len(keep) == len(points):
                return first  # the same problem, solved already
            # From the first solve, its pose corrections included: a few iterations.
            return refine(
                [points[i] for i in keep],
                T_all[keep],
                first.T_flange_sensor,
                first.cylinder,
                cfg,
                radius_m,
                first.pose_corrections[keep],
                first.scale,
            )
        T_start = T0 if previous is None else previous.T_flange_sensor
        axis = start if previous is None else previous.cylinder
        return refine([points[i] for i in keep], T_all[keep], T_start, axis, cfg, radius_m)

    outcome = solve_with_rejection(
        len(points),
        solve_subset,
        lambda result, _keep: _outlier_samples(result, cfg),
        cfg.max_outlier_fraction,
        cfg.min_samples,
    )
    result = outcome.outcome
    if outcome.left_flagged:
        result.warnings.append(
            f"{len(outcome.left_flagged)} more sample(s) look like outliers but "
            f"max_outlier_fraction {cfg.max_outlier_fraction:.2f} allows no more drops: "
            + "; ".join(f"sample {i}: {reason}" for i, reason in outcome.left_flagged)
        )
    result.used = outcome.kept
    result.dropped = [DroppedSample(i, reason) for i, reason in outcome.dropped]
    return result


# --------------------------------------------------------------------------------------
# Joint kinematic + hand-eye calibration


#: The pose corrections of a joint solve may be at most this multiple of the repeatability
#: (re-estimated robot σ): 0.6-0.7 on simulated UR5e arms with the right model, 7 with the
#: UR10e model on a UR5e.
MAX_REPEATABILITY_SCALE = 3.0
#: A kinematic correction may be at most this multiple of its prior 1σ (m or rad).
MAX_CORRECTION_PRIOR_SIGMAS = 10.0


def _check_kinematic_fit(scale: float, outcome: JointOutcome[Any], setup: KinematicSetup) -> None:
    """Refuse a joint solve whose kinematic model does not explain the robot's error (the
    re-estimated robot σ ``scale``, a multiple of the repeatability)."""
    delta = outcome.solution.state.delta
    ratio = np.abs(delta) / outcome.pose_model.prior_sigma
    if scale <= MAX_REPEATABILITY_SCALE and float(np.max(ratio, initial=0.0)) <= (
        MAX_CORRECTION_PRIOR_SIGMAS
    ):
        return
    worst = setup.model.parameter_names[int(outcome.pose_model.free[int(np.argmax(ratio))])]
    raise ModelMismatch(
        f"the {setup.model.name} kinematic model does not explain the robot's error: the "
        f"per-pose corrections are {scale:.1f} times the arm's repeatability of "
        f"{setup.config.repeatability_t_m * 1e3:.3f} mm and "
        f"{np.rad2deg(setup.config.repeatability_r_rad):.4f} deg, and the largest kinematic "
        f"correction ({worst}) is {float(np.max(ratio)):.0f} times its prior 1 sigma. "
        "Likely causes: the model is not the recorded robot's ({setting:kinematics}), the joint "
        "states are not the robot's encoders, or the arm's error is not kinematic "
        "(elasticity, heat). Calibrate with {setting:nominal_kinematics} to keep the model "
        "nominal. No result was written."
    )


def kinematic_problem(
    samples_points: list[FloatArray],
    q: FloatArray,
    setup: KinematicSetup,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
) -> tuple[CylinderProblem, CylinderState]:
    """The cylinder problem at the nominal forward kinematics of joint vectors q (M, n), with
    the arm's repeatability as the pose corrections' prior, and its start state."""
    cfg = RefineConfig() if config is None else config
    cfg = replace(
        cfg,
        robot_sigma_t_m=setup.config.repeatability_t_m,
        robot_sigma_r_rad=setup.config.repeatability_r_rad,
    )
    estimate_radius = radius_m is None or cfg.estimate_radius
    problem = build_problem(
        samples_points, forward_kinematics(setup.model, q), cfg, estimate_radius
    )
    state = initial_state(
        problem, T_flange_sensor0, cylinder0, cylinder0.radius if radius_m is None else radius_m
    )
    centroid = _data_centroid(problem, state)
    return replace(problem, centroid=centroid), _recentred(state, centroid)


@dataclass(frozen=True)
class JointScan:
    """One recording of a joint calibration: a cylinder placement's samples and joint states.

    Attributes
    ----------
    samples_points : list of ndarray, shape (N_j, 3)
        Inlier profile points of each sample in the sensor frame, m.
    stamps_ns : ndarray of int64, shape (M,)
        Profile stamps, ns (the joint states are interpolated there).
    cylinder0 : Cylinder
        Start, e.g. :func:`refine_with_outlier_rejection` on the nominal poses.
    setup : KinematicSetup
        The model (the same for every scan) and this recording's joint states.
    """

    samples_points: list[FloatArray]
    stamps_ns: NDArray[np.int64]
    cylinder0: Cylinder
    setup: KinematicSetup


def refine_kinematics(
    scans: Sequence[JointScan],
    T_flange_sensor0: ArrayLike,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
) -> tuple[list[RefineResult], JointOutcome[Any]]:
    """The refinement with the flange poses from joint states and a corrected robot model.

    The same cylinder problem, its flange poses the forward kinematics of each sample's
    joint vector with the identifiable kinematic corrections estimated
    (:func:`~linelaser_calib.core.robot.joint_calibration.solve_joint`); the per-sample pose
    corrections have the arm's repeatability as prior (``setup.config``). Several scans
    (cylinder placements scanned by the same arm) are solved together
    (:class:`~linelaser_calib.core.robot.joint_calibration.MultiScanProblem`: one hand-eye, one
    set of corrections, a cylinder per scan).

    Parameters
    ----------
    scans : sequence of JointScan
        At least one; the first one's model and settings apply to all.
    T_flange_sensor0 : array_like, shape (4, 4)
        Start.
    config : RefineConfig, optional
    radius_m : float, optional
        Known radius, m; None estimates it (per scan).

    Returns
    -------
    list of RefineResult
        Per scan, at the corrected poses; the 1σ are the hand-eye's, marginal over the
        kinematic corrections and every scan's cylinder.
    JointOutcome
        Its state is the first scan's state (one scan) or the tuple of the scans' states.
    """
    setup = scans[0].setup
    problems, states, qs = [], [], []
    for scan in scans:
        q = scan.setup.joint_positions(scan.stamps_ns)
        problem, state = kinematic_problem(
            scan.samples_points, q, scan.setup, T_flange_sensor0, scan.cylinder0, config, radius_m
        )
        problems.append(problem)
        states.append(state)
        qs.append(q)
    cfg = problems[0].config
    together: Any = problems[0] if len(scans) == 1 else MultiScanProblem(tuple(problems))
    start: Any = states[0] if len(scans) == 1 else tuple(states)
    outcome = solve_joint(together, start, setup.model, np.vstack(qs), setup.config, cfg.solver)
    joint = outcome.solution
    poses = outcome.pose_model.poses(joint.state.delta)
    found = [outcome.state] if len(scans) == 1 else list(outcome.state)
    bounds = np.cumsum([0, *(p.n_samples for p in problems)])
    results = []
    for i, (problem, state) in enumerate(zip(problems, found, strict=True)):
        corrected = problem.with_flange_poses(poses[bounds[i] : bounds[i + 1]])
        linearisation = corrected.linearise(state)
        inner = Solution(
            state=state,
            residuals=linearisation.residuals,
            normal=normal_equations(linearisation, cfg.solver),
            cost_history=joint.cost_history,
            iterations=joint.iterations,
            converged=joint.converged,
        )
        results.append(_summarise(corrected, inner))
    _check_kinematic_fit(max(r.robot_sigma_scale for r in results), outcome, setup)
    sigma = np.sqrt(np.diag(outcome.covariance)[:N_HAND_EYE])
    for result in results:
        result.sigma_rotation_rad, result.sigma_translation_m = sigma[:3], sigma[3:]
        result.covariance_hand_eye = outcome.covariance[:N_HAND_EYE, :N_HAND_EYE]
    return results, outcome
