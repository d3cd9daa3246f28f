"""Goals of issue 29 on the faces of a real profiler: the real scans, the realistic presets,
and each target on each face.

``real``
    The faces as the real scans in ``../shared/external/robcalibrator`` show them (skipped
    where absent): per set, the points per profile, the local noise (RMS of second
    differences / √6), the RMS about each profile's best circle and its smooth part (the
    residual smoothed over 10 points), the gaps inside an arc (runs of missing columns
    longer than 2 pitches) per profile and their mean length, and the share of the columns
    that return in each band of surface slope (against the ray fan's own count for a circle
    of the profile's radius: 100 % means no thinning beyond the geometry's).
``conic``
    Why a conic beats a circle on a single profile of a ball, on the real sets and on the
    simulator's ``sphere`` scene with each face (the stress matrix's: 14 views, pooled over
    seeds) and on ``sphere_sszn``: per set, the profiles whose conic's BIC lies
    :data:`~linelaser_calib.core.model_check.CLEAR_BIC` below the circle's (the sphere
    target's circle and a free conic, effective points as the target counts them), the
    median robust scale of each, the median BIC margin per point; the one fixed linear
    distortion of the sensor's plane that best makes every profile of the set a circle
    (x' = (1 + a) x + b z, z' = z + b x: its axes' difference, %, and the short axis's angle
    from x, deg) and the profiles a conic still wins after it is undone; the local noise
    (RMS of second differences / √6) and the smooth part of the corrected circle residual
    (a Gaussian fitted to its autocovariance from the second lag on: 1σ and correlation
    length).
``presets``
    Each realistic preset (a real profiler's datasheet geometry and shape errors:
    ``cylinder_keyence``, ``cylinder_scancontrol``, ``cylinder_gocator``, ``sphere_sszn``,
    and ``line_ridge``, a ridge seen with every face at full size) before and after the
    faces were added: ``before`` turns the gaps and the x/z scale errors off (and, on
    ``line_ridge``, the thinning at incidence), ``after`` is the preset as it is.
``faces``
    Each target on each face of :data:`~linelaser_calib.sim.sensor_models.REAL_FACES` at
    full size, and on :data:`COMBINED` (the faces that combine: ``scales`` and ``shape``
    each set the x scale), beside its clean twin (the stress matrix's scenes:
    ``ur_scancontrol`` 12 poses of 320 points, ``sphere`` 14 views, ``line`` 24 waypoints,
    ``weld_seam_general`` 20 poses).
``honesty``
    The sphere's 1σ on its faces (the stress matrix's scene, ``faces`` above), on the
    ``shape`` face with its stretch read in depth instead (z 1.01 % long, x true: the same
    x/z ratio, which the profiles cannot tell from it) and on ``sphere_sszn``: per row the
    share of per-axis errors within their 1σ (68 % for an honest Gaussian 1σ; the band
    asked for is 42-94 %), the largest |error| / 1σ, the RMS of error / 1σ per axis
    (rotation about the sensor's x, y, z; translation along the flange's x, y, z), and the
    hand-eye error and 1σ as in ``faces``.
``wrong``
    Each clean recording of those scenes given to each wrong target, once with the pairing
    of the command line (a swept seam's latency given) and once with ``--clock-offset auto``
    (searched from 0; only the cylinder and the line estimate an offset): the outcome, the
    target the refusal names (and the offset it was judged at), and the whole-recording
    figures the message gives (RMS distance of the points from each fitted target, µm).

Per row of ``presets`` and ``faces``, over seeds: profiles used of those recorded (pooled),
refused runs, the hand-eye error against truth (RMS over seeds, deg and mm), the 1σ as
reported (RMS over seeds of the length of the rotation and translation 1σ, self-check
widening included), and the largest per-axis |error| / 1σ. The goals: ≥ 98 % of profiles
used, no refusal, |error|/σ ≤ 3.

Run: ``.venv/bin/python bench/realism.py [--seeds N]
[--only real|conic|presets|faces|honesty|wrong]
[--presets A,B] [--targets A,B]`` (default 3 seeds; a calibration takes 5-40 s; ``wrong``
runs the stress matrix's seed, 3, only).
"""

from __future__ import annotations

import argparse
import itertools
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from realistic_sensors import Tally
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import curve_fit, least_squares

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix
from linelaser_calib.core.model_check import CLEAR_BIC, ShapeFit, compare_models, conic_fit
from linelaser_calib.core.offset_search import search_clock_offset
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, calibrate_samples, run_pipeline
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.sphere import SphereConfig
from linelaser_calib.core.targets.sphere.circle import (
    circle_residuals,
    fit_circle_algebraic,
    fit_circle_geometric,
)
from linelaser_calib.io.robcalibrator import read_robcalibrator
from linelaser_calib.settings import Front, pipeline_config, render
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.sensor_models import (
    REAL_FACES,
    second_difference_noise_m,
    with_faces,
)
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import simulate_sphere, sphere_scenario_from_preset
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset

EXTERNAL = Path(__file__).resolve().parents[2] / "shared" / "external" / "robcalibrator"
#: Realistic presets and their target.
PRESETS = {
    "cylinder_keyence": "cylinder",
    "cylinder_scancontrol": "cylinder",
    "cylinder_gocator": "cylinder",
    "sphere_sszn": "sphere",
    "line_ridge": "line",
}
#: The sensor-model terms turned off for a preset's ``before`` row.
BEFORE = {"gap_rate": 0.0, "x_scale_error": 0.0, "z_scale_error": 0.0}
TARGETS = ("cylinder", "sphere", "line", "known_point")
#: The faces of one recording in the ``faces`` table's last row, as the realistic presets
#: combine them.
COMBINED = ("grazing", "gaps", "shape")
SLOPE_BANDS_DEG = (0.0, 30.0, 50.0, 60.0, 70.0, 80.0)
#: A gap is a run of missing columns longer than this many pitches.
GAP_PITCHES = 2.0


def real_table() -> None:
    """The faces on the real sphere scans (see the module docstring)."""
    if not EXTERNAL.is_dir():
        print(f"real scans: not here ({EXTERNAL}); skipped")
        return
    print(
        f"{'set':<10}{'profiles':>9}{'points':>8}{'local um':>9}{'circle um':>10}{'smooth um':>10}"
        f"{'gaps/prof':>10}{'gap mm':>8}  columns returned by slope band (deg), %"
    )
    for name, folder in (("40 mm", EXTERNAL), ("12.7 mm", EXTERNAL / "ball")):
        scans = read_robcalibrator(folder)
        stats: list[tuple[float, ...]] = []
        gaps: list[float] = []
        seen = np.zeros(len(SLOPE_BANDS_DEG) - 1)
        expected = np.zeros(len(SLOPE_BANDS_DEG) - 1)
        for profile in scans.profiles:
            points = profile.points[np.all(np.isfinite(profile.points), axis=1)]
            xz = points[:, [0, 2]]
            centre, radius = fit_circle_algebraic(xz)
            centre, radius = fit_circle_geometric(xz, centre, radius)
            if radius > 2.0 * scans.sphere_radius_m:
                continue  # a profile of the table and the stem, not the ball's arc
            residual = circle_residuals(xz, centre, radius)
            smooth = gaussian_filter1d(residual, 10.0)
            stats.append(
                (
                    len(points),
                    second_difference_noise_m(points),
                    float(np.sqrt(np.mean(residual**2))),
                    float(np.sqrt(np.mean(smooth**2))),
                )
            )
            pitch = float(np.median(np.diff(xz[:, 0])))
            steps = np.diff(xz[:, 0])
            gaps.extend((steps[steps > (GAP_PITCHES + 1.0) * pitch] - pitch).tolist())
            slope = np.degrees(np.arccos(np.clip(np.abs(xz[:, 1] - centre[1]) / radius, 0, 1)))
            left = xz[:, 0] < centre[0]
            for b, (low, high) in enumerate(itertools.pairwise(SLOPE_BANDS_DEG)):
                for side in (left, ~left):
                    in_band = side & (slope >= low) & (slope < high)
                    reach = min(high, float(slope[side].max())) if side.any() else low
                    if reach <= low:
                        continue
                    seen[b] += in_band.sum()
                    span = radius * (math.sin(math.radians(reach)) - math.sin(math.radians(low)))
                    expected[b] += span / pitch
        s = np.array(stats)
        bands = " ".join(
            f"{lo:.0f}-{hi:.0f}: {100.0 * n / e:.0f}"
            for (lo, hi), n, e in zip(
                itertools.pairwise(SLOPE_BANDS_DEG), seen, expected, strict=True
            )
        )
        mean_gap = np.mean(gaps) * 1e3 if gaps else 0.0
        print(
            f"{name:<10}{len(s):>9}{np.median(s[:, 0]):>8.0f}{np.median(s[:, 1]) * 1e6:>9.1f}"
            f"{np.median(s[:, 2]) * 1e6:>10.1f}{np.median(s[:, 3]) * 1e6:>10.1f}"
            f"{len(gaps) / len(s):>10.2f}{mean_gap:>8.2f}  {bands}"
        )
    print(
        "medians over the ball's profiles; the 12.7 mm set's 3 profiles with other "
        "surfaces beside the ball skipped"
    )


def _arcs(profiles: Any, poses: Any, radius_m: float) -> list[FloatArray]:
    """Each profile's circle inliers (N, 2), x and z in the sensor, m, in scan order."""
    samples = pair_profiles(profiles, poses, PairingConfig()).samples
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=radius_m), 0, lambda *_: None
    )
    return [f.points[:, [0, 2]] for f in features]


def _circle_residuals(xz: FloatArray) -> FloatArray:
    centre, radius = fit_circle_geometric(xz, *fit_circle_algebraic(xz))
    return circle_residuals(xz, centre, radius)


def _undistorted(xz: FloatArray, a: float, b: float) -> FloatArray:
    return np.column_stack([(1.0 + a) * xz[:, 0] + b * xz[:, 1], xz[:, 1] + b * xz[:, 0]])


def _common_distortion(arcs: list[FloatArray]) -> tuple[float, float]:
    """The (a, b) of :func:`_undistorted` that makes every arc closest to a circle."""

    def residuals(p: FloatArray) -> FloatArray:
        return np.concatenate(
            [_circle_residuals(_undistorted(xz, p[0], p[1])) / math.sqrt(len(xz)) for xz in arcs]
        )

    a, b = least_squares(residuals, [0.0, 0.0], x_scale=1e-3, diff_step=1e-4).x
    return float(a), float(b)


def _smooth_part(arcs: list[FloatArray], pitch_m: float) -> tuple[float, float]:
    """1σ (m) and correlation length (m) of a Gaussian fitted to the arcs' mean residual
    autocovariance from the second lag on (the first holds the neighbour-correlated noise)."""
    lags = min(200, min(len(xz) for xz in arcs) // 2)
    covariance = np.zeros(lags)
    for xz in arcs:
        r = _circle_residuals(xz)
        r = r - r.mean()
        covariance += [float(np.mean(r[: len(r) - k] * r[k:])) for k in range(lags)]
    covariance /= len(arcs)
    d = np.arange(lags) * pitch_m

    def gaussian(d: FloatArray, variance: float, length: float) -> FloatArray:
        return np.asarray(variance * np.exp(-(d**2) / (2.0 * length**2)))

    (variance, length), _ = curve_fit(gaussian, d[2:], covariance[2:], p0=[covariance[2], 1e-3])
    return math.sqrt(max(variance, 0.0)), abs(length)


def conic_row(label: str, arcs: list[FloatArray]) -> None:
    """One row of the ``conic`` table (see the module docstring)."""
    margins = []
    for xz in arcs:
        comparison = compare_models(ShapeFit("circle", _circle_residuals(xz), 3), [conic_fit(xz)])
        assert comparison.rival is not None
        margins.append(
            (comparison.delta_bic, comparison.model.scale_m, comparison.rival.scale_m, len(xz))
        )
    m = np.array(margins)
    a, b = _common_distortion(arcs)
    undone = [_undistorted(xz, a, b) for xz in arcs]
    after = sum(
        compare_models(ShapeFit("circle", _circle_residuals(xz), 3), [conic_fit(xz)]).delta_bic
        > CLEAR_BIC
        for xz in undone
    )
    pitch = float(np.median([np.median(np.abs(np.diff(xz[:, 0]))) for xz in arcs]))
    sigma, length = _smooth_part(undone, pitch)
    local = np.median([second_difference_noise_m(np.insert(xz, 1, 0.0, axis=1)) for xz in arcs])
    wins = f"{int(np.sum(m[:, 0] > CLEAR_BIC))}/{len(arcs)}"
    print(
        f"{label:<26}{wins:>7}{np.median(m[:, 1]) * 1e6:>8.1f}{np.median(m[:, 2]) * 1e6:>9.1f}"
        f"{np.median(m[:, 0] / m[:, 3]):>8.3f}{100.0 * math.hypot(a, 2.0 * b):>8.2f}"
        f"{math.degrees(0.5 * math.atan2(2.0 * b, a)):>7.0f}{f'{after}/{len(arcs)}':>7}"
        f"{local * 1e6:>9.1f}{sigma * 1e6:>8.1f}"
        f"{f'{length * 1e3:.2f}' if sigma > 5e-7 else '-':>7}",
        flush=True,
    )


def conic_table(seeds: int) -> None:
    """Why a conic beats a circle on single profiles, real and simulated (module docstring)."""
    print(
        f"{'set':<26}{'conic':>7}{'circ um':>8}{'conic um':>9}{'BIC/pt':>8}{'aniso %':>8}"
        f"{'deg':>7}{'undone':>7}{'local um':>9}{'smooth':>8}{'L mm':>7}"
    )
    if EXTERNAL.is_dir():
        for name, folder in (("real 40 mm", EXTERNAL), ("real 12.7 mm", EXTERNAL / "ball")):
            scans = read_robcalibrator(folder)
            conic_row(name, _arcs(scans.profiles, scans.poses, scans.sphere_radius_m))
    scene = sphere_scenario_from_preset("sphere", n_poses=14)
    for face in ("", "shape before", *REAL_FACES):
        if face == "shape before":  # the face before issue 29's measurement: 42 um over 4 mm
            sensor = replace(scene.rig.sensor, shape_sigma_m=4.2e-5, shape_length_m=0.004)
        else:
            sensor = with_faces(scene.rig.sensor, *((face,) if face else ()))
        arcs = []
        for seed in range(seeds):
            data = simulate_sphere(replace(scene, rig=replace(scene.rig, sensor=sensor)), seed)
            arcs += _arcs(data.profiles, data.poses, scene.radius_m)
        conic_row(f"sphere, {face or 'clean'}", arcs)
    sszn = sphere_scenario_from_preset("sphere_sszn")
    arcs = []
    for seed in range(seeds):
        data = simulate_sphere(sszn, seed)
        arcs += _arcs(data.profiles, data.poses, sszn.radius_m)
    conic_row("sphere_sszn", arcs)


def cells(tally: Tally) -> str:
    """Error RMS (deg, mm), 1σ RMS (deg, mm; each the length over the axes) and the largest
    per-axis |error| / 1σ of a row."""
    if not tally.errors:
        return f"{'-':>10}{'-':>10}{'-':>9}{'-':>9}{'-':>9}"
    rot, trans = tally.rms()
    s = np.array(tally.sigmas)
    sigma_rot = math.degrees(float(np.sqrt(np.mean(np.sum(s[:, :3] ** 2, axis=1)))))
    sigma_trans = float(np.sqrt(np.mean(np.sum(s[:, 3:] ** 2, axis=1)))) * 1e3
    return (
        f"{rot:>10.4f}{trans:>10.4f}{sigma_rot:>9.4f}{sigma_trans:>9.4f}{tally.worst_ratio():>9.2f}"
    )


def _error(T: FloatArray, truth: FloatArray) -> FloatArray:
    rotation = rotvec_from_matrix(truth[:3, :3].T @ T[:3, :3])
    return np.concatenate([rotation, T[:3, 3] - truth[:3, 3]])


def _preset_data(preset: str, before: bool, seed: int) -> Any:
    off: dict[str, float] = dict(BEFORE) if before else {}
    if preset == "line_ridge" and before:
        off["incidence_falloff"] = 0.0
    sensor = {"sensor": off} if off else {}
    target = PRESETS[preset]
    if target == "cylinder":
        return simulate(scenario_from_preset(preset, **sensor), seed)
    if target == "sphere":
        return simulate_sphere(sphere_scenario_from_preset(preset, **sensor), seed)
    return simulate_line(line_scenario_from_preset(preset, **sensor), seed)


def _face_data(target: str, faces: tuple[str, ...], seed: int) -> Any:
    """The stress matrix's small scene of ``target`` with ``faces`` (none for clean)."""
    if target == "cylinder":
        scenario = scenario_from_preset("ur_scancontrol", n_poses=12, resolution=320)
        return simulate(replace(scenario, sensor=with_faces(scenario.sensor, *faces)), seed)
    if target == "sphere":
        sphere = sphere_scenario_from_preset("sphere", n_poses=14)
        rig = replace(sphere.rig, sensor=with_faces(sphere.rig.sensor, *faces))
        return simulate_sphere(replace(sphere, rig=rig), seed)
    if target == "line":
        line = line_scenario_from_preset("line", n_poses=24, resolution=640, profile_rate_hz=10.0)
        rig = replace(line.rig, sensor=with_faces(line.rig.sensor, *faces))
        return simulate_line(replace(line, rig=rig), seed)
    weld = weld_scenario_from_preset("weld_seam_general", n_poses=20)
    rig = replace(weld.rig, sensor=with_faces(weld.rig.sensor, *faces))
    return simulate_weld(replace(weld, rig=rig), seed)


def command_line_result(data: Any, target: str) -> CalibrationResult:
    """Calibrate one simulated recording as the command line does (the robot moving while a
    seam is swept, its latency known); a refusal raises its CalibrationError."""
    moving = target == "line"
    pairing = PairingConfig(
        max_linear_speed_m_s=0.0 if moving else PairingConfig().max_linear_speed_m_s,
        max_angular_speed_rad_s=0.0 if moving else PairingConfig().max_angular_speed_rad_s,
        clock_offset_s=-data.truth.scenario.rig.latency_s if moving else 0.0,
    )
    paired = pair_profiles(data.profiles, data.poses, pairing)
    config = pipeline_config(target, Method.DEFAULT, {}, Front.CLI, seed=0, pairing=pairing)
    return calibrate_samples(list(paired.samples), config, list(paired.rejected))


def calibrate(data: Any, target: str, tally: Tally, seed: int) -> None:
    """:func:`command_line_result` of one simulated recording, added to ``tally``."""
    tally.recorded += len(data.profiles)
    try:
        result = command_line_result(data, target)
    except CalibrationError as exc:
        tally.refused.append(f"seed {seed}: {render(str(exc), Front.CLI)[:200]}")
        return
    tally.used += len(result.samples_used)
    tally.errors.append(_error(result.T_flange_sensor, data.truth.T_flange_sensor))
    assert result.uncertainty_rotation_rad is not None
    assert result.uncertainty_translation_m is not None
    tally.sigmas.append(
        np.concatenate([result.uncertainty_rotation_rad, result.uncertainty_translation_m])
    )


HEAD = (
    f"{'used':>12}{'refused':>8}{'rot deg':>10}{'trans mm':>10}{'1σ deg':>9}{'1σ mm':>9}"
    f"{'|e|/σ':>9}"
)


def _row(label: str, tally: Tally) -> str:
    used = f"{tally.used}/{tally.recorded}"
    return f"{label:<34}{used:>12}{len(tally.refused):>8}{cells(tally)}"


def presets_table(presets: list[str], seeds: int) -> list[str]:
    print(f"Realistic presets, {seeds} seeds (before: gaps and x/z scale errors off)")
    print(f"{'preset':<34}{HEAD}")
    notes = []
    for preset in presets:
        for before in (True, False):
            tally = Tally()
            for seed in range(seeds):
                calibrate(_preset_data(preset, before, seed), PRESETS[preset], tally, seed)
            label = f"{preset} {'before' if before else 'after'}"
            print(_row(label, tally), flush=True)
            notes.extend(f"{label} refused {text}" for text in tally.refused)
    return notes


def faces_table(targets: list[str], seeds: int) -> list[str]:
    print(f"Each target on each face at full size, {seeds} seeds (the stress matrix's scenes)")
    print(f"{'target, face':<34}{HEAD}")
    notes = []
    for target in targets:
        for faces in ((), *((face,) for face in REAL_FACES), COMBINED):
            tally = Tally()
            for seed in range(seeds):
                calibrate(_face_data(target, faces, seed), target, tally, seed)
            label = f"{target}, {'+'.join(faces) or 'clean'}"
            print(_row(label, tally), flush=True)
            notes.extend(f"{label} refused {text}" for text in tally.refused)
    return notes


#: The ``honesty`` table's rows beyond the sphere's faces: the ``shape`` face's stretch read
#: in depth (the same x/z ratio), and the realistic preset.
DEPTH_TWIN = {"x_scale_error": 0.0, "z_scale_error": 0.0101}


def _honesty_data(row: str, seed: int) -> Any:
    if row == "sphere_sszn":
        return simulate_sphere(sphere_scenario_from_preset(row), seed)
    if row != "shape in depth":
        return _face_data("sphere", () if row == "clean" else tuple(row.split("+")), seed)
    sphere = sphere_scenario_from_preset("sphere", n_poses=14)
    sensor = replace(with_faces(sphere.rig.sensor, "shape"), **DEPTH_TWIN)
    return simulate_sphere(replace(sphere, rig=replace(sphere.rig, sensor=sensor)), seed)


def honesty_table(seeds: int) -> list[str]:
    print(f"The sphere's 1σ against its error, {seeds} seeds (self-check on)")
    print(
        f"{'row':<24}{'within 1σ':>10}{'|e|/σ':>7}  RMS e/σ rx ry rz tx ty tz"
        f"{'rot deg':>16}{'trans mm':>10}{'1σ deg':>9}{'1σ mm':>9}"
    )
    notes = []
    rows = ["clean", *REAL_FACES, "+".join(COMBINED), "shape in depth", "sphere_sszn"]
    for row in rows:
        tally = Tally()
        for seed in range(seeds):
            calibrate(_honesty_data(row, seed), "sphere", tally, seed)
        notes.extend(f"{row} refused {text}" for text in tally.refused)
        if not tally.errors:
            continue
        per_axis = " ".join(f"{v:4.2f}" for v in np.sqrt(np.mean(tally.z() ** 2, axis=0)))
        print(
            f"{row:<24}{tally.within_sigma():>9.0f}%{tally.worst_ratio():>7.2f}  {per_axis}"
            f"{cells(tally)[:38]}",
            flush=True,
        )
    return notes


def _refusal(data: Any, recording: str, target: str, auto: bool) -> str:
    """What the command line says of ``data`` given to ``target``: its refusal, or 'result'."""
    moving = recording == "line"
    gates = {"max_linear_speed_m_s": 0.0, "max_angular_speed_rad_s": 0.0} if moving else {}
    latency = -data.truth.scenario.rig.latency_s if moving and not auto else 0.0
    pairing = PairingConfig(clock_offset_s=latency, **gates)  # type: ignore[arg-type]
    config = pipeline_config(target, Method.DEFAULT, {}, Front.CLI, seed=0, pairing=pairing)
    config = replace(config, self_check_folds=0)
    try:
        extracted = None
        if auto:
            offset, extracted = search_clock_offset(data.profiles, data.poses, config)
            config = replace(config, pairing=replace(pairing, clock_offset_s=offset))
        run_pipeline(data.profiles, data.poses, config, extracted=extracted)
    except CalibrationError as exc:
        return render(str(exc), Front.CLI)
    return "result"


def wrong_table() -> None:
    print("Each clean recording given to each wrong target (seed 3): plain, then auto")
    print(f"{'recording':<12}{'target':<13}{'offset':<7}{'outcome':<40}figures (um RMS)")
    for recording in TARGETS:
        data = _face_data(recording, "", 3)
        for target, auto in itertools.product(TARGETS, (False, True)):
            if target == recording:
                continue
            text = _refusal(data, recording, target, auto)
            named = re.search(r"--target (\w+)", text)
            at = re.search(r"at its own clock offset of ([-+0-9.]+ ms)", text)
            outcome = (
                "result written"
                if text == "result"
                else f"refused naming {named[1]}" + (f" ({at[1]})" if at else "")
                if named
                else "refused: " + text[:60]
            )
            figures = ", ".join(
                f"{m[1]} {m[2]}"
                for m in re.finditer(
                    r"the ([a-z ]+) fitted with the poses"
                    r"(?: at its own clock offset of [-+0-9.]+ ms)?(?: explains .*? and)? leaves "
                    r"([0-9.]+) um",
                    text,
                )
            )
            print(
                f"{recording:<12}{target:<13}{'auto' if auto else 'plain':<7}{outcome:<40}"
                f"{figures}",
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--only", choices=("real", "conic", "presets", "faces", "honesty", "wrong"))
    parser.add_argument("--presets", default=",".join(PRESETS))
    parser.add_argument("--targets", default=",".join(TARGETS))
    args = parser.parse_args()
    notes: list[str] = []
    if args.only in (None, "real"):
        real_table()
        print()
    if args.only in (None, "conic"):
        conic_table(args.seeds)
        print()
    if args.only in (None, "presets"):
        notes += presets_table(args.presets.split(","), args.seeds)
        print()
    if args.only in (None, "faces"):
        notes += faces_table(args.targets.split(","), args.seeds)
        print()
    if args.only in (None, "honesty"):
        notes += honesty_table(args.seeds)
        print()
    if args.only in (None, "wrong"):
        wrong_table()
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
