"""Tests of the paper's centre-to-axis model (eq. 6-12) against truth geometry."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
from _synthetic_centres import paper_setup, random_setup, synthetic_centres

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.geometry import check_rotation
from linelaser_calib.core.targets.cylinder.model import (
    CentreAxisProblem,
    calibration_from_x,
    centre_distances,
    constraints,
    constraints_jacobian,
    x_from_calibration,
)


def _problem(
    seed: int, normalised: bool = True, n_poses: int = 30
) -> tuple[CentreAxisProblem, np.ndarray]:
    """A noise-free random problem and its true x (internal units)."""
    rng = np.random.default_rng(seed)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, n_poses, rng)
    problem = CentreAxisProblem.from_data(
        data.centres_xz, data.T_base_flange, normalised=normalised
    )
    return problem, x_from_calibration(T, cyl, problem.unit_m)


def _numeric_gradient(fun, x: np.ndarray, step: float = 1e-6) -> np.ndarray:
    return np.array([(fun(x + step * e) - fun(x - step * e)) / (2 * step) for e in np.eye(x.size)])


def _eq9(problem: CentreAxisProblem, x: np.ndarray) -> float:
    """Eq. 9 evaluated literally, one centre at a time."""
    total = 0.0
    for c, R, p in zip(problem.centres_xz, problem.rotations, problem.positions, strict=True):
        w = R @ (c[0] * x[0:3] + c[1] * x[3:6] + x[6:9]) + p - x[9:12]
        total += w @ w - (x[12:15] @ w) ** 2
    return total


@pytest.mark.parametrize("normalised", [True, False])
def test_gradient_matches_finite_differences(normalised: bool) -> None:
    rng = np.random.default_rng(1)
    for seed in range(4):
        problem, x_true = _problem(seed, normalised)
        x = x_true + rng.normal(scale=0.3, size=15)
        f, grad = problem.cost_and_gradient(x)
        numeric = _numeric_gradient(problem.cost, x)
        assert f == pytest.approx(float(problem.cost(x)), rel=1e-12)
        np.testing.assert_allclose(grad, numeric, rtol=1e-6, atol=1e-6 * np.abs(numeric).max())


def test_literal_cost_is_eq9_and_normalised_equals_it_on_the_constraint_surface() -> None:
    rng = np.random.default_rng(2)
    literal, x_true = _problem(3, normalised=False)
    normalised = CentreAxisProblem(
        literal.centres_xz, literal.rotations, literal.positions, literal.unit_m, True
    )
    x = x_true + rng.normal(scale=0.2, size=15)
    assert float(literal.cost(x)) == pytest.approx(_eq9(literal, x), rel=1e-10)
    x[12:15] /= np.linalg.norm(x[12:15])
    assert float(normalised.cost(x)) == pytest.approx(float(literal.cost(x)), rel=1e-10)


def test_cost_vanishes_at_truth_and_swarm_evaluation_matches_single() -> None:
    rng = np.random.default_rng(4)
    problem, x_true = _problem(5)
    assert float(problem.cost(x_true)) < 1e-24
    assert np.max(problem.distances_m(x_true)) < 1e-12
    swarm = x_true + rng.normal(scale=0.5, size=(7, 15))
    np.testing.assert_allclose(
        problem.cost(swarm), [float(problem.cost(x)) for x in swarm], rtol=1e-12
    )


def test_centre_distances_measure_offsets_from_the_axis() -> None:
    rng = np.random.default_rng(14)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, 12, rng)
    assert np.max(centre_distances(data.centres_xz, data.T_base_flange, T, cyl)) < 1e-12
    shift = np.cross(cyl.direction, [0.0, 0.0, 1.0])  # perpendicular to the axis
    moved = replace(cyl, point=cyl.point + 0.003 * shift / np.linalg.norm(shift))
    np.testing.assert_allclose(
        centre_distances(data.centres_xz, data.T_base_flange, T, moved), 0.003, rtol=1e-9
    )


def test_centres_in_base_follow_eq6() -> None:
    rng = np.random.default_rng(6)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, 10, rng)
    problem = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange, unit_m=1.0)
    centres_base = problem.centres_in_base(x_from_calibration(T, cyl))
    for j in range(10):
        p_sensor = np.array([data.centres_xz[j, 0], 0.0, data.centres_xz[j, 1], 1.0])
        np.testing.assert_allclose(
            centres_base[j], (data.T_base_flange[j] @ T @ p_sensor)[:3], atol=1e-12
        )


def test_constraints_and_jacobian() -> None:
    rng = np.random.default_rng(7)
    x = rng.normal(size=15)
    h = constraints(x)
    np.testing.assert_allclose(
        h, [x[0:3] @ x[0:3] - 1, x[3:6] @ x[3:6] - 1, x[12:15] @ x[12:15] - 1]
    )
    numeric = np.array(
        [(constraints(x + 1e-6 * e) - constraints(x - 1e-6 * e)) / 2e-6 for e in np.eye(15)]
    ).T
    np.testing.assert_allclose(constraints_jacobian(x), numeric, atol=1e-8)
    assert constraints(np.stack([x, 2 * x])).shape == (2, 3)
    _, x_true = _problem(8)
    np.testing.assert_allclose(constraints(x_true), 0.0, atol=1e-12)


def test_literal_cost_is_unbounded_below_while_normalised_stays_nonnegative() -> None:
    """The trap: |N| slightly above 1 and the axis point sliding away sends eq. 12 to -inf."""
    literal, x_true = _problem(9, normalised=False)
    normalised = CentreAxisProblem(
        literal.centres_xz, literal.rotations, literal.positions, literal.unit_m, True
    )
    n = x_true[12:15]
    costs_literal, costs_normalised = [], []
    for slide in [0.0, 1e1, 1e2, 1e3, 1e4]:
        x = x_true.copy()
        x[12:15] = 1.01 * n  # violates |N| = 1 by 2 %
        x[9:12] = x_true[9:12] - slide * n
        costs_literal.append(float(literal.cost(x)))
        costs_normalised.append(float(normalised.cost(x)))
    assert all(b < a for a, b in itertools.pairwise(costs_literal))
    assert costs_literal[-1] < -1e6
    assert min(costs_normalised) >= 0.0
    assert max(costs_normalised) < 1e-20


def test_calibration_round_trip_and_handedness() -> None:
    rng = np.random.default_rng(10)
    for _ in range(5):
        T, cyl = random_setup(rng)
        T_back, cyl_back = calibration_from_x(x_from_calibration(T, cyl, 0.1), 0.1)
        np.testing.assert_allclose(T_back, T, atol=1e-12)
        np.testing.assert_allclose(cyl_back.direction, cyl.direction, atol=1e-12)
        # the returned point is on the true axis and closest to the base origin
        w = cyl_back.point - cyl.point
        assert np.linalg.norm(w - (w @ cyl.direction) * cyl.direction) < 1e-12
        assert abs(cyl_back.point @ cyl_back.direction) < 1e-12
        assert np.isnan(cyl_back.radius)


def test_perturbed_x_gives_a_proper_rotation_with_a2_from_a3_cross_a1() -> None:
    rng = np.random.default_rng(11)
    T, cyl = random_setup(rng)
    x = x_from_calibration(T, cyl) + rng.normal(scale=0.01, size=15)
    R = calibration_from_x(x)[0][:3, :3]
    check_rotation(R, 1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert np.degrees(np.arccos((np.trace(R.T @ T[:3, :3]) - 1) / 2)) < 3.0


def test_internal_unit_scales_cost_and_keeps_distances() -> None:
    rng = np.random.default_rng(12)
    T, cyl = paper_setup()
    data = synthetic_centres(T, cyl, 20, rng, robot_sigma_m=1e-4)
    in_m = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange, unit_m=1.0)
    in_mm = CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange, unit_m=1e-3)
    x_m = x_from_calibration(T, cyl, 1.0)
    x_mm = x_from_calibration(T, cyl, 1e-3)
    assert float(in_mm.cost(x_mm)) == pytest.approx(float(in_m.cost(x_m)) * 1e6, rel=1e-9)
    np.testing.assert_allclose(in_mm.distances_m(x_mm), in_m.distances_m(x_m), rtol=1e-9)


def test_bad_inputs_raise_package_errors() -> None:
    rng = np.random.default_rng(13)
    T, cyl = random_setup(rng)
    data = synthetic_centres(T, cyl, 8, rng)
    with pytest.raises(InputError, match="shape"):
        CentreAxisProblem.from_data(data.centres_xz[:, :1], data.T_base_flange)
    with pytest.raises(InputError, match="to match"):
        CentreAxisProblem.from_data(data.centres_xz, data.T_base_flange[:-1])
    with pytest.raises(InputError, match="at least"):
        CentreAxisProblem.from_data(data.centres_xz[:3], data.T_base_flange[:3])
    bad = data.centres_xz.copy()
    bad[2, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        CentreAxisProblem.from_data(bad, data.T_base_flange)
    skewed = data.T_base_flange.copy()
    skewed[1, :3, :3] *= 1.1
    with pytest.raises(InputError, match=r"T_base_flange\[1\]"):
        CentreAxisProblem.from_data(data.centres_xz, skewed)
    same_orientation = data.T_base_flange.copy()
    same_orientation[:, :3, :3] = data.T_base_flange[0, :3, :3]
    with pytest.raises(DegenerateError, match="orientations"):
        CentreAxisProblem.from_data(data.centres_xz, same_orientation)
    x = x_from_calibration(T, cyl)
    x[3:6] = x[0:3]
    with pytest.raises(DegenerateError, match="parallel"):
        calibration_from_x(x)
    with pytest.raises(InputError):
        calibration_from_x(np.zeros(14))
