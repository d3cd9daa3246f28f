"""Where a result's 1σ comes from: the noise model's 1σ and each widening, by name.

A hand-eye's reported 1σ starts from what the noise model and the poses give (the
information of the solve, :func:`~.subsets.model_sigma`) and may be widened, per axis, in
this order:

``profile_scatter``
    The profiles scatter the hand-eye more than the noise model predicts (the sandwich
    dispersion, :attr:`~.targets.base.TargetSolution.sigma_widening`; for the corners of the
    line and the known point the recording's a-posteriori variance factor).
``shared_robot_error``
    The robot's error that neighbouring poses share (:mod:`.shared_pose`,
    :attr:`~.targets.base.TargetSolution.sigma_shared`).
``systematic_robot_error``
    The self-check found the robot's error systematic: the spread of the hand-eye over the
    regions left out and the arm's error common to the workspace (:mod:`.selfcheck`), where
    that exceeds the above.
``halves``
    The even and the odd poses' solves still disagree beyond the self-check's limit.
``scale_model``
    A model of the profiler's scales the profiles cannot tell apart, or a held scale's own
    1σ (:mod:`.model_spread`), added per axis in quadrature.

Each widening is kept as factors (6,) >= 1, [rotation, translation], the 1σ after it over
the 1σ before it, so that the noise model's 1σ times all factors is the reported one
(:attr:`SigmaBudget.total`). A user judges the 1σ by them: a 1σ widened mostly by the
robot's error asks for a better arm or more spread poses, one widened by the profiles'
scatter asks about the sensor.

Lengths in m, angles in rad; :meth:`SigmaBudget.text` in mm and degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .geometry import FloatArray
from .subsets import model_sigma, reported_sigma
from .targets.base import TargetSolution

PROFILE_SCATTER = "profile_scatter"
SHARED_ROBOT_ERROR = "shared_robot_error"
SYSTEMATIC_ROBOT_ERROR = "systematic_robot_error"
HALVES = "halves"
SCALE_MODEL = "scale_model"

#: Each contribution's name and what it is, in the words of the summary.
WORDS = {
    PROFILE_SCATTER: "the profiles' scatter beyond the noise model",
    SHARED_ROBOT_ERROR: "the robot's error shared between neighbouring poses",
    SYSTEMATIC_ROBOT_ERROR: "the robot's systematic error over the workspace (self-check)",
    HALVES: "the even and odd halves' disagreement (self-check)",
    SCALE_MODEL: "the profiler's scales the profiles cannot pin down",
}
#: A factor below this is not named in the summary's line (it is in the result file).
FACTOR_SHOWN = 1.05


@dataclass(frozen=True)
class SigmaBudget:
    """The noise model's 1σ and the named widenings that make the reported 1σ.

    Attributes
    ----------
    noise_model : ndarray, shape (6,)
        1σ [rotation about the sensor axes (rad), translation along the flange axes (m)]
        that the noise model and the poses give.
    factors : tuple of (str, ndarray of shape (6,))
        Each widening's name (a key of :data:`WORDS`) and its factors (>= 1, same order), in
        the order applied.
    """

    noise_model: FloatArray
    factors: tuple[tuple[str, FloatArray], ...] = ()

    @property
    def total(self) -> FloatArray:
        """(6,) the product of the factors: the reported 1σ over the noise model's."""
        return np.prod([np.ones(6)] + [factor for _, factor in self.factors], axis=0)

    @property
    def sigma(self) -> FloatArray:
        """(6,) the 1σ after every widening."""
        return np.asarray(self.noise_model * self.total)

    def then(self, name: str, sigma: FloatArray | None) -> SigmaBudget:
        """This budget widened by ``name`` to ``sigma`` (6,) (unchanged for None): the factor
        is ``sigma`` over the 1σ so far, at least 1 (a 1σ never narrows by a widening)."""
        if sigma is None:
            return self
        before = self.sigma
        with np.errstate(divide="ignore", invalid="ignore"):
            factor = np.where(before > 0.0, np.asarray(sigma, dtype=np.float64) / before, 1.0)
        return replace(self, factors=(*self.factors, (name, np.maximum(factor, 1.0))))

    def to_mapping(self) -> dict[str, Any]:
        """``quality.sigma_budget`` of the result file (plain floats, SI)."""
        return {
            "noise_model": {
                "rotation_rad": [float(v) for v in self.noise_model[:3]],
                "translation_m": [float(v) for v in self.noise_model[3:]],
            },
            "widened_by": {name: _groups(factor) for name, factor in self.factors},
            "total": _groups(self.total),
        }

    def text(self) -> str:
        """One line in words: the noise model's largest 1σ (mm, deg), then each widening's
        largest factor over the axes and what it is, largest first, and the largest of their
        product."""
        named = sorted(
            ((float(np.max(f)), name) for name, f in self.factors if np.max(f) >= FACTOR_SHOWN),
            reverse=True,
        )
        base = (
            f"the noise model's {float(np.max(self.noise_model[3:])) * 1e3:.4f} mm, "
            f"{float(np.degrees(np.max(self.noise_model[:3]))):.4f} deg (largest axis)"
        )
        if not named:
            return f"{base}, widened by nothing (quality.sigma_budget)"
        widened = ", ".join(f"up to {factor:.2f}x by {WORDS[name]}" for factor, name in named)
        return (
            f"{base}, widened {widened}; up to {float(np.max(self.total)):.2f}x in all "
            "(quality.sigma_budget)"
        )


def _groups(factor: FloatArray) -> dict[str, list[float]]:
    """A (6,) factor as the file's ``rotation`` and ``translation`` lists."""
    return {
        "rotation": [float(v) for v in factor[:3]],
        "translation": [float(v) for v in factor[3:]],
    }


def statistical_budget(solution: TargetSolution) -> SigmaBudget | None:
    """The budget of a solution's statistical 1σ (:func:`~.subsets.statistical_sigma`): the
    noise model's, widened for the profiles' scatter and the robot's shared error; None
    without a 1σ."""
    noise = model_sigma(solution)
    if noise is None:
        return None
    budget = SigmaBudget(noise)
    for name, factor in (
        (PROFILE_SCATTER, solution.sigma_widening),
        (SHARED_ROBOT_ERROR, solution.sigma_shared),
    ):
        if factor is not None:
            budget = replace(budget, factors=(*budget.factors, (name, np.asarray(factor))))
    return budget


def solution_budget(solution: TargetSolution) -> SigmaBudget | None:
    """The budget of a solution's reported 1σ without a self-check: the statistical one's
    (:func:`statistical_budget`) and the scale model's spread; None without a 1σ."""
    budget = statistical_budget(solution)
    if budget is None or solution.sigma_model_spread is None:
        return budget
    return budget.then(SCALE_MODEL, reported_sigma(solution))
