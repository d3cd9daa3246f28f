"""V-profile corner extraction against synthetic V profiles with a known corner."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linelaser_calib.core.errors import InputError, ProfileRejected
from linelaser_calib.core.profile.corner import CornerConfig, fit_corner

CONFIG = CornerConfig()


def v_profile(
    rng: np.random.Generator,
    corner: tuple[float, float] = (0.004, 0.1),
    opening_deg: float = 90.0,
    tilt_deg: float = 0.0,
    lengths: tuple[float, float] = (0.02, 0.015),
    spacing: float = 1.5e-4,
    sigma: float = 0.0,
) -> np.ndarray:
    """Points (x, z) of two flanks from ``corner`` (m), opening away from the sensor (+z is
    depth, so the V's flanks rise towards smaller z), sorted by x like a scan line."""
    half = math.radians(opening_deg) / 2.0
    tilt = math.radians(tilt_deg)
    pieces = []
    for sign, length in zip((-1.0, 1.0), lengths, strict=True):
        angle = tilt + sign * half
        direction = np.array([math.sin(angle), -math.cos(angle)])
        t = np.arange(spacing, length, spacing)
        pieces.append(np.asarray(corner) + t[:, None] * direction)
    p = np.vstack(pieces)
    p = p + rng.normal(size=p.shape) * sigma
    return p[np.argsort(p[:, 0])]


def test_noise_free_corner_is_exact() -> None:
    rng = np.random.default_rng(0)
    for opening in (60.0, 90.0, 120.0, 150.0):
        for tilt in (-20.0, 0.0, 25.0):
            points = v_profile(rng, opening_deg=opening, tilt_deg=tilt)
            fit = fit_corner(points, CONFIG, rng)
            np.testing.assert_allclose(fit.corner_xz, [0.004, 0.1], atol=1e-12)
            assert fit.bend_rad == pytest.approx(math.radians(min(opening, 180.0 - opening)))
            assert fit.inliers.sum() == len(points)


def test_noisy_corner_within_its_predicted_sigma() -> None:
    rng = np.random.default_rng(1)
    z = []
    for _ in range(60):
        points = v_profile(rng, opening_deg=rng.uniform(70.0, 130.0), sigma=8e-6)
        fit = fit_corner(points, CONFIG, rng)
        error = fit.corner_xz - [0.004, 0.1]
        z.append(float(error @ np.linalg.solve(fit.covariance_xz, error)))
        assert np.linalg.norm(error) < 2e-5
    # Mahalanobis distances of a 2-D Gaussian: mean 2 when the covariance is honest.
    assert 1.2 < np.mean(z) < 3.0


def test_outliers_and_spikes_do_not_move_the_corner() -> None:
    rng = np.random.default_rng(2)
    points = v_profile(rng, sigma=5e-6)
    spikes = rng.choice(len(points), 12, replace=False)
    points[spikes, 1] += rng.uniform(5e-4, 3e-3, len(spikes)) * rng.choice([-1.0, 1.0], 12)
    fit = fit_corner(points, CONFIG, rng)
    assert np.linalg.norm(fit.corner_xz - [0.004, 0.1]) < 5e-6
    assert not fit.inliers[:, spikes].any()


def test_flat_profile_is_rejected() -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(-0.02, 0.02, 200)
    points = np.column_stack([x, 0.1 + 0.05 * x + rng.normal(size=200) * 5e-6])
    with pytest.raises(ProfileRejected, match="flat, not a V"):
        fit_corner(points, CONFIG, rng)


def test_shallow_bend_is_rejected() -> None:
    rng = np.random.default_rng(4)
    points = v_profile(rng, opening_deg=174.0, sigma=2e-6)
    with pytest.raises(ProfileRejected, match=r"differ in direction by only 6\.0 deg"):
        fit_corner(points, CONFIG, rng)


def test_lines_meeting_away_from_their_points_are_rejected() -> None:
    rng = np.random.default_rng(5)
    points = v_profile(rng)
    near_corner = np.linalg.norm(points - [0.004, 0.1], axis=1) < 0.012
    with pytest.raises(ProfileRejected, match=r"the lines meet .* mm from the nearest point"):
        fit_corner(points[~near_corner], CONFIG, rng)


def test_crossing_lines_are_rejected() -> None:
    rng = np.random.default_rng(6)
    t = np.linspace(-0.015, 0.015, 150)
    a = np.column_stack([t, 0.1 + t])
    b = np.column_stack([t, 0.1 - 0.8 * t])
    with pytest.raises(ProfileRejected, match="beyond the corner"):
        fit_corner(np.vstack([a, b]), CONFIG, rng)


def test_too_few_points_are_rejected() -> None:
    rng = np.random.default_rng(7)
    with pytest.raises(ProfileRejected, match="only 10 points, fewer than the 20"):
        fit_corner(v_profile(rng, spacing=3e-3), CONFIG, rng)


def test_bad_input_raises_input_error() -> None:
    rng = np.random.default_rng(8)
    with pytest.raises(InputError):
        fit_corner(np.zeros((10, 3)), CONFIG, rng)
    with pytest.raises(InputError):
        fit_corner(np.full((40, 2), np.nan), CONFIG, rng)
    with pytest.raises(InputError):
        CornerConfig(min_bend_rad=2.0)
