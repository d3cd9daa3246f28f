"""The known-point target: one fixed point (a weld-seam corner) seen from many poses."""

from __future__ import annotations

from ...profile.corner import CornerSample
from ...seam_grid import GridStep, paper_correction, scatter_delta_r, weld_points_base
from .config import KnownPointConfig
from .features import extract_corner, extract_corners
from .linear import HandEyePrior, solve_linear
from .observability import KnownPointObservability, analyse_known_point
from .refine import KnownPointRefinement, refine_known_point
from .section import KnownPoint
from .target import TARGET, KnownPointResult, KnownPointTarget, calibrate_known_point

__all__ = [
    "TARGET",
    "CornerSample",
    "GridStep",
    "HandEyePrior",
    "KnownPoint",
    "KnownPointConfig",
    "KnownPointObservability",
    "KnownPointRefinement",
    "KnownPointResult",
    "KnownPointTarget",
    "analyse_known_point",
    "calibrate_known_point",
    "extract_corner",
    "extract_corners",
    "paper_correction",
    "refine_known_point",
    "scatter_delta_r",
    "solve_linear",
    "weld_points_base",
]
