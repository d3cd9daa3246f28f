"""Pose planning: constraints checked against the simulator's scene, gain over random poses,
rough placement from exploratory scans, the plan command and its refusals."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import invert_transform
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.planning import (
    PlanConstraints,
    choose,
    feasible,
    gather_candidates,
    greedy_order,
    log_det_marginal,
    marginal_hand_eye,
    plan_for_target,
    plan_poses,
    predicted_profiles,
    robot_angle,
    with_noise_levels,
)
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.cylinder import TARGET, CylinderConfig
from linelaser_calib.core.targets.cylinder.plan import (
    LONG_AXIS_CUT_RAD,
    SHORT_AXIS_CUT_RAD,
    CylinderPlanner,
    placement,
    rough_placement,
)
from linelaser_calib.core.targets.cylinder.section import CylinderSection
from linelaser_calib.core.targets.sphere import SphereConfig
from linelaser_calib.core.targets.sphere.plan import SpherePlacement, SpherePlanner
from linelaser_calib.sim import scenario_from_preset, simulate
from linelaser_calib.sim.poses import sample_sensor_poses
from linelaser_calib.sim.profiler import trace
from linelaser_calib.sim.scene import Scene, Surface
from linelaser_calib.sim.sphere import (
    Ball,
    simulate_sphere,
    sphere_scenario_from_preset,
    sphere_views,
    trace_ball,
)

RNG = np.random.default_rng
SCENARIO = scenario_from_preset("ur_scancontrol")
REACH_CENTRE = (0.35, 0.15, 0.25)
CONSTRAINTS = PlanConstraints(reach_centre_m=REACH_CENTRE)
PLANNER = CylinderPlanner()
CONFIG = CylinderConfig(radius_m=SCENARIO.cylinder_radius_m)


def _true_placement() -> object:
    return placement(SCENARIO.cylinder(), (0.0, SCENARIO.cylinder_length_m))


@pytest.mark.parametrize("seed", range(5))
def test_planned_poses_obey_every_constraint_in_the_simulated_scene(seed: int) -> None:
    plan = plan_poses(
        PLANNER,
        _true_placement(),
        SCENARIO.T_flange_sensor,
        CONFIG,
        8,
        np.random.default_rng(seed),
        CONSTRAINTS,
    )
    assert len(plan.poses) == 8
    T_sensor = np.stack([p.T_base_sensor for p in plan.poses])
    T_flange = np.stack([p.T_base_flange for p in plan.poses])
    np.testing.assert_allclose(T_flange @ SCENARIO.T_flange_sensor, T_sensor, atol=1e-12)
    # The simulator's own ray caster on the finite shaft standing on the table.
    scene = Scene.from_scenario(SCENARIO)
    traced = trace(scene, SCENARIO, T_sensor)
    on_shaft = (traced.surface == Surface.SIDE) | (traced.surface == Surface.CAP)
    assert not np.any(on_shaft[:, 0]) and not np.any(on_shaft[:, -1]), "arc not whole"
    assert not np.any(traced.surface == Surface.CAP)
    z = np.where(on_shaft, traced.points_sensor[..., 2], SCENARIO.z_min_m)
    assert np.all((z >= SCENARIO.z_min_m - 1e-9) & (z <= SCENARIO.z_max_m + 1e-9))
    assert np.all(on_shaft.sum(axis=1) >= 0.15 * SCENARIO.resolution)
    # Above the table (z = 0) with clearance, the laser not pointing up, not at the robot.
    assert np.all(T_sensor[:, 2, 3] >= CONSTRAINTS.clearance_m)
    assert np.all(T_flange[:, 2, 3] >= CONSTRAINTS.clearance_m)
    assert np.all(T_sensor[:, 2, 2] <= 0.0)
    assert np.all(robot_angle(T_sensor, np.array([0.0, 0.0, 1.0])) > math.radians(30.0))
    assert np.all(np.abs(T_flange[:, :3, 3] - REACH_CENTRE) <= CONSTRAINTS.reach_half_extent_m)
    # The paper's cut angles: the laser plane's normal (sensor y) against the axis.
    cut = np.arccos(np.abs(T_sensor[:, :3, 1] @ scene.axis))
    long_ok = (cut >= LONG_AXIS_CUT_RAD[0] - 1e-9) & (cut <= LONG_AXIS_CUT_RAD[1] + 1e-9)
    short_ok = (cut >= SHORT_AXIS_CUT_RAD[0] - 1e-9) & (cut <= SHORT_AXIS_CUT_RAD[1] + 1e-9)
    assert np.all(long_ok | short_ok)


def test_predicted_profile_matches_the_simulators_ray_caster() -> None:
    poses = sample_sensor_poses(np.random.default_rng(2), SCENARIO, Scene.from_scenario(SCENARIO))
    traced = trace(Scene.from_scenario(SCENARIO), SCENARIO, poses.T_base_sensor)
    predicted = predicted_profiles(PLANNER, _true_placement(), poses.T_base_sensor, CONSTRAINTS)
    for k, profile in enumerate(predicted):
        on_side = traced.surface[k] == Surface.SIDE
        expected = traced.points_sensor[k][on_side]
        assert len(profile) == len(expected)
        np.testing.assert_allclose(profile, expected, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_planned_poses_beat_random_rule_abiding_poses_in_predicted_sigma(seed: int) -> None:
    n = 10
    placed = _true_placement()
    plan = plan_poses(
        PLANNER,
        placed,
        SCENARIO.T_flange_sensor,
        CONFIG,
        n,
        np.random.default_rng(seed),
        CONSTRAINTS,
    )
    random_poses = sample_sensor_poses(
        np.random.default_rng(seed), SCENARIO, Scene.from_scenario(SCENARIO)
    ).T_base_sensor[:n]
    profiles = predicted_profiles(PLANNER, placed, random_poses, CONSTRAINTS)
    T_flange = random_poses @ invert_transform(SCENARIO.T_flange_sensor)
    info = PLANNER.information(placed, SCENARIO.T_flange_sensor, profiles, T_flange, CONFIG)
    covariance = np.linalg.inv(marginal_hand_eye(info.sum(axis=0)))
    random_sigma = np.sqrt(np.diag(covariance))
    last = plan.poses[-1]
    planned_sigma = np.concatenate([last.sigma_rotation_rad, last.sigma_translation_m])
    # D-optimal: the volume of the confidence ellipsoid (not each axis) is what it shrinks.
    assert np.prod(planned_sigma / random_sigma) < 0.5


def test_predicted_sigma_never_grows_and_the_goal_stops_early() -> None:
    plan = plan_poses(
        PLANNER,
        _true_placement(),
        SCENARIO.T_flange_sensor,
        CONFIG,
        40,
        np.random.default_rng(0),
        CONSTRAINTS,
        goal=(0.06e-3, math.radians(0.008)),
    )
    sigmas = np.array([np.r_[p.sigma_translation_m, p.sigma_rotation_rad] for p in plan.poses])
    assert np.all(np.diff(sigmas, axis=0) <= 1e-12)
    assert plan.goal_reached and len(plan.poses) < 40
    assert np.all(sigmas[-1, :3] <= 0.06e-3) and np.all(sigmas[-1, 3:] <= math.radians(0.008))
    assert not np.all(sigmas[-2, :3] <= 0.06e-3) or not np.all(sigmas[-2, 3:] <= 0.008)


def test_rough_placement_from_three_exploratory_scans_finds_the_axis() -> None:
    data = simulate(scenario_from_preset("ur_scancontrol", n_poses=3), seed=5)
    paired = pair_profiles(data.profiles, data.poses, PairingConfig())
    features, _ = TARGET.extract(paired.samples, CONFIG, 0, lambda *_: None)
    assert len(features) == 3
    placed = rough_placement(features, data.truth.T_flange_sensor, 0.02, None)
    truth = data.truth.cylinder
    angle = math.degrees(
        math.acos(min(1.0, abs(float(placed.cylinder.direction @ truth.direction))))
    )
    assert angle < 2.0
    offset = placed.cylinder.point - truth.point
    radial = offset - (offset @ truth.direction) * truth.direction
    assert np.linalg.norm(radial) < 2e-3
    lo, hi = placed.axial_range_m
    assert -1e-3 <= lo < hi <= SCENARIO.cylinder_length_m + 1e-3


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("plan")
    bag = root / "bag"
    assert main(["simulate", str(bag), "--scenario", "ur_scancontrol", "--seed", "1"]) == 0
    result = root / "result.yaml"
    assert main(["calibrate", str(bag), "--radius", "0.02", "--output", str(result)]) == 0
    return result


def test_plan_command_writes_the_poses(
    calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "poses.yaml"
    argv = ["plan", "--from", str(calibrated), "--axial-range", "0,0.1", "--n", "4"]
    argv += ["--reach-centre", "0.35,0.15,0.25", "--output", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "1 sigma translation (mm)" in printed and f"Wrote {out}" in printed
    written = yaml.safe_load(out.read_text())
    assert written["frame"] == "base_link" and len(written["poses"]) == 4
    for pose in written["poses"]:
        assert np.linalg.norm(pose["rotation_xyzw"]) == pytest.approx(1.0, abs=1e-9)
        flange = np.array(pose["translation"])
        assert np.all(np.abs(flange - REACH_CENTRE) <= 0.25 + 1e-9)
        assert len(pose["predicted_sigma"]["translation_m"]) == 3
        assert len(pose["predicted_sigma"]["rotation_rad"]) == 3
    assert max(written["poses"][-1]["predicted_sigma"]["translation_m"]) < 1e-3


def test_plan_figure_shows_the_predicted_curve(calibrated: Path, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    figure = tmp_path / "sigma.png"
    argv = ["plan", "--from", str(calibrated), "--axial-range", "0,0.1", "--n", "5"]
    assert main([*argv, "--reach-centre", "0.35,0.15,0.25", "--figure", str(figure)]) == 0
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--cylinder", "0.45,0.15,0,0,0,1", "--radius", "0.02"], "needs the current hand-eye"),
        (["--initial", "RESULT", "--radius", "0.02"], "needs the target's placement"),
        (["--initial", "RESULT", "--cylinder", "0.45,0.15,0,0,1"], "takes 6 numbers"),
        (["--initial", "RESULT", "--cylinder", "0.45,0.15,0,0,0,1"], "needs the cylinder's radius"),
        (["--from", "RESULT", "--n", "0", "--axial-range", "0,0.1"], "must be >= 1"),
        (["--from", "RESULT", "--initial", "RESULT"], "omit --initial"),
        (["--from", "RESULT", "--reach", "0.01", "--axial-range", "0,0.1"], "reach box"),
        (["--from", "RESULT"], "--axial-range"),
    ],
)
def test_plan_refuses_bad_input_with_one_clear_message(
    calibrated: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    argv = ["plan", *[str(calibrated) if a == "RESULT" else a for a in extra]]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err and err.count("\n") == 1


# --- the sphere -----------------------------------------------------------------------------

SPHERE = sphere_scenario_from_preset("sphere")
SPHERE_PLACEMENT = SpherePlacement(SPHERE.centre, SPHERE.radius_m, SPHERE.centre_side)
SPHERE_CONFIG = SphereConfig(radius_m=SPHERE.radius_m)
SPHERE_TABLE = SPHERE.centre_m[2] - SPHERE.radius_m - SPHERE.table_gap_m
SPHERE_CONSTRAINTS = PlanConstraints(table_height_m=SPHERE_TABLE, clearance_m=0.02)


@pytest.mark.parametrize("seed", range(3))
def test_planned_sphere_views_show_the_whole_cap_on_the_configured_side(seed: int) -> None:
    plan = plan_poses(
        SpherePlanner(),
        SPHERE_PLACEMENT,
        SPHERE.rig.T_flange_sensor,
        SPHERE_CONFIG,
        8,
        np.random.default_rng(seed),
        SPHERE_CONSTRAINTS,
    )
    T_sensor = np.stack([p.T_base_sensor for p in plan.poses])
    T_flange = np.stack([p.T_base_flange for p in plan.poses])
    traced = trace_ball(Ball.from_scenario(SPHERE), SPHERE.rig, T_sensor)
    on_ball = traced.surface == Surface.SIDE
    assert not np.any(on_ball[:, 0]) and not np.any(on_ball[:, -1])
    z = np.where(on_ball, traced.points_sensor[..., 2], SPHERE.rig.z_min_m)
    assert np.all((z >= SPHERE.rig.z_min_m - 1e-9) & (z <= SPHERE.rig.z_max_m + 1e-9))
    assert np.all(on_ball.sum(axis=1) >= 0.15 * SPHERE.rig.resolution)
    # The centre on the sensor's configured side of every laser plane, the cap off the equator.
    centre_sensor = np.einsum("kji,kj->ki", T_sensor[:, :3, :3], SPHERE.centre - T_sensor[:, :3, 3])
    assert np.all(SPHERE.centre_side * centre_sensor[:, 1] > 0.1 * SPHERE.radius_m)
    assert np.all(np.minimum(T_sensor[:, 2, 3], T_flange[:, 2, 3]) >= SPHERE_TABLE + 0.02)
    assert np.all(T_sensor[:, 2, 2] <= 0.0)


def test_planned_sphere_views_beat_the_simulators_views() -> None:
    ball = Ball.from_scenario(SPHERE)
    views = sphere_views(replace(SPHERE, rig=replace(SPHERE.rig, n_poses=20)), ball, RNG(1))
    planner = SpherePlanner()
    profiles = predicted_profiles(planner, SPHERE_PLACEMENT, views, SPHERE_CONSTRAINTS)
    T_flange = views @ invert_transform(SPHERE.rig.T_flange_sensor)
    info = planner.information(
        SPHERE_PLACEMENT, SPHERE.rig.T_flange_sensor, profiles, T_flange, SPHERE_CONFIG
    )
    random_sigma = np.sqrt(np.diag(np.linalg.inv(marginal_hand_eye(info.sum(axis=0)))))
    plan = plan_poses(
        planner,
        SPHERE_PLACEMENT,
        SPHERE.rig.T_flange_sensor,
        SPHERE_CONFIG,
        20,
        RNG(1),
        SPHERE_CONSTRAINTS,
    )
    last = plan.poses[-1]
    planned_sigma = np.concatenate([last.sigma_rotation_rad, last.sigma_translation_m])
    assert np.prod(planned_sigma / random_sigma) < 0.1


def test_rough_sphere_placement_from_three_scans_finds_the_centre() -> None:
    data = simulate_sphere(replace(SPHERE, rig=replace(SPHERE.rig, n_poses=3)), seed=4)
    paired = pair_profiles(data.profiles, data.poses, PairingConfig())
    target = get_target("sphere")
    features, _ = target.extract(paired.samples, SPHERE_CONFIG, 0, lambda *_: None)
    assert len(features) == 3
    placed = SpherePlanner().placement_from_features(
        features, SPHERE.rig.T_flange_sensor, SPHERE_CONFIG, None
    )
    assert placed.centre_side == SPHERE.centre_side
    assert np.linalg.norm(placed.centre - SPHERE.centre) < 1e-3


def test_plan_command_for_the_sphere(tmp_path: Path) -> None:
    out = tmp_path / "poses.yaml"
    centre = ",".join(str(v) for v in SPHERE.centre_m)
    x, y, z = SPHERE.rig.hand_eye_translation_m
    qx, qy, qz, qw = SPHERE.rig.hand_eye_rotation_xyzw
    argv = ["plan", "--target", "sphere", "--sphere", centre, "--radius", str(SPHERE.radius_m)]
    argv += ["--initial", f"{x} {y} {z} {qx} {qy} {qz} {qw}", "--centre-side=-y"]
    argv += ["--table-height", str(SPHERE_TABLE), "--reach-centre", centre, "--n", "5"]
    assert main([*argv, "--output", str(out)]) == 0
    assert len(yaml.safe_load(out.read_text())["poses"]) == 5


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--target", "sphere", "--sphere", "0.5,0.1,0.1", "--axial-range", "0,0.1"],
            "--axial-range",
        ),
        (["--target", "sphere", "--cylinder", "0.5,0.1,0.1,0,0,1"], "--cylinder does not apply"),
        (["--sphere", "0.5,0.1,0.1"], "--sphere does not apply"),
        (["--target", "sphere", "--sphere", "0.5,0.1"], "takes 3 numbers"),
    ],
)
def test_plan_refuses_placements_of_another_target(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    initial = ["--initial", "0 0 0.1 0 0 0 1", "--radius", "0.02"]
    assert main(["plan", *argv, *initial]) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


# --- choice, candidates and noise levels ----------------------------------------------------


def _pool(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` feasible sensor poses around the true shaft and their information."""
    placed = _true_placement()
    reach = np.asarray(REACH_CENTRE)
    T_sensor, _ = gather_candidates(
        PLANNER, placed, SCENARIO.T_flange_sensor, CONSTRAINTS, reach, RNG(seed), count
    )
    profiles = predicted_profiles(PLANNER, placed, T_sensor, CONSTRAINTS)
    T_flange = T_sensor @ invert_transform(SCENARIO.T_flange_sensor)
    return T_sensor, PLANNER.information(
        placed, SCENARIO.T_flange_sensor, profiles, T_flange, CONFIG
    )


def test_candidates_are_drawn_until_enough_are_feasible() -> None:
    placed = _true_placement()
    reach = np.asarray(REACH_CENTRE)
    T_sensor, drawn = gather_candidates(
        PLANNER, placed, SCENARIO.T_flange_sensor, CONSTRAINTS, reach, RNG(0), 150
    )
    assert len(T_sensor) == 150
    # The upright shaft on its table rejects every view from below: most draws fail.
    assert drawn > 2 * 150
    ok = feasible(PLANNER, placed, T_sensor, SCENARIO.T_flange_sensor, CONSTRAINTS, reach)
    assert np.all(ok)


def test_exchange_pass_moves_the_greedy_choice_towards_the_best_subset() -> None:
    k, greedy_gap, chosen_gap, optimal = 4, 0.0, 0.0, 0
    for seed in range(6):
        _, gains = _pool(seed, 14)
        start = np.eye(gains.shape[1])
        subsets = np.array(list(itertools.combinations(range(len(gains)), k)))
        best = float(np.max(log_det_marginal(start + gains[subsets].sum(axis=1))))
        available = np.ones(len(gains), dtype=bool)
        greedy = float(
            log_det_marginal(
                start + gains[greedy_order(start, gains, k, None, available)].sum(axis=0)
            )
        )
        chosen = float(log_det_marginal(start + gains[choose(start, gains, k, None)].sum(axis=0)))
        assert greedy - 1e-9 <= chosen <= best + 1e-9
        greedy_gap += best - greedy
        chosen_gap += best - chosen
        optimal += chosen > best - 1e-9
    assert chosen_gap < 0.5 * greedy_gap and optimal >= 3


def test_plan_from_a_result_uses_its_reestimated_noise() -> None:
    # The arm is 3 times less precise than configured: the result says so, and the plan
    # predicts with what the result found.
    truth = scenario_from_preset(
        "ur_scancontrol",
        robot_sigma_translation_m=3e-4,
        robot_sigma_rotation_rad=math.radians(0.03),
        n_poses=20,
    )
    data = simulate(truth, seed=0)
    samples = pair_profiles(data.profiles, data.poses, PairingConfig()).samples
    # The planner predicts with independent points; the learned line noise (a smooth part
    # this preset's residuals show) is left out so that the result's 1σ means the same.
    independent = replace(CONFIG, refine=replace(CONFIG.refine, learn_line_noise=False))
    result = calibrate_samples(
        samples, PipelineConfig(target="cylinder", target_config=independent, seed=0)
    )
    section = result.target
    assert isinstance(section, CylinderSection) and section.noise_levels is not None
    levels = section.noise_levels
    assert levels["robot_sigma_t_m"] == pytest.approx(3e-4, rel=0.3)
    assert levels["sensor_sigma_m"] == pytest.approx(truth.sigma_depth_m, rel=0.3)

    def start_sigma(section: object) -> np.ndarray:
        plan = plan_for_target(
            get_target("cylinder"),
            CONFIG,
            result.T_flange_sensor,
            1,
            samples=samples,
            section=section,
            extent=(0.0, truth.cylinder_length_m),
            constraints=CONSTRAINTS,
        )
        assert plan.sigma_translation_m is not None
        return plan.sigma_translation_m

    configured = start_sigma(replace(section, noise_levels=None))
    estimated = start_sigma(section)
    assert np.all((estimated > 2.0 * configured) & (estimated < 3.5 * configured))
    # The noise model's 1σ: the reported one is wider, since an arm erring 3 times its
    # stated repeatability is taken to err systematically (the self-check).
    assert result.self_check is not None and result.self_check.systematic
    np.testing.assert_allclose(estimated, result.self_check.sigma_model[3:], rtol=0.25)


@pytest.mark.parametrize("levels", [{"robot_sigma_t_m": -1e-4}, {"sensor_sigma": 1e-6}])
def test_bad_noise_levels_of_a_result_are_refused(levels: dict[str, float]) -> None:
    with pytest.raises(InputError, match="noise_estimated"):
        with_noise_levels(CONFIG, levels)


@pytest.mark.parametrize("n", [6, 12])
def test_planned_translation_meets_but_never_beats_the_robots_bound(n: int) -> None:
    # A profile of a cylinder shows 2 of the 3 translation directions, and the robot's
    # translation error adds to the hand-eye's: no n poses beat 3 σ_t / √(2n), even with a
    # perfect sensor, and the planner's poses come close to it.
    perfect = with_noise_levels(CONFIG, {"sensor_sigma_m": CONFIG.refine.sensor_sigma_m / 20})
    plan = plan_poses(
        PLANNER, _true_placement(), SCENARIO.T_flange_sensor, perfect, n, RNG(n), CONSTRAINTS
    )
    bound = 3.0 * CONFIG.refine.robot_sigma_t_m / math.sqrt(2.0 * n)
    achieved = float(np.linalg.norm(plan.poses[-1].sigma_translation_m))
    assert bound <= achieved < 1.1 * bound
