"""Settings of the cylinder target."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...profile.cleaning import CleaningConfig
from .arc import ArcConfig
from .ellipse import EllipseConfig
from .pso_alm import HybridConfig
from .refine import RefineConfig

#: Fewest fitted samples the hand-eye plus axis can be solved from with any margin.
MIN_SAMPLES = 8
#: How the default method treats the sensor's along-line scale (``CylinderConfig.scale``).
SCALE_MODES = ("auto", "fixed", "free")


@dataclass(frozen=True)
class CylinderConfig:
    """Every setting of the cylinder target; each stage's defaults are documented in its module.

    Attributes
    ----------
    radius_m : float or None
        Cylinder radius, m; None estimates it.
    scale : str
        The sensor's along-line scale in the default method: ``free`` estimates it with the
        hand-eye, ``fixed`` holds it at 1, ``auto`` (default) estimates it when the radius is
        given (:func:`.target.estimates_scale`).
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
