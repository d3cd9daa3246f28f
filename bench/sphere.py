"""The sphere target on real scans (RobCalibrator) beside their published hand-eye, and on
the simulator against truth.

Real scans (``bags/robcalibrator_sphere``: an SSZN SR7140 profiler on a FANUC arm, 15
profiles of a 40 mm-radius ball; MIT licence, see the bag's README): each hand-eye is judged
by the data alone, with the recorded flange poses:

- ``scatter``: the profiles' sphere centres (circle centre, √(R² − r²) off the laser plane on
  the resolved side) mapped into the base frame, RMS distance from their mean, mm;
- ``pt-sphere``: every profile point mapped into the base frame, RMS distance from the one
  sphere of the given radius that fits them best, um (no pose corrections);
- ``ML resid``: the default method's point-to-sphere residual with the robot's pose error
  modelled, um; ``1σ``: its predicted hand-eye 1σ (translation mm per flange axis, rotation
  deg per sensor axis);
- ``Δ published``: the difference to the authors' hand-eye (their estimate, not truth).

The same lab's 12.7 mm ball set (``../shared/external/robcalibrator/ball``, outside the
repository; skipped where absent): the centre scatter of the published hand-eye, a linear
fixed-point solve and the default method (radius given and free), the profiles used, and the
cylinder target's answer on it (refused, naming the sphere, by the whole-recording check).

Simulator (``sphere`` preset: a Ø50.8 mm ball on a table, scanCONTROL-class profiler, UR-class
arm 0.03 mm / 0.003 deg, 24 views): error against truth per method over seeds (RMS over
seeds), the share of per-axis errors within 2 predicted σ, and the time per calibration.

Run: ``.venv/bin/python bench/sphere.py [--seeds N]`` (default 10; ~3 s per seed).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix, transform_error
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, PipelineConfig, run_pipeline
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import configure
from linelaser_calib.core.targets.sphere import SphereConfig, SphereSection
from linelaser_calib.core.targets.sphere.model import (
    centre_scatter_m,
    centres_in_sensor,
    fit_sphere_centre,
    fixed_point_residuals,
    solve_fixed_point,
)
from linelaser_calib.io.bags import read_bag
from linelaser_calib.io.results import read_reference_yaml
from linelaser_calib.io.robcalibrator import convert_robcalibrator
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.settings import Front, render
from linelaser_calib.sim.sphere import simulate_sphere, sphere_scenario_from_preset

REAL = Path(__file__).resolve().parent.parent / "bags" / "robcalibrator_sphere"
#: The 12.7 mm ball set beside the repository (its README: ../shared/external/).
BALL = Path(__file__).resolve().parents[2] / "shared" / "external" / "robcalibrator" / "ball"


def _config(method: Method, **settings: Any) -> PipelineConfig:
    target = get_target("sphere")
    return PipelineConfig(
        method=method, target="sphere", target_config=configure(target, method.value, settings, {})
    )


def _judge(
    features: list[Any], X: FloatArray, radius: float, side: int, start: FloatArray
) -> tuple[float, float]:
    """Centre scatter (m) and point-to-sphere RMS (m) of a hand-eye on the recorded poses."""
    T = np.stack([f.T_base_flange for f in features])
    C = np.stack([f.circle.centre_xz for f in features])
    r = np.array([f.circle.radius_m for f in features])
    scatter = centre_scatter_m(fixed_point_residuals(T, centres_in_sensor(C, r, radius, side), X))
    _, d = fit_sphere_centre(T, [f.points for f in features], X, radius, start)
    return scatter, float(np.sqrt(np.mean(d**2)))


def real_table() -> None:
    published, _ = read_reference_yaml(REAL / "reference.yaml")
    bag = read_bag(REAL)
    samples = pair_profiles(bag.profiles, bag.poses, PairingConfig()).samples
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=0.04), 0, lambda *_: None
    )
    circle_rms = np.array([f.circle.rms_m for f in features]) * 1e6
    print(
        f"RobCalibrator scans: {len(features)} profiles; circle fit {circle_rms.min():.1f}-"
        f"{circle_rms.max():.1f} um RMS (median {np.median(circle_rms):.1f} um)"
    )
    runs: list[tuple[str, CalibrationResult | None, float]] = [("published (theirs)", None, 0.0)]
    for label, method, settings in (
        ("paper (R given)", Method.PAPER, {"radius_m": 0.04}),
        ("default (R given)", Method.DEFAULT, {"radius_m": 0.04}),
        ("paper (R estimated)", Method.PAPER, {}),
        ("default (R estimated)", Method.DEFAULT, {}),
    ):
        started = time.perf_counter()
        result = calibrate_bag(REAL, _config(method, **settings)).result
        runs.append((label, result, time.perf_counter() - started))
    head = (
        f"{'hand-eye':<22}{'scatter mm':>11}{'pt-sphere um':>13}{'ML resid um':>12}"
        f"{'1σ t mm':>20}{'1σ r deg':>20}{'Δ published':>20}{'R mm':>8}{'side':>5}{'s':>6}"
    )
    print(head)
    first = runs[1][1]
    assert first is not None and isinstance(first.target, SphereSection)
    start = first.target.centre_m
    for label, result, seconds in runs:
        X = published if result is None else result.T_flange_sensor
        section = None if result is None else result.target
        radius = 0.04 if not isinstance(section, SphereSection) else section.radius_m
        scatter, pt = _judge(features, X, radius, -1, start)
        resid = sig_t = sig_r = "-"
        if result is not None and result.method == "default":
            resid = f"{result.rms_residual_m * 1e6:.1f}"
            sig_t = "/".join(f"{v * 1e3:.2f}" for v in np.asarray(result.uncertainty_translation_m))
            sig_r = "/".join(
                f"{math.degrees(v):.3f}" for v in np.asarray(result.uncertainty_rotation_rad)
            )
        rot, trans = transform_error(X, published)
        diff = "-" if result is None else f"{math.degrees(rot):.3f}° {trans * 1e3:.3f} mm"
        side = (
            "-y"
            if not isinstance(section, SphereSection)
            else ("+y" if section.centre_side > 0 else "-y")
        )
        print(
            f"{label:<22}{scatter * 1e3:>11.3f}{pt * 1e6:>13.1f}{resid:>12}{sig_t:>20}{sig_r:>20}"
            f"{diff:>20}{radius * 1e3:>8.3f}{side:>5}{seconds:>6.2f}"
        )


def ball_table() -> None:
    """The same lab's 12.7 mm ball set (``../shared/external/robcalibrator/ball``, kept out
    of the repository): centre scatter of each hand-eye (its own radius; the published one
    and the linear solve at 12.7 mm), profiles used, and what the cylinder target says."""
    if not BALL.is_dir():
        print(f"12.7 mm ball set: not here ({BALL}); skipped")
        return
    with tempfile.TemporaryDirectory() as folder:
        bag = convert_robcalibrator(BALL, Path(folder) / "ball", "bench/sphere.py")
        published, _ = read_reference_yaml(bag / "reference.yaml")
        samples = pair_profiles(*_bag_streams(bag), PairingConfig()).samples
        runs: list[tuple[str, FloatArray, float, str]] = []
        for label, settings in (
            ("default (R given)", {"radius_m": 0.0127}),
            ("default (R free)", {}),
        ):
            try:
                result = calibrate_bag(bag, _config(Method.DEFAULT, **settings)).result
            except CalibrationError as exc:
                print(f"{label}: refused: {render(str(exc), Front.CLI)}")
                continue
            section = result.target
            assert isinstance(section, SphereSection)
            used = f"{len(result.samples_used)}/{len(samples)}"
            runs.append((label, result.T_flange_sensor, section.radius_m, used))
        try:
            calibrate_bag(bag, PipelineConfig(method=Method.DEFAULT, target="cylinder"))
            cylinder = "a result (exit 0)"
        except CalibrationError as exc:
            cylinder = f"refused: {render(str(exc), Front.CLI)}"
    features, _ = get_target("sphere").extract(
        samples, SphereConfig(radius_m=0.0127), 0, lambda *_: None
    )
    T = np.stack([f.T_base_flange for f in features])
    C = np.stack([f.circle.centre_xz for f in features])
    r = np.array([f.circle.radius_m for f in features])
    linear = solve_fixed_point(T, C, r, 0.0127, 1).T_flange_sensor
    print("12.7 mm ball set (10 profiles; published: 0.91 mm, a linear solve 0.82 mm):")
    print(f"{'hand-eye':<22}{'scatter mm':>11}{'R mm':>8}{'used':>7}")
    for label, X, radius, used in [
        ("published (theirs)", published, 0.0127, "-"),
        ("linear fixed-point", linear, 0.0127, "-"),
        *runs,
    ]:
        C_sensor = centres_in_sensor(np.stack([f.circle.centre_xz for f in features]), r, radius, 1)
        scatter = centre_scatter_m(fixed_point_residuals(T, C_sensor, X))
        print(f"{label:<22}{scatter * 1e3:>11.3f}{radius * 1e3:>8.3f}{used:>7}")
    print(f"--target cylinder: {cylinder}")


def _bag_streams(bag: Path) -> tuple[Any, Any]:
    contents = read_bag(bag)
    return contents.profiles, contents.poses


def simulator_table(seeds: int) -> None:
    errors: dict[str, list[tuple[float, float]]] = {"paper": [], "default": []}
    within: list[float] = []
    seconds: dict[str, list[float]] = {"paper": [], "default": []}
    for seed in range(seeds):
        data = simulate_sphere(sphere_scenario_from_preset("sphere", n_poses=24), seed)
        truth = data.truth.T_flange_sensor
        for method in (Method.PAPER, Method.DEFAULT):
            started = time.perf_counter()
            result = run_pipeline(data.profiles, data.poses, _config(method))
            seconds[method.value].append(time.perf_counter() - started)
            rot, trans = transform_error(result.T_flange_sensor, truth)
            errors[method.value].append((math.degrees(rot), trans * 1e3))
            if method is Method.DEFAULT:
                X = result.T_flange_sensor
                e = np.concatenate(
                    [rotvec_from_matrix(truth[:3, :3].T @ X[:3, :3]), X[:3, 3] - truth[:3, 3]]
                )
                sigma = np.concatenate(
                    [
                        np.asarray(result.uncertainty_rotation_rad),
                        np.asarray(result.uncertainty_translation_m),
                    ]
                )
                within.append(float(np.mean(np.abs(e) <= 2.0 * sigma)))
    print(f"Simulator, preset sphere (24 views), {seeds} seeds: error against truth")
    print(
        f"{'method':<10}{'rot RMS deg':>13}{'rot max deg':>13}{'trans RMS mm':>14}"
        f"{'trans max mm':>14}{'time s':>9}"
    )
    for name, values in errors.items():
        a = np.array(values)
        print(
            f"{name:<10}{np.sqrt(np.mean(a[:, 0] ** 2)):>13.4f}{a[:, 0].max():>13.4f}"
            f"{np.sqrt(np.mean(a[:, 1] ** 2)):>14.4f}{a[:, 1].max():>14.4f}"
            f"{np.median(seconds[name]):>9.2f}"
        )
    print(
        f"default: {100.0 * np.mean(within):.0f} % of per-axis errors within 2 predicted sigma "
        "(95 % expected)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    real_table()
    print()
    ball_table()
    print()
    simulator_table(args.seeds)


if __name__ == "__main__":
    main()
