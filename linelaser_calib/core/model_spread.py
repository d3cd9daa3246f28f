"""Two models of a profiler's scales that the profiles cannot tell apart, and the 1σ that
counts their difference.

A target that keeps one model of the sensor's scales (the sphere its along-line scale held
at 1, or estimated and the same stretch read as a depth scale; the cylinder with its radius
free the ratio of its x and z scales read as an x scale) solves the other too. Where the
two hand-eyes differ by more than the kept one's 1σ on some axis, the move (over √3 where
the truth lies anywhere between the two) is kept as the solution's model spread
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
    kept: TargetSolution,
    other: TargetSolution,
    reading: str,
    advice: str,
    between: bool = False,
) -> TargetSolution:
    """``kept``, with the move to ``other``'s hand-eye as its model spread where that move
    exceeds its 1σ on some axis (:data:`~.targets.base.TargetSolution.sigma_model_spread`,
    added to the 1σ per axis in quadrature), and a warning: ``reading`` (what the other
    model reads, ending in what solving it changed), the move, then ``advice``. Unchanged
    when the move is within the 1σ or ``kept`` has no 1σ.

    ``between``: the truth lies anywhere between the two models (two readings of one ratio
    of the sensor's scales, ``kept`` one end), so the spread is the move over √3, the RMS
    distance from one end of a uniform spread; otherwise (the truth is either model) the
    whole move."""
    sigma = reported_sigma(kept)
    if sigma is None:
        return kept
    move = np.abs(hand_eye_difference(kept.T_flange_sensor, other.T_flange_sensor))
    if not np.any(move > sigma):
        return kept
    spread = move / math.sqrt(3.0) if between else move
    widened = np.hypot(sigma, spread)
    counted = "that move over the square root of 3 (the truth anywhere between the two)"
    warning = (
        f"{reading} moves the hand-eye by {float(np.linalg.norm(move[3:])) * 1e3:.3f} mm and "
        f"{math.degrees(float(np.linalg.norm(move[:3]))):.4f} deg, beyond its 1 sigma: the 1 "
        f"sigma now counts {counted if between else 'that move'} (added per axis). {advice}"
    )
    return replace(
        kept,
        sigma_rotation_rad=widened[:3],
        sigma_translation_m=widened[3:],
        sigma_model_spread=spread,
        warnings=[*kept.warnings, warning],
    )


def with_held_sigma(kept: TargetSolution, free: TargetSolution) -> TargetSolution:
    """``kept``, which holds a scale of the sensor at 1 that its reading did not find clearly
    off, with its 1σ per axis widened by what that scale may move the hand-eye: the larger
    of the move to ``free`` (the same profiles with the scale estimated) and the part of
    ``free``'s 1σ the scale adds.

    Held at 1, the scale is still known only to its reading ŝ ± σ_s. In the linearised
    model the free hand-eye is the held one moved by K ŝ, with variance σ_free² =
    σ_kept² + K² σ_s², and the held one is off by K s for the true s: so the 1σ counts
    K · max(|ŝ|, σ_s) per axis, the move (|K ŝ|) or √(σ_free² − σ_kept²), whichever is
    larger, in quadrature. That part is kept as the model spread
    (:attr:`~.targets.base.TargetSolution.sigma_model_spread`, out of the self-check's
    yardstick); nothing says the scale is off, so no warning is added. Unchanged where
    either solution has no 1σ.
    """
    sigma, wider = reported_sigma(kept), reported_sigma(free)
    if sigma is None or wider is None:
        return kept
    move = np.abs(hand_eye_difference(kept.T_flange_sensor, free.T_flange_sensor))
    spread = np.maximum(move, np.sqrt(np.maximum(wider**2 - sigma**2, 0.0)))
    widened = np.hypot(sigma, spread)
    return replace(
        kept,
        sigma_rotation_rad=widened[:3],
        sigma_translation_m=widened[3:],
        sigma_model_spread=spread,
    )
