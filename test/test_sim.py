"""Simulator tests: geometry against the true scene, noise statistics, gates, timing, determinism.

The checks recompute the geometry here from the truth (cylinder axis, radius, length, plane)
instead of calling the simulator's own ray caster.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from functools import lru_cache
from typing import Any

import numpy as np
import pytest
from _compare import assert_floats_close

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    apply_transform,
    invert_transform,
    rotation_angle,
    rotvec_from_matrix,
)
from linelaser_calib.sim import (
    PRESETS,
    Scenario,
    SimulatedData,
    Surface,
    random_scenario,
    scenario_from_preset,
    simulate,
)
from linelaser_calib.sim.sensor_models import SensorModel
from linelaser_calib.sim.sphere import SPHERE_PRESETS, sphere_scenario_from_preset

PRESET_NAMES = sorted(PRESETS)


def plain(scenario: Scenario) -> Scenario:
    """The scenario without the clutter pieces (sim.clutter: fixture, camera effects,
    clusters), whose own tests are below; the checks of the plain scene apply to the rest."""
    return replace(
        scenario,
        fixture_length_m=0.0,
        sigma_spread=0.0,
        edge_bias_m=0.0,
        lateral_scale_error=0.0,
        depth_quantum_m=0.0,
        pose_clusters=0,
    )


PLAIN_PRESETS = [plain(s) for s in PRESETS.values()]


@lru_cache(maxsize=64)
def run(scenario: Scenario, seed: int) -> SimulatedData:
    return simulate(scenario, seed)


def quiet(scenario: Scenario) -> Scenario:
    """No noise: no white noise, no spikes, no real profiler's shape errors."""
    return replace(
        scenario,
        sigma_depth_m=0.0,
        sigma_lateral_m=0.0,
        spike_fraction=0.0,
        sensor=SensorModel(),
    )


def plane_of(scenario: Scenario) -> tuple[np.ndarray, np.ndarray] | None:
    if scenario.background == "table":
        return np.array(scenario.cylinder_base_m), scenario.axis_unit
    if scenario.background == "plane":
        n = np.array(scenario.background_normal)
        return np.array(scenario.background_point_m), n / np.linalg.norm(n)
    return None


def axial_radial(scenario: Scenario, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axial position from the cylinder base (m) and distance from the axis (m)."""
    a = scenario.axis_unit
    w = p - np.array(scenario.cylinder_base_m)
    h = w @ a
    return h, np.linalg.norm(w - h[:, None] * a, axis=1)


def surface_distance_and_normal(
    scenario: Scenario, p: np.ndarray, surface: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Distance of base-frame points to their labelled surface, and its outward normal."""
    a = scenario.axis_unit
    h, r = axial_radial(scenario, p)
    w = p - np.array(scenario.cylinder_base_m)
    radial = w - h[:, None] * a
    dist = np.full(len(p), np.nan)
    normal = np.full((len(p), 3), np.nan)
    side = surface == Surface.SIDE
    dist[side] = r[side] - scenario.cylinder_radius_m
    normal[side] = radial[side] / r[side, None]
    cap = surface == Surface.CAP
    top = h > 0.5 * scenario.cylinder_length_m
    dist[cap] = np.where(top, h - scenario.cylinder_length_m, -h)[cap]
    normal[cap] = np.where(top[:, None], a, -a)[cap]
    back = surface == Surface.BACKGROUND
    if back.any():
        plane = plane_of(scenario)
        assert plane is not None
        dist[back] = (p[back] - plane[0]) @ plane[1]
        normal[back] = plane[1]
    return dist, normal


def valid_points(data: SimulatedData, k: int) -> np.ndarray:
    """Valid points of profile k, rows aligned with the per-ray truth ``valid[k]``."""
    points = data.profiles[k].points
    return points[data.truth.valid[k]] if data.scenario.organised else points


def sensor_poses(data: SimulatedData) -> np.ndarray:
    return data.truth.T_base_flange_true @ data.truth.T_flange_sensor


def sigma_3d(s: Scenario) -> float:
    """The white noise's 3-D σ, with a real profiler's shape errors (bow, smooth error,
    speckle, output steps) counted as one more σ each, so that 6 of them bound a point, and
    its scale errors as a sixth of the most they move a point in the range."""
    m = s.sensor
    shape = (m.linearity_m / 3.0) ** 2 + m.shape_sigma_m**2 + m.speckle_sigma_m**2
    steps = (m.x_step_m**2 + m.z_step_m**2) / 12.0
    reach = abs(m.x_scale_error) * math.tan(s.fan_half_angle_rad) + abs(m.z_scale_error)
    scales = (reach * s.z_max_m / 6.0) ** 2
    white = s.sigma_depth_m**2 + s.sigma_lateral_m**2 + s.sigma_y_m**2
    return math.sqrt(white + shape + steps + scales)


def check_on_surfaces(data: SimulatedData, tolerance: float) -> int:
    s, truth = data.scenario, data.truth
    checked = 0
    for k, T in enumerate(sensor_poses(data)):
        keep = ~truth.spike[k][truth.valid[k]]
        p = apply_transform(T, valid_points(data, k)[keep])
        surface = truth.surface[k][truth.valid[k]][keep]
        dist, _ = surface_distance_and_normal(s, p, surface)
        assert np.all(np.abs(dist) < tolerance), (k, np.nanmax(np.abs(dist)))
        checked += len(p)
    return checked


TILTED_FLOOR = scenario_from_preset(
    "ur_scancontrol",
    background="plane",
    background_point_m=(0.45, 0.15, 0.01),
    background_normal=(0.0, math.sin(0.2), math.cos(0.2)),
)


@pytest.mark.parametrize("scenario", [*PLAIN_PRESETS, TILTED_FLOOR], ids=lambda s: s.name)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_points_lie_on_true_surfaces_within_noise(scenario: Scenario, seed: int) -> None:
    data = run(scenario, seed)
    assert check_on_surfaces(data, 6.0 * sigma_3d(data.scenario)) > 1000


def test_surface_check_detects_a_wrong_hand_eye() -> None:
    data = run(PRESETS["paper"], 0)
    wrong = data.truth.T_flange_sensor.copy()
    wrong[:3, 3] += [0.0, 0.0, 5e-4]
    bad = replace(data, truth=replace(data.truth, T_flange_sensor=wrong))
    with pytest.raises(AssertionError):
        check_on_surfaces(bad, 6.0 * sigma_3d(data.scenario))


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_points_lie_exactly_on_true_surfaces_without_noise(name: str) -> None:
    data = run(quiet(plain(PRESETS[name])), 4)
    assert check_on_surfaces(data, 1e-9) > 1000
    for k in range(len(data.profiles)):
        np.testing.assert_allclose(
            valid_points(data, k), data.truth.points_true_sensor[k][data.truth.valid[k]], atol=0
        )


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_profiles_lie_in_the_laser_plane(name: str) -> None:
    data = run(PRESETS[name], 0)
    for k, profile in enumerate(data.profiles):
        assert profile.frame_id == data.scenario.sensor_frame
        assert np.all(valid_points(data, k)[:, 1] == 0.0)


def test_table_is_seen_in_the_ur_preset() -> None:
    truth = run(PRESETS["ur_scancontrol"], 0).truth
    table_points = np.sum(truth.valid & (truth.surface == Surface.BACKGROUND), axis=1)
    assert np.sum(table_points >= 10) >= 3


def test_spikes_are_displaced_along_their_ray() -> None:
    s = scenario_from_preset("ur_scancontrol", spike_fraction=0.05)
    data = run(s, 3)
    truth = data.truth
    tol = 6.0 * sigma_3d(s)
    for k in range(len(data.profiles)):
        spikes = truth.spike[k][truth.valid[k]]
        measured = valid_points(data, k)[spikes]
        true = truth.points_true_sensor[k][truth.valid[k]][spikes]
        offset = np.linalg.norm(measured - true, axis=1)
        assert np.all((offset > s.spike_min_m - tol) & (offset < s.spike_max_m + tol))
        cross = np.cross(measured, true)  # collinear with the ray through the origin
        assert np.all(np.linalg.norm(cross, axis=1) < tol * np.linalg.norm(true, axis=1))


@pytest.mark.parametrize("scenario", [*PLAIN_PRESETS, TILTED_FLOOR], ids=lambda s: s.name)
def test_only_the_near_side_is_seen(scenario: Scenario) -> None:
    data = run(scenario, 1)
    s = data.scenario
    for k, T in enumerate(sensor_poses(data)):
        keep = ~data.truth.spike[k][data.truth.valid[k]]
        p = apply_transform(T, data.truth.points_true_sensor[k][data.truth.valid[k]][keep])
        surface = data.truth.surface[k][data.truth.valid[k]][keep]
        _, normal = surface_distance_and_normal(s, p, surface)
        to_sensor = T[:3, 3] - p
        assert np.all(np.sum(normal * to_sensor, axis=1) > 0.0)
        camera = T[:3, 3] + s.camera_baseline_m * T[:3, 1]
        assert np.all(np.sum(normal * (camera - p), axis=1) > 0.0)
        # Nothing (cylinder or plane) lies between the sensor and any returned point.
        f = np.linspace(0.0, 0.999, 60)
        segment = (T[:3, 3] + f[:, None, None] * (p - T[:3, 3])[None]).reshape(-1, 3)
        h, r = axial_radial(s, segment)
        inside = (r < s.cylinder_radius_m - 1e-9) & (h > 1e-9) & (h < s.cylinder_length_m - 1e-9)
        assert not inside.any()
        plane = plane_of(s)
        if plane is not None:
            assert np.all((segment - plane[0]) @ plane[1] > -1e-9)


def cut_angles(scenario: Scenario, T_base_sensor: np.ndarray) -> np.ndarray:
    y = T_base_sensor[:, :3, 1]
    return np.arccos(np.clip(np.abs(y @ scenario.axis_unit), 0.0, 1.0))


@pytest.mark.parametrize(
    "scenario",
    [
        *PLAIN_PRESETS,
        scenario_from_preset("paper", pose_mode="general", n_poses=40),
        scenario_from_preset("paper", long_axis_cut_range_rad=(0.9, 1.0), long_axis_fraction=1.0),
    ],
    ids=lambda s: s.name + "-" + s.pose_mode,
)
def test_cut_angles_fall_in_the_configured_ranges(scenario: Scenario) -> None:
    truth = run(scenario, 5).truth
    cut = cut_angles(scenario, truth.T_base_sensor_waypoints)
    np.testing.assert_allclose(truth.waypoint_cut_angles_rad, cut, atol=1e-9)
    ranges = {
        "long": scenario.long_axis_cut_range_rad,
        "short": scenario.short_axis_cut_range_rad,
        "general": scenario.general_cut_range_rad,
    }
    for angle, kind in zip(cut, truth.waypoint_kinds, strict=True):
        lo, hi = ranges[kind]
        assert lo - 1e-9 <= angle <= hi + 1e-9, (kind, math.degrees(angle))
    if scenario.pose_mode == "paper" and 0.0 < scenario.long_axis_fraction < 1.0:
        assert {"long", "short"} <= set(truth.waypoint_kinds)


def visible_ellipse(s: Scenario, T_base_sensor: np.ndarray) -> np.ndarray:
    """Front-facing points (sensor frame) of the laser plane's ellipse on the infinite side."""
    a, R = s.axis_unit, s.cylinder_radius_m
    o, y = T_base_sensor[:3, 3], T_base_sensor[:3, 1]
    base = np.array(s.cylinder_base_m)
    centre = base + ((o - base) @ y) / (a @ y) * a
    m = np.cross(a, y)
    m /= np.linalg.norm(m)
    u = a - (a @ y) * y
    u /= np.linalg.norm(u)
    t = np.linspace(0.0, 2.0 * math.pi, 2000, endpoint=False)
    p = centre + (R / abs(a @ y)) * np.cos(t)[:, None] * u + R * np.sin(t)[:, None] * m
    h = (p - base) @ a
    outward = (p - base - h[:, None] * a) / R
    front = np.sum(outward * (o - p), axis=1) > 0.0
    assert np.all((h[front] > 0.0) & (h[front] < s.cylinder_length_m))
    return apply_transform(invert_transform(T_base_sensor), p[front])


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_whole_visible_arc_is_inside_range_and_fan(name: str) -> None:
    s = PRESETS[name]
    truth = run(s, 2).truth
    for T in truth.T_base_sensor_waypoints:
        arc = visible_ellipse(s, T)
        assert np.all((arc[:, 2] >= s.z_min_m) & (arc[:, 2] <= s.z_max_m))
        assert np.all(np.abs(arc[:, 0]) <= arc[:, 2] * math.tan(s.fan_half_angle_rad))
    if s.motion == "step":
        # An arm with kinematic errors shoots from near its waypoints (sub-millimetre off).
        atol = 3e-3 if s.robot_model else 0.0
        np.testing.assert_allclose(
            sensor_poses(run(s, 2)), truth.T_base_sensor_waypoints, atol=atol
        )


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_poses_rotate_about_several_axes(name: str) -> None:
    R = run(PRESETS[name], 0).truth.T_base_flange_true[:, :3, :3]
    axes = []
    for i in range(len(R)):
        for j in range(i + 1, len(R)):
            w = rotvec_from_matrix(R[i].T @ R[j])
            if np.linalg.norm(w) > 0.1:
                axes.append(w / np.linalg.norm(w))
    eig = np.linalg.eigvalsh(np.array(axes).T @ np.array(axes) / len(axes))
    assert eig[0] > 0.1, eig


def pose_errors(truth_true: np.ndarray, recorded: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    E = invert_transform_stack(truth_true) @ recorded
    return E[:, :3, 3], np.array([rotvec_from_matrix(e[:3, :3]) for e in E])


def invert_transform_stack(T: np.ndarray) -> np.ndarray:
    return np.array([invert_transform(t) for t in T])


def test_recorded_poses_carry_the_configured_robot_noise() -> None:
    s = scenario_from_preset("paper", n_poses=100, resolution=50, min_arc_fraction=0.1)
    truth = run(s, 6).truth
    dt, dr = pose_errors(truth.T_base_flange_true, truth.T_base_flange_recorded)
    for err, sigma in ((dt, s.robot_sigma_translation_m), (dr, s.robot_sigma_rotation_rad)):
        assert np.std(err) == pytest.approx(sigma, rel=0.15)
        assert np.all(np.abs(err.mean(axis=0)) < 4.0 * sigma / math.sqrt(len(err)))


def test_recorded_poses_equal_truth_without_robot_noise() -> None:
    s = scenario_from_preset("ur_scancontrol", robot_sigma_translation_m=0.0)
    s = replace(s, robot_sigma_rotation_rad=0.0)
    truth = run(s, 0).truth
    assert_floats_close(truth.T_base_flange_recorded, truth.T_base_flange_true)


def test_systematic_robot_error_is_a_fixed_flange_offset() -> None:
    s = scenario_from_preset(
        "ur_scancontrol",
        robot_sigma_translation_m=0.0,
        robot_sigma_rotation_rad=0.0,
        robot_systematic_translation_m=(1e-4, -2e-4, 3e-4),
        robot_systematic_rotvec_rad=(1e-4, 0.0, -1e-4),
    )
    truth = run(s, 0).truth
    dt, dr = pose_errors(truth.T_base_flange_true, truth.T_base_flange_recorded)
    np.testing.assert_allclose(
        dt, np.tile(s.robot_systematic_translation_m, (len(dt), 1)), atol=1e-15
    )
    np.testing.assert_allclose(dr, np.tile(s.robot_systematic_rotvec_rad, (len(dr), 1)), atol=1e-15)


def stream(data: SimulatedData) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.array([p.stamp_ns for p in data.poses]),
        np.array([p.T_base_flange for p in data.poses]),
    )


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_pose_stream_is_regular_and_brackets_every_profile(name: str) -> None:
    data = run(PRESETS[name], 0)
    s = data.scenario
    stamps, _ = stream(data)
    assert stamps.dtype.kind == "i" and stamps[0] == s.epoch_ns
    assert np.all(np.diff(stamps) == round(1e9 / s.robot_rate_hz))
    profile_stamps = np.array([p.stamp_ns for p in data.profiles])
    assert np.all(np.diff(profile_stamps) > 0)
    np.testing.assert_array_equal(profile_stamps, data.truth.stamps_ns)
    assert stamps[0] < profile_stamps.min() and stamps[-1] > profile_stamps.max()
    assert all(p.frame_id == s.base_frame for p in data.poses)
    assert s.profile_topic == "/profile" and s.pose_topic == "/flange_pose"
    assert (s.sensor_frame, s.flange_frame, s.base_frame) == ("laser", "tool0", "base_link")


def test_step_stream_holds_the_recorded_pose_during_each_dwell() -> None:
    data = run(PRESETS["ur_scancontrol"], 0)
    stamps, poses = stream(data)
    for stamp, recorded in zip(
        data.truth.acquisition_stamps_ns, data.truth.T_base_flange_recorded, strict=True
    ):
        near = np.abs(stamps - stamp) <= 0.1e9  # dwell is 0.3 s, profile mid-dwell
        assert near.sum() >= 20
        assert_floats_close(poses[near], np.broadcast_to(recorded, poses[near].shape))
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert step.max() * data.scenario.robot_rate_hz < 1.0  # flange below 1 m/s: no jumps


def test_pose_jitter_is_per_message_and_small() -> None:
    s = scenario_from_preset("ur_scancontrol", pose_jitter_translation_m=1e-6)
    data = run(s, 0)
    stamps, poses = stream(data)
    k = np.searchsorted(stamps, data.truth.acquisition_stamps_ns[0])
    offsets = poses[k - 10 : k + 10, :3, 3] - data.truth.T_base_flange_recorded[0, :3, 3]
    assert 0.3e-6 < np.std(offsets) < 3e-6


def test_continuous_truth_is_taken_at_the_true_acquisition_time() -> None:
    data = run(PRESETS["continuous"], 0)
    s, truth = data.scenario, data.truth
    latency_ns = round(s.latency_s * 1e9)
    np.testing.assert_array_equal(truth.stamps_ns - truth.acquisition_stamps_ns, latency_ns)
    stamps, poses = stream(data)

    def stream_at(t_ns: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t_ns, stamps, poses[:, i, 3]) for i in range(3)], axis=1)

    p_true_time = stream_at(truth.acquisition_stamps_ns)
    p_stamped = stream_at(truth.stamps_ns)
    recorded = truth.T_base_flange_recorded[:, :3, 3]
    assert np.max(np.linalg.norm(p_true_time - recorded, axis=1)) < 2e-6
    shift = np.linalg.norm(p_stamped - recorded, axis=1)
    assert np.max(shift) > 1e-4  # the robot moves: a 4 ms latency shifts the pose visibly
    assert len(data.profiles) > 2 * s.n_poses


def test_a_sensor_override_changes_only_the_terms_it_names() -> None:
    """``simulate --profiler-errors gap_rate=0`` (how the committed bags of the real
    profilers' presets are regenerated without the faces added later)."""
    preset = PRESETS["cylinder_gocator"]
    assert preset.sensor.gap_rate > 0.0
    changed = scenario_from_preset("cylinder_gocator", sensor={"gap_rate": 0.0})
    assert changed.sensor == replace(preset.sensor, gap_rate=0.0)
    sphere = sphere_scenario_from_preset("sphere_sszn", sensor={"x_scale_error": 0.0})
    assert sphere.rig.sensor == replace(SPHERE_PRESETS["sphere_sszn"].rig.sensor, x_scale_error=0.0)
    with pytest.raises(InputError, match="bow"):
        scenario_from_preset("cylinder_gocator", sensor={"bow": 1.0})


def test_same_seed_same_output_other_seed_other_output() -> None:
    s = PRESETS["ur_scancontrol"]
    a, b, c = simulate(s, 11), simulate(s, 11), simulate(s, 12)
    for pa, pb in zip(a.profiles, b.profiles, strict=True):
        assert pa.stamp_ns == pb.stamp_ns
        assert_floats_close(pa.points, pb.points)
    for ia, ib in zip(a.intensities, b.intensities, strict=True):
        assert_floats_close(ia, ib)
    assert_floats_close(stream(a)[1], stream(b)[1])
    assert not np.array_equal(a.truth.T_base_flange_true[0], c.truth.T_base_flange_true[0])
    assert not np.array_equal(a.truth.T_base_flange_recorded, c.truth.T_base_flange_recorded)


def test_sensor_noise_has_the_configured_sigma() -> None:
    # Noise draws do not change the poses, so the two runs differ by the noise alone.
    noisy, exact = run(PRESETS["paper"], 4), run(quiet(PRESETS["paper"]), 4)
    assert_floats_close(noisy.truth.T_base_flange_true, exact.truth.T_base_flange_true)
    diff = np.concatenate(
        [valid_points(noisy, k) - valid_points(exact, k) for k in range(len(noisy.profiles))]
    )
    assert np.std(diff[:, 0]) == pytest.approx(noisy.scenario.sigma_lateral_m, rel=0.1)
    assert np.std(diff[:, 2]) == pytest.approx(noisy.scenario.sigma_depth_m, rel=0.1)


def test_organised_and_dense_carry_the_same_points() -> None:
    organised = scenario_from_preset("ur_scancontrol", organised=True)
    dense = replace(organised, organised=False)
    a, b = run(organised, 8), run(dense, 8)
    for k, (pa, pb) in enumerate(zip(a.profiles, b.profiles, strict=True)):
        valid = a.truth.valid[k]
        assert pa.points.shape == (organised.resolution, 3)
        assert np.all(np.isnan(pa.points[~valid])) and np.all(np.isfinite(pa.points[valid]))
        np.testing.assert_array_equal(pb.points, pa.points[valid])
        ia, ib = a.intensities[k], b.intensities[k]
        assert ia is not None and ib is not None
        np.testing.assert_array_equal(ib, ia[valid])
        assert np.all(ia[~valid] == 0.0) and np.all((ia >= 0.0) & (ia <= 1.0))


def test_spike_and_dropout_fractions_match_the_configuration() -> None:
    s = scenario_from_preset("ur_scancontrol", spike_fraction=0.05, dropout_fraction=0.1)
    truth = run(s, 9).truth
    returned = truth.valid | truth.dropout
    assert truth.dropout.sum() / returned.sum() == pytest.approx(0.1, abs=0.01)
    assert truth.spike.sum() / truth.valid.sum() == pytest.approx(0.05, abs=0.01)


def test_intensity_follows_incidence_and_glints_on_spikes() -> None:
    s = scenario_from_preset("ur_scancontrol", spike_fraction=0.05)
    data = run(s, 10)
    intensities = [i for i in data.intensities if i is not None]
    assert len(intensities) == len(data.profiles)  # organised: rows align with the rays
    values = np.concatenate([i[data.truth.valid[k]] for k, i in enumerate(intensities)])
    spikes = data.truth.spike[data.truth.valid]
    assert np.all(values[spikes] >= 0.8)
    assert np.all(values[~spikes] <= s.cylinder_reflectance * (1.0 + 6.0 * s.intensity_noise))
    assert np.median(values[~spikes]) > 0.3


def test_paper_preset_matches_the_paper() -> None:
    s = PRESETS["paper"]
    eq17 = np.array(
        [[0.5771, 0.4940, 0.6503], [-0.8153, 0.3021, 0.4940], [0.0475, -0.8153, 0.5771]]
    )
    X = s.T_flange_sensor
    np.testing.assert_allclose(X[:3, :3], eq17, atol=5e-4)
    np.testing.assert_allclose(X[:3, :3].T @ X[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(X[:3, 3], [0.150, 0.200, 0.250])
    cylinder = s.cylinder()
    np.testing.assert_allclose(cylinder.direction, np.array([3.0, 1.0, 1.0]) / math.sqrt(11.0))
    offset = np.array([0.001, 0.001, 0.001]) - cylinder.point
    assert np.linalg.norm(np.cross(offset, cylinder.direction)) < 1e-15
    assert abs(cylinder.point @ cylinder.direction) < 1e-15
    assert cylinder.radius == 0.020 and s.n_poses == 50
    assert (s.sigma_depth_m, s.robot_sigma_translation_m) == (5e-6, 1e-4)
    assert s.robot_sigma_rotation_rad == pytest.approx(math.radians(0.01))


@pytest.mark.parametrize("seed", range(4))
def test_random_scenarios_simulate(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = random_scenario(rng, n_poses_range=(12, 20))
    assert random_scenario(np.random.default_rng(seed), n_poses_range=(12, 20)) == s
    assert 12 <= s.n_poses <= 20
    data = run(s, seed)
    assert len(data.profiles) == s.n_poses
    check_on_surfaces(data, 6.0 * sigma_3d(s))
    cut = cut_angles(s, data.truth.T_base_sensor_waypoints)
    assert np.all((cut >= math.radians(40.0) - 1e-9) & (cut <= math.radians(75.0) + 1e-9))


def test_scenario_round_trips_through_plain_values() -> None:
    s = PRESETS["ur_scancontrol"]
    values: dict[str, Any] = {
        k: list(v) if isinstance(v, tuple) else v for k, v in asdict(s).items()
    }
    assert Scenario(**values) == s


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"z_min_m": 0.3}, "z_max_m"),
        ({"latency_s": 0.5}, "latency_s"),
        ({"resolution": 2}, "resolution"),
        ({"hand_eye_rotation_xyzw": (0.0, 0.0, 0.0, 2.0)}, "hand_eye_rotation_xyzw"),
        ({"short_axis_cut_range_rad": (0.9, 0.8)}, "short_axis_cut_range_rad"),
        ({"motion": "teleport"}, "motion"),
        ({"no_such_field": 1}, "unknown scenario field"),
    ],
)
def test_bad_scenarios_are_rejected_with_a_reason(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(InputError, match=message):
        scenario_from_preset("ur_scancontrol", **overrides)


def test_unknown_preset_and_infeasible_geometry_are_reported() -> None:
    with pytest.raises(InputError, match="ur_scancontrol"):
        scenario_from_preset("nope")
    too_narrow = scenario_from_preset("paper", fan_half_angle_rad=math.radians(3.0))
    with pytest.raises(InputError, match="feasible sensor poses"):
        simulate(too_narrow, 0)


# ------------------------------------------------------------------- clutter (sim.clutter)

SMALL_CLUTTERED = scenario_from_preset(
    "cluttered_camera", n_poses=18, robot_sigma_translation_m=0.0, robot_sigma_rotation_rad=0.0
)


def test_camera_profiler_scales_x_and_quantises_depth() -> None:
    s = replace(quiet(SMALL_CLUTTERED), edge_bias_m=0.0)
    data = run(s, 1)
    truth = data.truth
    for k, profile in enumerate(data.profiles):
        true = truth.points_true_sensor[k][truth.valid[k]]
        measured = profile.points
        np.testing.assert_allclose(measured[:, 0], (1.0 + s.lateral_scale_error) * true[:, 0])
        steps = measured[:, 2] / s.depth_quantum_m
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
        assert np.all(np.abs(measured[:, 2] - true[:, 2]) <= 0.5 * s.depth_quantum_m + 1e-12)


def test_grazing_bias_moves_steep_returns_out_of_the_surface() -> None:
    s = replace(quiet(plain(SMALL_CLUTTERED)), edge_bias_m=3e-5)
    data = run(s, 1)
    truth = data.truth
    for k, T in enumerate(sensor_poses(data)):
        side = truth.surface[k][truth.valid[k]] == Surface.SIDE
        p = apply_transform(T, data.profiles[k].points[side])
        dist, _ = surface_distance_and_normal(s, p, np.full(len(p), Surface.SIDE))
        assert np.all(dist >= -1e-9) and np.all(dist <= 10 * s.edge_bias_m + 1e-9)
        assert dist.max() > s.edge_bias_m  # the steep ends move most


def test_robot_error_field_shifts_each_profile_by_its_offset() -> None:
    data = run(SMALL_CLUTTERED, 2)
    truth = data.truth
    offsets = truth.field_offset_sensor_m
    assert offsets is not None
    T_fs = truth.T_flange_sensor
    for k in range(len(data.profiles)):
        true = truth.points_true_sensor[k][truth.valid[k]][:5]
        recorded = apply_transform(truth.T_base_flange_recorded[k] @ T_fs, true)
        shifted = apply_transform(truth.T_base_flange_true[k] @ T_fs, true + offsets[k])
        np.testing.assert_allclose(recorded, shifted, atol=1e-9)
    amplitude = np.array(SMALL_CLUTTERED.robot_field_m)
    assert np.all(np.abs(offsets) <= 2.5 * amplitude + 1e-12)
    assert np.all(np.abs(offsets).max(axis=0) >= 0.2 * amplitude)


def test_poses_come_in_clusters() -> None:
    s = SMALL_CLUTTERED
    T = run(s, 3).truth.T_base_sensor_waypoints
    owner = np.arange(s.n_poses) * s.pose_clusters // s.n_poses
    for c in range(s.pose_clusters):
        members = T[owner == c]
        spread = np.linalg.norm(members[:, :3, 3] - members[0, :3, 3], axis=1)
        angles = [rotation_angle(members[0, :3, :3].T @ R) for R in members[:, :3, :3]]
        assert spread.max() <= 2.0 * math.sqrt(3.0) * s.cluster_spread_m + 1e-9
        assert max(angles) <= 2.0 * math.sqrt(3.0) * s.cluster_spread_rad + 1e-9


def test_fixture_fin_is_seen_on_its_plane() -> None:
    data = run(quiet(SMALL_CLUTTERED), 2)
    s, truth = data.scenario, data.truth
    axis = s.axis_unit
    direction = np.array(s.fixture_direction)
    normal = np.cross(axis, direction - (direction @ axis) * axis)
    seen = 0
    for k, T in enumerate(sensor_poses(data)):
        fin = truth.surface[k] == Surface.FIXTURE
        p = apply_transform(T, truth.points_true_sensor[k][fin & truth.valid[k]])
        h, r = axial_radial(s, p)
        w = p - np.array(s.cylinder_base_m)
        np.testing.assert_allclose(w @ normal, 0.0, atol=1e-9)
        assert np.all((h >= s.fixture_band_m[0] - 1e-9) & (h <= s.fixture_band_m[1] + 1e-9))
        assert np.all(r <= s.cylinder_radius_m + s.fixture_length_m + 1e-9)
        seen += len(p)
    assert seen > 0
