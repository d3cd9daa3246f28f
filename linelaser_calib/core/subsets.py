"""The self-check's solves of subsets of a solution's features, and what they give.

:func:`solve_subsets` runs the target's default solve on the interleaved folds' training
features, the even and the odd features and the features without each region of the
workspace (:func:`region_subsets`); :func:`solve_each` runs a solve on given subsets (the
plain model's). Each outcome is kept :func:`lean`: the statistics read a solution's
hand-eye, section and 1σ, never its per-sample records, so the twelve subsets of a long
recording hold no copy of its points. :func:`region_jackknife` and
:func:`halves_difference` reduce the outcomes; :func:`hand_eye_difference` and
:func:`model_sigma` are their units.

All lengths in m and angles in rad.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import CalibrationError
from .forked import map_forked
from .geometry import FloatArray, rotvec_from_matrix
from .targets.base import Progress, TargetSolution


def hand_eye_difference(T_a: FloatArray, T_b: FloatArray) -> FloatArray:
    """(6,) rotation of b relative to a (rad, rotation vector of R_aᵀR_b) and translation
    b − a (m, flange axes), in the order of the 1σ vectors."""
    rotation = rotvec_from_matrix(T_a[:3, :3].T @ T_b[:3, :3])
    return np.concatenate([rotation, T_b[:3, 3] - T_a[:3, 3]])


def reported_sigma(solution: TargetSolution) -> FloatArray | None:
    """(6,) 1σ [rotation, translation] a solution reports, None if it has none."""
    if solution.sigma_rotation_rad is None or solution.sigma_translation_m is None:
        return None
    return np.concatenate([solution.sigma_rotation_rad, solution.sigma_translation_m])


def statistical_sigma(solution: TargetSolution) -> FloatArray | None:
    """(6,) 1σ [rotation, translation] a solution reports without its model spread (the
    move to a model of the sensor its profiles cannot tell apart,
    :attr:`~.targets.base.TargetSolution.sigma_model_spread`, taken out in quadrature),
    None if it has none."""
    sigma = reported_sigma(solution)
    spread = solution.sigma_model_spread
    if sigma is None or spread is None:
        return sigma
    return np.asarray(np.sqrt(np.maximum(sigma**2 - spread**2, 0.0)))


def model_sigma(solution: TargetSolution) -> FloatArray | None:
    """(6,) noise-model 1σ [rotation, translation] of a solution (its statistical 1σ without
    the widening for profiles that scatter it more than the model says, nor for the robot's
    error that neighbouring views share), None if it has none. The statistics below compare
    with the model; the widening is a floor of the final 1σ, to which the model spread is
    added."""
    sigma = statistical_sigma(solution)
    if sigma is None:
        return sigma
    for factors in (solution.sigma_widening, solution.sigma_shared):
        if factors is not None:
            sigma = sigma / factors
    return np.asarray(sigma)


@dataclass(frozen=True)
class RegionJackknife:
    """The jackknife over regions of the workspace (:func:`region_jackknife`).

    Attributes
    ----------
    sigma : ndarray, shape (6,)
        √((G − 1)/G · Σ_g (θ_g − θ)²) per axis, θ_g the solve without region g and θ the full
        solution (the order of :func:`hand_eye_difference`).
    expected : ndarray, shape (6,)
        What the noise model predicts for it: √((G − 1)/G · Σ_g (σ_g² − σ²)), σ_g the 1σ of
        the solve without region g and σ the full solution's (the variance of θ_g − θ for
        nested estimates), at least σ. A region whose absence leaves the poses weak (a whole
        direction of view missing) moves the estimate more, and the model says so.
    regions : int
        G, the regions solved without.
    """

    sigma: FloatArray
    expected: FloatArray
    regions: int

    @property
    def ratio(self) -> float:
        """√(mean over the axes of (sigma / expected)²), the region dispersion."""
        return float(np.sqrt(np.mean((self.sigma / self.expected) ** 2)))


def region_subsets(kept: list[Any], label: NDArray[np.int64]) -> list[list[Any]]:
    """The features without each region of the workspace (``label`` (M,) of
    :func:`~linelaser_calib.core.regions.workspace_regions`), one list per region."""
    return [
        [f for f, lab in zip(kept, label, strict=True) if lab != g]
        for g in range(int(label.max()) + 1)
    ]


def region_jackknife(
    solves: Sequence[TargetSolution | CalibrationError],
    solution: TargetSolution,
    sigma_model: FloatArray,
) -> RegionJackknife | None:
    """The jackknife of the hand-eye over the solves of :func:`region_subsets` (each region
    left out in turn; :class:`RegionJackknife`); None when fewer than 3 regions could be
    solved without.

    Leaving a whole region out moves the estimate by what that region's shared robot error
    put into it; interleaved folds keep every region in every fold and cannot show it.
    """
    moves, spreads = [], []
    for fold in solves:
        if isinstance(fold, CalibrationError):
            continue
        moves.append(hand_eye_difference(solution.T_flange_sensor, fold.T_flange_sensor))
        sigma_fold = model_sigma(fold)
        spreads.append(np.zeros(6) if sigma_fold is None else sigma_fold**2 - sigma_model**2)
    G = len(moves)
    if G < 3:
        return None
    factor = (G - 1) / G
    return RegionJackknife(
        sigma=np.sqrt(factor * np.sum(np.square(moves), axis=0)),
        expected=np.sqrt(np.maximum(factor * np.sum(spreads, axis=0), sigma_model**2)),
        regions=G,
    )


def lean(solution: TargetSolution) -> TargetSolution:
    """``solution`` without its per-sample records (``sample_fits``: a copy of every used
    profile's points) and its subset start: what a subset's outcome is kept as."""
    return replace(solution, sample_fits=[], subset_start=None)


def solve_each(
    solve: Callable[[list[Any]], TargetSolution],
    subsets: Sequence[list[Any]],
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> list[TargetSolution | CalibrationError]:
    """``solve`` of each subset, :func:`lean`, or the CalibrationError it raised (in a forked
    child for half of them with ``workers`` 2, :func:`~.forked.map_forked`)."""
    return map_forked(lambda subset: lean(solve(subset)), subsets, workers, progress)


def reporting(progress: Progress | None, stage: str) -> Callable[[int, int], None] | None:
    """``progress`` of ``stage`` as :func:`~.forked.map_forked` reports it."""
    if progress is None:
        return None
    report = progress
    return lambda done, total: report(stage, done, total)


def solve_subsets(
    kept: list[Any],
    folds: int,
    solve: Callable[[list[Any]], TargetSolution],
    label: NDArray[np.int64] | None = None,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> list[TargetSolution | CalibrationError]:
    """The solves of the self-check, each a solution or the CalibrationError it raised: every
    interleaved fold's training features (all but every ``folds``-th from k), the even and
    the odd features, then the features without each region (``label``, when given).
    They are independent (:func:`solve_each`: with ``workers`` 2 a forked child takes half
    of them, same outcomes as one process)."""
    group = np.arange(len(kept)) % folds
    subsets = [[f for f, g in zip(kept, group, strict=True) if g != k] for k in range(folds)]
    subsets += [kept[0::2], kept[1::2]]
    if label is not None:
        subsets += region_subsets(kept, label)
    return solve_each(solve, subsets, workers, progress)


def halves_difference(
    a: TargetSolution | CalibrationError, b: TargetSolution | CalibrationError
) -> tuple[FloatArray, FloatArray] | None:
    """|θ_even − θ_odd| (6,) and the halves' combined model 1σ √(σ_even² + σ_odd²) (6,) of the
    even (a) and odd (b) solves, or None when they could not be solved apart."""
    if isinstance(a, CalibrationError) or isinstance(b, CalibrationError):
        return None
    sigma_a, sigma_b = model_sigma(a), model_sigma(b)
    if sigma_a is None or sigma_b is None:
        return None
    difference = hand_eye_difference(a.T_flange_sensor, b.T_flange_sensor)
    return np.abs(difference), np.sqrt(sigma_a**2 + sigma_b**2)
