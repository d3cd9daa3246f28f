"""The straight-line target (teach-free seam): model, features, solve, clock offset, diagnosis.

Everything is checked against the simulator's truth (:mod:`linelaser_calib.sim.line`).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from linelaser_calib.cli import main
from linelaser_calib.core.errors import DegenerateError, ModelMismatch
from linelaser_calib.core.geometry import invert_transform, transform_error
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import SolveContext
from linelaser_calib.core.targets.known_point import CornerSample
from linelaser_calib.core.targets.line.config import LineConfig
from linelaser_calib.core.targets.line.features import LineFeatureConfig, extract_line_feature
from linelaser_calib.core.targets.line.model import (
    Line,
    line_residuals,
    retract_line,
    solve_line_linear,
)
from linelaser_calib.core.targets.line.section import LineSection, read_line_section
from linelaser_calib.core.types import Rejection, Sample
from linelaser_calib.io.results import read_result_yaml, read_truth_yaml
from linelaser_calib.sim.line import LineSimulatedData, line_scenario_from_preset, simulate_line
from linelaser_calib.sim.sensor_models import with_faces

BAG = Path(__file__).resolve().parents[1] / "bags" / "line"
MOVING = PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)


@pytest.fixture(scope="module")
def features_run() -> LineSimulatedData:
    """A seam-tracker S-sweep: three feature points per message."""
    return simulate_line(line_scenario_from_preset("line_features"), 3)


def _paired(data: LineSimulatedData, offset_s: float) -> list[Sample]:
    return pair_profiles(
        data.profiles, data.poses, replace(MOVING, clock_offset_s=offset_s)
    ).samples


def _truth_line(data: LineSimulatedData) -> Line:
    return Line(data.truth.line_point, data.truth.line_direction)


def test_simulated_corners_lie_on_the_seam_and_the_clocks_follow_the_preset(
    features_run: LineSimulatedData,
) -> None:
    truth = features_run.truth
    assert np.max(_truth_line(features_run).distances(truth.corner_true_base)) < 1e-12
    np.testing.assert_allclose(np.abs(truth.corner_true_sensor[:, 1]), 0.0, atol=1e-12)
    latency = truth.stamps_ns - truth.acquisition_stamps_ns
    assert set(latency.tolist()) == {12_000_000}
    gaps = np.diff([p.stamp_ns for p in features_run.poses]) * 1e-9
    assert np.all(gaps > 0.0)
    assert abs(float(np.mean(gaps)) - 0.004) < 1e-5
    # Stamp jitter of 0.25 ms per message: the gaps scatter by 0.25 ms * sqrt(2).
    assert 0.3e-3 < float(np.std(gaps)) < 0.42e-3
    # The S: the seam crosses the laser line over tens of mm, at changing depths.
    assert np.ptp(truth.corner_true_sensor[:, 0]) > 0.04
    assert np.ptp(truth.corner_true_sensor[:, 2]) > 0.03
    middle = np.array([p.points[1] for p in features_run.profiles])
    np.testing.assert_allclose(middle[:, [0, 2]], truth.corner_true_sensor[:, [0, 2]], atol=5e-5)


def test_residuals_vanish_on_the_line_and_jacobians_match_finite_differences(
    features_run: LineSimulatedData,
) -> None:
    truth = features_run.truth
    c = truth.corner_true_sensor[:, [0, 2]]
    T = truth.T_base_flange_true
    X = truth.T_flange_sensor
    R_L, offset = _truth_line(features_run).frame()
    M = len(c)
    W = np.tile(np.eye(2) / 1e-5, (M, 1, 1))
    rng = np.random.default_rng(0)
    # A state on the line with pose corrections: move the flange by δ and the recorded pose
    # by its inverse, so every corrected pose is the true one.
    pose = rng.normal(size=(M, 6)) * np.array([1e-3] * 3 + [1e-3] * 3)
    D = np.tile(np.eye(4), (M, 1, 1))
    D[:, :3, :3] = Rotation.from_rotvec(pose[:, :3]).as_matrix()
    D[:, :3, 3] = pose[:, 3:]
    D_inv = np.tile(np.eye(4), (M, 1, 1))
    D_inv[:, :3, :3] = np.transpose(D[:, :3, :3], (0, 2, 1))
    D_inv[:, :3, 3] = -np.einsum("mji,mj->mi", D[:, :3, :3], D[:, :3, 3])
    T_recorded = T @ D_inv
    base = line_residuals(c, W, T_recorded, X, R_L, offset, pose)
    assert np.max(np.abs(base.offsets_xz)) < 1e-11
    assert np.min(base.crossing_sine) > 0.3

    h = 1e-7

    def moved(d_hand_eye: np.ndarray, d_line: np.ndarray, d_pose: np.ndarray) -> np.ndarray:
        Xm = X.copy()
        Xm[:3, :3] = X[:3, :3] @ Rotation.from_rotvec(d_hand_eye[:3]).as_matrix()
        Xm[:3, 3] += d_hand_eye[3:]
        R2, o2 = retract_line(R_L, offset, d_line)
        return line_residuals(c, W, T_recorded, Xm, R2, o2, pose + d_pose).residuals

    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        numeric = (moved(e, np.zeros(4), np.zeros((M, 6))) - base.residuals) / h
        np.testing.assert_allclose(
            numeric, base.hand_eye[:, :, k], atol=2e-6 * np.abs(numeric).max()
        )
        local = np.zeros((M, 6))
        local[:, k] = h
        numeric = (moved(np.zeros(6), np.zeros(4), local) - base.residuals) / h
        np.testing.assert_allclose(numeric, base.pose[:, :, k], atol=2e-6 * np.abs(numeric).max())
    for k in range(4):
        e = np.zeros(4)
        e[k] = h
        numeric = (moved(np.zeros(6), e, np.zeros((M, 6))) - base.residuals) / h
        np.testing.assert_allclose(numeric, base.line[:, :, k], atol=2e-6 * np.abs(numeric).max())


def test_line_retraction_keeps_four_degrees_of_freedom() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        line = Line.through(rng.normal(size=3), rng.normal(size=3))
        R_L, offset = line.frame()
        np.testing.assert_allclose(R_L.T @ R_L, np.eye(3), atol=1e-12)
        R2, o2 = retract_line(R_L, offset, rng.normal(size=4) * 0.1)
        moved = Line.from_frame(R2, o2)
        assert abs(float(moved.point @ moved.direction)) < 1e-12
        assert abs(float(np.linalg.norm(moved.direction)) - 1.0) < 1e-12
        again = Line.through(moved.point + 0.3 * moved.direction, -moved.direction)
        np.testing.assert_allclose(again.point, moved.point, atol=1e-12)


def test_closed_form_is_exact_on_noise_free_corners(features_run: LineSimulatedData) -> None:
    truth = features_run.truth
    X, line = solve_line_linear(truth.corner_true_sensor[:, [0, 2]], truth.T_base_flange_true)
    rotation, translation = transform_error(X, truth.T_flange_sensor)
    assert rotation < 1e-9 and translation < 1e-9
    np.testing.assert_allclose(line.point, truth.line_point, atol=1e-9)
    assert abs(float(line.direction @ truth.line_direction)) > 1.0 - 1e-12


def _sample(points: list[list[float]]) -> Sample:
    return Sample(7, 123, np.eye(4), np.array(points, dtype=np.float64))


def test_feature_points_give_the_seam_point_and_are_not_too_few() -> None:
    config = LineFeatureConfig()
    rng = np.random.default_rng(0)
    alone = extract_line_feature(_sample([[0.01, 0.0, 0.1]]), config, rng)
    assert isinstance(alone, CornerSample)
    np.testing.assert_allclose(alone.corner_xz, [0.01, 0.1])
    groove = [[0.02, 0.0, 0.09], [0.001, 0.0, 0.11], [-0.018, 0.0, 0.092], [np.nan] * 3]
    root = extract_line_feature(_sample(groove), config, rng)
    assert isinstance(root, CornerSample)
    np.testing.assert_allclose(root.corner_xz, [0.001, 0.11])
    np.testing.assert_allclose(np.sqrt(np.diag(root.covariance_xz)), config.feature_point_sigma_m)
    two = extract_line_feature(_sample(groove[:2]), config, rng)
    assert isinstance(two, Rejection) and "which one is the seam" in two.reason
    flat = extract_line_feature(
        _sample([[0.0, 0.0, 0.1], [0.01, 0.0, 0.1001], [0.02, 0.0, 0.1]]), config, rng
    )
    assert isinstance(flat, Rejection) and "bend" in flat.reason


def test_line_target_on_an_s_sweep_of_feature_points(features_run: LineSimulatedData) -> None:
    target = get_target("line")
    config = LineConfig()
    samples = _paired(features_run, -0.012)
    features, rejections = target.extract(samples, config, 0, lambda *_: None)
    assert len(features) == len(samples) and not rejections
    solution = target.solve_default(features, config, SolveContext(n_samples=len(samples)))
    target.check_fit(solution, config)
    rotation, translation = transform_error(
        solution.T_flange_sensor, features_run.truth.T_flange_sensor
    )
    assert math.degrees(rotation) < 0.1 and translation < 2e-4
    assert solution.sigma_translation_m is not None and solution.sigma_rotation_rad is not None
    assert np.all(solution.sigma_translation_m < 2e-4)
    line = solution.section.line  # type: ignore[attr-defined]
    assert (
        np.max(
            _truth_line(features_run).distances(line.point + np.outer([-0.1, 0.1], line.direction))
        )
        < 5e-4
    )
    assert not solution.warnings


def test_the_profilers_x_and_z_scales_are_estimated_where_they_are_off() -> None:
    """x read 0.6 % long and z 0.2 % short (about the sensor origin): ``auto`` keeps both
    estimates, each within 3 sigma of the truth, and the hand-eye is as good as on a profiler
    without them (0.05 mm on the clean twin; 0.54 mm with the scales held). The result
    section carries them and maps the points with them."""
    base = line_scenario_from_preset("line", n_poses=24, resolution=640, profile_rate_hz=10.0)
    sensor = with_faces(base.rig.sensor, "scales")
    data = simulate_line(replace(base, rig=replace(base.rig, sensor=sensor)), 3)
    target = get_target("line")
    config = LineConfig()
    samples = _paired(data, -base.rig.latency_s)
    features, rejections = target.extract(samples, config, 0, lambda *_: None)
    assert not rejections
    solution = target.solve_default(features, config, SolveContext(n_samples=len(samples)))
    target.check_fit(solution, config)
    assert len(solution.samples_used) == len(features)
    section = solution.section
    assert isinstance(section, LineSection)
    for (scale, sigma), truth in zip(
        section.scale_estimates(), (sensor.x_scale_error, sensor.z_scale_error), strict=True
    ):
        assert sigma is not None and abs(scale - truth) < 3.0 * sigma < 0.002
    _, translation = transform_error(solution.T_flange_sensor, data.truth.T_flange_sensor)
    assert translation < 1.2e-4
    read = read_line_section(section.to_mapping("base_link"))
    assert np.allclose(read.scales, section.scales) and read.scale_sigmas == section.scale_sigmas
    sx, sz = section.scales
    assert sx is not None and sz is not None
    mapped = read.sensor_points(np.array([[0.01, 0.0, 0.1]]))
    assert np.allclose(mapped, [[0.01 / (1.0 + sx), 0.0, 0.1 / (1.0 + sz)]], rtol=0, atol=1e-12)
    assert "depth (z) scale 0.99" in section.describe("base_link")


def test_unsynchronised_clocks_are_refused(features_run: LineSimulatedData) -> None:
    samples = _paired(features_run, 0.0)
    with pytest.raises(ModelMismatch, match="clocks are not synchronised") as refused:
        calibrate_samples(samples, PipelineConfig(target="line", pairing=MOVING))
    # The latency is 12 ms; the fit absorbs part of it, the regression finds the rest.
    found = re.search(r"a clock offset of about ([-+]\d+\.\d) ms", str(refused.value))
    assert found is not None and -12.0 < float(found.group(1)) < -3.0


def _views(T_base_sensor: np.ndarray, X: np.ndarray, line: Line) -> list[CornerSample]:
    """Noise-free corners where each laser plane meets the line."""
    y = T_base_sensor[:, :3, 1]
    lam = np.einsum("ki,ki->k", y, T_base_sensor[:, :3, 3] - line.point) / (y @ line.direction)
    corner = line.point + lam[:, None] * line.direction
    s = np.einsum("kji,kj->ki", T_base_sensor[:, :3, :3], corner - T_base_sensor[:, :3, 3])
    T_base_flange = T_base_sensor @ invert_transform(X)
    return [
        CornerSample(k, k, T_base_flange[k], s[k, [0, 2]], np.eye(2) * 1e-12, s[k][None])
        for k in range(len(s))
    ]


def test_one_flange_orientation_leaves_the_translations_undetermined(
    features_run: LineSimulatedData,
) -> None:
    truth = features_run.truth
    waypoints = truth.T_base_sensor_waypoints
    rng = np.random.default_rng(2)
    T = np.tile(waypoints[0], (40, 1, 1))
    T[:, :3, 3] += rng.uniform(-0.03, 0.03, (40, 3))
    views = _views(T, truth.T_flange_sensor, _truth_line(features_run))
    target = get_target("line")
    with pytest.raises(DegenerateError) as caught:
        target.solve_default(views, LineConfig(), SolveContext(n_samples=40))
    message = str(caught.value)
    assert "one flange orientation" in message and "translations" in message
    # With the old hand-eye the same views give a result that keeps it there, with a warning.
    solution = target.solve_default(
        views,
        LineConfig(),
        SolveContext(initial_T_flange_sensor=truth.T_flange_sensor, n_samples=40),
    )
    assert any("translation of the sensor" in w for w in solution.warnings)


def test_the_paper_method_corrects_an_old_hand_eye(features_run: LineSimulatedData) -> None:
    target = get_target("line")
    config = LineConfig()
    features, _ = target.extract(_paired(features_run, -0.012), config, 0, lambda *_: None)
    features = features[::5]
    truth = features_run.truth
    old = truth.T_flange_sensor @ np.vstack(
        [
            np.hstack(
                [Rotation.from_rotvec([0.01, -0.015, 0.01]).as_matrix(), [[0.001], [-0.001], [0.0]]]
            ),
            [0, 0, 0, 1],
        ]
    )
    solution = target.solve_paper(
        features, replace(config, min_samples=10), SolveContext(initial_T_flange_sensor=old)
    )
    before = transform_error(old, truth.T_flange_sensor)
    after = transform_error(solution.T_flange_sensor, truth.T_flange_sensor)
    assert after[0] < before[0] and after[1] < before[1]
    assert solution.sigma_translation_m is None


def test_calibrate_the_committed_line_bag(tmp_path: Path) -> None:
    out = tmp_path / "result.yaml"
    code = main(
        [
            "calibrate",
            str(BAG),
            "--target",
            "line",
            "--max-speed",
            "0",
            "--max-angular-speed",
            "0",
            "--clock-offset",
            "auto",
            "--output",
            str(out),
        ]
    )
    assert code == 0
    result = read_result_yaml(out)
    truth = read_truth_yaml(BAG / "truth.yaml")
    rotation, translation = transform_error(result.T_flange_sensor, truth.T_flange_sensor)
    assert math.degrees(rotation) < 0.05 and translation < 1e-4
    assert abs(result.clock_offset_s + 0.012) < 5e-4
    line = result.target.line  # type: ignore[attr-defined]
    truth_line = truth.target.line  # type: ignore[attr-defined]
    np.testing.assert_allclose(line.point, truth_line.point, atol=5e-4)
