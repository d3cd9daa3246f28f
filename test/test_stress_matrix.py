"""The stress matrix of issue 29: every target on each face of a real profiler.

A real profiler's profiles thin out on steep surfaces, have gaps, show a floor or a wall
beside the target, have x and z scales a little off, and carry a shape error (a fixed x/z
distortion and a smooth part, as the real ball sets show) with which a conic beats a circle
on a single profile (:data:`~linelaser_calib.sim.
sensor_models.REAL_FACES`). Each target calibrates a recording with one such face as well as
its clean twin (the same scene and seed without it): nothing refused, no profile set aside
that the clean twin uses, and an error against the truth within 1.5 times the clean twin's
(or 1.5 times the larger of the two runs' 1σ: a face that adds noise, such as the shape
error, rightly widens the error and its stated 1σ with it). Each recording given to a
wrong target is refused naming the right one.

The cylinder and the sphere already scan a table beside the target, so their ``floor`` is
their clean twin; the seam targets get a plate beside a flank. Small pose counts keep each
case to a few seconds; the whole matrix is marked slow.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from linelaser_calib.core.errors import DegenerateError, InputError, ModelMismatch
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.model_check import CLEAR_BIC, ShapeFit, compare_models, conic_fit
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, calibrate_samples
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.sphere import SphereConfig
from linelaser_calib.core.targets.sphere.circle import circle_residuals
from linelaser_calib.io.robcalibrator import read_robcalibrator
from linelaser_calib.settings import Front, pipeline_config
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.sensor_models import REAL_FACES, SensorModel, with_faces
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import SPHERE_PRESETS, simulate_sphere, sphere_scenario_from_preset
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset

pytestmark = pytest.mark.slow

TARGETS = ("cylinder", "sphere", "line", "known_point")
FACES = (*REAL_FACES, "floor")
#: Width of the plate beside the seam targets' flank (the ``floor`` face), m.
FLOOR_WIDTH_M = 0.01
#: The same lab's 12.7 mm ball set, kept out of the repository (../shared/external/README).
BALL = Path(__file__).resolve().parents[2] / "shared" / "external" / "robcalibrator" / "ball"


@cache
def _recording(target: str, face: str, seed: int = 3) -> tuple[list[Any], Any, np.ndarray, float]:
    """Paired samples, pairing rejections, the true hand-eye and the clock offset of a
    small recording of ``target`` with one ``face`` ('' for the clean twin)."""
    sensor_faces = (face,) if face in REAL_FACES else ()
    floor = FLOOR_WIDTH_M if face == "floor" else 0.0
    offset = 0.0
    if target == "cylinder":
        scenario = scenario_from_preset("ur_scancontrol", n_poses=12, resolution=320)
        scenario = replace(scenario, sensor=with_faces(scenario.sensor, *sensor_faces))
        data: Any = simulate(scenario, seed)
    elif target == "sphere":
        base = sphere_scenario_from_preset("sphere", n_poses=14)
        sensor = with_faces(base.rig.sensor, *sensor_faces)
        data = simulate_sphere(replace(base, rig=replace(base.rig, sensor=sensor)), seed)
    elif target == "line":
        base_line = line_scenario_from_preset(
            "line", n_poses=24, resolution=640, profile_rate_hz=10.0, floor_width_m=floor
        )
        sensor = with_faces(base_line.rig.sensor, *sensor_faces)
        line = replace(base_line, rig=replace(base_line.rig, sensor=sensor))
        data = simulate_line(line, seed)
        offset = -line.rig.latency_s
    else:
        weld = weld_scenario_from_preset("weld_seam_general", n_poses=20, floor_width_m=floor)
        sensor = with_faces(weld.rig.sensor, *sensor_faces)
        data = simulate_weld(replace(weld, rig=replace(weld.rig, sensor=sensor)), seed)
    moving = target == "line"
    pairing = PairingConfig(
        max_linear_speed_m_s=0.0 if moving else PairingConfig().max_linear_speed_m_s,
        max_angular_speed_rad_s=0.0 if moving else PairingConfig().max_angular_speed_rad_s,
        clock_offset_s=offset,
    )
    paired = pair_profiles(data.profiles, data.poses, pairing)
    return paired.samples, paired.rejected, data.truth.T_flange_sensor, offset


def _calibrate(target: str, recording: str, face: str) -> CalibrationResult:
    samples, rejected, _, offset = _recording(recording, face)
    pairing = PairingConfig(clock_offset_s=offset)
    config = pipeline_config(target, Method.DEFAULT, {}, Front.CLI, seed=0, pairing=pairing)
    return calibrate_samples(list(samples), replace(config, self_check_folds=0), list(rejected))


@cache
def _clean(target: str) -> CalibrationResult:
    return _calibrate(target, target, "")


def _error(result: CalibrationResult, target: str) -> tuple[float, float]:
    truth = _recording(target, "")[2]
    rotation, translation = transform_error(result.T_flange_sensor, truth)
    return rotation, translation


def _sigma(result: CalibrationResult) -> tuple[float, float]:
    """The length of the 1σ of the hand-eye's translation (m) and rotation (rad)."""
    assert result.uncertainty_translation_m is not None
    assert result.uncertainty_rotation_rad is not None
    return (
        float(np.linalg.norm(result.uncertainty_translation_m)),
        float(np.linalg.norm(result.uncertainty_rotation_rad)),
    )


@pytest.mark.parametrize("face", FACES)
@pytest.mark.parametrize("target", TARGETS)
def test_each_target_calibrates_on_each_face_as_well_as_its_clean_twin(
    target: str, face: str
) -> None:
    if face == "floor" and target in ("cylinder", "sphere"):
        pytest.skip("the cylinder's and the sphere's scenes show a table beside the target")
    clean = _clean(target)
    result = _calibrate(target, target, face)
    set_aside = [
        r for r in result.samples_rejected if r.index in clean.samples_used and r.stage != "pairing"
    ]
    assert len(result.samples_used) >= len(clean.samples_used) - 1, [r.reason for r in set_aside]
    rotation, translation = _error(result, target)
    clean_rotation, clean_translation = _error(clean, target)
    allowed_t = 1.5 * max(clean_translation, _sigma(clean)[0], _sigma(result)[0])
    allowed_r = 1.5 * max(clean_rotation, _sigma(clean)[1], _sigma(result)[1])
    assert translation <= allowed_t, (translation * 1e3, allowed_t * 1e3)
    assert rotation <= allowed_r, (math.degrees(rotation), math.degrees(allowed_r))


@pytest.mark.parametrize(
    ("recording", "target"),
    [(r, t) for r in TARGETS for t in TARGETS if r != t],
)
def test_each_recording_given_to_a_wrong_target_is_refused_naming_the_right_one(
    recording: str, target: str
) -> None:
    with pytest.raises((ModelMismatch, DegenerateError)) as refused:
        _calibrate(target, recording, "")
    assert recording in str(refused.value), str(refused.value)


def test_the_cylinder_learns_the_shape_face_beside_its_depth_noise() -> None:
    """``ur_scancontrol``'s depth noise (8 µm against 6 µm lateral) with the ``shape`` face's
    smooth error (4 µm over 2 mm) beside it: the learned line noise holds both (issue 29:
    the depth noise alone took the smooth error as independent, and the rotation about the
    line was 1.3 times its 1σ RMS)."""
    noise = getattr(_calibrate("cylinder", "cylinder", "shape").target, "line_noise", None)
    assert noise is not None
    assert noise.depth_sigma_m > 0.0
    assert noise.smooth_sigma_m == pytest.approx(4e-6, rel=0.3)
    assert noise.length_m == pytest.approx(2e-3, rel=0.3)


def test_the_faces_are_what_the_field_showed() -> None:
    """Each face does what it says on a profile: thinning, gaps, scales."""
    model = SensorModel()
    assert not model.active
    for face in REAL_FACES:
        assert with_faces(model, face).active
    scales = with_faces(model, "scales")
    assert 0.003 <= abs(scales.x_scale_error - scales.z_scale_error) <= 0.01
    with pytest.raises(InputError, match="x_scale_error"):
        with_faces(model, "scales", "shape")


def _conic_margins(samples: list[Any], radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per profile, the circle's BIC minus a free conic's (the sphere target's circle and
    inliers; positive: the conic fits better), and the same over the profile's points."""
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=radius_m), 0, lambda *_: None
    )
    margins = []
    for f in features:
        xz = f.points[:, [0, 2]]
        circle = ShapeFit("circle", circle_residuals(xz, f.circle.centre_xz, f.circle.radius_m), 3)
        margins.append((compare_models(circle, [conic_fit(xz)]).delta_bic, len(xz)))
    m = np.array(margins)
    return m[:, 0], m[:, 0] / m[:, 1]


def test_the_shape_face_makes_a_conic_beat_a_circle_as_on_the_real_ball_set() -> None:
    """Issue 29: on the real 12.7 mm ball set a conic fits all 10 profiles clearly better
    than a circle, by a median 0.41 of BIC per point (``bench/realism.py --only conic``);
    the ``shape`` face does so on the stress matrix's sphere scene, its clean twin not."""
    radius = SPHERE_PRESETS["sphere"].radius_m
    sets = {
        "shape": _conic_margins(_recording("sphere", "shape")[0], radius),
        "clean": _conic_margins(_recording("sphere", "")[0], radius),
    }
    if BALL.is_dir():
        scans = read_robcalibrator(BALL)
        paired = pair_profiles(scans.profiles, scans.poses, PairingConfig())
        sets["real"] = _conic_margins(list(paired.samples), scans.sphere_radius_m)
    for name, (margin, per_point) in sets.items():
        wins, typical = float(np.mean(margin > CLEAR_BIC)), float(np.median(per_point))
        if name == "clean":
            assert wins < 0.5 and typical < 0.05, (name, margin)
        else:
            assert wins >= 0.8 and 0.2 <= typical <= 0.8, (name, margin, per_point)
