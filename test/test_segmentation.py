"""Profile segmentation, the noise estimate and the cylinder's arc in a cluttered scene."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.profile.segmentation import (
    SegmentKind,
    estimate_noise,
    segment_profile,
    segment_profiles,
)
from linelaser_calib.core.targets.cylinder import CylinderConfig, CylinderSection
from linelaser_calib.core.targets.cylinder.arc import (
    fit_arc_in_scene,
    grazing_ends_biased,
    radius_mismatch,
    without_grazing_ends,
)
from linelaser_calib.core.targets.cylinder.ellipse import EllipseConfig
from linelaser_calib.io.results import read_truth_yaml
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.sim import Surface, scenario_from_preset, simulate

RADIUS = 0.0125
CENTRE = np.array([0.01, 1.0])  # (x, z) of the circle's centre, m
SIGMA = 50e-6
QUANTUM = 16e-6
PITCH = 0.2e-3


def _cluttered_profile(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A camera-like profile: background plane on both sides (behind a gap), the arc of a
    12.5 mm circle (its grazing ends left out), and a ramp that starts at the arc's right
    end with no gap. Returns the points (N, 2) and which of them are on the arc."""
    half = 0.93 * RADIUS
    x_arc = np.arange(CENTRE[0] - half, CENTRE[0] + half, PITCH)
    z_arc = CENTRE[1] - np.sqrt(RADIUS**2 - (x_arc - CENTRE[0]) ** 2)
    x_end, z_end = x_arc[-1], z_arc[-1]
    x_ramp = np.arange(x_end + PITCH, x_end + 0.06, PITCH)
    z_ramp = z_end + (x_ramp - x_end) * math.tan(math.radians(35.0))
    x_left = np.arange(-0.30, -0.03, PITCH * 1.4)
    x_right = np.arange(0.12, 0.35, PITCH * 1.4)
    z_back = 1.40 - 0.1 * np.concatenate([x_left, x_right])
    x = np.concatenate([x_left, x_arc, x_ramp, x_right])
    z = np.concatenate([z_back[: len(x_left)], z_arc, z_ramp, z_back[len(x_left) :]])
    on_arc = np.zeros(len(x), dtype=bool)
    on_arc[len(x_left) : len(x_left) + len(x_arc)] = True
    z = z + rng.normal(0.0, SIGMA, len(z))
    z = np.round(z / QUANTUM) * QUANTUM
    return np.stack([x, z], axis=1), on_arc


def test_arc_found_among_planes_and_a_ramp_with_no_gap() -> None:
    rng = np.random.default_rng(3)
    points, on_arc = _cluttered_profile(rng)
    assert on_arc.mean() < 0.1  # the arc is a small share of the profile
    segmented = segment_profile(points)
    lines = segmented.lines()
    assert len(lines) >= 3  # left and right background, and the ramp
    for line in lines:
        assert on_arc[line.indices].mean() < 0.05
    arc = fit_arc_in_scene(points, EllipseConfig(), rng)
    picked = on_arc[arc.rows][arc.ellipse.inliers]
    assert picked.mean() > 0.95
    assert picked.sum() > 0.85 * on_arc.sum()
    assert np.linalg.norm(arc.ellipse.centre_xz - CENTRE) < 0.3e-3
    assert abs(arc.ellipse.semi_axes[1] - RADIUS) < 0.3e-3


def test_noise_estimate_sees_noise_and_quantisation() -> None:
    rng = np.random.default_rng(4)
    points, _ = _cluttered_profile(rng)
    noise = estimate_noise(points[np.argsort(np.arctan2(points[:, 0], points[:, 1]))])
    assert noise.sigma_m == pytest.approx(SIGMA, rel=0.2)
    assert noise.depth_quantum_m == pytest.approx(QUANTUM, rel=0.01)
    # Noise far below the quantum: the rounding sets the floor, q / sqrt(12).
    x = np.arange(0.0, 0.1, PITCH)
    z = np.round((1.0 + 0.2 * x + rng.normal(0.0, 1e-7, len(x))) / QUANTUM) * QUANTUM
    quiet = estimate_noise(np.stack([x, z], axis=1))
    assert quiet.sigma_m >= QUANTUM / math.sqrt(12.0) * 0.99


def test_noise_estimate_against_simulator_truth() -> None:
    """The estimate is the noise normal to the surface: on a surface at angle theta to the
    line, depth noise sigma_z and lateral noise sigma_x give
    sqrt((sigma_z cos theta)^2 + (sigma_x sin theta)^2), theta from the true points."""
    scenario = scenario_from_preset("cluttered_camera", n_poses=12, pose_clusters=3)
    data = simulate(scenario, 5)
    truth = data.truth
    assert truth.sigma_factor is not None
    ratios = []
    for k, profile in enumerate(data.profiles):
        xz = profile.points[:, [0, 2]]
        xz = xz[np.argsort(np.arctan2(xz[:, 0], xz[:, 1]))]
        true_xz = truth.points_true_sensor[k][truth.valid[k]][:, [0, 2]]
        true_xz = true_xz[np.argsort(np.arctan2(true_xz[:, 0], true_xz[:, 1]))]
        theta = np.arctan2(np.diff(true_xz[:, 1]), np.diff(true_xz[:, 0]))
        factor = truth.sigma_factor[k]
        normal_sigma = np.hypot(
            scenario.sigma_depth_m * factor * np.cos(theta),
            scenario.sigma_lateral_m * factor * np.sin(theta),
        )
        ratios.append(estimate_noise(xz).sigma_m / float(np.median(normal_sigma)))
    assert np.median(ratios) == pytest.approx(1.0, abs=0.1)
    assert min(ratios) > 0.75 and max(ratios) < 1.25


def test_simulated_arcs_are_extracted_next_to_the_fixture() -> None:
    scenario = scenario_from_preset("cluttered_camera", n_poses=30, pose_clusters=6)
    data = simulate(scenario, 2)
    truth = data.truth
    touching = np.flatnonzero(np.sum(truth.valid & (truth.surface == Surface.FIXTURE), axis=1))
    assert len(touching)
    rng = np.random.default_rng(0)
    shares = []
    for k in range(len(data.profiles)):
        valid = truth.valid[k]
        points = data.profiles[k].points[:, [0, 2]]
        side = truth.surface[k][valid] == Surface.SIDE
        shares.append(side.mean())
        arc = fit_arc_in_scene(points, EllipseConfig(), rng)
        picked = side[arc.rows][arc.ellipse.inliers]
        assert picked.mean() > 0.97, k
        assert picked.sum() > 0.7 * side.sum(), k
    assert np.median(shares) < 0.15


def test_biased_grazing_ends_are_found_over_a_recording_and_trimmed() -> None:
    rng = np.random.default_rng(6)
    angle = np.linspace(-1.45, 1.45, 300)  # surface normal from the sensor's view, rad
    normal = np.stack([np.sin(angle), -np.cos(angle)], axis=1)
    outward = 20e-6 * np.maximum(1.0 / np.cos(angle) - 1.0, 0.0)
    clean_shifts, biased_shifts = [], []
    for _ in range(12):
        clean = CENTRE + RADIUS * normal + rng.normal(0.0, 20e-6, (len(angle), 2))
        biased = clean + outward[:, None] * normal
        clean_shifts.append(fit_arc_in_scene(clean, EllipseConfig(), rng).grazing_shift_sigmas)
        arc = fit_arc_in_scene(biased, EllipseConfig(), rng)
        biased_shifts.append(arc.grazing_shift_sigmas)
        trimmed = without_grazing_ends(
            arc.points_xz, arc.grazing, arc.ellipse_config, arc.noise_sigma_m, None
        )
        assert trimmed is not None and arc.grazing.sum() > 0
        assert not np.any(trimmed.inliers & arc.grazing)
        trimmed_error = abs(trimmed.semi_axes[1] - RADIUS)
        assert trimmed_error < abs(arc.ellipse.semi_axes[1] - RADIUS)
    assert grazing_ends_biased(clean_shifts) is None
    shift = grazing_ends_biased(biased_shifts)
    assert shift is not None and shift > 0.0


def test_radius_mismatch_names_both_numbers_and_the_scale() -> None:
    rng = np.random.default_rng(7)
    axes = 0.01308 + rng.normal(0.0, 0.1e-3, 120)
    message = radius_mismatch(axes, RADIUS)
    assert message is not None
    assert f"{np.median(axes) * 1e3:.2f}" in message and "12.50 mm" in message
    assert "scale" in message
    assert radius_mismatch(RADIUS + rng.normal(0.0, 0.1e-3, 120), RADIUS) is None
    assert radius_mismatch(axes, None) is None


def test_segments_partition_in_scan_order() -> None:
    rng = np.random.default_rng(8)
    points, _ = _cluttered_profile(rng)
    segmented = segment_profile(points[::-1])
    rows = np.concatenate([s.indices for s in segmented.segments])
    assert len(np.unique(rows)) == len(rows)
    kinds = {s.kind for s in segmented.segments}
    assert kinds == {SegmentKind.LINE, SegmentKind.CURVE}


def test_profiles_segmented_together_are_each_segmented_alone() -> None:
    # The scan order, noise and gaps of a batch are each profile's own (quantised or not).
    rng = np.random.default_rng(5)
    profiles = [_cluttered_profile(rng)[0] for _ in range(6)]
    profiles[1][:, 1] += rng.normal(0.0, 1e-6, len(profiles[1]))  # no longer quantised
    profiles[2] = profiles[2][rng.permutation(len(profiles[2]))]
    profiles[3] = profiles[3][:2]
    profiles[4] = profiles[4][:0]
    for alone, together in zip(
        [segment_profile(p) for p in profiles], segment_profiles(profiles), strict=True
    ):
        assert together.noise.sigma_m == pytest.approx(alone.noise.sigma_m, rel=1e-12)
        assert together.noise.depth_quantum_m == pytest.approx(
            alone.noise.depth_quantum_m, rel=1e-12, abs=1e-15
        )
        assert [s.kind for s in together.segments] == [s.kind for s in alone.segments]
        for a, b in zip(alone.segments, together.segments, strict=True):
            np.testing.assert_array_equal(b.indices, a.indices)
    assert segment_profiles(profiles)[0].noise.depth_quantum_m == pytest.approx(QUANTUM)
    assert segment_profiles(profiles)[1].noise.depth_quantum_m == pytest.approx(0.0, abs=1e-15)


def test_committed_cluttered_bag_uses_every_profile_and_names_the_radius_mismatch() -> None:
    """The given radius is the bar's true one, but the sensor's 0.5 % along-line scale and
    the grazing-angle bias make the profiles fit a larger one: the warning names both."""
    bag = Path(__file__).resolve().parent.parent / "bags" / "cluttered_camera"
    truth = read_truth_yaml(bag / "truth.yaml")
    run = calibrate_bag(bag, PipelineConfig(target_config=CylinderConfig(radius_m=RADIUS)))
    result = run.result
    assert not result.samples_rejected
    mismatch = [w for w in result.warnings if w.startswith("the profiles fit a radius")]
    assert len(mismatch) == 1
    assert "12.50 mm" in mismatch[0] and "scale" in mismatch[0]
    free = calibrate_bag(bag, PipelineConfig()).result
    assert isinstance(free.target, CylinderSection)
    assert free.target.cylinder.radius > RADIUS
    assert not any(w.startswith("the profiles fit a radius") for w in free.warnings)
    rotation, translation = transform_error(free.T_flange_sensor, truth.T_flange_sensor)
    assert translation < 5e-3 and rotation < math.radians(0.5)
