"""Two models of a profiler's scales that the profiles cannot tell apart, and the 1σ that
counts their difference.

A target that keeps one model of the sensor's scales (the sphere its along-line scale held
at 1, the cylinder with its radius free the ratio of its x and z scales read as an x scale)
solves the other too; where the two hand-eyes differ by more than the kept one's 1σ on some
axis, the difference is added to every axis's 1σ in quadrature, with a warning of kind
``scale-model-spread`` (:mod:`linelaser_calib.core.verdict`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..geometry import rotvec_from_matrix
from .base import TargetSolution


def with_model_spread(
    kept: TargetSolution, other: TargetSolution, reading: str, advice: str
) -> TargetSolution:
    """``kept``, its 1σ widened by the move to ``other``'s hand-eye where that move exceeds
    it on some axis (added per axis in quadrature), with a warning: ``reading`` (what the
    other model reads, ending in what solving it changed), the move, then ``advice``.
    Unchanged when the move is within the 1σ or ``kept`` has no 1σ."""
    sigma_r, sigma_t = kept.sigma_rotation_rad, kept.sigma_translation_m
    if sigma_r is None or sigma_t is None:
        return kept
    X_kept, X_other = kept.T_flange_sensor, other.T_flange_sensor
    move = np.concatenate(
        [rotvec_from_matrix(X_kept[:3, :3].T @ X_other[:3, :3]), X_other[:3, 3] - X_kept[:3, 3]]
    )
    sigma = np.concatenate([sigma_r, sigma_t])
    if not np.any(np.abs(move) > sigma):
        return kept
    widened = np.hypot(sigma, move)
    warning = (
        f"{reading} moves the hand-eye by {float(np.linalg.norm(move[3:])) * 1e3:.3f} mm and "
        f"{math.degrees(float(np.linalg.norm(move[:3]))):.4f} deg, beyond its 1 sigma: the 1 "
        f"sigma now counts that move (added per axis). {advice}"
    )
    return replace(
        kept,
        sigma_rotation_rad=widened[:3],
        sigma_translation_m=widened[3:],
        warnings=[*kept.warnings, warning],
    )
