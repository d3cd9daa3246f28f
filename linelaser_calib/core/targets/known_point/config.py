"""Settings of the known-point target."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...geometry import FloatArray
from ...profile.cleaning import CleaningConfig
from ...profile.corner import CornerConfig
from ...seam_grid import PAPER_GRID_COARSE, PAPER_GRID_FINE, GridStep


@dataclass(frozen=True)
class KnownPointConfig:
    """Settings of the known-point calibration (SI units).

    Attributes
    ----------
    point_m : ndarray, shape (3,), or None
        The taught point in the base frame, m; None estimates it (the ``paper`` method needs
        it).
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
    scale_prior_sigma : float
        Prior 1σ of the profiler's x and z scale errors where they are estimated (relative).
        Default 1 % (a poorly calibrated profiler's; the stress matrix's ``scales`` face has
        them 0.3-1 % apart). Views that determine the scales read them to about 0.1 %; views
        in one orientation stepped in z (the paper's) confuse one mix of them with the
        hand-eye, and without the prior the 1σ that counts a held scale grew from 0.8 to
        6 mm along flange axes there (``bench/known_point_regional.py``).
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

    point_m: FloatArray | None = None
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    corner: CornerConfig = field(default_factory=CornerConfig)
    robot_sigma_t_m: float = 5e-5
    robot_sigma_r_rad: float = math.radians(0.005)
    corner_sigma_floor_m: float = 5e-6
    aim_sigma_m: float = 2e-5
    initial_sigma_rotation_rad: float = math.radians(5.0)
    initial_sigma_translation_m: float = 0.01
    point_sigma_m: float = 0.0
    scale_prior_sigma: float = 0.01
    grid_coarse: GridStep = PAPER_GRID_COARSE
    grid_fine: GridStep = PAPER_GRID_FINE
    min_samples: int = 6
    max_iterations: int = 50
    tolerance: float = 1e-12
    outlier_probability: float = 1e-4
    max_outlier_fraction: float = 0.2
    weak_sigma_m: float = 2e-4
    unobservable_sigma_m: float = 1e-3

    def __post_init__(self) -> None:
        if self.point_m is not None:
            point = np.asarray(self.point_m, dtype=np.float64)
            if point.shape != (3,) or not np.all(np.isfinite(point)):
                raise InputError(f"the known point must be 3 finite numbers in m, got {point}")
            object.__setattr__(self, "point_m", point)
        positive = (
            "robot_sigma_t_m",
            "robot_sigma_r_rad",
            "corner_sigma_floor_m",
            "aim_sigma_m",
            "initial_sigma_rotation_rad",
            "initial_sigma_translation_m",
            "scale_prior_sigma",
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
