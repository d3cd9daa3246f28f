"""Drop the samples a target flags as outliers and solve again, until none is left.

One loop for every target: the target supplies the solve of a subset of its samples (started
from the previous round's estimate) and the test that flags a sample; the loop owns the
budget (at most ``max_fraction`` of the samples over all rounds, never below
``min_samples``), the order (most severe first) and the bookkeeping of what was dropped.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, NamedTuple, TypeVar

import numpy as np
from scipy.special import chdtri

Outcome = TypeVar("Outcome")


class Flag(NamedTuple):
    """A sample flagged as an outlier after a solve.

    Attributes
    ----------
    severity : float
        Larger is worse; the most severe are dropped first.
    position : int
        Position of the sample in the subset that was solved.
    reason : str
        Why, in plain words with units.
    """

    severity: float
    position: int
    reason: str


@dataclass
class RejectionOutcome(Generic[Outcome]):
    """The last solve and what was dropped on the way.

    Attributes
    ----------
    outcome : Outcome
        The last solve (of the samples in ``kept``).
    kept : list of int
        Indices (into the caller's samples) of the last solve, in order.
    dropped : list of (int, str)
        Dropped sample indices with their reasons, sorted by index.
    left_flagged : list of (int, str)
        Samples flagged after the last solve that the budget did not allow to drop.
    """

    outcome: Outcome
    kept: list[int]
    dropped: list[tuple[int, str]]
    left_flagged: list[tuple[int, str]]


def recording_chi2_scale(chi2: np.ndarray, dof: int) -> float:
    """How much wider the recording's own scatter is than its noise model: the median of
    the samples' normalised residuals (chi2 with ``dof`` degrees of freedom, shape (N,)) over
    the chi2 distribution's median, at least 1. Dividing a sample's chi2 by it judges the
    sample against the recording's other samples (a real profiler's shape error widens
    every corner's scatter beyond its line fits' covariance), not against the model alone.
    """
    values = np.asarray(chi2, dtype=np.float64)
    values = values[np.isfinite(values)]
    if not len(values):
        return 1.0
    return max(1.0, float(np.median(values)) / float(chdtri(dof, 0.5)))


def recording_widening(chi2: np.ndarray, dof: int, n_global: int) -> tuple[float, str | None]:
    """The factor (>= 1) by which a solve's 1σ is widened for the recording's own scatter,
    and a warning when it at least doubles it (else None).

    The a-posteriori variance factor: the samples' chi2 (each with ``dof`` degrees of
    freedom, shape (M,)) summed over the redundancy ``dof`` M − ``n_global``; its root where
    it exceeds 1. A profiler whose x and z scales differ by 0.8 % (the stress matrix's
    ``scales`` face) gave the line target's corners 1.9-7.5 times their modelled variance
    with the scales held (clean twins 0.1-0.3, so no widening there); it now estimates them.
    """
    values = np.asarray(chi2, dtype=np.float64)
    redundancy = dof * len(values) - n_global
    if redundancy <= 0 or not np.all(np.isfinite(values)):
        return 1.0, None
    factor = math.sqrt(max(1.0, float(np.sum(values)) / redundancy))
    if factor < 2.0:
        return factor, None
    return factor, (
        f"the views lie off the fit {factor:.1f} times farther than their corner fits and the "
        f"robot's prior predict (chi2 {float(np.sum(values)):.0f} over {redundancy} degrees "
        "of freedom): something the model lacks moves every corner, such as a profiler whose "
        "x and z scales differ, its shape error or a robot error. The 1 sigma is widened by "
        "that factor"
    )


def solve_with_rejection(
    n_samples: int,
    solve: Callable[[list[int], Outcome | None], Outcome],
    flag: Callable[[Outcome, list[int]], list[Flag]],
    max_fraction: float,
    min_samples: int,
    screen: bool = True,
) -> RejectionOutcome[Outcome]:
    """Solve, drop flagged samples (most severe first, within the budget), repeat.

    Parameters
    ----------
    n_samples : int
        Samples available.
    solve : callable
        ``solve(kept, previous)``: the solve of the samples ``kept`` (indices), started from
        ``previous`` (None in the first round).
    flag : callable
        ``flag(outcome, kept)``: the outliers of a solve, positions into ``kept``.
    max_fraction : float
        Largest share of the samples dropped over all rounds.
    min_samples : int
        Never drop below this many samples.
    screen : bool
        False: the samples are a set already screened (:attr:`~linelaser_calib.core.targets.
        base.SolveContext.screen_outliers`): one solve of all of them, none flagged.
    """
    budget = min(int(np.floor(max_fraction * n_samples)), n_samples - min_samples)
    kept = list(range(n_samples))
    if not screen:
        return RejectionOutcome(solve(kept, None), kept, [], [])
    dropped: list[tuple[int, str]] = []
    previous: Outcome | None = None
    while True:
        outcome = solve(kept, previous)
        flagged = sorted(flag(outcome, kept), key=lambda f: (f.severity, f.position), reverse=True)
        room = budget - len(dropped)
        if not flagged or room <= 0:
            left = [(kept[f.position], f.reason) for f in flagged]
            return RejectionOutcome(outcome, kept, sorted(dropped), left)
        drop = {f.position: f.reason for f in flagged[:room]}
        dropped.extend((kept[j], reason) for j, reason in drop.items())
        kept = [i for j, i in enumerate(kept) if j not in drop]
        previous = outcome
