"""Issue 29's goals for the real recordings kept out of the repository, on simulator twins.

The real sets cannot be run here; each goal is measured on the closest twin the simulator
gives, beside a plain fit of the same data (no robot error modelled, every profile used):

``cell``
    The industrial cell: two SSZN-class sensors (``sphere_sszn``: 0.05 mm pitch, 42 um smooth
    shape error over 4 mm) on one arm, each scanning the one 40 mm-radius ball from 18 views;
    sensor A with x 0.3 % long of z (the preset's), sensor B on another bracket with x 0.6 %
    long and z 0.2 % short (0.8 % apart). Both see the same regional robot error: a smooth
    field of the flange position (translation 0.4 mm, rotation 0.02 deg, about 2σ per axis,
    length scale 0.1 m, :func:`~linelaser_calib.sim.clutter.field_offsets`) added to the
    recorded poses, over the preset's per-view 0.03 mm / 0.005 deg. Per sensor: profiles
    used and what was set aside; the ball-centre scatter (each profile's circle centre,
    √(R² − r²) off the plane, mapped into the base frame; RMS about the mean, mm) of the
    tool's hand-eye, of the linear fixed-point solve
    (:func:`~linelaser_calib.core.targets.sphere.model.resolve_side`, polished: bench/sphere.py's
    reference) and of the true hand-eye, on the raw profiles; ``own``: the tool's scatter
    with its own profile corrections (the scales it estimated) applied; each hand-eye's
    translation error against truth, and the tool's largest per-axis |error| / 1σ
    (:func:`error_over_sigma`). The polished linear solve minimises the raw scatter,
    so no other hand-eye can score below it there (the true one does not); ``raw`` and
    ``own`` judge the goal each way. Then the distance between the two sensors' ball centres
    in the base frame (truth 0). Goals: used 18/18, scatter ≤ the linear solve's, centres
    ≤ 1.2 mm apart.
``cylinder``
    The real cylinder: ``cluttered_camera`` (a coarse profiler about 1 m from a Ø25 mm bar,
    clutter, a regional robot error field of 0.7 mm) with its 120 profiles in 12 pose
    clusters. Each cluster is held out in turn (12 calibrations of 110 profiles): refused or
    not, profiles used against an independent per-profile count (profiles with at least
    :data:`MIN_ARC_POINTS` returns on the bar, by the simulator's labels), and the held-out
    error: the held-out cluster's bar points mapped with the recorded poses and the hand-eye
    from the other clusters (the tool's scale correction applied), RMS distance from the TRUE
    bar, um (``true X``: the same with the true hand-eye, the robot error's own share);
    ``*``: from each fit's own cylinder instead, as a real recording can measure it. The
    plain fit: the points of the same labelled arcs fitted to one cylinder (radius free) by
    plain least squares over the hand-eye and the axis. Goals: none refused, used ≥ the
    independent count less one, held-out error ≤ 1.10 × the plain fit's.
``edge``
    The ridge on a block: ``line_ridge`` (an SSZN-class profiler with every face of reality)
    at 2.8 Hz, three recordings (seeds) of 26-30 profiles. The plain fit: the corner of each
    profile as a vendor's tool gives it (two lines fitted by cv2.fitLine, Huber, to the
    points within :data:`VENDOR_WINDOW_M` of the taught corner on each side, intersected),
    the closed-form line solve, then least squares over the hand-eye and the line on the
    corners' distances from it. Held out by a ball of the same sensor: the same rig (hand-eye,
    profiler, robot error) scans the 40 mm-radius ball of ``sphere_sszn`` from 15 views; the
    ball-centre scatter of each hand-eye (as ``cell``; ``*``: with the profiler's true x/z
    scale errors removed, so that the hand-eye's share shows) and its translation error
    against truth, with the tool's 1σ (length). Goals: used ≥ the plain fit's less one, ball
    scatter ≤ 1.10 × the plain fit's. Two twins (``--twin``): ``line_ridge`` as the preset is,
    and ``recording 1`` (:data:`RECORDING_1`), the preset made as harsh as the real recording
    1's description allows (the recording the tool refused before the corner finder was
    moved off fixed fractions; this twin is refused on that code too), with the cell's
    regional robot error (:func:`_regional`, the same field on its ball).

Run: ``.venv/bin/python bench/private_twins.py [--seeds N] [--only cell|cylinder|edge]
[--twin line_ridge|'recording 1']``
(default 3 seeds for ``cell`` and ``edge``, the first seed for ``cylinder``; 2.5 min of CPU,
about 7 min wall on a loaded machine, most of it the cylinder's 13 calibrations).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix, transform_error
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, calibrate_samples
from linelaser_calib.core.profile.along_line import measured_to_true
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.line.model import solve_line_linear
from linelaser_calib.core.targets.sphere import SphereConfig, SphereSection
from linelaser_calib.core.targets.sphere.model import (
    centre_scatter_m,
    centres_in_sensor,
    fixed_point_residuals,
    resolve_side,
)
from linelaser_calib.core.types import FlangePose, Sample
from linelaser_calib.settings import Front, pipeline_config, render
from linelaser_calib.sim.clutter import field_offsets
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.scene import Surface
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import (
    SphereScenario,
    simulate_sphere,
    sphere_scenario_from_preset,
)

BALL_RADIUS_M = 0.040
#: The regional robot error of the cell: translation (m) and rotation (rad) amplitudes
#: (about 2σ per axis) and the length scale over the flange position (m).
FIELD_T_M, FIELD_R_RAD, FIELD_LENGTH_M = 4e-4, math.radians(0.02), 0.1
#: Sensor B of the cell: hand-eye (translation m, roll-pitch-yaw deg) and x/z scale errors.
SENSOR_B = ((-0.05, 0.03, 0.10), (6.0, -7.0, -95.0), 0.006, -0.002)
MIN_ARC_POINTS = 20
VENDOR_WINDOW_M = 0.015
RIDGE_RATE_HZ = 2.8
HOLD_LIMIT = 1.10


def _mark(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def _calibrate(
    samples: list[Sample], target: str, given: dict[str, Any], pairing: PairingConfig
) -> CalibrationResult | str:
    """The tool's default method as the command line runs it, or the refusal's text."""
    config = pipeline_config(target, Method.DEFAULT, given, Front.CLI, seed=0, pairing=pairing)
    try:
        return calibrate_samples(samples, config)
    except CalibrationError as exc:
        return render(str(exc), Front.CLI)


# --- the industrial cell ---------------------------------------------------------------------


def _regional(poses: list[FlangePose], seed: int) -> list[FlangePose]:
    """The recorded poses with the cell's regional robot error (one field per seed: the same
    for every sensor of the arm)."""
    T = np.stack([p.T_base_flange for p in poses])
    rig = scenario_from_preset("ur_scancontrol")
    where = T[:, :3, 3]
    shift = field_offsets(
        np.random.default_rng(seed),
        replace(rig, robot_field_m=(FIELD_T_M,) * 3, robot_field_length_m=FIELD_LENGTH_M),
        where,
    )
    turn = field_offsets(
        np.random.default_rng(seed + 10_000),
        replace(rig, robot_field_m=(FIELD_R_RAD,) * 3, robot_field_length_m=FIELD_LENGTH_M),
        where,
    )
    out = T.copy()
    out[:, :3, :3] = Rotation.from_rotvec(turn).as_matrix() @ T[:, :3, :3]
    out[:, :3, 3] += shift
    return [replace(p, T_base_flange=t) for p, t in zip(poses, out, strict=True)]


def _cell_scenario(sensor: str) -> SphereScenario:
    base = sphere_scenario_from_preset("sphere_sszn", n_poses=18)
    if sensor == "A":
        return base
    translation, rpy, x_scale, z_scale = SENSOR_B
    q = Rotation.from_euler("xyz", np.radians(rpy)).as_quat()
    rig = replace(
        base.rig,
        hand_eye_translation_m=translation,
        hand_eye_rotation_xyzw=tuple(float(v) for v in q),
        sensor=replace(base.rig.sensor, x_scale_error=x_scale, z_scale_error=z_scale),
    )
    return replace(base, rig=rig)


def ball_scatter(
    samples: list[Sample],
    X: FloatArray,
    radius_m: float,
    correct: Callable[[FloatArray], FloatArray] | None = None,
) -> tuple[float, FloatArray]:
    """Centre scatter (m) of hand-eye ``X`` on a ball recording, and the mean centre (base);
    with ``correct``, the profiles' points corrected first (scale errors removed)."""
    if correct is not None:
        samples = [
            replace(s, points=correct(np.asarray(s.points, dtype=np.float64))) for s in samples
        ]
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=radius_m), 0, lambda *_: None
    )
    T = np.stack([f.T_base_flange for f in features])
    C = np.stack([f.circle.centre_xz for f in features])
    r = np.array([f.circle.radius_m for f in features])
    side = resolve_side(T, C, r, radius_m)[0].side
    mapped = fixed_point_residuals(T, centres_in_sensor(C, r, radius_m, side), X)
    return centre_scatter_m(mapped), mapped.mean(axis=0)


def error_over_sigma(result: CalibrationResult, truth: FloatArray) -> float:
    """The largest per-axis |error| / 1σ of a result's hand-eye (rotation about and
    translation along the flange axes), NaN without a 1σ."""
    if result.uncertainty_rotation_rad is None or result.uncertainty_translation_m is None:
        return math.nan
    T = result.T_flange_sensor
    error = np.concatenate(
        [rotvec_from_matrix(truth[:3, :3].T @ T[:3, :3]), T[:3, 3] - truth[:3, 3]]
    )
    sigma = np.concatenate([result.uncertainty_rotation_rad, result.uncertainty_translation_m])
    return float(np.max(np.abs(error) / sigma))


def _linear(samples: list[Sample], radius_m: float) -> FloatArray:
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=radius_m), 0, lambda *_: None
    )
    T = np.stack([f.T_base_flange for f in features])
    C = np.stack([f.circle.centre_xz for f in features])
    r = np.array([f.circle.radius_m for f in features])
    return resolve_side(T, C, r, radius_m)[0].T_flange_sensor


def cell_table(seeds: list[int]) -> None:
    print("Industrial cell twin: two SSZN-class sensors, one 40 mm-radius ball, 18 views each")
    print(
        f"{'seed':>4}{'sensor':>7}{'used':>7}{'tool mm':>9}{'linear mm':>10}{'truth mm':>9}"
        f"{'ratio':>7}{'own mm':>8}{'ratio':>7}{'tool err mm':>12}{'|e|/σ':>7}{'lin err mm':>11}"
        f"  {'raw':<5}{'own':<5}set aside"
    )
    apart: list[tuple[int, float, float]] = []
    for seed in seeds:
        centres: dict[str, list[FloatArray]] = {"tool": [], "linear": []}
        for sensor in ("A", "B"):
            data = simulate_sphere(_cell_scenario(sensor), seed)
            poses = _regional(data.poses, seed)
            samples = list(pair_profiles(data.profiles, poses, PairingConfig()).samples)
            truth = data.truth.T_flange_sensor
            linear = _linear(samples, BALL_RADIUS_M)
            lin_scatter, lin_centre = ball_scatter(samples, linear, BALL_RADIUS_M)
            result = _calibrate(samples, "sphere", {"radius_m": BALL_RADIUS_M}, PairingConfig())
            if isinstance(result, str):
                print(f"{seed:>4}{sensor:>7}  refused: {result[:160]}")
                continue
            assert isinstance(result.target, SphereSection)
            scatter, _ = ball_scatter(samples, result.T_flange_sensor, BALL_RADIUS_M)
            own, _ = ball_scatter(
                samples, result.T_flange_sensor, BALL_RADIUS_M, result.target.sensor_points
            )
            true_scatter, _ = ball_scatter(samples, truth, BALL_RADIUS_M)
            centres["tool"].append(result.target.centre_m)
            centres["linear"].append(lin_centre)
            used = len(result.samples_used)
            all_used = used == len(data.profiles)
            print(
                f"{seed:>4}{sensor:>7}{f'{used}/{len(data.profiles)}':>7}{scatter * 1e3:>9.3f}"
                f"{lin_scatter * 1e3:>10.3f}{true_scatter * 1e3:>9.3f}{scatter / lin_scatter:>7.2f}"
                f"{own * 1e3:>8.3f}{own / lin_scatter:>7.2f}"
                f"{transform_error(result.T_flange_sensor, truth)[1] * 1e3:>12.3f}"
                f"{error_over_sigma(result, truth):>7.2f}"
                f"{transform_error(linear, truth)[1] * 1e3:>11.3f}"
                f"  {_mark(all_used and scatter <= lin_scatter):<5}"
                f"{_mark(all_used and own <= lin_scatter):<5}"
                + "; ".join(f"{r.index}: {r.reason[:90]}" for r in result.samples_rejected)
            )
        if len(centres["tool"]) == 2:
            apart.append(
                (
                    seed,
                    float(np.linalg.norm(np.subtract(*centres["tool"]))),
                    float(np.linalg.norm(np.subtract(*centres["linear"]))),
                )
            )
    print(f"{'seed':>4}{'A-B tool mm':>13}{'A-B linear mm':>15}  goal (≤ 1.2 mm; truth 0)")
    for seed, tool, linear in apart:
        print(f"{seed:>4}{tool * 1e3:>13.3f}{linear * 1e3:>15.3f}  {_mark(tool <= 1.2e-3)}")


# --- the real cylinder -----------------------------------------------------------------------


def _arc_points(data: Any, index: int) -> FloatArray:
    """Profile ``index``'s returns on the bar (the simulator's labels), sensor frame."""
    valid = data.truth.valid[index]
    on_bar = (data.truth.surface[index] == Surface.SIDE) & ~data.truth.spike[index]
    return np.asarray(data.profiles[index].points)[on_bar[valid]]


def _distances(points_base: FloatArray, axis: Cylinder) -> FloatArray:
    """Signed distances (m) of base-frame points from a cylinder's surface."""
    v = points_base - axis.point
    radial = v - np.outer(v @ axis.direction, axis.direction)
    return np.asarray(np.linalg.norm(radial, axis=1) - axis.radius)


def _mapped(T: list[FloatArray], points: list[FloatArray], X: FloatArray) -> FloatArray:
    return np.concatenate(
        [p @ (t @ X)[:3, :3].T + (t @ X)[:3, 3] for t, p in zip(T, points, strict=True)]
    )


def _perpendicular(d: FloatArray) -> tuple[FloatArray, FloatArray]:
    u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def plain_cylinder_fit(
    T: list[FloatArray],
    points: list[FloatArray],
    X0: FloatArray,
    start: Cylinder,
    radius: float | None = None,
    axis: bool = True,
) -> tuple[FloatArray, Cylinder]:
    """Plain least squares over the hand-eye and a cylinder (radius free unless given; the
    axis held at ``start``'s unless ``axis``) on every fourth point of every arc; the
    hand-eye and the cylinder."""
    u, v = _perpendicular(start.direction)
    thinned = [p[::4] for p in points]
    free = np.r_[np.ones(6), np.full(4, axis), [radius is None]].astype(bool)
    x0 = np.concatenate([np.zeros(10), [start.radius if radius is None else radius]])

    def unpack(z: FloatArray) -> tuple[FloatArray, Cylinder]:
        x = x0.copy()
        x[free] = z
        X = X0.copy()
        X[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix() @ X0[:3, :3]
        X[:3, 3] += x[3:6]
        direction = Rotation.from_rotvec(x[6] * u + x[7] * v).apply(start.direction)
        return X, Cylinder(start.point + x[8] * u + x[9] * v, direction, x[10])

    def residuals(z: FloatArray) -> FloatArray:
        X, cylinder = unpack(z)
        return _distances(_mapped(T, thinned, X), cylinder)

    return unpack(least_squares(residuals, x0[free], x_scale="jac").x)


def _rms_from(
    T: list[FloatArray], points: list[FloatArray], X: FloatArray, truth: Cylinder
) -> float:
    return float(np.sqrt(np.mean(_distances(_mapped(T, points, X), truth) ** 2)))


def cylinder_table(seed: int) -> None:
    data = simulate(scenario_from_preset("cluttered_camera", pose_clusters=12), seed)
    samples = list(pair_profiles(data.profiles, data.poses, PairingConfig()).samples)
    truth = data.truth.cylinder
    arcs = {s.index: _arc_points(data, s.index).astype(np.float64) for s in samples}
    clusters, n = 12, len(data.profiles)
    full = _calibrate(samples, "cylinder", {}, PairingConfig())
    if isinstance(full, str):
        print(f"Real cylinder twin, seed {seed}: the whole recording refused: {full[:200]}")
        return
    assert isinstance(full.target, CylinderSection)
    shown = sum(len(arcs[s.index]) >= MIN_ARC_POINTS for s in samples)
    print(
        f"Real cylinder twin (cluttered_camera, Ø25 mm, {n} profiles in {clusters} pose clusters, "
        f"seed {seed}): whole set {len(full.samples_used)}/{n} used (independent {shown}), "
        f"free radius {full.target.cylinder.radius * 1e3:.3f} mm (truth {truth.radius * 1e3:.3f})"
    )
    print(
        f"{'held out':>8}{'used':>9}{'indep':>7}{'tool um':>9}{'plain um':>10}{'true X um':>10}"
        f"{'ratio':>7}{'tool* um':>9}{'plain* um':>10}{'ratio*':>7}{'tool R mm':>10}"
        f"{'plain R mm':>11}{'tool err mm':>12}{'plain err mm':>13}  goal goal*"
    )
    ratios: list[tuple[float, float]] = []
    for cluster in range(clusters):
        train = [s for s in samples if s.index * clusters // n != cluster]
        held = [
            s
            for s in samples
            if s.index * clusters // n == cluster and len(arcs[s.index]) >= MIN_ARC_POINTS
        ]
        independent = [s for s in train if len(arcs[s.index]) >= MIN_ARC_POINTS]
        result = _calibrate(train, "cylinder", {}, PairingConfig())
        start = full if isinstance(result, str) else result
        assert isinstance(start.target, CylinderSection)
        plain_X, plain_axis = plain_cylinder_fit(
            [s.T_base_flange for s in independent],
            [arcs[s.index] for s in independent],
            start.T_flange_sensor,
            start.target.cylinder,
        )
        T_held = [s.T_base_flange for s in held]
        raw = [arcs[s.index] for s in held]
        plain = _rms_from(T_held, raw, plain_X, truth)
        plain_own = _rms_from(T_held, raw, plain_X, plain_axis)
        if isinstance(result, str):
            print(f"{cluster:>8}  refused: {result[:150]}  FAIL")
            continue
        assert isinstance(result.target, CylinderSection)
        corrected = [result.target.sensor_points(p) for p in raw]
        tool = _rms_from(T_held, corrected, result.T_flange_sensor, truth)
        tool_own = _rms_from(T_held, corrected, result.T_flange_sensor, result.target.cylinder)
        used = len(result.samples_used)
        ratios.append((tool / plain, tool_own / plain_own))
        enough = used >= len(independent) - 1
        X_true = data.truth.T_flange_sensor
        print(
            f"{cluster:>8}{f'{used}/{len(train)}':>9}{len(independent):>7}{tool * 1e6:>9.1f}"
            f"{plain * 1e6:>10.1f}{_rms_from(T_held, raw, X_true, truth) * 1e6:>10.1f}"
            f"{tool / plain:>7.2f}{tool_own * 1e6:>9.1f}{plain_own * 1e6:>10.1f}"
            f"{tool_own / plain_own:>7.2f}{result.target.cylinder.radius * 1e3:>10.3f}"
            f"{plain_axis.radius * 1e3:>11.3f}"
            f"{transform_error(result.T_flange_sensor, X_true)[1] * 1e3:>12.3f}"
            f"{transform_error(plain_X, X_true)[1] * 1e3:>13.3f}"
            f"  {_mark(enough and tool <= HOLD_LIMIT * plain)} "
            f"{_mark(enough and tool_own <= HOLD_LIMIT * plain_own)}"
        )
    if ratios:
        a = np.array(ratios)
        print(
            f"held-out ratio tool/plain against the true bar: median {np.median(a[:, 0]):.2f}, "
            f"max {a[:, 0].max():.2f}; against each fit's own cylinder (*): median "
            f"{np.median(a[:, 1]):.2f}, max {a[:, 1].max():.2f}"
        )


# --- the edge --------------------------------------------------------------------------------


def vendor_corner(points: FloatArray, taught_xz: FloatArray) -> FloatArray | None:
    """The corner (x, z) as a vendor's tool gives it: a robust line on each side of the taught
    corner within :data:`VENDOR_WINDOW_M`, intersected; None without 5 points a side."""
    xz = np.asarray(points, dtype=np.float64)[:, [0, 2]]
    xz = xz[np.all(np.isfinite(xz), axis=1)]
    distance = np.linalg.norm(xz - taught_xz, axis=1)
    near = xz[(distance <= VENDOR_WINDOW_M) & (distance >= 3e-4)]
    lines = []
    for side in (near[:, 0] < taught_xz[0], near[:, 0] > taught_xz[0]):
        if np.count_nonzero(side) < 5:
            return None
        vx, vz, x0, z0 = cv2.fitLine(near[side].astype(np.float32), cv2.DIST_HUBER, 0, 1e-2, 1e-2)
        lines.append((np.array([x0[0], z0[0]]), np.array([vx[0], vz[0]])))
    (p, d), (q, e) = lines
    a = np.column_stack([d, -e])
    if abs(np.linalg.det(a)) < 1e-6:
        return None
    s = np.linalg.solve(a, q - p)
    return np.asarray(p + s[0] * d)


def plain_line_fit(corners_xz: FloatArray, T: FloatArray) -> FloatArray:
    """Closed-form line solve, then least squares over the hand-eye and the line on the
    corners' distances from the line; the hand-eye."""
    X0, line0 = solve_line_linear(corners_xz, T)
    d0 = line0.direction / np.linalg.norm(line0.direction)
    u, v = _perpendicular(d0)
    s = np.column_stack([corners_xz[:, 0], np.zeros(len(corners_xz)), corners_xz[:, 1]])

    def residuals(x: FloatArray) -> FloatArray:
        X = X0.copy()
        X[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix() @ X0[:3, :3]
        X[:3, 3] += x[3:6]
        d = Rotation.from_rotvec(x[6] * u + x[7] * v).apply(d0)
        point = line0.point + x[8] * u + x[9] * v
        mapped = np.einsum("kij,kj->ki", (T @ X)[:, :3, :3], s) + (T @ X)[:, :3, 3] - point
        return np.asarray((mapped - np.outer(mapped @ d, d)).ravel())

    x = least_squares(residuals, np.zeros(10), x_scale="jac").x
    X = X0.copy()
    X[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix() @ X0[:3, :3]
    X[:3, 3] += x[3:6]
    return X


#: Recording 1's twin: ``line_ridge`` made as harsh as the real recording's description
#: allows (issue 29). The gentle flank (5 deg) fills most of the line (the seam at 0.3-0.7 of
#: the half fan width on the steep side), so that a profile holds 450-1,800 points; the steep
#: flank (25 mm at 70 deg) is met at grazing incidence (the view turned only 14 deg towards
#: it; returns beyond 84 deg lost) and keeps about 40-150 points, fewer where the gaps fall
#: on it; a 10 mm floor beside it in about two thirds of the profiles; 28-29 profiles
#: (2.2 Hz); the cell's regional robot error on top of the preset's per-view error.
RECORDING_1 = {
    "profile_rate_hz": 2.2,
    "opening_angle_rad": math.radians(105.0),
    "flank_turn_rad": math.radians(32.5),
    "flank_width_m": 0.14,
    "second_flank_width_m": 0.025,
    "floor_width_m": 0.01,
    "view_tilt_rad": math.radians(14.0),
    "depth_range_m": (0.122, 0.147),
    "tilt_along_rad": math.radians(34.4),
    "weave_centre": -0.5,
    "weave_fraction": 0.2,
    "min_flank_points": 110,
    "max_incidence_rad": math.radians(84.0),
}
#: The edge twins: (name, ``line_ridge`` overrides, with the regional robot error).
EDGE_TWINS: dict[str, tuple[dict[str, Any], bool]] = {
    "line_ridge": ({"profile_rate_hz": RIDGE_RATE_HZ}, False),
    "recording 1": (RECORDING_1, True),
}


def edge_recording(twin: str, seed: int) -> tuple[Any, list[Sample], PairingConfig, Any]:
    """One edge twin's recording: the simulated data, its samples, their pairing (the
    latency known) and the ball the same rig scans (data)."""
    overrides, regional = EDGE_TWINS[twin]
    scenario = line_scenario_from_preset("line_ridge", **overrides)
    data = simulate_line(scenario, seed)
    rig = scenario.rig
    pairing = PairingConfig(
        max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0, clock_offset_s=-rig.latency_s
    )
    poses = _regional(data.poses, seed) if regional else data.poses
    samples = list(pair_profiles(data.profiles, poses, pairing).samples)
    ball_scenario = replace(
        sphere_scenario_from_preset("sphere_sszn", n_poses=15),
        rig=replace(rig, name="ridge_ball", motion="step", n_poses=15),
    )
    ball = simulate_sphere(ball_scenario, seed)
    if regional:
        ball = replace(ball, poses=_regional(ball.poses, seed))
    return data, samples, pairing, ball


def edge_table(seeds: list[int], twins: list[str]) -> None:
    print(
        "Edge twins held out by a 40 mm-radius ball scanned by the same sensor (15 views): "
        + "; ".join(twins)
    )
    print(
        f"{'twin':<12}{'seed':>4}{'used':>7}{'plain':>7}{'tool mm':>9}{'plain mm':>10}"
        f"{'truth mm':>10}{'ratio':>7}{'tool* mm':>10}{'plain* mm':>10}{'truth* mm':>10}"
        f"{'ratio*':>7}{'tool err mm':>12}{'1σ mm':>7}{'plain err mm':>13}  goal goal*  set aside"
    )
    for twin in twins:
        for seed in seeds:
            _edge_row(twin, seed)


def _edge_row(twin: str, seed: int) -> None:
    data, samples, pairing, ball = edge_recording(twin, seed)
    rig = data.truth.scenario.rig
    n = len(data.profiles)
    found = [
        (s, vendor_corner(s.points, data.truth.corner_true_sensor[s.index][[0, 2]]))
        for s in samples
    ]
    vendor = [(s, c) for s, c in found if c is not None]
    plain_X = plain_line_fit(
        np.stack([c for _, c in vendor]), np.stack([s.T_base_flange for s, _ in vendor])
    )
    ball_samples = list(pair_profiles(ball.profiles, ball.poses, PairingConfig()).samples)
    truth = data.truth.T_flange_sensor
    calibrated = partial(
        measured_to_true,
        scale=rig.sensor.x_scale_error,
        depth_scale=rig.sensor.z_scale_error,
    )
    plain, _ = ball_scatter(ball_samples, plain_X, BALL_RADIUS_M)
    floor, _ = ball_scatter(ball_samples, truth, BALL_RADIUS_M)
    plain_s, _ = ball_scatter(ball_samples, plain_X, BALL_RADIUS_M, calibrated)
    floor_s, _ = ball_scatter(ball_samples, truth, BALL_RADIUS_M, calibrated)
    result = _calibrate(samples, "line", {}, pairing)
    head = f"{twin:<12}{seed:>4}"
    if isinstance(result, str):
        print(f"{head}{'-':>7}{f'{len(vendor)}/{n}':>7}  refused: {result[:300]}  FAIL")
        return
    tool, _ = ball_scatter(ball_samples, result.T_flange_sensor, BALL_RADIUS_M)
    tool_s, _ = ball_scatter(ball_samples, result.T_flange_sensor, BALL_RADIUS_M, calibrated)
    used = len(result.samples_used)
    enough = used >= len(vendor) - 1
    assert result.uncertainty_translation_m is not None
    sigma = float(np.linalg.norm(result.uncertainty_translation_m))
    print(
        f"{head}{f'{used}/{n}':>7}{f'{len(vendor)}/{n}':>7}{tool * 1e3:>9.3f}"
        f"{plain * 1e3:>10.3f}{floor * 1e3:>10.3f}{tool / plain:>7.2f}{tool_s * 1e3:>10.3f}"
        f"{plain_s * 1e3:>10.3f}{floor_s * 1e3:>10.3f}{tool_s / plain_s:>7.2f}"
        f"{transform_error(result.T_flange_sensor, truth)[1] * 1e3:>12.3f}{sigma * 1e3:>7.3f}"
        f"{transform_error(plain_X, truth)[1] * 1e3:>13.3f}"
        f"  {_mark(enough and tool <= HOLD_LIMIT * plain)} "
        f"{_mark(enough and tool_s <= HOLD_LIMIT * plain_s)}  "
        + "; ".join(f"{r.index}: {r.reason[:100]}" for r in result.samples_rejected)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--only", choices=("cell", "cylinder", "edge"))
    parser.add_argument(
        "--twin", choices=sorted(EDGE_TWINS), action="append", help="edge twins (default all)"
    )
    args = parser.parse_args()
    seeds = list(range(args.seeds))
    if args.only in (None, "cell"):
        cell_table(seeds)
        print()
    if args.only in (None, "edge"):
        edge_table(seeds, args.twin or list(EDGE_TWINS))
        print()
    if args.only in (None, "cylinder"):
        cylinder_table(seeds[0])


if __name__ == "__main__":
    main()
