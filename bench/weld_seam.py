"""The weld-seam paper's hand-eye correction against ours, on the same simulated scans.

For every seed a weld-seam run is simulated (:mod:`linelaser_calib.sim.weld`: a 90 deg fillet
joint, 20 views of one taught point, a scanCONTROL-class profiler, robot error 0.05 mm and
0.002 deg per axis, 1σ), the profiles are paired with the pose stream, and the true
hand-eye is disturbed as by a bumped mount: a rotation of 1-2 deg about a random axis and a
shift of 1-3 mm in a random direction. Both methods start from that hand-eye and the taught
point (``calibrate_known_point``, ``paper`` and ``default``).

Pose patterns:

- ``paper``: the paper's eq. 6, one flange orientation, stepping 2.5 mm in base z;
- ``paper+sideways``: the same with the sensor also moved by up to ±15 mm along the laser line;
- ``general``: tilted views (up to 25 deg) and laser planes turned by up to ±30 deg.

Metrics (means over seeds; mm and deg):

- ``in-sample``: the paper's figure of merit, the taught point against the point
  reconstructed through each view (recorded pose, measured corner, estimated hand-eye),
  averaged over the views; it includes the robot's own error at each view;
- ``hand-eye only``: the same views reconstructed with the true flange pose and the true
  corner, so only the hand-eye's error remains;
- ``held-out``: like ``hand-eye only`` on 20 fresh general views of the same point (the
  paper's "random positions and angles" test, Fig. 6);
- the hand-eye's rotation and translation error.

Run: ``.venv/bin/python bench/weld_seam.py [--seeds N] [--robot-sigma-mm S]`` (defaults 25
seeds and 0.05 mm; ~1.5 s per seed).
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.geometry import (
    FloatArray,
    matrix_from_rotvec,
    transform_error,
    transform_from_rotation_translation,
)
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.targets.known_point import (
    KnownPointConfig,
    KnownPointResult,
    calibrate_known_point,
    weld_points_base,
)
from linelaser_calib.sim.weld import WeldTruth, simulate_weld, weld_scenario_from_preset

PATTERNS = {
    "paper": ("weld_seam", {}),
    "paper+sideways": ("weld_seam", {"lateral_spread_m": 0.015}),
    "general": ("weld_seam_general", {}),
}
METHODS = ("initial", "paper", "default")
METRICS = ("in-sample", "hand-eye only", "held-out", "rotation", "translation", "time")
UNITS = ("mm", "mm", "mm", "deg", "mm", "s")


@dataclass
class Row:
    """Per-seed metric values of one (pattern, method)."""

    values: dict[str, list[float]]


def bumped(T: FloatArray, rng: np.random.Generator) -> FloatArray:
    """The hand-eye after a bumped mount: 1-2 deg about a random axis, 1-3 mm shift."""
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    R = T[:3, :3] @ matrix_from_rotvec(
        axis / np.linalg.norm(axis) * math.radians(rng.uniform(1.0, 2.0))
    )
    return transform_from_rotation_translation(
        R, T[:3, 3] + shift / np.linalg.norm(shift) * rng.uniform(1e-3, 3e-3)
    )


def true_view_error(truth: WeldTruth, T_flange_sensor: FloatArray) -> float:
    """Mean distance (m) of the seen seam point from its reconstruction through the true
    flange pose and the true corner, with the given hand-eye."""
    points = weld_points_base(
        truth.corner_true_sensor[:, [0, 2]], truth.T_base_flange_true, T_flange_sensor
    )
    return float(np.mean(np.linalg.norm(points - truth.corner_true_base, axis=1)))


def in_sample_error(result: KnownPointResult, truth: WeldTruth) -> float:
    """Mean distance (m) of the taught point from its reconstruction through each used view."""
    corners = np.array([c.corner_xz for c in result.corners])
    T = np.array([c.T_base_flange for c in result.corners])
    points = weld_points_base(corners, T, result.T_flange_sensor)
    return float(np.mean(np.linalg.norm(points - truth.taught_point_m, axis=1)))


def run(seeds: int, robot_sigma_m: float) -> dict[tuple[str, str], Row]:
    config = KnownPointConfig(robot_sigma_t_m=robot_sigma_m, robot_sigma_r_rad=math.radians(0.002))
    rig = {"robot_sigma_translation_m": robot_sigma_m}
    rows = {(p, m): Row({k: [] for k in METRICS}) for p in PATTERNS for m in METHODS}
    for seed in range(seeds):
        held_out = simulate_weld(weld_scenario_from_preset("weld_seam_general"), 10_000 + seed)
        for pattern, (preset, overrides) in PATTERNS.items():
            data = simulate_weld(weld_scenario_from_preset(preset, **overrides, **rig), seed)
            truth = data.truth
            samples = pair_profiles(data.profiles, data.poses, PairingConfig()).samples
            initial = bumped(truth.T_flange_sensor, np.random.default_rng(seed))
            for method in METHODS:
                start = time.perf_counter()
                if method == "initial":
                    T = initial
                    corners = truth.corner_true_sensor[:, [0, 2]]
                    points = weld_points_base(corners, truth.T_base_flange_recorded, T)
                    in_sample = float(
                        np.mean(np.linalg.norm(points - truth.taught_point_m, axis=1))
                    )
                else:
                    result = calibrate_known_point(
                        samples,
                        initial,
                        truth.taught_point_m,
                        config,
                        method,
                        seed,
                    )
                    T = result.T_flange_sensor
                    in_sample = in_sample_error(result, truth)
                elapsed = time.perf_counter() - start
                rotation, translation = transform_error(T, truth.T_flange_sensor)
                values = rows[(pattern, method)].values
                values["in-sample"].append(in_sample * 1e3)
                values["hand-eye only"].append(true_view_error(truth, T) * 1e3)
                values["held-out"].append(true_view_error(held_out.truth, T) * 1e3)
                values["rotation"].append(math.degrees(rotation))
                values["translation"].append(translation * 1e3)
                values["time"].append(elapsed)
    return rows


def print_table(rows: dict[tuple[str, str], Row], seeds: int, robot_sigma_m: float) -> None:
    header = " | ".join(f"{m} ({u})" for m, u in zip(METRICS, UNITS, strict=True))
    print(
        f"Weld-seam hand-eye correction, robot 1 sigma {robot_sigma_m * 1e3:.3f} mm per axis, "
        f"{seeds} seeds, mean (90th percentile)\n"
    )
    print(f"| pattern | method | {header} |")
    print("|---|---|" + "---|" * len(METRICS))
    for (pattern, method), row in rows.items():
        cells = []
        for metric in METRICS:
            v = np.array(row.values[metric])
            digits = 2 if metric == "time" else 3
            cells.append(f"{v.mean():.{digits}f} ({np.percentile(v, 90):.{digits}f})")
        print(f"| {pattern} | {method} | " + " | ".join(cells) + " |")
    print("\nRatio paper / default (of the means):\n")
    print("| pattern | " + " | ".join(METRICS[:5]) + " |")
    print("|---|" + "---|" * 5)
    for pattern in PATTERNS:
        ratios = [
            np.mean(rows[(pattern, "paper")].values[m])
            / np.mean(rows[(pattern, "default")].values[m])
            for m in METRICS[:5]
        ]
        print(f"| {pattern} | " + " | ".join(f"{r:.1f}x" for r in ratios) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=25)
    parser.add_argument(
        "--robot-sigma-mm",
        type=float,
        default=0.05,
        help="robot position error, 1 sigma per axis, mm (0.05: the paper's PR1400 "
        "repeatability taken as 1 sigma; 0.015: the ISO 9283 reading of +-0.05 mm)",
    )
    args = parser.parse_args()
    sigma = args.robot_sigma_mm * 1e-3
    print_table(run(args.seeds, sigma), args.seeds, sigma)


if __name__ == "__main__":
    main()
