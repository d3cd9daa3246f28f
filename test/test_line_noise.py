"""The point noise along the line, learned from residuals, and the refinement weighed by it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from _cylinder_points import make_scene, perturbed_start

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import rotvec_from_matrix
from linelaser_calib.core.profile.noise import LineNoise, learn_line_noise, line_whitening
from linelaser_calib.core.targets.cylinder.config import RefineConfig
from linelaser_calib.core.targets.cylinder.refine import refine_with_outlier_rejection
from linelaser_calib.sim.sensor_models import SensorModel, shape_error

#: A Keyence-class profiler (sim preset ``cylinder_keyence``): 1.5 µm white noise, 6 µm of
#: smooth depth error over 3 mm.
KEYENCE = LineNoise(white_sigma_m=1.5e-6, smooth_sigma_m=6e-6, length_m=3e-3)


def _profiles(
    rng: np.random.Generator, noise: LineNoise, m: int = 30, k: int = 200
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Places x (M, K), cosines, a mask with some short profiles, and the fit's directions
    (constant, slope, cosine: an arc's shift and tilt) of M profiles."""
    x = np.sort(rng.uniform(-6e-3, 6e-3, (m, k)), axis=1)
    cosine = np.cos(np.arcsin(np.clip(x / 8e-3, -0.95, 0.95)))
    mask = np.ones((m, k))
    mask[:5, 150:] = 0.0
    bases = np.stack([np.ones((m, k)), x / 6e-3, cosine], axis=2) * mask[..., None]
    return x, cosine, mask, bases


def test_learned_noise_recovers_the_simulated_sigmas_and_length() -> None:
    rng = np.random.default_rng(0)
    x, cosine, mask, bases = _profiles(rng, KEYENCE)
    draws = np.linalg.cholesky(KEYENCE.covariance(x, cosine)) @ rng.normal(size=(*x.shape, 1))
    residuals = draws[..., 0].copy()
    for j in range(len(x)):  # what a fit of each profile's own directions leaves
        fit = np.linalg.lstsq(bases[j], residuals[j] * mask[j], rcond=None)[0]
        residuals[j] -= bases[j] @ fit
    learned = learn_line_noise(residuals, x, cosine, mask, bases)
    assert learned.white_sigma_m == pytest.approx(KEYENCE.white_sigma_m, rel=0.1)
    assert learned.smooth_sigma_m == pytest.approx(KEYENCE.smooth_sigma_m, rel=0.25)
    assert learned.length_m == pytest.approx(KEYENCE.length_m, rel=0.25)


def test_white_residuals_learn_no_smooth_error() -> None:
    rng = np.random.default_rng(1)
    x, cosine, mask, bases = _profiles(rng, KEYENCE)
    learned = learn_line_noise(rng.normal(0.0, 2e-6, x.shape), x, cosine, mask, bases)
    assert learned.white_sigma_m == pytest.approx(2e-6, rel=0.1)
    assert learned.smooth_sigma_m < 0.4 * learned.white_sigma_m
    assert learned.depth_sigma_m == 0.0  # nor a per-point variance


#: A scanCONTROL-class profiler (committed bag ``ur_scancontrol``): 6 µm lateral and 8 µm
#: depth noise, no smooth error: a point's variance 6² + c² (8² − 6²) µm².
SCANCONTROL = LineNoise(
    white_sigma_m=6e-6, smooth_sigma_m=0.0, length_m=1e-3, depth_sigma_m=np.sqrt(28.0) * 1e-6
)


def test_a_variance_growing_with_the_cosine_learns_the_diagonal_model() -> None:
    """Residuals drawn with the variance σ_w² + c² σ_d² (no correlation along the line)
    learn σ_w and σ_d, no smooth part, and the whitening weighs each point by its own
    variance (diagonal, no basis functions)."""
    rng = np.random.default_rng(2)
    x, _, mask, _ = _profiles(rng, SCANCONTROL)
    cosine = np.cos(np.arcsin(np.clip(x / 6.5e-3, -0.95, 0.95)))  # 0.31 to 1
    bases = np.stack([np.ones_like(x), x / 6e-3, cosine], axis=2) * mask[..., None]
    residuals = rng.normal(size=x.shape) * np.sqrt(SCANCONTROL.point_variance(cosine))
    for j in range(len(x)):  # what a fit of each profile's own directions leaves
        residuals[j] -= bases[j] @ np.linalg.lstsq(bases[j], residuals[j] * mask[j])[0]
    learned = learn_line_noise(residuals, x, cosine, mask, bases)
    assert learned.smooth_sigma_m == 0.0
    assert learned.white_sigma_m == pytest.approx(SCANCONTROL.white_sigma_m, rel=0.1)
    assert learned.depth_sigma_m == pytest.approx(SCANCONTROL.depth_sigma_m, rel=0.25)
    whitening = line_whitening(learned, x, cosine, mask, 3e-6)
    assert whitening.U.shape[2] == 0
    weights = whitening.apply(mask)[~np.isclose(mask, 0.0)] ** 2  # 1 / σ_i² in 1 / (3 µm)²
    truth = (3e-6) ** 2 / SCANCONTROL.point_variance(cosine[mask > 0.0])
    np.testing.assert_allclose(weights, truth, rtol=0.25)
    assert np.ptp(np.log(weights)) == pytest.approx(np.ptp(np.log(truth)), rel=0.25)


def test_the_low_rank_whitening_whitens_the_dense_covariance() -> None:
    """line_whitening (a few tens of basis functions per profile, applied without K x K
    matrices) whitens the exact Gaussian-kernel covariance to 0.1 %, on profiles of 400
    points and on a shorter, padded one, and it selects profiles like the dense form."""
    rng = np.random.default_rng(4)
    smooth = LineNoise(white_sigma_m=3e-6, smooth_sigma_m=10e-6, length_m=4e-3)
    x, cosine, mask, _ = _profiles(rng, smooth, m=6, k=400)
    mask[:5, 150:] = 0.0
    mask[5, 300:] = 0.0
    # the smooth part alone, with a per-point depth noise beside it, and the latter alone
    for noise in (smooth, replace(smooth, depth_sigma_m=5e-6), replace(SCANCONTROL)):
        whitening = line_whitening(noise, x, cosine, mask, 3e-6)
        assert whitening.U.shape[2] < 40
        identity = np.broadcast_to(np.eye(400), (6, 400, 400))
        W = whitening.apply(np.ascontiguousarray(identity))
        for j in (0, 5):
            n = int(mask[j].sum())
            C = noise.covariance(x[j, :n], cosine[j, :n]) / 3e-6**2
            np.testing.assert_allclose(W[j, :n, :n] @ C @ W[j, :n, :n].T, np.eye(n), atol=1e-3)
            # the white share w² (C⁻¹)_ii that weighs the scales' regressors
            share = noise.white_sigma_m**2 * np.diag(np.linalg.inv(C * 3e-6**2))
            np.testing.assert_allclose(whitening.white_share()[j, :n], share, atol=1e-3)
        residuals = rng.normal(size=(6, 400)) * mask
        np.testing.assert_allclose(
            whitening.take([5, 0]).apply(residuals[[5, 0]]), whitening.apply(residuals)[[5, 0]]
        )


def test_learn_line_noise_refuses_too_few_profiles() -> None:
    x, cosine, mask, bases = _profiles(np.random.default_rng(3), KEYENCE, m=1)
    with pytest.raises(InputError, match="two profiles"):
        learn_line_noise(np.zeros_like(x), x, cosine, mask, bases)


def test_generalised_least_squares_beats_independent_points_on_smooth_errors() -> None:
    """Profiles with a Keyence-class smooth depth error (sim's own generator): weighing the
    points with the learned noise is more accurate than taking them as independent, and its
    1σ holds the error."""
    model = SensorModel(shape_sigma_m=6e-6, shape_length_m=3e-3)
    independent, weighed = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        scene = make_scene(
            rng, sensor_sigma=1.5e-6, robot_sigma_t=3e-5, robot_sigma_r=float(np.deg2rad(0.003))
        )
        points = [p.copy() for p in scene.points]
        for p in points:
            p[:, 2] += shape_error(rng, model, p[None, :, 0])[0]
        T0, cylinder0 = perturbed_start(rng, scene)
        for learn, errors in ((False, independent), (True, weighed)):
            config = RefineConfig(learn_line_noise=learn)
            result = refine_with_outlier_rejection(
                points, scene.T_base_flange, T0, cylinder0, config, radius_m=0.02
            )
            T, truth = result.T_flange_sensor, scene.T_flange_sensor
            error = np.concatenate(
                [rotvec_from_matrix(T[:3, :3].T @ truth[:3, :3]), truth[:3, 3] - T[:3, 3]]
            )
            errors.append(error)
            if learn:
                assert result.line_noise is not None
                assert result.line_noise.smooth_sigma_m == pytest.approx(6e-6, rel=0.3)
                sigma = np.concatenate([result.sigma_rotation_rad, result.sigma_translation_m])
                assert np.max(np.abs(error) / sigma) < 3.0
            else:
                assert result.line_noise is None
    rms = [
        np.sqrt(np.mean(np.sum(np.array(e)[:, 3:] ** 2, axis=1))) for e in (independent, weighed)
    ]
    assert rms[1] < 0.7 * rms[0]


def test_line_noise_rejects_bad_values() -> None:
    with pytest.raises(InputError, match="white"):
        LineNoise(0.0, 1e-6, 1e-3)
    with pytest.raises(InputError, match="length"):
        replace(KEYENCE, length_m=0.0)
    with pytest.raises(InputError, match="depth"):
        replace(KEYENCE, depth_sigma_m=-1e-6)


def test_an_error_as_long_as_the_profile_is_not_weighed_by() -> None:
    """A smooth error whose correlation length exceeds the arc moves each profile as its
    pose would: its size cannot be learned, so the points stay independent."""
    rng = np.random.default_rng(5)
    scene = make_scene(rng, n_poses=30, sensor_sigma=2e-6)
    model = SensorModel(shape_sigma_m=2e-5, shape_length_m=0.05)
    points = [p.copy() for p in scene.points]
    for p in points:
        p[:, 2] += shape_error(rng, model, p[None, :, 0])[0]
    T0, cylinder0 = perturbed_start(rng, scene)
    result = refine_with_outlier_rejection(points, scene.T_base_flange, T0, cylinder0)
    assert result.line_noise is None
    assert result.solved is not None and result.solved.problem.whitening is None


def test_the_profiled_restricted_likelihood_is_the_dense_one() -> None:
    """The REML cost the learning profiles over (one eigendecomposition per length, σ_w in
    closed form) equals log|C| + log|XᵀC⁻¹X| + rᵀPr computed with dense matrices, at its own
    σ_w and τ, with padding and a profile of lower rank (up to a constant)."""
    from linelaser_calib.core.profile.noise import _orthonormal_bases, _Profile

    rng = np.random.default_rng(3)
    x, cosine, mask, bases = _profiles(rng, KEYENCE, m=5, k=40)
    mask[:5, 30:] = 0.0
    bases = bases * mask[..., None]
    bases[1, :, 2] = bases[1, :, 0]  # a dependent column: rank 2
    residuals = rng.normal(0.0, 3e-6, x.shape) * mask
    X = _orthonormal_bases(bases)
    profile = _Profile(residuals, x, cosine, mask, X, 3e-6)
    for length in (0.0, 2e-3, 6e-3):
        cost, white, tau = profile(length)
        dense = 0.0
        for j in range(5):
            n = int(mask[j].sum())
            noise = LineNoise(white, np.sqrt(tau) * white, length if length else 1e-9)
            C = noise.covariance(x[j, :n], cosine[j, :n])  # σ in units of 3 µm
            Xj = X[j, :n][:, np.any(X[j] != 0.0, axis=0)]
            Ci = np.linalg.inv(C)
            XtCiX = Xj.T @ Ci @ Xj
            P = Ci - Ci @ Xj @ np.linalg.solve(XtCiX, Xj.T @ Ci)
            r = residuals[j, :n] / 3e-6
            dense += np.linalg.slogdet(C)[1] + np.linalg.slogdet(XtCiX)[1] + r @ P @ r
        # The profiled cost drops rᵀPr's value at the optimum, N − p, the same at any ℓ.
        assert cost + profile.free == pytest.approx(dense, rel=1e-9, abs=1e-9)


def test_a_short_correlation_length_is_found_wherever_a_search_would_start() -> None:
    """Regression (bags/paper on branch s3): the likelihood is flat where the smooth part is
    small, and one L-BFGS-B start at 0.2 of the span (20 mm here) stopped at 3.6 mm with the
    white σ 15 % high. The global search over ℓ finds the simulated 1.5 mm."""
    rng = np.random.default_rng(1)
    truth = LineNoise(white_sigma_m=1.5e-6, smooth_sigma_m=1.5e-6, length_m=1.5e-3)
    x = np.sort(rng.uniform(-0.05, 0.05, (30, 200)), axis=1)
    cosine = np.cos(np.arcsin(np.clip(x / 0.0665, -0.95, 0.95)))
    mask = np.ones_like(x)
    mask[:5, 150:] = 0.0
    bases = np.stack([np.ones_like(x), x / 0.05, cosine], axis=2) * mask[..., None]
    draws = np.linalg.cholesky(truth.covariance(x, cosine)) @ rng.normal(size=(*x.shape, 1))
    residuals = draws[..., 0].copy()
    for j in range(len(x)):
        residuals[j] -= bases[j] @ np.linalg.lstsq(bases[j], residuals[j] * mask[j])[0]
    learned = learn_line_noise(residuals, x, cosine, mask, bases)
    assert learned.length_m == pytest.approx(truth.length_m, rel=0.25)
    assert learned.white_sigma_m == pytest.approx(truth.white_sigma_m, rel=0.1)
    assert learned.smooth_sigma_m == pytest.approx(truth.smooth_sigma_m, rel=0.25)


def test_the_learned_line_noise_is_reported_and_read_back(tmp_path: Path) -> None:
    """The committed Gocator-class bag (1.2 µm-step depth, 12 µm of smooth shape error over
    5 mm): the result names the line noise that weighed the points, in the summary and in
    quality.line_noise, and reads it back; bags/paper (5 µm in x and z, no smooth error)
    learns no smooth part but a per-point variance growing with the cosine (surface normals
    out of the laser plane), a point facing the sensor 4-6 µm, and reads its depth σ back."""
    from linelaser_calib.core.pipeline import PipelineConfig, run_pipeline
    from linelaser_calib.core.targets.cylinder import CylinderSection
    from linelaser_calib.io import read_bag, read_result_yaml, write_result_yaml
    from linelaser_calib.summary import format_summary

    root = Path(__file__).resolve().parents[1] / "bags"
    bag = read_bag(root / "cylinder_gocator")
    result = run_pipeline(bag.profiles, bag.poses, PipelineConfig(self_check_folds=0))
    section = result.target
    assert isinstance(section, CylinderSection) and section.line_noise is not None
    assert 6e-6 < section.line_noise.smooth_sigma_m < 24e-6
    assert 2.5e-3 < section.line_noise.length_m < 10e-3
    assert "line noise            learned from the residuals" in format_summary(result)
    back = read_result_yaml(write_result_yaml(result, tmp_path / "r.yaml")).target
    assert isinstance(back, CylinderSection) and back.line_noise is not None
    assert back.line_noise.length_m == pytest.approx(section.line_noise.length_m, rel=1e-9)

    paper = read_bag(root / "paper")
    diagonal = run_pipeline(paper.profiles, paper.poses, PipelineConfig(self_check_folds=0))
    section = diagonal.target
    assert isinstance(section, CylinderSection) and section.line_noise is not None
    assert section.line_noise.smooth_sigma_m == 0.0 and section.line_noise.depth_sigma_m > 0.0
    assert 4e-6 < section.line_noise.point_sigma_m < 6e-6
    assert "um more in depth" in format_summary(diagonal)
    back = read_result_yaml(write_result_yaml(diagonal, tmp_path / "d.yaml")).target
    assert isinstance(back, CylinderSection) and back.line_noise is not None
    assert back.line_noise.depth_sigma_m == pytest.approx(section.line_noise.depth_sigma_m)


def test_a_profile_with_a_large_draw_of_the_smooth_error_is_no_outlier() -> None:
    """Regression (cylinder_gocator seed 0): two profiles whose smooth shape error happened to
    be large (18-19 um RMS against a median 9.9 um) were set aside as outliers, their RMS
    judged against the small spread of the other profiles' (robust z 6). Weighed by the
    recording's learned line noise they are ordinary draws of it. This small scene shows it
    at robust z 3 (the default is 6): with the points taken as independent the profile is
    dropped, weighed by the learned noise it is kept (before the fix: dropped)."""
    rng = np.random.default_rng(5)
    model = SensorModel(shape_sigma_m=12e-6, shape_length_m=5e-3)
    scene = make_scene(rng, n_poses=16, n_points=150, sensor_sigma=6e-6)
    points = [p.copy() for p in scene.points]
    for j, p in enumerate(points):  # profile 3: of 1000 draws of the same error, the one
        # a fit of the profile's position, tilt and bend leaves most of
        draws = shape_error(rng, model, np.repeat(p[None, :, 0], 1000 if j == 3 else 1, axis=0))
        bend = np.vander(p[:, 0], 3)
        left = draws.T - bend @ np.linalg.lstsq(bend, draws.T, rcond=None)[0]
        p[:, 2] += draws[np.argmax(np.sum(left**2, axis=0))]
    T0, cylinder0 = perturbed_start(rng, scene)
    for learn in (False, True):
        config = RefineConfig(learn_line_noise=learn, outlier_zscore=3.0)
        result = refine_with_outlier_rejection(
            points, scene.T_base_flange, T0, cylinder0, config, radius_m=0.02
        )
        dropped = [d.sample_index for d in result.dropped]
        if learn:
            assert result.line_noise is not None and dropped == []
            assert result.sample_rms_m[3] > 1.8 * np.median(result.sample_rms_m)
        else:
            assert 3 in dropped


def test_a_learned_noise_dropped_gives_the_first_solve_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Regression (issue 32, memory): the first solve's problem is let go once a line noise
    is learned from it. Where the noise is then dropped (here: any residual too large), the
    outcome is that first solve, solved again: the result of not learning the noise at all,
    with its solved problem (where the self-check's subset solves start)."""
    import importlib

    refine_module = importlib.import_module("linelaser_calib.core.targets.cylinder.refine")
    rng = np.random.default_rng(2)
    scene = make_scene(rng, n_poses=16, n_points=150, sensor_sigma=1.5e-6)
    points = [p.copy() for p in scene.points]
    for p in points:
        p[:, 2] += shape_error(
            rng, SensorModel(shape_sigma_m=6e-6, shape_length_m=3e-3), p[None, :, 0]
        )[0]
    T0, cylinder0 = perturbed_start(rng, scene)
    plain = refine_with_outlier_rejection(
        points, scene.T_base_flange, T0, cylinder0, RefineConfig(learn_line_noise=False), 0.02
    )
    monkeypatch.setattr(refine_module, "MAX_NOISE_RESIDUAL_RATIO", 0.0)
    dropped = refine_with_outlier_rejection(
        points, scene.T_base_flange, T0, cylinder0, RefineConfig(learn_line_noise=True), 0.02
    )
    assert dropped.line_noise is None
    assert dropped.solved is not None and dropped.solved.problem.whitening is None
    sigma = np.concatenate([plain.sigma_rotation_rad, plain.sigma_translation_m])
    moved = np.concatenate(
        [
            rotvec_from_matrix(plain.T_flange_sensor[:3, :3].T @ dropped.T_flange_sensor[:3, :3]),
            dropped.T_flange_sensor[:3, 3] - plain.T_flange_sensor[:3, 3],
        ]
    )
    assert np.all(np.abs(moved) <= 1e-6 * sigma), moved / sigma
    assert dropped.used == plain.used
