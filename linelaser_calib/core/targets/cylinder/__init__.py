"""The cylinder target (the cylinder paper, and maximum likelihood on every point)."""

from __future__ import annotations

from .config import CylinderConfig, RefineConfig
from .features import FittedSample, fit_sample
from .refine import RefineResult, refine, refine_with_outlier_rejection
from .section import CylinderSection
from .target import TARGET, CylinderTarget

__all__ = [
    "TARGET",
    "CylinderConfig",
    "CylinderSection",
    "CylinderTarget",
    "FittedSample",
    "RefineConfig",
    "RefineResult",
    "fit_sample",
    "refine",
    "refine_with_outlier_rejection",
]
