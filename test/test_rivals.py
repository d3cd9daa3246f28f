"""The whole recording decides the target (core/targets/rivals.py): a rival's full fit is
compared only where the target's own fit is in doubt or too few profiles show its feature,
refuses only when it is clearly better (naming it with both figures), and a failed check
that every rival explains clearly worse is kept with a warning. The decisions on stand-ins;
then the seam targets' recordings given to each other, and arcs given to the line target,
through the pipeline. The real cases (a ball given to the cylinder, whose single profiles
mostly prefer a conic yet which calibrates as a sphere; cylinder scans given to the sphere)
are in test_robcalibrator.py and test_sphere.py; every wrong-target pair of the simulator is
in test_stress_matrix.py (slow)."""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from linelaser_calib.core.errors import ModelMismatch, TooFewFeatures
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, calibrate_samples
from linelaser_calib.core.targets import get_target, rivals, target_names
from linelaser_calib.core.targets.base import RobotError, SolveContext, TargetSolution
from linelaser_calib.core.targets.extraction import Extractions
from linelaser_calib.core.types import Rejection, Sample, SampleFit
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.settings import Front, pipeline_config
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.sphere import simulate_sphere, sphere_scenario_from_preset
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset

BAGS = Path(__file__).resolve().parent.parent / "bags"
ORIGIN = np.zeros(2)


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
    soft_fit_check = True

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
    state: dict[str, Any] = {"distance_m": None, "fits": 0, "check_fails": False}

    class Tube:
        name = "tube"
        title = "tube"
        config_type = dict

        def check_fit(self, solution: TargetSolution, config: Any) -> None:
            if state["check_fails"]:
                raise ModelMismatch("the tube model does not fit these data")

    def fit(name: str, samples: Any, context: Any, rival_samples: Any, extractions: Any) -> Any:
        state["fits"] += 1
        if state["distance_m"] is None:
            return None
        return rivals.PairedFit(Tube(), solution(state["distance_m"]), {})  # type: ignore[arg-type]

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
    hard = Target(check_fails=True)
    hard.soft_fit_check = False  # e.g. the seam targets: their check is never overruled
    with pytest.raises(ModelMismatch, match="5 times the noise"):
        check(hard, solution(1e-4))
    rival_leaves["distance_m"] = 1.5e-4  # no clear winner either way: the check refuses
    with pytest.raises(ModelMismatch, match="On the whole recording, the tube fitted"):
        check(Target(check_fails=True), solution(1e-4))


def test_a_robot_error_twenty_times_the_prior_is_a_misfit_unless_the_rival_is_far_worse(
    rival_leaves: Any,
) -> None:
    with pytest.raises(ModelMismatch, match="20 times the robot's stated error"):
        check(Target(), solution(1e-4, robot_excess=20.0))
    rival_leaves["distance_m"] = 5e-3
    check(Target(), solution(1e-4, robot_excess=20.0))


def test_a_rival_that_cannot_calibrate_is_not_a_winner() -> None:
    assert rivals._rival_solution("sphere", [], SolveContext(), None, Extractions(0)) is None


def refuse(found: int) -> None:
    """The ball target's refusal for want of features, ``found`` of 10 showing one."""
    refusal = TooFewFeatures(
        f"only {found} of 10 recorded profiles show a ball, and at least 6 are needed. "
        "Rejected: ...",
        found,
    )
    rivals.refuse_without_fit(Target(), [], refusal, SolveContext(n_samples=10))  # type: ignore[arg-type]


def test_too_few_features_name_only_a_rival_that_explains_clearly_more(rival_leaves: Any) -> None:
    refuse(found=0)  # no rival could be fitted: the ball's own refusal stands
    rival_leaves["distance_m"] = 2e-5
    with pytest.raises(ModelMismatch) as refused:
        refuse(found=2)
    text = str(refused.value)
    assert "only 2 of 10 recorded profiles show a ball, and at least 6 are needed; but" in text
    assert "the tube fitted with the poses explains 10 of the 10 recorded profiles and " in text
    assert "leaves 20.0 um RMS" in text and "choose {setting:target} tube" in text
    refuse(found=6)  # the tube explains fewer than twice as many profiles
    rival_leaves["check_fails"] = True
    refuse(found=0)  # the tube's fit fails its own check: it explains nothing


def _samples(recording: str) -> tuple[list[Any], PairingConfig]:
    """Paired samples of a small simulated recording, and its pairing: a straight seam swept
    in motion (``line``), one weld point (``known_point``) or a ball (``sphere``)."""
    if recording == "line":
        scenario = line_scenario_from_preset(
            "line", n_poses=12, resolution=640, profile_rate_hz=10.0
        )
        data: Any = simulate_line(scenario, 3)
        pairing = PairingConfig(
            max_linear_speed_m_s=0.0,
            max_angular_speed_rad_s=0.0,
            clock_offset_s=-scenario.rig.latency_s,
        )
    elif recording == "known_point":
        data, pairing = simulate_weld(weld_scenario_from_preset("weld_seam_general"), 3), None
    else:
        data = simulate_sphere(sphere_scenario_from_preset("sphere", n_poses=8), 3)
        pairing = None
    pairing = pairing or PairingConfig()
    return pair_profiles(data.profiles, data.poses, pairing).samples, pairing


def _refusal(recording: str, target: str) -> str:
    samples, pairing = _samples(recording)
    config = pipeline_config(target, Method.DEFAULT, {}, Front.CLI, pairing=pairing)
    with pytest.raises(ModelMismatch) as refused:
        calibrate_samples(samples, replace(config, self_check_folds=0))
    return str(refused.value)


def test_a_line_sweep_given_to_the_known_point_is_refused_naming_the_line() -> None:
    text = _refusal("line", "known_point")
    line = re.search(r"the straight line fitted with the poses leaves ([0-9.]+) um RMS", text)
    point = re.search(r"the known point fitted with the poses leaves ([0-9.]+) um RMS", text)
    assert line is not None and point is not None, text
    assert 10.0 * float(line[1]) < float(point[1]) and "choose {setting:target} line" in text


def test_one_weld_point_given_to_the_line_is_refused_naming_the_known_point() -> None:
    """A line through one point explains the corners as well as the point does; the simpler
    model is named, with both whole-recording figures."""
    text = _refusal("known_point", "line")
    assert "one point explains them to" in text and "{setting:target} known_point" in text
    assert "the known point fitted with the poses leaves" in text
    assert "the straight line fitted with the poses leaves" in text


def test_a_balls_arcs_given_to_the_line_are_refused_naming_the_sphere() -> None:
    text = _refusal("sphere", "line")
    assert "only 0 of 8 recorded profiles show a seam corner" in text
    assert "the sphere fitted with the poses explains 8 of the 8 recorded profiles" in text
    assert "choose {setting:target} sphere" in text


def test_each_profile_is_extracted_once_where_a_rival_is_judged_at_its_own_clock_offset(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """One weld point given to the cylinder with the clock offset estimated: the cylinder's
    offset search, then the rivals, the line searched at its own offset and fitted there.
    Every target extracts each profile once (the line's corners were extracted twice: for
    its search and for its fit)."""
    extracted: Counter[tuple[str, int]] = Counter()
    for name in target_names():
        kind = type(get_target(name))

        def counted(self: Any, samples: Any, *args: Any, _extract: Any = kind.extract) -> Any:
            extracted.update((self.name, s.index) for s in samples)
            return _extract(self, samples, *args)

        monkeypatch.setattr(kind, "extract", counted)
    config = pipeline_config("cylinder", Method.DEFAULT, {}, Front.CLI)
    with pytest.raises(ModelMismatch) as refused:
        calibrate_bag(BAGS / "weld_seam", config, estimate_offset=True)
    assert "the straight line fitted with the poses at its own clock offset" in str(refused.value)
    assert {name for name, _ in extracted} == {"cylinder", "known_point", "sphere", "line"}
    assert set(extracted.values()) == {1}, extracted


@dataclass
class Seam:
    """A stand-in target whose features re-pair (``with_samples``) or not."""

    name: str
    repairs: bool
    calls: int = 0

    def extract(self, samples: list[Any], config: Any, seed: int, *_: Any) -> Any:
        self.calls += 1
        features = [
            SampleFit(k.index, k.stamp_ns, k.T_base_flange, k.points, ORIGIN) for k in samples
        ]
        return features, [Rejection(-1, 0, "corner", "stand-in")]

    def __getattr__(self, name: str) -> Any:
        if name == "with_samples" and self.repairs:
            return lambda features, samples: [
                replace(f, T_base_flange=s.T_base_flange)
                for f, s in zip(features, samples, strict=True)
            ]
        raise AttributeError(name)


def test_the_runs_store_re_pairs_the_profiles_it_holds_and_extracts_the_rest() -> None:
    samples = [Sample(k, k, np.eye(4), np.zeros((3, 3))) for k in range(4)]
    moved = [replace(s, T_base_flange=np.diag([1.0, 1.0, 1.0, 2.0])) for s in samples[1:]]
    store, seam = Extractions(seed=0), Seam("seam", repairs=True)
    store.of(seam, "config", samples)  # type: ignore[arg-type]
    features, rejections = store.of(seam, "config", moved)  # type: ignore[arg-type]
    assert seam.calls == 1 and [f.index for f in features] == [1, 2, 3] and not rejections
    assert all(f.T_base_flange[3, 3] == 2.0 for f in features)
    store.of(seam, "other config", moved)  # type: ignore[arg-type]
    assert seam.calls == 2
    more = [*moved, Sample(9, 9, np.eye(4), np.zeros((3, 3)))]
    store.of(seam, "other config", more)  # type: ignore[arg-type]
    assert seam.calls == 3
    fixed = Seam("fixed", repairs=False)
    store.of(fixed, "config", samples)  # type: ignore[arg-type]
    store.of(fixed, "config", samples)  # type: ignore[arg-type]
    assert fixed.calls == 2
