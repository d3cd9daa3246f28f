"""Tests of GALM, PSO and the PSO+GALM hybrid against known optima and truth geometry."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from _compare import assert_floats_close, assert_trees_close
from _synthetic_centres import MM, axis_errors, paper_setup, random_setup, synthetic_centres

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.targets.cylinder.galm import GalmConfig, galm
from linelaser_calib.core.targets.cylinder.model import CentreAxisProblem, x_from_calibration
from linelaser_calib.core.targets.cylinder.pso import PsoConfig, pso
from linelaser_calib.core.targets.cylinder.pso_alm import HybridConfig, search_box, solve_pso_galm


@dataclass(frozen=True)
class _CircleProblem:
    """min x1 + x2 s.t. x1² + x2² = 2: optimum (-1, -1) with multiplier -1/2."""

    def cost(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(np.sum(np.atleast_2d(x), axis=-1))

    def cost_and_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        return float(np.sum(x)), np.ones(2)

    def constraints(self, x: np.ndarray) -> np.ndarray:
        return np.sum(np.asarray(x) ** 2, axis=-1, keepdims=True) - 2.0

    def constraints_jacobian(self, x: np.ndarray) -> np.ndarray:
        return 2.0 * np.asarray(x)[None, :]


def test_galm_solves_a_textbook_equality_constrained_problem() -> None:
    result = galm([2.0, 0.5], _CircleProblem(), GalmConfig(sigma0=1.0))
    assert result.converged and not result.diverged
    np.testing.assert_allclose(result.x, [-1.0, -1.0], atol=1e-8)
    np.testing.assert_allclose(result.multipliers, [-0.5], atol=1e-6)
    assert result.f == pytest.approx(-2.0, abs=1e-8)
    assert len(result.history_f) == result.iterations


def test_galm_converges_to_the_true_cylinder_from_near_truth() -> None:
    rng = np.random.default_rng(20)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, 30, rng)
    problem = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange)
    x_true = x_from_calibration(T, cyl, problem.unit_m)
    result = galm(x_true + rng.normal(scale=0.05, size=15), problem)
    assert result.converged and not result.diverged
    assert result.h_norm <= GalmConfig().epsilon
    assert result.f < 1e-16
    np.testing.assert_allclose(result.x[:9], x_true[:9], atol=1e-7)


def test_galm_on_the_literal_cost_diverges_and_is_flagged() -> None:
    """Table 3's "GALM alone diverges": eq. 12 as printed is unbounded below."""
    rng = np.random.default_rng(21)
    T, cyl = paper_setup()
    data = synthetic_centres(T, cyl, 30, rng)
    problem = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange, normalised=False)
    lower, upper = search_box(problem, HybridConfig(box="paper"))
    result = galm(rng.uniform(lower, upper), problem)
    assert result.diverged and not result.converged
    assert result.phi < -GalmConfig().divergence_cost or np.abs(result.x).max() > 1e5


def test_pso_finds_the_minimum_of_sphere_and_rosenbrock() -> None:
    config = PsoConfig(n_particles=30, max_generations=400, psi=1e-10, stagnation_generations=0)
    sphere = pso(
        lambda X: np.sum((X - 0.3) ** 2, axis=1),
        -np.ones(6),
        np.ones(6),
        config,
        np.random.default_rng(22),
    )
    np.testing.assert_allclose(sphere.x, 0.3, atol=1e-4)
    assert sphere.fitness < 1e-10
    assert sphere.history == sorted(sphere.history, reverse=True)
    rosenbrock = pso(
        lambda X: (1 - X[:, 0]) ** 2 + 100 * (X[:, 1] - X[:, 0] ** 2) ** 2,
        [-2.0, -1.0],
        [2.0, 3.0],
        config,
        np.random.default_rng(23),
    )
    np.testing.assert_allclose(rosenbrock.x, [1.0, 1.0], atol=1e-3)


@pytest.mark.parametrize("faithful", [False, True])
def test_hybrid_recovers_the_paper_setup_exactly_from_no_guess(faithful: bool) -> None:
    """§4.1.1 set-up (axis eq. 16, T_EL eq. 17), noise-free; faithful mode uses Table 2's box."""
    T, cyl = paper_setup()
    data = synthetic_centres(T, cyl, 50, np.random.default_rng(24))
    config = HybridConfig(faithful=faithful, box="paper" if faithful else "data")
    solution = solve_pso_galm(data.centres_xz, data.T_base_flange, config, np.random.default_rng(0))
    rotation_error, translation_error = transform_error(solution.T_flange_sensor, T)
    assert rotation_error < 1e-7 and translation_error < 1e-7 * MM
    angle, distance = axis_errors(solution.cylinder, cyl)
    assert angle < 1e-7 and distance < 1e-7 * MM
    assert solution.accepted and solution.f_m2 < 1e-9 * MM**2
    assert solution.history["pso_best"] and solution.history["galm_phi"]


def test_hybrid_recovers_random_setups_exactly_from_no_guess() -> None:
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        T, cyl = random_setup(rng)
        data = synthetic_centres(T, cyl, 25, rng, azimuth_spread_deg=40.0)
        solution = solve_pso_galm(data.centres_xz, data.T_base_flange, rng=rng)
        rotation_error, translation_error = transform_error(solution.T_flange_sensor, T)
        assert rotation_error < 1e-8 and translation_error < 1e-9, seed
        assert axis_errors(solution.cylinder, cyl)[1] < 1e-9, seed
        assert solution.rms_m < 1e-9 and solution.h_norm < 1e-12


def test_hybrid_with_paper_noise_stays_near_truth() -> None:
    """Robot 0.1 mm and sensor 5 µm (1 sigma): errors stay at the noise scale."""
    T, cyl = paper_setup()
    rng = np.random.default_rng(25)
    data = synthetic_centres(T, cyl, 50, rng, robot_sigma_m=0.1 * MM, sensor_sigma_m=5e-3 * MM)
    solution = solve_pso_galm(data.centres_xz, data.T_base_flange, rng=rng)
    rotation_error, translation_error = transform_error(solution.T_flange_sensor, T)
    assert np.degrees(rotation_error) < 1.0 and translation_error < 2.0 * MM
    assert 0.05 * MM < solution.rms_m < 0.3 * MM
    assert solution.accepted


def test_hybrid_is_deterministic_given_the_generator() -> None:
    rng = np.random.default_rng(26)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, 20, rng, robot_sigma_m=0.05 * MM)
    a = solve_pso_galm(data.centres_xz, data.T_base_flange, rng=np.random.default_rng(5))
    b = solve_pso_galm(data.centres_xz, data.T_base_flange, rng=np.random.default_rng(5))
    assert_floats_close(a.x, b.x)
    assert_trees_close(a.history, b.history)


def test_data_box_contains_the_truth() -> None:
    for seed in range(20):
        rng = np.random.default_rng(200 + seed)
        T, cyl = random_setup(rng)
        data = synthetic_centres(T, cyl, 10, rng)
        problem = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange)
        lower, upper = search_box(problem, HybridConfig())
        x_true = x_from_calibration(T, cyl, problem.unit_m)
        centre_on_axis = problem.centres_in_base(x_true)[0]  # a stretch of the axis is inside
        inside = np.concatenate([x_true[:9], centre_on_axis, x_true[12:]])
        assert np.all((lower <= inside) & (inside <= upper)), seed


def test_invalid_configurations_raise_input_error() -> None:
    with pytest.raises(InputError, match="eta"):
        GalmConfig(eta=0.5)
    with pytest.raises(InputError, match="particles"):
        PsoConfig(n_particles=1)
    with pytest.raises(InputError, match="box"):
        HybridConfig(box="anywhere")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="search box"):
        pso(lambda X: X[:, 0], [1.0], [0.0], PsoConfig(), np.random.default_rng(0))


def test_accept_early_seed_stops_at_the_first_accepted_polish() -> None:
    """The default method's seed: same answer as the full hybrid on clean data, far fewer
    generations, and never combined with the faithful mode."""
    T, cyl = paper_setup()
    data = synthetic_centres(T, cyl, 40, np.random.default_rng(31))
    full = solve_pso_galm(
        data.centres_xz, data.T_base_flange, HybridConfig(), np.random.default_rng(1)
    )
    early = solve_pso_galm(
        data.centres_xz,
        data.T_base_flange,
        HybridConfig(accept_early=True),
        np.random.default_rng(1),
    )
    assert early.accepted and early.generations <= full.generations
    rotation_error, translation_error = transform_error(early.T_flange_sensor, T)
    assert rotation_error < 1e-7 and translation_error < 1e-7 * MM
    with pytest.raises(InputError):
        HybridConfig(accept_early=True, faithful=True)


@dataclass(frozen=True)
class _Ellipse:
    semi_axes: tuple[float, float]
    short: bool = False


@dataclass(frozen=True)
class _Centre:
    """A fitted profile as the seed solve reads it: its ellipse, centre and flange pose."""

    ellipse: _Ellipse
    centre: np.ndarray
    T_base_flange: np.ndarray

    def centre_xz(self, radius_m: float) -> np.ndarray:
        return self.centre


def test_default_seed_of_a_long_recording_uses_a_bounded_spread_of_centres(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Regression (issue 32, continuous 4,000 poses): the seed's PSO + GALM ran over every
    centre of a long recording. It now takes at most SEED_MOST_CENTRES, spread over the
    whole recording, and still lands next to the truth."""
    from linelaser_calib.core.targets.base import SolveContext
    from linelaser_calib.core.targets.cylinder import target as cylinder_target

    T, cyl = paper_setup()
    n = 3 * cylinder_target.SEED_MOST_CENTRES
    data = synthetic_centres(
        T, cyl, n, np.random.default_rng(5), robot_sigma_m=0.1 * MM, sensor_sigma_m=0.05 * MM
    )
    features = [
        _Centre(_Ellipse((0.04, 0.02)), c, Tb)
        for c, Tb in zip(data.centres_xz, data.T_base_flange, strict=True)
    ]
    seen: list[np.ndarray] = []

    def spy(centres: np.ndarray, *args: object) -> object:
        seen.append(np.asarray(centres))
        return solve_pso_galm(centres, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(cylinder_target, "solve_pso_galm", spy)
    config = cylinder_target.CylinderConfig(radius_m=0.02)
    seed = cylinder_target.TARGET._seed(features, config, SolveContext(), paper=False)  # type: ignore[arg-type]
    (centres,) = seen
    assert len(centres) == cylinder_target.SEED_MOST_CENTRES
    assert_floats_close(centres[[0, -1]], data.centres_xz[[0, -1]], atol=0.0)
    rotation_error, translation_error = transform_error(seed.T_flange_sensor, T)
    assert rotation_error < np.radians(0.1) and translation_error < 0.5 * MM
