"""Two models of a profiler's scales that the profiles cannot tell apart, and the 1σ that
counts their difference.

A target that keeps one model of the sensor's scales (the sphere its along-line scale held
at 1; the cylinder with its radius free the ratio of its x and z scales read as an x scale)
solves the other too. Where the two hand-eyes differ by more than the kept one's 1σ on some
axis, the move is kept as the solution's model spread
(:attr:`~.targets.base.TargetSolution.sigma_model_spread`) and added to every axis's 1σ in
quadrature, with a warning of kind ``scale-model-spread`` (:mod:`.verdict`). The self-check
judges the data against the 1σ without it (:func:`~.subsets.statistical_sigma`).

Lengths in m, angles in rad; the warning in mm and degrees.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .subsets import hand_eye_difference, reported_sigma
from .targets.base import TargetSolution


def with_model_spread(
    kept: TargetSolution, other: TargetSolution, reading: str, advice: str
) -> TargetSolution:
    """``kept``, with the move to ``other``'s hand-eye as its model spread where that move
    exceeds its 1σ on some axis (:data:`~.targets.base.TargetSolution.sigma_model_spread`,
    added to the 1σ per axis in quadrature), and a warning: ``reading`` (what the other
    model reads, ending in what solving it changed), the move, then ``advice``. Unchanged
    when the move is within the 1σ or ``kept`` has no 1σ."""
    sigma = reported_sigma(kept)
    if sigma is None:
        return kept
    move = np.abs(hand_eye_difference(kept.T_flange_sensor, other.T_flange_sensor))
    if not np.any(move > sigma):
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
        sigma_model_spread=move,
        warnings=[*kept.warnings, warning],
    )
