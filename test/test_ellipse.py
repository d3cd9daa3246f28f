"""Tests of the RANSAC ellipse fit and the conic algebra against known ellipses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _compare import assert_floats_close

from linelaser_calib.core.errors import InputError, ProfileRejected
from linelaser_calib.core.targets.cylinder.arc import circle_centre, circle_radius
from linelaser_calib.core.targets.cylinder.conic import (
    centre_from_conic,
    centre_from_gradient,
    ellipse_geometry,
    is_ellipse,
    refine_geometric,
    sampson_distance,
    sampson_from_rows,
    sampson_jacobian,
    sampson_rows,
)
from linelaser_calib.core.targets.cylinder.ellipse import (
    EllipseConfig,
    fit_ellipse_direct,
    fit_ellipse_ransac,
)

RADIUS = 0.02  # m, the paper's 40 mm shaft
CUT = math.radians(60.0)  # angle between the laser plane and the cylinder axis
SEMI_MAJOR = RADIUS / math.sin(CUT)
SIGMA = 5e-6  # m, the paper's sensor

# Short test arcs need a lower coverage limit than the default.
CONFIG = EllipseConfig(min_arc_coverage_rad=math.radians(50.0))


def rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def ellipse_points(t: np.ndarray, centre: np.ndarray, angle: float) -> np.ndarray:
    """Points of the test ellipse (SEMI_MAJOR, RADIUS) at parametric angles t."""
    local = np.column_stack([SEMI_MAJOR * np.cos(t), RADIUS * np.sin(t)])
    return np.asarray(local @ rotation(angle).T + centre)


def random_arc(
    rng: np.random.Generator, coverage_deg: float, n: int = 800, sigma: float = 0.0
) -> tuple[np.ndarray, np.ndarray, float]:
    """An arc of the test ellipse at a random pose; returns points, true centre, angle."""
    centre = np.array([rng.uniform(-0.03, 0.03), rng.uniform(0.15, 0.3)])
    angle = rng.uniform(0.0, math.pi)
    start = rng.uniform(0.0, 2 * math.pi)
    t = np.linspace(start, start + math.radians(coverage_deg), n)
    points = ellipse_points(t, centre, angle) + sigma * rng.standard_normal((n, 2))
    return points, centre, angle


def distance_to_ellipse(points: np.ndarray, centre: np.ndarray, angle: float) -> np.ndarray:
    """Distance of points to the test ellipse, by a dense polygon (error < 0.1 um)."""
    dense = ellipse_points(np.linspace(0, 2 * math.pi, 20000, endpoint=False), centre, angle)
    return np.asarray(np.min(np.linalg.norm(points[:, None] - dense[None], axis=2), axis=1))


def true_conic(centre: np.ndarray, angle: float, scale: float = 1.0) -> np.ndarray:
    """Conic coefficients of the test ellipse, multiplied by ``scale``."""
    R = rotation(angle)
    M = R @ np.diag([SEMI_MAJOR**-2, RADIUS**-2]) @ R.T
    linear = -2 * M @ centre
    constant = centre @ M @ centre - 1.0
    return scale * np.array([M[0, 0], 2 * M[0, 1], M[1, 1], linear[0], linear[1], constant])


@pytest.mark.parametrize("coverage_deg", [60.0, 90.0, 120.0, 180.0])
def test_noise_free_arc_gives_exact_ellipse(coverage_deg: float) -> None:
    rng = np.random.default_rng(1)
    for _ in range(5):
        points, centre, _ = random_arc(rng, coverage_deg)
        fit = fit_ellipse_ransac(points, CONFIG, rng)
        assert np.linalg.norm(fit.centre_xz - centre) < 1e-9
        np.testing.assert_allclose(fit.semi_axes, [SEMI_MAJOR, RADIUS], rtol=1e-8)
        assert fit.inliers.all()
        assert fit.coverage_rad == pytest.approx(math.radians(coverage_deg), abs=1e-6)
        assert fit.rms_m < 1e-10
        assert fit.conic[5] == 1.0  # eq. 4 normalisation


# RMS centre error over 12 arcs at sigma = 5 um is about half of these bounds (measured
# over 50 arcs: 208, 52, 13 and 2.5 um).
NOISY_BOUNDS_M = {60.0: 400e-6, 90.0: 100e-6, 120.0: 30e-6, 180.0: 6e-6}


@pytest.mark.parametrize("coverage_deg", sorted(NOISY_BOUNDS_M))
def test_noisy_arc_centre_error_is_bounded(coverage_deg: float) -> None:
    rng = np.random.default_rng(2)
    errors = []
    for _ in range(12):
        points, centre, _ = random_arc(rng, coverage_deg, sigma=SIGMA)
        fit = fit_ellipse_ransac(points, CONFIG, rng)
        errors.append(np.linalg.norm(fit.centre_xz - centre))
        assert fit.inliers.mean() > 0.99
        assert fit.rms_m == pytest.approx(SIGMA, rel=0.2)
        assert fit.coverage_rad == pytest.approx(math.radians(coverage_deg), abs=0.02)
    assert math.sqrt(np.mean(np.square(errors))) < NOISY_BOUNDS_M[coverage_deg]


def test_spikes_are_outliers_and_do_not_move_the_centre() -> None:
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(12):
        points, centre, angle = random_arc(rng, 120.0, sigma=SIGMA)
        spike = rng.random(len(points)) < 0.05
        # Spikes of 0.5-5 mm along the depth axis, as reflections produce.
        points[spike, 1] += rng.uniform(0.5e-3, 5e-3, spike.sum()) * rng.choice(
            [-1, 1], spike.sum()
        )
        fit = fit_ellipse_ransac(points, CONFIG, rng)
        errors.append(np.linalg.norm(fit.centre_xz - centre))
        # A spike can land back on the ellipse where it is steep; those are inliers rightly.
        off = spike.copy()
        off[spike] = distance_to_ellipse(points[spike], centre, angle) > CONFIG.inlier_threshold_m
        assert off.sum() > 0.8 * spike.sum()
        assert not fit.inliers[off].any()
        assert fit.inliers[~spike].mean() > 0.99
    assert math.sqrt(np.mean(np.square(errors))) < NOISY_BOUNDS_M[120.0]


def test_an_arc_explained_within_its_noise_needs_no_ransac_and_clutter_still_gets_it() -> None:
    """With the profile's noise given, a clean arc's ellipse is found without drawing a
    hypothesis (the generator is left untouched) and equals RANSAC's; spikes or a table in
    the points make RANSAC search, with the fit it gives without the noise."""
    rng = np.random.default_rng(13)
    centre = np.array([0.0, 0.25])
    arc = ellipse_points(np.linspace(math.radians(190.0), math.radians(350.0), 400), centre, 0.0)
    x_table = np.arange(arc[-1, 0] + 50e-6, 0.07, 50e-6)
    table = np.column_stack([x_table, np.full(len(x_table), arc[-1, 1])])
    spiked, _, _ = random_arc(rng, 120.0, sigma=SIGMA)
    spiked[::20, 1] += 2e-3
    cases = {"spikes": spiked, "table": np.vstack([arc, table])}
    for k in range(8):
        cases[f"clean {k}"] = random_arc(rng, rng.uniform(90.0, 180.0), sigma=SIGMA)[0]
    drawn = {}
    for name, points in cases.items():
        points = points + (SIGMA * rng.standard_normal(points.shape) if name == "table" else 0.0)
        searched = fit_ellipse_ransac(points, EllipseConfig(), np.random.default_rng(0))
        generator = np.random.default_rng(0)
        before = generator.bit_generator.state
        fit = fit_ellipse_ransac(points, EllipseConfig(), generator, noise_sigma_m=SIGMA)
        drawn[name] = generator.bit_generator.state != before
        assert np.linalg.norm(fit.centre_xz - searched.centre_xz) < 1e-9, name
        np.testing.assert_allclose(fit.semi_axes, searched.semi_axes, rtol=1e-9, atol=0.0)
        assert np.array_equal(fit.inliers, searched.inliers), name
    assert drawn["spikes"] and drawn["table"]
    assert sum(not drawn[f"clean {k}"] for k in range(8)) >= 6


def test_arc_between_table_segments_is_found() -> None:
    """A cylinder standing on a table: the arc is found, the table line is all outliers."""
    rng = np.random.default_rng(4)
    for table_points in (400, 800):
        centre = np.array([0.005, 0.25])
        # The near side of an axis-aligned ellipse (the sensor looks along +z).
        t = np.linspace(math.radians(200.0), math.radians(340.0), 300)
        arc = ellipse_points(t, centre, 0.0)
        x_table = np.concatenate(
            [
                np.linspace(-0.07, -0.035, table_points // 2),
                np.linspace(0.035, 0.07, table_points // 2),
            ]
        )
        table = np.column_stack([x_table, np.full(table_points, centre[1] + 0.03)])
        points = np.vstack([arc, table]) + SIGMA * rng.standard_normal((300 + table_points, 2))
        fit = fit_ellipse_ransac(points, EllipseConfig(), rng)
        assert fit.inliers[:300].all()
        assert not fit.inliers[300:].any()
        assert np.linalg.norm(fit.centre_xz - centre) < 30e-6
        assert fit.coverage_rad == pytest.approx(math.radians(140.0), abs=0.01)


def test_arc_running_into_the_table_keeps_its_accuracy() -> None:
    """The laser crosses the cylinder's foot: the table line starts where the arc ends.

    Table points next to the corner pass within 0.1 mm of the ellipse; the inlier threshold
    that shrinks to the noise keeps them from bending the fit.
    """
    rng = np.random.default_rng(12)
    centre = np.array([0.0, 0.25])
    errors = []
    for _ in range(8):
        arc = ellipse_points(
            np.linspace(math.radians(190.0), math.radians(350.0), 400), centre, 0.0
        )
        x_table = np.concatenate(
            [np.arange(-0.07, arc[0, 0], 50e-6), np.arange(arc[-1, 0] + 50e-6, 0.07, 50e-6)]
        )
        table = np.column_stack([x_table, np.full(len(x_table), arc[0, 1])])
        points = np.vstack([arc, table]) + SIGMA * rng.standard_normal((400 + len(table), 2))
        fit = fit_ellipse_ransac(points, EllipseConfig(), rng)
        errors.append(np.linalg.norm(fit.centre_xz - centre))
        assert fit.inliers[:400].mean() > 0.99
        assert fit.inliers[400:].sum() <= 2
    assert math.sqrt(np.mean(np.square(errors))) < 20e-6


def test_short_arc_is_kept_as_a_short_arc_or_rejected_with_its_coverage() -> None:
    """A 20 deg arc is too short for its centre: without short arcs it is rejected with its
    coverage; with them it is a short arc holding its points. A 10 deg arc is neither."""
    rng = np.random.default_rng(5)
    points, _, _ = random_arc(rng, 20.0)
    no_short_arcs = EllipseConfig(min_short_arc_turn_rad=0.0)
    with pytest.raises(ProfileRejected, match=r"covers only 20\.0 deg, below the 60\.0 deg"):
        fit_ellipse_ransac(points, no_short_arcs, rng)
    noisy, centre, angle = random_arc(rng, 20.0, sigma=SIGMA)
    with pytest.raises(ProfileRejected):
        fit_ellipse_ransac(noisy, no_short_arcs, rng)
    for radius in (None, RADIUS):
        fit = fit_ellipse_ransac(noisy, EllipseConfig(), rng, radius_m=radius)
        assert fit.short
        assert fit.inliers.mean() > 0.95
        assert np.max(distance_to_ellipse(noisy[fit.inliers], centre, angle)) < 6 * SIGMA
    tiny, _, _ = random_arc(rng, 10.0, sigma=SIGMA)
    with pytest.raises(ProfileRejected, match=r"nor is it a short arc: its tangent turns by"):
        fit_ellipse_ransac(tiny, EllipseConfig(), rng)


def test_regression_an_arc_too_short_about_the_major_axis_end_is_a_short_arc() -> None:
    """A plausible cut covering 54 deg about the end of its major axis (a 40 deg cut, axis
    ratio 1.56), whose tangent turns by 77 deg, was rejected whole: its turn passed the
    coverage, so the short-arc rule took it for a long arc of no cylinder. Thinned at
    grazing incidence, one such arc in twelve was lost on the stress matrix's scene."""
    rng = np.random.default_rng(8)
    t = np.linspace(math.radians(-27.0), math.radians(27.0), 300)
    semi_major = RADIUS / math.sin(math.radians(40.0))
    points = np.column_stack([semi_major * np.cos(t), 0.2 + RADIUS * np.sin(t)])
    points += SIGMA * rng.standard_normal(points.shape)
    for radius in (None, RADIUS):
        fit = fit_ellipse_ransac(points, EllipseConfig(), rng, radius_m=radius)
        assert fit.short
        assert fit.inliers.mean() > 0.95


def test_given_radius_accepts_the_cylinder_and_rejects_a_wrong_radius() -> None:
    rng = np.random.default_rng(6)
    points, centre, _ = random_arc(rng, 120.0, sigma=SIGMA)
    fit = fit_ellipse_ransac(points, CONFIG, rng, radius_m=RADIUS)
    assert np.linalg.norm(fit.centre_xz - centre) < 50e-6
    assert fit.semi_axes[1] == pytest.approx(RADIUS, rel=0.01)
    # The diameter given instead of the radius: no ellipse fits the cylinder then.
    with pytest.raises(ProfileRejected, match=r"40\.00 mm"):
        fit_ellipse_ransac(points, CONFIG, rng, radius_m=2 * RADIUS)
    with pytest.raises(InputError):
        fit_ellipse_ransac(points, CONFIG, rng, radius_m=-RADIUS)


def test_straight_line_is_rejected() -> None:
    rng = np.random.default_rng(7)
    x = np.linspace(-0.03, 0.03, 500)
    line = np.column_stack([x, 0.25 + 0.1 * x]) + SIGMA * rng.standard_normal((500, 2))
    with pytest.raises(ProfileRejected):
        fit_ellipse_ransac(line, EllipseConfig(), rng)
    with pytest.raises(ProfileRejected, match="collinear"):
        fit_ellipse_direct(np.column_stack([x, 0.25 + 0.1 * x]))


def test_a_bowed_plane_is_no_short_arc() -> None:
    """A plane seen by a profiler whose 40 mm line bows by 50 um: a smooth curve that an
    ellipse fits far better than a line, yet neither an arc nor a short arc (its tangent
    turns by half a degree; an ellipse hugging it from both sides turns by 180 deg)."""
    rng = np.random.default_rng(9)
    x = np.linspace(-0.02, 0.02, 500)
    bow = 50e-6 * (1.0 - (x / 0.02) ** 2)
    plane = np.column_stack([x, 0.25 + 0.1 * x + bow]) + SIGMA * rng.standard_normal((500, 2))
    with pytest.raises(ProfileRejected):
        fit_ellipse_ransac(plane, EllipseConfig(), rng)


def test_too_few_points_and_bad_input() -> None:
    rng = np.random.default_rng(8)
    points, _, _ = random_arc(rng, 120.0, n=10)
    with pytest.raises(ProfileRejected, match="only 10 points"):
        fit_ellipse_ransac(points, EllipseConfig(), rng)
    points, _, _ = random_arc(rng, 120.0)
    points[3, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit_ellipse_ransac(points, EllipseConfig(), rng)
    with pytest.raises(InputError, match="shape"):
        fit_ellipse_ransac(np.zeros((100, 3)), EllipseConfig(), rng)


def test_same_seed_gives_the_same_fit() -> None:
    points, _, _ = random_arc(np.random.default_rng(9), 120.0, sigma=SIGMA)
    points[::10, 1] += 2e-3  # outliers, so that the samples matter
    fits = [fit_ellipse_ransac(points, CONFIG, np.random.default_rng(42)) for _ in range(2)]
    assert_floats_close(fits[0].centre_xz, fits[1].centre_xz)
    assert_floats_close(fits[0].conic, fits[1].conic)
    np.testing.assert_array_equal(fits[0].inliers, fits[1].inliers)


def test_eq5_centre_matches_the_general_centre_formula() -> None:
    rng = np.random.default_rng(10)
    for _ in range(20):
        centre = rng.uniform(-0.3, 0.3, 2)
        conic = true_conic(centre, rng.uniform(0, math.pi), scale=rng.uniform(-1e3, 1e3))
        np.testing.assert_allclose(centre_from_conic(conic), centre, atol=1e-12)
        np.testing.assert_allclose(centre_from_gradient(conic), centre, atol=1e-12)
        conic_f1 = conic / conic[5]  # the paper's F = 1 form
        np.testing.assert_allclose(centre_from_conic(conic_f1), centre, atol=1e-12)


def test_ellipse_geometry_recovers_axes_and_flags_non_ellipses() -> None:
    centre, angle = np.array([0.01, 0.2]), 0.7
    geometry = ellipse_geometry(true_conic(centre, angle, scale=-3.0))
    assert geometry.valid
    np.testing.assert_allclose(geometry.centre, centre, atol=1e-12)
    np.testing.assert_allclose(geometry.semi_axes, [SEMI_MAJOR, RADIUS], rtol=1e-12)
    assert abs(geometry.major_axis @ [math.cos(angle), math.sin(angle)]) == pytest.approx(1.0)
    hyperbola = np.array([1.0, 0.0, -1.0, 0.0, 0.0, -1.0])  # x^2 - z^2 = 1
    empty = np.array([1.0, 0.0, 1.0, 0.0, 0.0, 1.0])  # x^2 + z^2 = -1
    assert not ellipse_geometry(np.stack([hyperbola, empty])).valid.any()


def test_the_refits_shortcuts_agree_with_the_array_forms() -> None:
    """The scalar ellipse check is ellipse_geometry's, distances from held rows are
    sampson_distance's, and a refit's held Jacobian is the one at its conic."""
    rng = np.random.default_rng(12)
    hyperbola, empty = [1.0, 0, -1, 0, 0, -1], [1.0, 0, 1, 0, 0, 1]
    conics = np.concatenate([rng.normal(size=(400, 6)), [hyperbola, empty]])
    assert [is_ellipse(k) for k in conics] == ellipse_geometry(conics).valid.tolist()
    points, _, _ = random_arc(rng, 90.0, n=60)
    u = (points - points.mean(axis=0)) / points.std()
    rows = sampson_rows(u)
    np.testing.assert_allclose(
        sampson_from_rows(conics[0], rows), sampson_distance(conics[0], u), rtol=1e-12
    )
    start = np.linalg.svd(rows[0])[2][-1]  # the algebraic fit
    fit = refine_geometric(start, u, rows)
    assert fit.residual is not None and fit.jacobian is not None
    residual, jacobian = sampson_jacobian(fit.conic, rows)
    np.testing.assert_allclose(fit.residual, residual, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fit.jacobian, jacobian, rtol=1e-12, atol=1e-15)


def test_direct_fit_is_exact_on_an_ellipse() -> None:
    rng = np.random.default_rng(11)
    points, centre, angle = random_arc(rng, 90.0, n=50)
    conic = fit_ellipse_direct(points)
    assert conic[5] == 1.0
    np.testing.assert_allclose(
        conic, true_conic(centre, angle) / true_conic(centre, angle)[5], rtol=1e-6
    )
    np.testing.assert_allclose(centre_from_conic(conic), centre, atol=1e-9)


def test_sampson_distance_approximates_the_normal_offset() -> None:
    centre, angle = np.array([0.0, 0.25]), 0.3
    t = np.linspace(0.0, 2 * math.pi, 50, endpoint=False)
    on = ellipse_points(t, centre, angle)
    # Outward normal of the ellipse at t, in the rotated frame.
    normal = np.column_stack([RADIUS * np.cos(t), SEMI_MAJOR * np.sin(t)]) @ rotation(angle).T
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = 20e-6
    distance = sampson_distance(true_conic(centre, angle), on + offset * normal)
    np.testing.assert_allclose(distance, offset, rtol=2e-3)


def test_regression_table_line_never_captures_the_ellipse() -> None:
    """Arcs with the table in view (cylinder standing on it): RANSAC once accepted large
    ellipses hugging the table line; every accepted fit must have the radius as semi-minor
    axis and lie on the true arc."""
    from linelaser_calib.core.targets.cylinder import CylinderConfig, FittedSample, fit_sample
    from linelaser_calib.core.types import Sample
    from linelaser_calib.sim import random_scenario, simulate

    fitted = 0
    for seed in range(4):
        scenario = random_scenario(
            np.random.default_rng(500 + seed), background="table", n_poses=12, resolution=400
        )
        data = simulate(scenario, seed)
        radius = data.truth.cylinder.radius
        rng = np.random.default_rng(seed)
        for k, profile in enumerate(data.profiles):
            sample = Sample(k, profile.stamp_ns, data.truth.T_base_flange_true[k], profile.points)
            outcome = fit_sample(sample, CylinderConfig(), rng)
            if isinstance(outcome, FittedSample):
                fitted += 1
                assert abs(outcome.ellipse.semi_axes[1] - radius) < 2e-4, (seed, k)
    assert fitted >= 30


def test_a_short_circular_arc_fixes_its_circle_of_known_radius() -> None:
    """A 25 deg arc leaves an ellipse loose, but the circle of the radius through it lands on
    its centre (the seed's stand-in for a short arc's centre), from either side of the arc."""
    rng = np.random.default_rng(8)
    for _ in range(5):
        centre = np.array([rng.uniform(-0.03, 0.03), rng.uniform(0.15, 0.3)])
        t = rng.uniform(0.0, 2 * math.pi) + np.radians(np.linspace(0.0, 25.0, 200))
        arc = centre + RADIUS * np.column_stack([np.cos(t), np.sin(t)])
        arc += SIGMA * rng.standard_normal(arc.shape)
        assert np.linalg.norm(circle_centre(arc, RADIUS) - centre) < 20e-6
        assert circle_radius(arc) == pytest.approx(RADIUS, rel=0.02)
