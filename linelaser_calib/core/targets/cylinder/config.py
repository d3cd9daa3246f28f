"""Settings of the cylinder target."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...observability import ObservabilityConfig
from ...profile.along_line import SCALE_MODES
from ...profile.cleaning import CleaningConfig
from ...solver import LOSSES, SolverConfig
from .arc import ArcConfig
from .ellipse import EllipseConfig
from .pso_alm import HybridConfig

#: Fewest fitted samples the hand-eye plus axis can be solved from with any margin.
MIN_SAMPLES = 8


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
    max_points_per_profile_correlated : int
        The same for the solve weighed by a learned line noise (``learn_line_noise``); 0
        (default) keeps all. With a smooth shape error the points beyond 200 carry what
        tells the error from the surface: on ``cylinder_scancontrol`` (8 seeds) every point
        gives 0.131 mm RMS against 0.167 mm for 200, for about 1.5 times the solve's time.
    estimate_radius : bool
        Estimate the radius even when ``radius_m`` is given (it is then the start value).
        Without a ``radius_m`` the radius is always estimated.
    estimate_scale : bool
        Estimate the sensor's along-line scale error s (the profiler reports x as (1 + s)
        times the true value; a point (x, z) is taken as (x / (1 + s), z)) as one more global
        parameter. Default False: s = 0.
    estimate_depth_scale : bool
        Estimate the sensor's depth scale error s_z about its origin (a point (x, z) is taken
        as (x, z / (1 + s_z))) as one more global parameter. Default False: s_z = 0.
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
        :func:`.refine.refine_with_outlier_rejection` drops at most this share of the samples.
        Default 0.2.
    point_outlier_sigmas : float
        :func:`.refine.refine_with_outlier_rejection` removes points whose residual after the first
        solve exceeds this many sensor σ (the re-estimated one, if larger), then solves
        again: spikes that passed the ellipse RANSAC otherwise bias their sample's pose
        correction. 0 disables. Default 6.
    learn_line_noise : bool
        :func:`.refine.refine_with_outlier_rejection` learns the recording's point noise
        along the line (white, and smooth with a correlation length) from the first solve's
        residuals and weighs each profile's points with it (generalised least squares):
        a profiler's smooth shape error does not average out over a profile's points as
        white noise does. Default True.
    widen_by_dispersion : bool
        Widen the 1σ of a parameter where the profiles scatter the estimate more than the
        noise model says (:func:`~linelaser_calib.core.solver.sample_dispersion`: a
        delete-one-profile jackknife against its expectation under the model). Default True.
    """

    sensor_sigma_m: float = 5e-6
    robot_sigma_t_m: float = 1e-4
    robot_sigma_r_rad: float = float(np.deg2rad(0.01))
    loss: str = "huber"
    loss_scale: float = 3.0
    max_points_per_profile: int = 200
    max_points_per_profile_correlated: int = 0
    estimate_radius: bool = False
    estimate_scale: bool = False
    estimate_depth_scale: bool = False
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
    learn_line_noise: bool = True
    widen_by_dispersion: bool = True

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
        if (
            min(self.max_points_per_profile, self.max_points_per_profile_correlated) < 0
            or self.max_iterations < 1
        ):
            raise InputError(
                "RefineConfig.max_points_per_profile and max_points_per_profile_correlated "
                "must be >= 0 and max_iterations >= 1, got "
                f"{self.max_points_per_profile}, {self.max_points_per_profile_correlated} "
                f"and {self.max_iterations}"
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


@dataclass(frozen=True)
class CylinderConfig:
    """Every setting of the cylinder target; each stage's defaults are documented in its module.

    Attributes
    ----------
    radius_m : float or None
        Cylinder radius, m; None estimates it.
    scale : str
        The sensor's along-line (x) scale, and with the radius given its depth (z) scale, in
        the default method: ``free`` estimates them with the hand-eye, ``fixed`` holds them at
        1, ``auto`` (default) estimates them and keeps each only where it lies clearly off 1
        (the x scale always with the radius given; :func:`.scales.estimates_scale`).
    min_samples : int
        Fewest fitted samples accepted.
    cleaning : CleaningConfig
    ellipse : EllipseConfig
    arc : ArcConfig
        Finding the arc among the planes of the scene (:mod:`.arc`).
    hybrid : HybridConfig
        The global solve of the ``paper`` method.
    seed_hybrid : HybridConfig
        The global solve that seeds the ``default`` method's refinement. It only has to
        reach the refinement's basin, so by default it stops as soon as a polished solution
        is accepted (``accept_early``): ~10-100 ms instead of 0.3-0.7 s, same result after
        refinement (bench/accuracy.py).
    refine : RefineConfig
        The ``default`` method's maximum likelihood (noise levels, robust loss, outliers).
    """

    radius_m: float | None = None
    scale: str = "auto"
    min_samples: int = MIN_SAMPLES
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    ellipse: EllipseConfig = field(default_factory=EllipseConfig)
    arc: ArcConfig = field(default_factory=ArcConfig)
    hybrid: HybridConfig = field(default_factory=HybridConfig)
    seed_hybrid: HybridConfig = field(default_factory=lambda: HybridConfig(accept_early=True))
    refine: RefineConfig = field(default_factory=RefineConfig)

    def __post_init__(self) -> None:
        if self.radius_m is not None and not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise InputError(
                f"the cylinder radius must be a positive length in m, got {self.radius_m}"
            )
        if self.scale not in SCALE_MODES:
            raise InputError(
                f"the along-line scale must be one of {', '.join(SCALE_MODES)}, got {self.scale!r}"
            )
        if self.min_samples < 3:
            raise InputError(f"min_samples must be >= 3, got {self.min_samples}")
