"""Settings of the sphere target."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.observability import ObservabilityConfig
from linelaser_calib.core.profile.along_line import SCALE_MODES
from linelaser_calib.core.profile.cleaning import CleaningConfig
from linelaser_calib.core.targets.sphere.circle import CircleConfig
from linelaser_calib.core.targets.sphere.model import SIDE_LABELS
from linelaser_calib.core.targets.sphere.refine import SphereRefineConfig


@dataclass(frozen=True)
class SphereConfig:
    """Everything the sphere target can be told.

    Attributes
    ----------
    radius_m : float or None
        The sphere radius, m (``--radius``); None estimates it.
    scale : str
        The sensor's along-line scale in the default method: ``free`` estimates it with the
        hand-eye; ``fixed`` holds it at 1; ``auto`` (default) estimates it where the whole
        recording shows it clearly off 1 and holding it would move the hand-eye beyond its
        1σ, and otherwise holds it, the 1σ counting the move between the two
        (:func:`estimates_scale`, :func:`~.scales.with_scale_model_spread`).
    centre_side : str or None
        ``+y`` or ``-y``: the side of the laser plane (sensor y) the sphere centre lies on,
        when the user knows it; None resolves it from the data.
    min_samples : int
        Fewest usable profiles. Default 6 (the linear solve needs 5).
    cleaning : CleaningConfig
    circle : CircleConfig
    profile_outlier_sigmas : float
        A profile whose circle's RMS residual lies this many robust spreads (1.4826 · MAD,
        at least a tenth of the median) above the median over the recording's profiles is
        set aside. Default 6.
    max_residual_ratio : float
        The default method's result is refused when its RMS residual (in the laser plane) is this
        many times the median RMS the profiles' circles leave. Default 4.
    refine : SphereRefineConfig
        The default method's noise levels and solver settings.
    observability : ObservabilityConfig
    max_robot_ratio : float
        A calibration whose pose corrections are this many times the robot's stated σ is
        refused (clocks, motion during the scans, or a wrong robot σ). Default 10.
    max_scatter_ratio : float
        ``--method paper``: a centre scatter this many times what the robot's σ explains is
        refused. Default 10.
    outlier_sigmas : float
        A sample whose RMS residual lies this many robust σ (1.4826 · MAD) above the median,
        and above 3 sensor σ, is dropped and the solve repeated. Default 6.
    max_outlier_fraction : float
        Largest share of samples dropped as outliers. Default 0.2.
    """

    radius_m: float | None = None
    scale: str = "auto"
    centre_side: str | None = None
    min_samples: int = 6
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)
    circle: CircleConfig = field(default_factory=CircleConfig)
    profile_outlier_sigmas: float = 6.0
    max_residual_ratio: float = 4.0
    refine: SphereRefineConfig = field(default_factory=SphereRefineConfig)
    observability: ObservabilityConfig = field(default_factory=ObservabilityConfig)
    max_robot_ratio: float = 10.0
    max_scatter_ratio: float = 10.0
    outlier_sigmas: float = 6.0
    max_outlier_fraction: float = 0.2

    def __post_init__(self) -> None:
        if self.radius_m is not None and not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise InputError(
                f"the sphere radius must be a positive length in m, got {self.radius_m}"
            )
        if self.scale not in SCALE_MODES:
            raise InputError(
                f"the along-line scale must be one of {', '.join(SCALE_MODES)}, got {self.scale!r}"
            )
        if self.centre_side is not None and self.centre_side not in SIDE_LABELS.values():
            raise InputError(
                f"the sphere centre side must be '+y' or '-y', got {self.centre_side!r}"
            )
        if self.min_samples < 5:
            raise InputError(f"the sphere target needs min_samples >= 5, got {self.min_samples}")
        for name in (
            "max_robot_ratio",
            "max_scatter_ratio",
            "outlier_sigmas",
            "profile_outlier_sigmas",
            "max_residual_ratio",
        ):
            if not getattr(self, name) > 1.0:
                raise InputError(f"SphereConfig.{name} must be > 1, got {getattr(self, name)}")
        if not 0.0 <= self.max_outlier_fraction < 1.0:
            raise InputError("SphereConfig.max_outlier_fraction must be in [0, 1)")


def estimates_scale(config: SphereConfig, warm_estimated: bool | None = None) -> bool:
    """Whether the default method's first solve estimates the sensor's along-line scale:
    ``free`` always, ``fixed`` never, ``auto`` (default) not at first; a warm start (the
    self-check's subsets) follows the whole recording's choice (``warm_estimated``) unless
    the scale is ``fixed``.

    ``auto`` then solves with the scale estimated as well and keeps that solution only where
    the whole recording shows the scale clearly off 1 and holding it would move the hand-eye
    beyond its 1σ (:func:`~.scales.with_scale_model_spread`). The real scans say why not
    always: on the real 40 mm ball set with the radius free a free scale reads 0.99911 ±
    0.00012, clearly off 1, yet the centres then scatter more (0.262 mm against 0.244 mm
    held) and the free radius moves from the independent circle fits' 39.977 mm to
    40.034 mm: the scale takes up the profiler's own shape error, and the hand-eye moves
    within its 1σ. With the radius given it also takes up a ball that is not the given size
    (the 12.7 mm set: 0.958 ± 0.003, beyond a plausible scale error, so it is held).
    """
    if config.scale == "fixed":
        return False
    if warm_estimated is not None:
        return warm_estimated
    return config.scale == "free"
