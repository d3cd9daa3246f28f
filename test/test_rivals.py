"""The whole recording decides the target (core/targets/rivals.py): a rival's full fit is
compared only where the target's own fit is in doubt, refuses only when it is clearly better
(naming it with both figures), and a failed check that every rival explains clearly worse is
kept with a warning. The real cases (a ball given to the cylinder, cylinder scans given to the
sphere) are in test_robcalibrator.py and test_sphere.py; here the decisions, on stand-ins."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from linelaser_calib.core.errors import ModelMismatch
from linelaser_calib.core.targets import rivals
from linelaser_calib.core.targets.base import RobotError, SolveContext, TargetSolution
from linelaser_calib.core.types import SampleFit


@dataclass
class Section:
    """A stand-in fit whose points all lie ``distance_m`` from its target."""

    distance_m: float

    def surface_distances(self, fit: SampleFit, T_base_sensor: Any) -> Any:
        return np.full(len(fit.points), self.distance_m)


def solution(distance_m: float, robot_excess: float = 1.0) -> TargetSolution:
    fits = [SampleFit(k, k, np.eye(4), np.zeros((50, 3)), np.zeros(2)) for k in range(10)]
    return TargetSolution(
        T_flange_sensor=np.eye(4),
        section=Section(distance_m),  # type: ignore[arg-type]
        method="default",
        samples_used=list(range(10)),
        rejections=[],
        rms_residual_m=distance_m,
        sample_residuals_m={},
        sigma_translation_m=None,
        sigma_rotation_rad=None,
        warnings=[],
        history={},
        sample_fits=fits,
        noise_m=1e-5,
        robot_error=RobotError(1e-4 * robot_excess, 1e-4 * robot_excess, robot_excess),
    )


class Target:
    """A stand-in target with one rival; its fit check fails when told to."""

    name = "ball"
    title = "ball"
    rivals = ("tube",)

    def __init__(self, check_fails: bool = False, shapes_doubt: bool = False) -> None:
        self.check_fails = check_fails
        self.shapes_doubt = shapes_doubt

    def check_fit(self, solution: TargetSolution, config: Any) -> None:
        if self.check_fails:
            raise ModelMismatch(
                "the ball model does not fit these data: the residual is 5 times the noise. "
                "Likely causes: ... No result was written."
            )

    def model_doubt(self, features: list[Any], config: Any) -> str | None:
        return "most profiles fit a conic better one by one" if self.shapes_doubt else None


@pytest.fixture
def rival_leaves(monkeypatch: pytest.MonkeyPatch) -> Any:
    """Set what the rival's full fit leaves (None: it cannot be fitted); counts its fits."""
    state: dict[str, Any] = {"distance_m": None, "fits": 0}

    class Tube:
        name = "tube"
        title = "tube"

    def fit(name: str, samples: Any, context: Any) -> Any:
        state["fits"] += 1
        if state["distance_m"] is None:
            return None
        return Tube(), solution(state["distance_m"])

    monkeypatch.setattr(rivals, "_rival_solution", fit)
    monkeypatch.setattr(rivals, "get_target", lambda name: Tube())
    return state


def check(target: Target, own: TargetSolution) -> None:
    rivals.check_model(target, None, [], [], own, SolveContext())  # type: ignore[arg-type]


def test_no_doubt_no_rival_fit(rival_leaves: Any) -> None:
    check(Target(), solution(1e-4, robot_excess=1.5))
    assert rival_leaves["fits"] == 0


def test_a_rival_clearly_better_is_named_with_both_figures(rival_leaves: Any) -> None:
    rival_leaves["distance_m"] = 2e-5
    with pytest.raises(ModelMismatch) as refused:
        check(Target(shapes_doubt=True), solution(1e-4))
    text = str(refused.value)
    assert "the tube fitted with the poses leaves 20.0 um RMS" in text
    assert "the ball fitted with the poses leaves 100.0 um RMS" in text
    assert "{setting:target} tube" in text and "most profiles fit a conic" in text


def test_shapes_alone_never_refuse_when_the_rival_is_no_better(rival_leaves: Any) -> None:
    rival_leaves["distance_m"] = 0.7e-4
    own = solution(1e-4)
    check(Target(shapes_doubt=True), own)
    assert rival_leaves["fits"] == 1 and own.warnings == []


def test_a_failed_check_that_the_rival_explains_far_worse_is_a_warning(
    rival_leaves: Any,
) -> None:
    rival_leaves["distance_m"] = 5e-3
    own = solution(1e-4)
    check(Target(check_fails=True), own)
    (warning,) = own.warnings
    assert (
        "5 times the noise" in warning and "the tube fitted with the poses leaves 5000.0" in warning
    )
    rival_leaves["distance_m"] = 1.5e-4  # no clear winner either way: the check refuses
    with pytest.raises(ModelMismatch, match="A rival fitted with the poses does no better"):
        check(Target(check_fails=True), solution(1e-4))


def test_a_robot_error_twenty_times_the_prior_is_a_misfit_unless_the_rival_is_far_worse(
    rival_leaves: Any,
) -> None:
    with pytest.raises(ModelMismatch, match="20 times the robot's stated error"):
        check(Target(), solution(1e-4, robot_excess=20.0))
    rival_leaves["distance_m"] = 5e-3
    check(Target(), solution(1e-4, robot_excess=20.0))


def test_a_rival_that_cannot_calibrate_is_not_a_winner() -> None:
    assert rivals._rival_solution("sphere", [], SolveContext()) is None
