"""Tests of profile cleaning on synthetic profiles with known good and bad points."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from linelaser_calib.core.errors import InputError, ProfileRejected
from linelaser_calib.core.profile.cleaning import (
    MAX_BRIDGED_POINTS,
    CleaningConfig,
    clean_profile,
    clean_profiles,
    segment_labels,
)
from linelaser_calib.core.targets.cylinder.ellipse import EllipseConfig, fit_ellipse_ransac

RADIUS = 0.02  # m
SEMI_MAJOR = RADIUS / math.sin(math.radians(60.0))
CENTRE_Z = 0.25  # m, depth of the ellipse centre
TABLE_Z = CENTRE_Z + 0.03  # m, a table behind the cylinder
SIGMA = 5e-6  # m


def arc_profile(rng: np.random.Generator, pitch: float, sigma: float = SIGMA) -> np.ndarray:
    """The near side of the cylinder's ellipse sampled every ``pitch`` m along x, (N, 3).

    Like a profiler's columns: the points thin out on the arc's steep flanks.
    """
    x = np.arange(-SEMI_MAJOR + 0.5 * pitch, SEMI_MAJOR, pitch)
    z = CENTRE_Z - RADIUS * np.sqrt(1.0 - (x / SEMI_MAJOR) ** 2)
    z += sigma * rng.standard_normal(len(x))
    return np.column_stack([x, np.zeros_like(x), z])


def distance_to_arc(points: np.ndarray) -> np.ndarray:
    """Distance of (N, 3) points to the cylinder's ellipse in x-z, by a dense polygon."""
    t = np.linspace(0.0, 2 * math.pi, 40000, endpoint=False)
    dense = np.column_stack([SEMI_MAJOR * np.cos(t), CENTRE_Z + RADIUS * np.sin(t)])
    xz = points[:, [0, 2]]
    return np.asarray(np.min(np.linalg.norm(xz[:, None] - dense[None], axis=2), axis=1))


def table_profile(rng: np.random.Generator, pitch: float) -> np.ndarray:
    """Table points on both sides beyond the cylinder's shadow, (N, 3)."""
    x = np.concatenate([np.arange(-0.06, -0.035, pitch), np.arange(0.035, 0.06, pitch)])
    z = TABLE_Z + SIGMA * rng.standard_normal(len(x))
    return np.column_stack([x, np.zeros_like(x), z])


def add_spikes(
    rng: np.random.Generator, points: np.ndarray, rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """Reflection spikes of 0.2-5 mm in depth on a share ``rate`` of the points."""
    spiked = points.copy()
    spike = rng.random(len(points)) < rate
    size = rng.uniform(0.2e-3, 5e-3, spike.sum()) * rng.choice([-1.0, 1.0], spike.sum())
    spiked[spike, 2] += size
    return spiked, spike


@pytest.mark.parametrize("pitch", [50e-6, 200e-6])
def test_clean_arc_is_kept_entirely(pitch: float) -> None:
    rng = np.random.default_rng(1)
    for sigma in (0.0, SIGMA):
        points = arc_profile(rng, pitch, sigma)
        cleaned = clean_profile(points, CleaningConfig())
        assert cleaned.mask.all()
        assert cleaned.counts["kept"] == len(points)
        np.testing.assert_array_equal(cleaned.points, points)
        assert cleaned.warnings == ()


def test_non_finite_points_are_dropped() -> None:
    rng = np.random.default_rng(2)
    points = arc_profile(rng, 50e-6)
    bad = np.zeros(len(points), dtype=bool)
    bad[[0, 10, 11, 500, len(points) - 1]] = True
    points[0] = np.nan
    points[10, 2] = np.inf
    points[11, 0] = -np.inf
    points[500, 1] = np.nan
    points[-1, 2] = np.nan
    cleaned = clean_profile(points, CleaningConfig())
    assert cleaned.counts["non_finite"] == 5
    np.testing.assert_array_equal(cleaned.mask, ~bad)
    assert np.all(np.isfinite(cleaned.points))


def test_range_gate_on_depth_and_width() -> None:
    rng = np.random.default_rng(3)
    arc, table = arc_profile(rng, 50e-6), table_profile(rng, 50e-6)
    points = np.vstack([arc, table])
    cleaned = clean_profile(points, CleaningConfig(max_depth_m=TABLE_Z - 0.005))
    assert cleaned.counts["range_gate"] == len(table)
    np.testing.assert_array_equal(cleaned.mask, np.arange(len(points)) < len(arc))
    narrow = clean_profile(points, CleaningConfig(max_abs_x_m=0.01))
    np.testing.assert_array_equal(narrow.mask, np.abs(points[:, 0]) <= 0.01)
    near = clean_profile(points, CleaningConfig(min_depth_m=CENTRE_Z - 0.01))
    assert np.all(near.points[:, 2] >= CENTRE_Z - 0.01)


@pytest.mark.parametrize("pitch", [50e-6, 200e-6])
def test_spikes_are_removed_and_the_arc_kept(pitch: float) -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        clean = arc_profile(rng, pitch)
        points, spike = add_spikes(rng, clean, 0.05)
        cleaned = clean_profile(points, CleaningConfig())
        # On the steep flanks a depth spike can stay close to the curve; the others go.
        off = spike.copy()
        off[spike] = distance_to_arc(points[spike]) > 0.1e-3
        assert off.sum() >= 0.8 * spike.sum()
        assert not cleaned.mask[off].any()
        # Only good points next to clusters of spikes may go.
        assert cleaned.mask[~spike].mean() > 0.97
        removed = cleaned.counts["small_segment"] + cleaned.counts["spike"]
        assert removed == len(points) - cleaned.mask.sum()
        # The ends of the arc (its coverage) survive.
        good = np.flatnonzero(~spike)
        assert cleaned.mask[good[1]] and cleaned.mask[good[-2]]


def test_isolated_cluster_and_table_behind_the_arc() -> None:
    rng = np.random.default_rng(5)
    arc, table = arc_profile(rng, 50e-6), table_profile(rng, 50e-6)
    # A small cluster of stray returns floating 5 mm in front of the table.
    cluster = np.column_stack(
        [np.linspace(0.04, 0.0402, 6), np.zeros(6), np.full(6, TABLE_Z - 5e-3)]
    )
    points = np.vstack([arc, table, cluster])
    cleaned = clean_profile(points, CleaningConfig())
    assert cleaned.counts["small_segment"] == 6
    assert cleaned.mask[: len(arc) + len(table)].all()
    # Each table side holds fewer points than the arc here.
    largest = clean_profile(points, CleaningConfig(keep_largest_segment=True))
    np.testing.assert_array_equal(largest.points, arc)
    assert largest.counts["other_segment"] == len(table)


def test_cleaned_table_scene_gives_the_arc_to_the_ellipse_fit() -> None:
    rng = np.random.default_rng(6)
    arc, table = arc_profile(rng, 50e-6), table_profile(rng, 50e-6)
    points, _ = add_spikes(rng, np.vstack([arc, table]), 0.03)
    cleaned = clean_profile(points, CleaningConfig())
    fit = fit_ellipse_ransac(cleaned.points_xz, EllipseConfig(), rng)
    is_arc = np.arange(len(points)) < len(arc)
    kept_arc = is_arc[cleaned.mask]
    assert fit.inliers[~kept_arc].sum() == 0
    assert fit.inliers[kept_arc].mean() > 0.99
    assert np.linalg.norm(fit.centre_xz - [0.0, CENTRE_Z]) < 20e-6
    assert fit.semi_axes[1] == pytest.approx(RADIUS, rel=1e-3)


def test_too_few_points_are_rejected_with_counts() -> None:
    rng = np.random.default_rng(7)
    points = arc_profile(rng, 50e-6)[:25]
    with pytest.raises(ProfileRejected, match=r"only 25 of 25 points .* at least 30"):
        clean_profile(points, CleaningConfig())
    nothing = np.full((100, 3), np.nan)
    with pytest.raises(ProfileRejected, match="100 non finite"):
        clean_profile(nothing, CleaningConfig())
    with pytest.raises(ProfileRejected, match="range gate"):
        clean_profile(arc_profile(rng, 50e-6), CleaningConfig(max_depth_m=0.1))


def test_points_off_the_laser_plane_are_flagged() -> None:
    rng = np.random.default_rng(8)
    points = arc_profile(rng, 50e-6)
    points[:, 1] = 0.004 * points[:, 2] / CENTRE_Z  # e.g. a cloud in a tilted frame
    cleaned = clean_profile(points, CleaningConfig())
    assert cleaned.typical_abs_y_m > 1e-3
    assert len(cleaned.warnings) == 1 and "sensor frame" in cleaned.warnings[0]
    with pytest.raises(ProfileRejected, match="not be in the sensor frame"):
        clean_profile(points, CleaningConfig(reject_off_plane=True))


@pytest.mark.parametrize("largest", [False, True])
def test_profiles_cleaned_together_are_each_cleaned_alone(largest: bool) -> None:
    # No stage links points of neighbouring profiles: a batch gives each profile's own result.
    rng = np.random.default_rng(9)
    scenes = []
    for k in range(12):
        arc, table = arc_profile(rng, 50e-6 * (1 + k % 3)), table_profile(rng, 100e-6)
        points, _ = add_spikes(rng, np.vstack([table, arc] if k % 2 else [arc, table]), 0.03)
        points[rng.random(len(points)) < 0.05] = np.nan
        scenes.append(points)
    scenes[3] = scenes[3][:25]  # too few points
    scenes[5] = np.full((40, 3), np.nan)
    scenes[7] = np.zeros((0, 3))
    scenes[8][:, 2] -= CENTRE_Z  # a frame whose origin is not at the emitter: ordered by x
    config = CleaningConfig(keep_largest_segment=largest)
    for alone, together in zip(
        [clean_profiles([p], config)[0] for p in scenes],
        clean_profiles(scenes, config),
        strict=True,
    ):
        assert type(alone) is type(together)
        if isinstance(alone, ProfileRejected):
            assert str(alone) == str(together)
            continue
        assert isinstance(together, type(alone))
        np.testing.assert_array_equal(together.mask, alone.mask)
        assert together.counts == alone.counts
        assert together.spike_threshold_m == pytest.approx(alone.spike_threshold_m, rel=1e-12)
    assert sum(isinstance(c, ProfileRejected) for c in clean_profiles(scenes, config)) == 3


def test_bad_input_and_config() -> None:
    with pytest.raises(InputError, match="shape"):
        clean_profile(np.zeros((10, 2)), CleaningConfig())
    with pytest.raises(ValueError, match="min_depth_m"):
        CleaningConfig(min_depth_m=0.5, max_depth_m=0.1)
    with pytest.raises(ValueError, match="min_segment_points"):
        CleaningConfig(spike_half_window=5, min_segment_points=5)


def test_scan_line_pieces_are_the_connected_components_of_the_links() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(1, 200))
        xz = np.cumsum(rng.normal(scale=rng.uniform(0.1, 3.0), size=(n, 2)), axis=0)
        stray = rng.random(n) < rng.uniform(0.0, 0.5)
        xz[stray] += rng.normal(scale=10.0, size=(int(stray.sum()), 2))
        near = [
            (i, i + k)
            for k in range(1, MAX_BRIDGED_POINTS + 2)
            for i in np.flatnonzero(np.linalg.norm(xz[k:] - xz[:-k], axis=1) <= 2.0)
        ]
        rows, cols = np.array(near, dtype=np.intp).reshape(-1, 2).T
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
        _, components = connected_components(graph, directed=False)
        first, expected = np.unique(components, return_index=True, return_inverse=True)[1:]
        np.testing.assert_array_equal(
            segment_labels(xz, 2.0), np.argsort(np.argsort(first))[expected]
        )
