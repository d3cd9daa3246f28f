"""The cylinder's model checks (issue 22): rival shapes, not a residual against local noise."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.core.errors import CalibrationError, DegenerateError
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pipeline import Method, PipelineConfig, run_pipeline
from linelaser_calib.core.targets.cylinder import CylinderConfig
from linelaser_calib.core.targets.cylinder.ellipse import EllipseConfig
from linelaser_calib.core.targets.cylinder.features import FittedSample, fit_sample
from linelaser_calib.core.targets.cylinder.section import CylinderSection
from linelaser_calib.core.types import Sample
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.simulate import SimulatedData, simulate

BAGS = Path(__file__).resolve().parents[1] / "bags"
RADIUS, MAJOR = 0.0125, 0.015


def _real_like_arc(rng: np.random.Generator, span_deg: float) -> np.ndarray:
    """A cut of a 12.5 mm cylinder (semi-major 15 mm) seen over ``span_deg`` of its
    parametric angle, 600 points, with a 25 um smooth bow, 4 um of local noise and a 0.3 %
    along-line scale error, as a real profiler shows it; (N, 3) in the sensor frame, m."""
    t = np.radians(np.linspace(-span_deg / 2, span_deg / 2, 600)) - math.pi / 2
    x = MAJOR * np.cos(t) * 1.003
    z = 0.12 + RADIUS * np.sin(t)
    z += 25e-6 * np.sin(2 * math.pi * (x - x[0]) / (x[-1] - x[0]) * 1.5)
    z += 4e-6 * rng.standard_normal(len(z))
    return np.column_stack([x, np.zeros_like(x), z])


@pytest.mark.parametrize("radius_m", [None, RADIUS])
def test_a_real_like_profile_with_shape_error_is_an_arc(radius_m: float | None) -> None:
    rng = np.random.default_rng(3)
    points = _real_like_arc(rng, 110.0)
    sample = Sample(0, 0, np.eye(4), points)
    fitted = fit_sample(sample, CylinderConfig(), rng, radius_m)
    assert isinstance(fitted, FittedSample), fitted
    # 25 um of bow is many times the 4 um of local noise, yet every point is on the arc.
    assert fitted.ellipse.inliers.mean() > 0.9
    # One partial arc with a bow pins its semi-minor axis only loosely (here 12 % off).
    assert fitted.ellipse.semi_axes[1] == pytest.approx(RADIUS, rel=0.2)


def test_a_feature_holds_its_arc_at_float32_and_no_raw_profile() -> None:
    """Regression (issue 32): a feature held its sample's raw profile, its segmentation and
    copies of its arc's points (35 kB a profile, pickled from the forked extraction too);
    with a profiler's float32 coordinates it now holds the arc's points as float32, and hands
    them out as float64 of the same values."""
    rng = np.random.default_rng(4)
    raw = _real_like_arc(rng, 110.0).astype(np.float32)
    sample = Sample(0, 0, np.eye(4), np.vstack([raw, np.full((200, 3), np.nan, np.float32)]))
    fitted = fit_sample(sample, CylinderConfig(), rng)
    assert isinstance(fitted, FittedSample), fitted
    assert fitted.points.dtype == np.float32
    inliers = fitted.inlier_points
    assert inliers.dtype == np.float64
    assert np.isin(inliers[:, 0], raw[:, 0].astype(np.float64)).all()  # the raw values
    assert np.array_equal(fitted.record().points, inliers)
    assert len(pickle.dumps(fitted)) < 15 * len(fitted.points) + 4000


def test_partial_arcs_with_a_free_radius_calibrate() -> None:
    """Arcs cut to 45-60 deg by the profiler's incidence limit, Gocator-class shape errors,
    radius estimated: the joint fit of all profiles pins the radius."""
    scenario = scenario_from_preset(
        "cylinder_gocator", max_incidence_rad=math.radians(40.0), min_arc_fraction=0.05, n_poses=20
    )
    data = simulate(scenario, 0)
    result = run_pipeline(data.profiles, data.poses, PipelineConfig())
    section = result.target
    assert isinstance(section, CylinderSection) and section.radius_estimated
    assert abs(section.cylinder.radius - data.truth.cylinder.radius) < 1e-4
    assert len(result.samples_used) >= 10


@pytest.fixture(scope="module")
def short_arcs() -> SimulatedData:
    """``cylinder_gocator`` losing its returns beyond 12 deg of incidence: arcs of about 25
    deg of the Ø40 mm shaft, with the Gocator's smooth shape errors."""
    scenario = scenario_from_preset(
        "cylinder_gocator", max_incidence_rad=math.radians(12.0), min_arc_fraction=0.02, n_poses=20
    )
    return simulate(scenario, 0)


def test_short_arcs_of_25_deg_are_used_and_calibrate(short_arcs: SimulatedData) -> None:
    """Every arc is short: without short arcs the recording is refused (most profiles give no
    ellipse, and the failed ones look like line pairs); with them their points give the
    hand-eye, the radius given. The paper's method, on centres, refuses short arcs."""
    data = short_arcs
    radius = data.truth.cylinder.radius
    arcs_only = CylinderConfig(radius_m=radius, ellipse=EllipseConfig(min_short_arc_turn_rad=0.0))
    with pytest.raises(CalibrationError):
        run_pipeline(data.profiles, data.poses, PipelineConfig(target_config=arcs_only))
    config = PipelineConfig(target_config=CylinderConfig(radius_m=radius), self_check_folds=0)
    with pytest.raises(DegenerateError, match=r"the paper's method needs \d+; \d+ more show short"):
        run_pipeline(data.profiles, data.poses, replace(config, method=Method.PAPER))
    result = run_pipeline(data.profiles, data.poses, config)
    assert len(result.samples_used) >= 12
    rotation, translation = transform_error(result.T_flange_sensor, data.truth.T_flange_sensor)
    assert math.degrees(rotation) < 0.6 and translation < 1.5e-3


def test_a_free_radius_from_short_arcs_lands_near_truth(short_arcs: SimulatedData) -> None:
    """No arc pins its ellipse, yet the joint fit of all profiles pins the radius."""
    data = short_arcs
    result = run_pipeline(data.profiles, data.poses, PipelineConfig(self_check_folds=0))
    section = result.target
    assert isinstance(section, CylinderSection) and section.radius_estimated
    assert abs(section.cylinder.radius - data.truth.cylinder.radius) < 2e-4
    assert len(result.samples_used) >= 12
