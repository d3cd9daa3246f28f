"""Tests of the cylinder's maximum-likelihood refinement (core/targets/cylinder/refine.py), its
block form for the shared solver (core/solver) and its observability check."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from _cylinder_points import Scene, make_scene, perturbed_start

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.geometry import (
    FloatArray,
    matrix_from_rotvec,
    rotvec_from_matrix,
    transform_error,
)
from linelaser_calib.core.solver import normal_equations, solve_damped
from linelaser_calib.core.solver.lm import linearised
from linelaser_calib.core.targets.cylinder.config import RefineConfig
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.problem import build_problem, initial_state
from linelaser_calib.core.targets.cylinder.refine import (
    RefineResult,
    refine,
    refine_with_outlier_rejection,
)

RADIUS = 0.02
NOISE_FREE: dict[str, Any] = {"sensor_sigma": 0.0, "robot_sigma_t": 0.0, "robot_sigma_r": 0.0}


def scene_and_start(seed: int, **kwargs: Any) -> tuple[Scene, FloatArray, Cylinder]:
    rng = np.random.default_rng(seed)
    scene = make_scene(rng, **kwargs)
    T0, cylinder0 = perturbed_start(rng, scene)
    return scene, T0, cylinder0


def hand_eye_error(result: RefineResult, scene: Scene) -> FloatArray:
    """[θ (rad, sensor axes), ρ (m, flange axes)] with truth = estimate ∘ (Exp θ, +ρ)."""
    T, truth = result.T_flange_sensor, scene.T_flange_sensor
    return np.concatenate(
        [rotvec_from_matrix(T[:3, :3].T @ truth[:3, :3]), truth[:3, 3] - T[:3, 3]]
    )


def axis_error(result: RefineResult, scene: Scene) -> tuple[float, float]:
    """Angle between the axes (rad) and distance of the estimated point from the true axis (m)."""
    d, d_true = result.cylinder.direction, scene.cylinder.direction
    w = result.cylinder.point - scene.cylinder.point
    angle = float(np.arccos(min(1.0, abs(float(d @ d_true)))))
    return angle, float(np.linalg.norm(w - (w @ d_true) * d_true))


@pytest.mark.parametrize("estimate_radius", [False, True])
def test_noise_free_data_is_recovered_exactly(estimate_radius: bool) -> None:
    rng = np.random.default_rng(1)
    scene = make_scene(rng, n_poses=20, n_points=100, **NOISE_FREE)
    T0, cylinder0 = perturbed_start(rng, scene, radius_offset=5e-4 if estimate_radius else 0.0)
    result = refine(
        scene.points,
        scene.T_base_flange,
        T0,
        cylinder0,
        radius_m=None if estimate_radius else RADIUS,
    )
    rotation, translation = transform_error(result.T_flange_sensor, scene.T_flange_sensor)
    assert rotation < 1e-9 and translation < 1e-9
    angle, distance = axis_error(result, scene)
    assert angle < 1e-9 and distance < 1e-9
    assert abs(result.cylinder.radius - RADIUS) < 1e-9
    assert result.radius_estimated is estimate_radius
    assert result.converged
    assert np.max(np.abs(result.pose_corrections)) < 1e-9
    # The reported axis point is the one closest to the base origin.
    assert abs(float(result.cylinder.point @ result.cylinder.direction)) < 1e-12


@pytest.mark.parametrize("scales", [(False, False), (True, False), (True, True)])
def test_jacobian_matches_finite_differences(scales: tuple[bool, bool]) -> None:
    """With a scale estimated the residuals are kept in measured units (their stretch's
    shares of the noise), whose derivative the scale columns carry too."""
    rng = np.random.default_rng(2)
    scene = make_scene(rng, n_poses=6, n_points=15)
    # Unequal profile lengths exercise the padded layout (padding rows must stay zero).
    points = [p[: 10 + j] for j, p in enumerate(scene.points)]
    config = RefineConfig(estimate_scale=scales[0], estimate_depth_scale=scales[1])
    problem = build_problem(points, scene.T_base_flange, config, True)
    T0, cylinder0 = perturbed_start(rng, scene, radius_offset=1e-3)
    state = initial_state(problem, T0, cylinder0, cylinder0.radius)
    problem = problem.with_scale_shares(state)
    assert (problem.scale_shares is not None) is scales[0]
    # Evaluate away from zero corrections (and scales) so that the right Jacobian of Exp and
    # the scaled points matter.
    start_step = np.zeros(problem.n_global)
    for index, value in ((problem.scale_index, 0.01), (problem.depth_scale_index, -0.02)):
        if index is not None:
            start_step[index] = value
    state = problem.retract(
        state,
        start_step,
        np.hstack([rng.normal(0.0, 0.05, (6, 3)), rng.normal(0.0, 2e-3, (6, 3))]),
    )
    assert state.scale == pytest.approx(0.01 if scales[0] else 0.0)
    linearisation = problem.linearise(state)
    J_global, J_local = linearisation.J_global, linearisation.J_local

    def residuals(step_global: FloatArray, step_local: FloatArray) -> FloatArray:
        moved = problem.retract(state, step_global, step_local)
        return problem.residuals(moved).points.ravel()

    h = 1e-7
    for k in range(problem.n_global):
        step = np.zeros(problem.n_global)
        step[k] = h
        numeric = (residuals(step, np.zeros((6, 6))) - residuals(-step, np.zeros((6, 6)))) / (2 * h)
        np.testing.assert_allclose(
            J_global[..., k].ravel(), numeric, rtol=1e-5, atol=1e-5 * np.abs(numeric).max()
        )
    for k in range(6):
        step = np.zeros((6, 6))
        step[:, k] = h
        numeric = (
            residuals(np.zeros(problem.n_global), step)
            - residuals(np.zeros(problem.n_global), -step)
        ) / (2 * h)
        np.testing.assert_allclose(
            J_local[..., k].ravel(), numeric, rtol=1e-5, atol=1e-5 * np.abs(numeric).max()
        )


def test_a_problem_of_every_sample_in_order_shares_the_arrays_a_subset_copies() -> None:
    # The held and plain re-solves take every sample of the solved problem: no second copy
    # of a long recording's padded points; a subset is its own.
    scene = make_scene(np.random.default_rng(8), n_poses=7, n_points=20)
    points = [p[: 12 + j] for j, p in enumerate(scene.points)]
    problem = build_problem(points, scene.T_base_flange, RefineConfig(), True)
    assert problem.take(np.arange(7)) is problem
    subset = problem.take(np.array([4, 1]))
    assert not np.shares_memory(subset.points, problem.points)
    np.testing.assert_array_equal(subset.counts, [16, 13])
    np.testing.assert_array_equal(subset.points[1, :13], points[1])


def test_schur_solve_equals_dense_solve() -> None:
    rng = np.random.default_rng(3)
    scene = make_scene(rng, n_poses=7, n_points=20)
    points = [p[: 12 + j] for j, p in enumerate(scene.points)]
    problem = build_problem(points, scene.T_base_flange, RefineConfig(), True)
    T0, cylinder0 = perturbed_start(rng, scene)
    state = initial_state(problem, T0, cylinder0, RADIUS)
    normal = normal_equations(problem.linearise(state), RefineConfig().solver)
    damping = 1e-3
    step_global, step_local = solve_damped(normal, damping)

    G, M = problem.n_global, problem.n_samples
    H = np.zeros((G + 6 * M, G + 6 * M))
    H[:G, :G] = normal.A
    C = normal.C()
    for j in range(M):
        rows = slice(G + 6 * j, G + 6 * j + 6)
        H[:G, rows] = normal.B[j]
        H[rows, :G] = normal.B[j].T
        H[rows, rows] = C[j]
    g = np.concatenate([normal.g_global, normal.g_local.ravel()])
    dense = np.linalg.solve(H + damping * np.diag(np.diag(H)), -g)
    np.testing.assert_allclose(step_global, dense[:G], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(step_local.ravel(), dense[G:], rtol=1e-6, atol=1e-12)


def test_subset_equations_taken_from_the_whole_are_its_own() -> None:
    """A subset's solve starts from the solved problem's equations (BlockNormal.take): they
    must be those of linearising the subset alone at the same state."""
    rng = np.random.default_rng(4)
    scene = make_scene(rng, n_poses=9, n_points=30)
    problem = build_problem(scene.points, scene.T_base_flange, RefineConfig(), True)
    T0, cylinder0 = perturbed_start(rng, scene)
    state = initial_state(problem, T0, cylinder0, RADIUS)
    state = replace(state, omega=rng.normal(0, 1e-4, (9, 3)), tau=rng.normal(0, 1e-4, (9, 3)))
    solver = RefineConfig().solver
    whole, residuals = linearised(problem, state, solver)
    rows = np.array([6, 0, 3, 4])
    part = replace(state, omega=state.omega[rows], tau=state.tau[rows])
    own, own_residuals = linearised(problem.take(rows), part, solver)
    taken = whole.take(rows)
    for name in ("A", "B", "C_data", "g_global", "g_local", "A_sample", "g_sample"):
        np.testing.assert_allclose(getattr(taken, name), getattr(own, name), rtol=1e-12)
    np.testing.assert_allclose(residuals.points[rows], own_residuals.points, rtol=1e-12)


def test_paper_noise_accuracy_beats_plain_least_squares() -> None:
    plain = RefineConfig(robot_sigma_t_m=1e-10, robot_sigma_r_rad=1e-10, loss="linear")
    errors, plain_errors = [], []
    for seed in range(3):
        scene, T0, cylinder0 = scene_and_start(seed, n_points=400)
        result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
        assert result.converged
        assert 0.5 < result.chi2_dof < 1.5
        errors.append(hand_eye_error(result, scene))
        baseline = refine(scene.points, scene.T_base_flange, T0, cylinder0, plain, radius_m=RADIUS)
        plain_errors.append(hand_eye_error(baseline, scene))
    E, P = np.array(errors), np.array(plain_errors)
    rms_rot = np.sqrt(np.mean(np.sum(E[:, :3] ** 2, axis=1)))
    rms_trans = np.sqrt(np.mean(np.sum(E[:, 3:] ** 2, axis=1)))
    # Targets 0.01 deg and 0.06 mm RMS over many seeds; loose bounds for three seeds.
    assert np.rad2deg(rms_rot) < 0.02
    assert rms_trans < 0.12e-3
    assert np.sqrt(np.mean(np.sum(P[:, :3] ** 2, axis=1))) > 3 * rms_rot


def test_robust_loss_resists_spikes() -> None:
    rng = np.random.default_rng(4)
    scene = make_scene(rng, n_poses=30, n_points=200)
    T0, cylinder0 = perturbed_start(rng, scene)
    spiky = []
    for p in scene.points:
        q = p.copy()
        hit = rng.random(len(q)) < 0.03
        q[hit, 2] += rng.uniform(0.2e-3, 2e-3, int(hit.sum()))
        spiky.append(q)
    robust = refine(spiky, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    linear = refine(
        spiky, scene.T_base_flange, T0, cylinder0, RefineConfig(loss="linear"), radius_m=RADIUS
    )
    clean = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    assert (
        np.linalg.norm(hand_eye_error(robust, scene)[3:])
        < 2 * np.linalg.norm(hand_eye_error(clean, scene)[3:]) + 2e-5
    )
    assert (
        transform_error(robust.T_flange_sensor, scene.T_flange_sensor)[1]
        < transform_error(linear.T_flange_sensor, scene.T_flange_sensor)[1]
    )
    assert 0.02 < float(np.mean(robust.sample_downweighted)) < 0.04  # 3 % spikes


def test_radius_estimated_or_known() -> None:
    rng = np.random.default_rng(5)
    scene = make_scene(rng, n_poses=30, n_points=200)
    T0, cylinder0 = perturbed_start(rng, scene, radius_offset=0.5e-3)
    estimated = refine(scene.points, scene.T_base_flange, T0, cylinder0)
    assert estimated.radius_estimated
    assert estimated.sigma_radius_m is not None
    assert abs(estimated.cylinder.radius - RADIUS) < max(5 * estimated.sigma_radius_m, 2e-6)
    known = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    assert not known.radius_estimated and known.sigma_radius_m is None
    assert known.cylinder.radius == RADIUS
    for result in (estimated, known):
        rotation, translation = transform_error(result.T_flange_sensor, scene.T_flange_sensor)
        assert np.rad2deg(rotation) < 0.03 and translation < 0.2e-3
    # Estimating the radius with a given start value.
    both = refine(
        scene.points,
        scene.T_base_flange,
        T0,
        cylinder0,
        RefineConfig(estimate_radius=True),
        radius_m=RADIUS + 3e-4,
    )
    assert both.radius_estimated
    assert abs(both.cylinder.radius - estimated.cylinder.radius) < 1e-8


def test_predicted_sigma_matches_spread_over_seeds() -> None:
    errors, sigmas = [], []
    for seed in range(12):
        scene, T0, cylinder0 = scene_and_start(100 + seed, n_poses=30, n_points=100)
        result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
        errors.append(hand_eye_error(result, scene))
        sigmas.append(np.concatenate([result.sigma_rotation_rad, result.sigma_translation_m]))
        np.testing.assert_allclose(np.sqrt(np.diag(result.covariance_hand_eye)), sigmas[-1])
    E, S = np.array(errors), np.array(sigmas)
    for block in (slice(0, 3), slice(3, 6)):
        empirical = np.sqrt(np.mean(E[:, block] ** 2))
        predicted = np.sqrt(np.mean(S[:, block] ** 2))
        assert 0.5 < empirical / predicted < 2.0


def test_variance_factors_follow_the_actual_noise() -> None:
    scene, T0, cylinder0 = scene_and_start(
        6,
        n_poses=40,
        n_points=200,
        sensor_sigma=10e-6,
        robot_sigma_t=2e-4,
        robot_sigma_r=float(np.deg2rad(0.02)),
    )
    result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    # Noise is added to x and z while the residual sees its normal part (about 0.9 of it).
    assert 7e-6 < result.sensor_sigma_estimated_m < 11e-6
    assert 1.6 < result.robot_sigma_scale < 2.4


@pytest.mark.parametrize(
    ("motion", "phrases"),
    [
        (
            "same_orientation",
            ["3 direction(s)", "translation of the sensor", "rotate the flange", "hardly rotates"],
        ),
        ("along_axis", ["4 direction(s)", "parallel to the cylinder axis", "rotate the flange"]),
        (
            "about_axis",
            [
                "2 direction(s)",
                "about the cylinder axis itself",
                "i.e. along the cylinder axis",
                "rotating only about the cylinder axis",
            ],
        ),
    ],
)
def test_degenerate_motions_name_the_missing_motion(motion: str, phrases: list[str]) -> None:
    scene, T0, cylinder0 = scene_and_start(7, motion=motion, n_poses=15, n_points=60)
    with pytest.raises(DegenerateError) as info:
        refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    for phrase in phrases:
        assert phrase in str(info.value)


def test_narrow_orientations_give_weak_warnings() -> None:
    scene, T0, cylinder0 = scene_and_start(8, motion="narrow", n_poses=30, n_points=100)
    result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    assert result.warnings and all("weak hand-eye direction" in w for w in result.warnings)
    assert any("rotate the flange" in w for w in result.warnings)
    assert {d.status for d in result.observability.directions} == {"weak"}


def test_diverse_poses_have_no_warnings() -> None:
    scene, T0, cylinder0 = scene_and_start(9, n_poses=30, n_points=100)
    result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    assert result.warnings == []
    assert np.all(result.observability.sigma_m < RefineConfig().observability.weak_sigma_m)


def test_sample_paired_with_another_shots_pose_is_dropped() -> None:
    scene, T0, cylinder0 = scene_and_start(10, n_poses=30, n_points=200)
    poses = scene.T_base_flange.copy()
    poses[7] = scene.T_base_flange[20]
    result = refine_with_outlier_rejection(scene.points, poses, T0, cylinder0, radius_m=RADIUS)
    assert [d.sample_index for d in result.dropped] == [7]
    assert "mm" in result.dropped[0].reason and "recorded flange pose" in result.dropped[0].reason
    assert result.used == [j for j in range(30) if j != 7]
    assert set(result.sample_residuals_m) == set(result.used)
    rotation, translation = transform_error(result.T_flange_sensor, scene.T_flange_sensor)
    assert np.rad2deg(rotation) < 0.03 and translation < 0.2e-3


def test_clean_data_loses_no_sample() -> None:
    scene, T0, cylinder0 = scene_and_start(11, n_poses=30, n_points=100)
    result = refine_with_outlier_rejection(
        scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS
    )
    assert result.dropped == [] and result.used == list(range(30))


def test_input_validation() -> None:
    scene, T0, cylinder0 = scene_and_start(12, n_poses=8, n_points=30)
    with pytest.raises(DegenerateError, match="at least 6"):
        refine(scene.points[:5], scene.T_base_flange[:5], T0, cylinder0, radius_m=RADIUS)
    with pytest.raises(InputError, match="one pose per profile"):
        refine(scene.points, scene.T_base_flange[:7], T0, cylinder0, radius_m=RADIUS)
    bad = [p.copy() for p in scene.points]
    bad[3][0, 0] = np.nan
    with pytest.raises(InputError, match="profile 3 contains NaN"):
        refine(bad, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    with pytest.raises(InputError, match="positive length"):
        refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=-0.02)
    with pytest.raises(InputError, match="loss"):
        RefineConfig(loss="cauchy")


def test_a_robot_error_shared_by_every_pose_goes_into_the_hand_eye_whole() -> None:
    # Issue 29, the real cylinder's twin: an arm whose every reported pose is off by one
    # flange-frame offset D (here 4-5 times the per-pose prior) is calibrated to D·X, the
    # hand-eye that is right wherever that arm scans; no recording can tell D from the
    # hand-eye, so the per-pose corrections, which the prior pulls to zero, keep none of it.
    scene, T0, cylinder0 = scene_and_start(3, n_poses=20, n_points=200)
    D = np.eye(4)
    D[:3, :3] = matrix_from_rotvec(np.deg2rad([0.02, -0.03, 0.01]))
    D[:3, 3] = [4e-4, -5e-4, 3e-4]
    off = scene.T_base_flange @ np.linalg.inv(D)
    as_recorded = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    shared = refine(scene.points, off, T0, cylinder0, radius_m=RADIUS)
    rotation, translation = transform_error(shared.T_flange_sensor, D @ as_recorded.T_flange_sensor)
    assert rotation < 1e-7 and translation < 1e-7
    np.testing.assert_allclose(
        shared.sigma_translation_m, as_recorded.sigma_translation_m, rtol=1e-3
    )
    np.testing.assert_allclose(shared.pose_corrections, as_recorded.pose_corrections, atol=1e-6)


def test_profiles_that_err_alike_widen_the_sigma() -> None:
    # Every profile's points share a depth error (a tilt of 20 µm across the line) that the
    # model, weighing them as independent, does not know: the hand-eye scatters from
    # profile to profile beyond what the model predicts, and the 1σ is widened by it.
    scene, T0, cylinder0 = scene_and_start(
        21, n_poses=30, n_points=150, robot_sigma_t=1e-5, robot_sigma_r=float(np.deg2rad(0.001))
    )
    rng = np.random.default_rng(22)
    points = []
    for p in scene.points:
        q = np.array(p, dtype=np.float64)
        span = np.ptp(q[:, 0])
        q[:, 2] += rng.normal(0.0, 20e-6) * (q[:, 0] - q[:, 0].mean()) / span
        points.append(q)
    config = RefineConfig(robot_sigma_t_m=1e-5, robot_sigma_r_rad=float(np.deg2rad(0.001)))
    plain = refine(
        points, scene.T_base_flange, T0, cylinder0, replace(config, widen_by_dispersion=False)
    )
    widened = refine(points, scene.T_base_flange, T0, cylinder0, config)
    assert plain.sample_dispersion is None and widened.sample_dispersion is not None
    assert np.max(widened.sample_dispersion) > 2.0
    np.testing.assert_allclose(widened.T_flange_sensor, plain.T_flange_sensor, atol=1e-12)
    scale = np.sqrt(np.maximum(widened.sample_dispersion, 1.0))
    np.testing.assert_allclose(
        widened.sigma_translation_m, plain.sigma_translation_m * scale[3:], rtol=1e-9
    )
    np.testing.assert_allclose(
        widened.sigma_rotation_rad, plain.sigma_rotation_rad * scale[:3], rtol=1e-9
    )


def test_profiles_with_white_noise_are_not_widened_much() -> None:
    scene, T0, cylinder0 = scene_and_start(23, n_poses=40, n_points=150)
    result = refine(scene.points, scene.T_base_flange, T0, cylinder0, radius_m=RADIUS)
    assert result.sample_dispersion is not None
    assert np.all(result.sample_dispersion < 2.0), result.sample_dispersion
