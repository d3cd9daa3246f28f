"""Solves shared with a forked child, and the self-check's subset solves started at the full
solve: the same outcomes as one process solving each subset from its own seed."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.core.errors import CalibrationError, DegenerateError
from linelaser_calib.core.forked import available_workers, map_forked
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pairing import pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.targets.base import SolveContext
from linelaser_calib.core.types import Sample
from linelaser_calib.io.bags import read_bag

PAPER_BAG = Path(__file__).resolve().parent.parent / "bags" / "paper"


def seeded_mean(item: int) -> float:
    """A deterministic computation of one item; items divisible by 3 are refused."""
    if item % 3 == 0:
        raise DegenerateError(f"item {item} refused")
    return float(np.mean(np.random.default_rng(item).normal(size=1000)))


def assert_no_child_left() -> None:
    with pytest.raises(ChildProcessError):
        os.waitpid(-1, os.WNOHANG)


def assert_same_outcomes(
    got: list[float | CalibrationError], expected: list[float | CalibrationError]
) -> None:
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        if isinstance(b, CalibrationError):
            assert type(a) is type(b) and str(a) == str(b)
        else:
            assert isinstance(a, float) and a == pytest.approx(b, rel=1e-12)


def test_a_forked_child_gives_the_outcomes_of_one_process_in_order() -> None:
    items = list(range(1, 12))
    serial = map_forked(seeded_mean, items, workers=1)
    assert sum(isinstance(o, DegenerateError) for o in serial) == 3
    assert_same_outcomes(map_forked(seeded_mean, items, workers=2), serial)
    assert_no_child_left()


def test_a_failing_child_costs_only_time() -> None:
    """A child that fails (here: an error that is not a CalibrationError, in the child only)
    leaves its items to this process."""
    parent = os.getpid()

    def fails_in_the_child(item: int) -> float:
        if os.getpid() != parent:
            raise RuntimeError("child failure")
        return seeded_mean(item)

    items = list(range(1, 8))
    assert_same_outcomes(
        map_forked(fails_in_the_child, items, workers=2), map_forked(seeded_mean, items)
    )
    assert_no_child_left()


def test_available_workers_is_one_or_two() -> None:
    assert available_workers() in (1, 2)


@pytest.fixture(scope="module")
def paper_samples() -> tuple[PipelineConfig, list[Sample]]:
    config = PipelineConfig()
    bag = read_bag(PAPER_BAG)
    return config, pair_profiles(bag.profiles, bag.poses, config.pairing).samples


def test_a_subset_solve_started_at_the_full_solve_equals_one_from_its_own_seed(
    paper_samples: tuple[PipelineConfig, list[Sample]],
) -> None:
    config, samples = paper_samples
    target, target_config = config.target_impl, config.target_config
    features, _ = target.extract(samples, target_config, config.seed, lambda *_: None)
    context = SolveContext(seed=config.seed, n_samples=len(features))
    full = target.solve_default(features, target_config, context)
    subset = features[1::3] + features[2::3]
    cold = target.solve_default(subset, target_config, context)
    warm = target.solve_default(subset, target_config, replace(context, warm_start=full))
    rotation, translation = transform_error(cold.T_flange_sensor, warm.T_flange_sensor)
    assert rotation < 1e-9 and translation < 1e-9
    assert cold.samples_used == warm.samples_used
    assert cold.sigma_translation_m is not None and warm.sigma_translation_m is not None
    np.testing.assert_allclose(warm.sigma_translation_m, cold.sigma_translation_m, rtol=1e-6)


def test_the_self_check_with_a_forked_child_equals_one_process(
    paper_samples: tuple[PipelineConfig, list[Sample]],
) -> None:
    config, samples = paper_samples
    one = calibrate_samples(samples, config)
    two = calibrate_samples(samples, replace(config, workers=2))
    assert one.self_check is not None and two.self_check is not None
    assert two.self_check.accuracy_in_use_m == pytest.approx(
        one.self_check.accuracy_in_use_m, rel=1e-9
    )
    np.testing.assert_allclose(two.self_check.sigma_jackknife, one.self_check.sigma_jackknife)
    np.testing.assert_allclose(two.uncertainty_translation_m, one.uncertainty_translation_m)
    assert two.self_check.indices == one.self_check.indices
    assert_no_child_left()
