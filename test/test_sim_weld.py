"""Weld-seam simulator: groove geometry, view patterns, errors, determinism, presets.

The checks recompute the geometry from the scenario (seam, bisector, opening angle) rather
than calling the simulator's ray caster.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np
import pytest
from _compare import assert_floats_close

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    apply_transform,
    rotation_angle,
    rotvec_from_matrix,
)
from linelaser_calib.core.profile.cleaning import CleaningConfig, clean_profile
from linelaser_calib.core.profile.corner import CornerConfig, fit_corner
from linelaser_calib.sim.weld import (
    WELD_PRESETS,
    WeldScenario,
    WeldSimulatedData,
    simulate_weld,
    weld_scenario_from_preset,
)


@lru_cache(maxsize=16)
def run(name: str, seed: int, **overrides: Any) -> WeldSimulatedData:
    return simulate_weld(weld_scenario_from_preset(name, **overrides), seed)


def flank_planes(scenario: WeldScenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seam s, and per flank the unit in-plane direction f and the plane normal, from the
    scenario's numbers."""
    s = np.asarray(scenario.seam_direction, dtype=float)
    s /= np.linalg.norm(s)
    b = np.asarray(scenario.groove_bisector, dtype=float)
    b -= (b @ s) * s
    b /= np.linalg.norm(b)
    half = scenario.opening_angle_rad / 2.0
    m = np.cross(s, b)
    f = np.array([math.cos(half) * b + k * math.sin(half) * m for k in (1.0, -1.0)])
    return s, f, np.cross(s, f)


@pytest.mark.parametrize("name", sorted(WELD_PRESETS))
def test_returns_lie_on_the_flanks(name: str) -> None:
    data = run(name, 0, sigma_depth_m=0.0, sigma_lateral_m=0.0, spike_fraction=0.0)
    truth = data.truth
    scenario = truth.scenario
    s, f, n = flank_planes(scenario)
    T_sensor = truth.T_base_flange_true @ truth.T_flange_sensor
    p = truth.weld_point_m
    for k, profile in enumerate(data.profiles):
        ok = truth.valid[k]
        base = apply_transform(T_sensor[k], profile.points[ok]) - p
        flank = truth.flank[k][ok] - 1
        assert np.all(flank >= 0)
        np.testing.assert_allclose(np.einsum("ij,ij->i", base, n[flank]), 0.0, atol=1e-12)
        across = np.einsum("ij,ij->i", base, f[flank])
        assert np.all((across >= -1e-12) & (across <= scenario.flank_width_m + 1e-12))
        assert np.all(np.abs(base @ s) <= scenario.seam_half_length_m + 1e-12)
        for side in (0, 1):
            assert np.sum(flank == side) >= 0.8 * scenario.min_flank_points


@pytest.mark.parametrize("name", sorted(WELD_PRESETS))
def test_every_laser_plane_passes_through_the_weld_point(name: str) -> None:
    truth = run(name, 1).truth
    T_sensor = truth.T_base_flange_true @ truth.T_flange_sensor
    in_sensor = apply_transform(np.linalg.inv(T_sensor), np.tile(truth.weld_point_m, (20, 1)))
    np.testing.assert_allclose(in_sensor[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(truth.corner_true_sensor, in_sensor, atol=1e-12)
    np.testing.assert_allclose(truth.corner_true_base, np.tile(truth.weld_point_m, (20, 1)))
    rig = truth.scenario.rig
    assert np.all((in_sensor[:, 2] > rig.z_min_m) & (in_sensor[:, 2] < rig.z_max_m))


def test_aim_error_moves_the_corner_along_the_seam() -> None:
    sigma = 2e-4
    truth = run("weld_seam_general", 2, aim_sigma_m=sigma).truth
    offset = truth.corner_true_base - truth.weld_point_m
    along = offset @ truth.seam_direction
    np.testing.assert_allclose(np.cross(offset, truth.seam_direction), 0.0, atol=1e-12)
    assert 0.3 * sigma < np.std(along) < 3.0 * sigma
    T_sensor = truth.T_base_flange_true @ truth.T_flange_sensor
    np.testing.assert_allclose(truth.corner_true_sensor[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(
        apply_transform(T_sensor, truth.corner_true_sensor), truth.corner_true_base, atol=1e-12
    )


def test_paper_pattern_keeps_one_orientation_and_steps_in_z() -> None:
    truth = run("weld_seam", 3).truth
    scenario = truth.scenario
    R = truth.T_base_flange_true[:, :3, :3]
    assert max(rotation_angle(R[0].T @ Rk) for Rk in R) < 1e-12
    steps = np.diff(truth.T_base_flange_true[:, :3, 3], axis=0)
    np.testing.assert_allclose(steps[:, 2], scenario.step_m, atol=1e-12)
    # The x-y correction is along the laser-plane normal's horizontal part only.
    y_axis = (R[0] @ truth.T_flange_sensor[:3, :3])[:, 1]
    horizontal = y_axis - y_axis[2] * np.array([0.0, 0.0, 1.0])
    cross = steps[:, 0] * horizontal[1] - steps[:, 1] * horizontal[0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-12)
    # The weld point moves through the sensor along one line.
    corners = truth.corner_true_sensor[:, [0, 2]]
    singular = np.linalg.svd(corners - corners.mean(axis=0), compute_uv=False)
    assert singular[1] < 1e-9 * singular[0]


def test_sideways_spread_moves_the_point_along_the_line() -> None:
    truth = run("weld_seam", 3, lateral_spread_m=0.01).truth
    corners = truth.corner_true_sensor[:, [0, 2]]
    singular = np.linalg.svd(corners - corners.mean(axis=0), compute_uv=False)
    assert singular[1] > 0.1 * singular[0]


def test_general_pattern_tilts_the_flange() -> None:
    truth = run("weld_seam_general", 4).truth
    R = truth.T_base_flange_true[:, :3, :3]
    angles = [rotation_angle(R[0].T @ Rk) for Rk in R]
    assert max(angles) > math.radians(15.0)


def test_robot_errors_follow_the_rig() -> None:
    exact = run("weld_seam_general", 5, robot_sigma_translation_m=0.0, robot_sigma_rotation_rad=0.0)
    np.testing.assert_allclose(
        exact.truth.T_base_flange_recorded, exact.truth.T_base_flange_true, atol=1e-12
    )
    sigma_t, sigma_r = 1e-4, math.radians(0.01)
    noisy = run(
        "weld_seam_general",
        5,
        robot_sigma_translation_m=sigma_t,
        robot_sigma_rotation_rad=sigma_r,
        n_poses=60,
    ).truth
    E = np.linalg.inv(noisy.T_base_flange_true) @ noisy.T_base_flange_recorded
    assert 0.7 * sigma_t < np.std(E[:, :3, 3]) < 1.3 * sigma_t
    assert 0.7 * sigma_r < np.std(rotvec_from_matrix(E[:, :3, :3])) < 1.3 * sigma_r


def test_taught_point_error() -> None:
    truth = run("weld_seam", 6, teach_sigma_m=1e-4).truth
    error = truth.taught_point_m - truth.weld_point_m
    assert 0.0 < np.linalg.norm(error) < 6e-4
    assert_floats_close(
        run("weld_seam", 6).truth.taught_point_m, run("weld_seam", 6).truth.weld_point_m
    )


def test_stream_and_profiles_pair_up_and_are_deterministic() -> None:
    a = run("weld_seam", 7)
    b = simulate_weld(weld_scenario_from_preset("weld_seam"), 7)
    for pa, pb in zip(a.profiles, b.profiles, strict=True):
        assert pa.stamp_ns == pb.stamp_ns
        assert_floats_close(pa.points, pb.points)
    stamps = np.array([p.stamp_ns for p in a.poses])
    assert np.all(np.diff(stamps) > 0)
    assert stamps[0] < a.profiles[0].stamp_ns and a.profiles[-1].stamp_ns < stamps[-1]
    rig = a.scenario
    assert len(a.profiles) == rig.n_poses
    assert all(len(p.points) == rig.resolution for p in a.profiles)  # organised output
    assert a.intensities[0] is not None


@pytest.mark.parametrize("name", sorted(WELD_PRESETS))
def test_profiles_give_the_true_corner(name: str) -> None:
    data = run(name, 8)
    rng = np.random.default_rng(0)
    for k, profile in enumerate(data.profiles):
        cleaned = clean_profile(profile.points, CleaningConfig())
        fit = fit_corner(cleaned.points_xz, CornerConfig(), rng)
        error = fit.corner_xz - data.truth.corner_true_sensor[k, [0, 2]]
        assert np.linalg.norm(error) < 1e-5


def test_preset_overrides_route_to_the_rig() -> None:
    scenario = weld_scenario_from_preset("weld_seam", n_poses=12, step_m=0.002)
    assert scenario.rig.n_poses == 12 and scenario.step_m == 0.002
    with pytest.raises(InputError, match="unknown weld scenario field"):
        weld_scenario_from_preset("weld_seam", cylinder_colour=1)
    with pytest.raises(InputError, match="unknown weld preset"):
        weld_scenario_from_preset("fillet")


def test_infeasible_patterns_say_what_to_change() -> None:
    with pytest.raises(InputError, match="Reduce step_m"):
        simulate_weld(weld_scenario_from_preset("weld_seam", step_m=0.01), 0)
    with pytest.raises(InputError, match="opening_angle_rad"):
        weld_scenario_from_preset("weld_seam", opening_angle_rad=math.pi)
    with pytest.raises(InputError, match="step-and-shoot"):
        weld_scenario_from_preset("weld_seam", motion="continuous")
