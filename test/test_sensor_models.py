"""Real-profiler sensor models: measured statistics against the facts they reproduce."""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Any

import numpy as np
import pytest

from linelaser_calib.core.errors import InputError
from linelaser_calib.sim.presets import PRESETS
from linelaser_calib.sim.profiler import Trace, measure
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Surface
from linelaser_calib.sim.sensor_models import (
    SensorModel,
    apply_sensor_model,
    circle_rms_m,
    second_difference_noise_m,
    sensor_model_from_mapping,
)
from linelaser_calib.sim.sphere import (
    SPHERE_PRESETS,
    Ball,
    simulate_sphere,
    sphere_views,
    trace_ball,
)


def _sphere_statistics(seed: int) -> tuple[list[float], list[float]]:
    """Local noise and circle RMS (m) of each sphere profile of ``sphere_sszn``."""
    data = simulate_sphere(SPHERE_PRESETS["sphere_sszn"], seed)
    local, circle = [], []
    for k, profile in enumerate(data.profiles):
        # Dense profiles: the rows are the valid rays, in ray order.
        on_ball = data.truth.surface[k][data.truth.valid[k]] == Surface.SIDE
        points = profile.points[on_ball]
        local.append(second_difference_noise_m(points))
        circle.append(circle_rms_m(points))
    return local, circle


def test_sszn_fanuc_reproduces_the_measured_noise_and_circle_residual() -> None:
    local, circle = _sphere_statistics(seed=2)
    # The real FANUC cell: 3.5-4.5 um local noise, 20-40 um RMS circle residual.
    assert 3.5e-6 <= float(np.median(local)) <= 4.5e-6
    assert 20e-6 <= float(np.median(circle)) <= 40e-6
    assert np.mean((np.array(circle) >= 15e-6) & (np.array(circle) <= 45e-6)) >= 0.8


def test_shape_error_is_smooth_not_local() -> None:
    local, circle = _sphere_statistics(seed=5)
    # The residual about the circle is many times the point-to-point noise.
    assert float(np.median(np.array(circle) / np.array(local))) > 4.0


def _sphere_trace() -> tuple[Scenario, Trace]:
    sphere = SPHERE_PRESETS["sphere_sszn"]
    ball = Ball.from_scenario(sphere)
    views = sphere_views(sphere, ball, np.random.default_rng(0))
    return sphere.rig, trace_ball(ball, sphere.rig, views)


def test_weak_returns_drop_more_at_steep_incidence_and_on_dark_surfaces() -> None:
    rig, traced = _sphere_trace()
    measured = measure(np.random.default_rng(1), rig, traced)
    cos_inc = traced.cos_incidence
    seen = traced.seen
    with np.errstate(invalid="ignore"):
        steep, facing = seen & (cos_inc < 0.3), seen & (cos_inc > 0.8)
    assert steep.sum() > 100 and facing.sum() > 100
    steep_rate = measured.dropout[steep].mean()
    assert steep_rate > 5.0 * measured.dropout[facing].mean()
    dark = measure(np.random.default_rng(1), replace(rig, cylinder_reflectance=0.3), traced)
    assert dark.dropout[steep].mean() > steep_rate


def test_quantisation_rounds_x_and_z_to_their_steps() -> None:
    rig, traced = _sphere_trace()
    model = SensorModel(x_step_m=1e-5, z_step_m=4e-6)
    measured = measure(np.random.default_rng(3), replace(rig, sensor=model), traced)
    p = measured.points[measured.valid]
    for axis, step in ((0, 1e-5), (2, 4e-6)):
        assert np.allclose(p[:, axis] / step, np.round(p[:, axis] / step), atol=1e-6)


def test_the_scales_act_about_the_sensor_origin() -> None:
    """x and z are each multiplied by (1 + their scale error), whatever the measuring range:
    a pivot elsewhere would shift the sensor frame, which is part of the hand-eye."""
    model = SensorModel(x_scale_error=0.006, z_scale_error=-0.002)
    points = np.array([[[0.012, 0.0, 0.09], [-0.02, 0.0, 0.13]]])
    measured, weak = apply_sensor_model(
        np.random.default_rng(0),
        model,
        points,
        points,
        (0.07, 0.15),
        np.ones((1, 2)),
        np.ones((1, 2)),
    )
    assert not weak.any()
    assert np.allclose(measured[..., 0], 1.006 * points[..., 0], rtol=0, atol=1e-15)
    assert np.allclose(measured[..., 2], 0.998 * points[..., 2], rtol=0, atol=1e-15)


def test_linearity_bow_is_bounded_by_the_datasheet_figure() -> None:
    rig, traced = _sphere_trace()
    quiet = replace(rig, sigma_depth_m=0.0, sigma_lateral_m=0.0)
    model = SensorModel(linearity_m=2e-5)
    measured = measure(np.random.default_rng(4), replace(quiet, sensor=model), traced)
    error = measured.points[..., 2] - traced.points_sensor[..., 2]
    error = error[measured.valid]
    assert float(np.max(np.abs(error))) <= 2e-5 + 1e-12
    assert float(np.std(error)) > 1e-6


def test_the_default_sensor_model_adds_only_white_noise() -> None:
    rig, traced = _sphere_trace()
    assert not SensorModel().active
    plain = measure(np.random.default_rng(6), replace(rig, sensor=SensorModel()), traced)
    error = plain.points[..., 2] - traced.points_sensor[..., 2]
    error = error[plain.valid]
    assert abs(float(np.std(error)) / rig.sigma_depth_m - 1.0) < 0.05
    assert not plain.dropout.any()


def test_scenario_takes_a_sensor_model_from_plain_values() -> None:
    s = replace(PRESETS["paper"], sensor=SensorModel(shape_sigma_m=1e-5))
    values: dict[str, Any] = {**asdict(PRESETS["paper"]), "sensor": {"shape_sigma_m": 1e-5}}
    assert Scenario(**values) == s
    with pytest.raises(InputError, match="unknown field"):
        sensor_model_from_mapping({"bow": 1.0})
    with pytest.raises(InputError, match="shape_length_m"):
        SensorModel(shape_length_m=0.0)
