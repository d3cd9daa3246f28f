"""Settings of the straight-line target (SI units)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ...errors import InputError
from ...profile.along_line import SCALE_MODES
from .features import LineFeatureConfig


@dataclass(frozen=True)
class LineConfig:
    """Settings of the straight-line calibration (SI units).

    Attributes
    ----------
    features : LineFeatureConfig
        How each profile's corner is found.
    robot_sigma_t_m, robot_sigma_r_rad : float
        1σ per axis of the flange position (m) and orientation (rad) error. Defaults 0.03 mm
        and 0.003 deg (a UR-class arm).
    corner_sigma_floor_m : float
        Smallest 1σ of a fitted corner in x and z, m (flank roughness, bead shape). Default
        5 µm.
    initial_sigma_rotation_rad, initial_sigma_translation_m : float
        Loose prior around an initial hand-eye, per axis. Defaults 5 deg and 10 mm.
    scale : str
        The profiler's x (along the line) and z (depth) scales in the default method, both
        about the sensor origin: ``free`` estimates them with the hand-eye, ``fixed`` holds
        them at 1, ``auto`` (default) estimates them and keeps each one only where it lies
        clearly off 1 (:meth:`.target.LineTarget.solve_default`).
    min_samples : int
        Fewest views with a corner. Default 20 (the closed form needs 17).
    max_iterations : int
        Levenberg-Marquardt linearisations. Default 50.
    tolerance : float
        Stop when an accepted step lowers the cost by less than this fraction. Default 1e-10.
    outlier_probability : float
        A view whose normalised residual (χ², 2 dof) has a smaller upper-tail probability is
        an outlier. Default 1e-4.
    max_outlier_fraction : float
        Largest share of views dropped as outliers. Default 0.2.
    weak_sigma_m, unobservable_sigma_m : float
        Thresholds of the observability diagnosis, m (rotations times the lever). Defaults
        0.2 mm and 1 mm.
    """

    features: LineFeatureConfig = field(default_factory=LineFeatureConfig)
    robot_sigma_t_m: float = 3e-5
    robot_sigma_r_rad: float = math.radians(0.003)
    corner_sigma_floor_m: float = 5e-6
    initial_sigma_rotation_rad: float = math.radians(5.0)
    initial_sigma_translation_m: float = 0.01
    scale: str = "auto"
    min_samples: int = 20
    max_iterations: int = 50
    tolerance: float = 1e-10
    outlier_probability: float = 1e-4
    max_outlier_fraction: float = 0.2
    weak_sigma_m: float = 2e-4
    unobservable_sigma_m: float = 1e-3

    def __post_init__(self) -> None:
        for name in (
            "robot_sigma_t_m",
            "robot_sigma_r_rad",
            "corner_sigma_floor_m",
            "initial_sigma_rotation_rad",
            "initial_sigma_translation_m",
            "tolerance",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"LineConfig.{name} must be positive and finite, got {value}")
        if self.scale not in SCALE_MODES:
            raise InputError(
                f"the profiler scale must be one of {', '.join(SCALE_MODES)}, got {self.scale!r}"
            )
        if self.min_samples < 3 or self.max_iterations < 1:
            raise InputError("LineConfig.min_samples must be >= 3 and max_iterations >= 1")
        if not 0.0 < self.outlier_probability < 1.0:
            raise InputError("LineConfig.outlier_probability must be in (0, 1)")
        if not 0.0 <= self.max_outlier_fraction < 1.0:
            raise InputError("LineConfig.max_outlier_fraction must be in [0, 1)")
        if not 0.0 < self.weak_sigma_m < self.unobservable_sigma_m:
            raise InputError("LineConfig needs 0 < weak_sigma_m < unobservable_sigma_m")
