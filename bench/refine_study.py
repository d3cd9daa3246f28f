"""Accuracy, speed and covariance calibration of the maximum-likelihood refinement.

Prints tables (markdown) at the cylinder paper's noise (robot 0.1 mm and 0.01 deg per axis,
sensor 5 µm, 50 poses, Ø40 mm) over many seeds:

1. ``accuracy``: RMS hand-eye error of the centre-to-axis least squares (the paper's cost,
   solved to its optimum from the same start), plain point-to-surface least squares (no pose
   nuisance) and the maximum-likelihood refinement, with the time per solve;
2. ``subsampling``: points per profile against error and time;
3. ``calibration``: the share of per-axis errors within the predicted 1σ (68 % if honest);
4. ``scaling``: time per solve against the number of profiles.

Run: ``.venv/bin/python bench/refine_study.py [accuracy|subsampling|calibration|scaling]
[--seeds N]``. Data come from the tests' small generator (test/_cylinder_points.py) until the
package simulator is used here.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from _cylinder_points import Scene, make_scene, perturbed_start

from linelaser_calib.core.geometry import (
    FloatArray,
    matrix_from_rotvec,
    rotvec_from_matrix,
    transform_from_rotation_translation,
)
from linelaser_calib.core.targets.cylinder.config import RefineConfig
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.refine import RefineResult, refine

RADIUS = 0.02
#: Plain least squares: the pose corrections pinned to zero by a negligible prior σ.
PLAIN = RefineConfig(
    robot_sigma_t_m=1e-10, robot_sigma_r_rad=1e-10, loss="linear", max_points_per_profile=0
)


def hand_eye_error(T_est: FloatArray, T_true: FloatArray) -> FloatArray:
    """[θ (rad, sensor axes), ρ (m, flange axes)] with truth = estimate ∘ (Exp θ, +ρ)."""
    theta = rotvec_from_matrix(T_est[:3, :3].T @ T_true[:3, :3])
    return np.concatenate([theta, T_true[:3, 3] - T_est[:3, 3]])


def _centres(scene: Scene) -> FloatArray:
    """Algebraic conic fit per profile (x-z) and its centre (paper eq. 4-5), (M, 2) m."""
    centres = []
    for p in scene.points:
        x, z = p[:, 0], p[:, 2]
        D = np.column_stack([x * x, x * z, z * z, x, z])
        A, B, C, Dc, E = np.linalg.lstsq(D, -np.ones(len(x)), rcond=None)[0]
        det = 4 * A * C - B * B
        centres.append([(B * E - 2 * C * Dc) / det, (B * Dc - 2 * A * E) / det])
    return np.asarray(centres)


def centre_to_axis(scene: Scene, T0: FloatArray, cylinder0: Cylinder) -> FloatArray:
    """Hand-eye minimising Σ centre-to-axis distance² (paper eq. 12), from (T0, cylinder0)."""
    centres = np.column_stack(
        [_centres(scene)[:, 0], np.zeros(len(scene.points)), _centres(scene)[:, 1]]
    )
    R_bf, t_bf = scene.T_base_flange[:, :3, :3], scene.T_base_flange[:, :3, 3]

    def unpack(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        d = cylinder0.direction + x[9:12]
        return (
            T0[:3, :3] @ matrix_from_rotvec(x[:3]),
            T0[:3, 3] + x[3:6],
            cylinder0.point + x[6:9],
            d / np.linalg.norm(d),
        )

    def residuals(x: FloatArray) -> FloatArray:
        R, t, c, d = unpack(x)
        w = np.einsum("mij,mj->mi", R_bf, centres @ R.T + t) + t_bf - c
        return np.concatenate([(w - np.outer(w @ d, d)).ravel(), [x[9:12] @ cylinder0.direction]])

    x = least_squares(residuals, np.zeros(12), x_scale=np.r_[[0.01] * 3, [1e-3] * 6, [0.01] * 3]).x
    R, t, _, _ = unpack(x)
    return transform_from_rotation_translation(R, t)


def _run(seed: int, config: RefineConfig, n_poses: int = 50) -> tuple[Scene, RefineResult, float]:
    rng = np.random.default_rng(seed)
    scene = make_scene(rng, n_poses=n_poses)
    T0, cylinder0 = perturbed_start(rng, scene)
    start = time.perf_counter()
    result = refine(scene.points, scene.T_base_flange, T0, cylinder0, config, radius_m=RADIUS)
    return scene, result, time.perf_counter() - start


def _rms(errors: list[FloatArray]) -> tuple[float, float]:
    E = np.asarray(errors)
    return (
        float(np.rad2deg(np.sqrt(np.mean(np.sum(E[:, :3] ** 2, axis=1))))),
        float(1e3 * np.sqrt(np.mean(np.sum(E[:, 3:] ** 2, axis=1)))),
    )


def accuracy(seeds: int) -> None:
    methods = {
        "plain LS, all 800 points": PLAIN,
        "ML, all 800 points": RefineConfig(max_points_per_profile=0),
        "ML, default (200 points)": RefineConfig(),
    }
    errors: dict[str, list[FloatArray]] = {name: [] for name in ["centre-to-axis LS", *methods]}
    times: dict[str, list[float]] = {name: [] for name in errors}
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        scene = make_scene(rng)
        T0, cylinder0 = perturbed_start(rng, scene)
        start = time.perf_counter()
        T = centre_to_axis(scene, T0, cylinder0)
        times["centre-to-axis LS"].append(time.perf_counter() - start)
        errors["centre-to-axis LS"].append(hand_eye_error(T, scene.T_flange_sensor))
        for name, config in methods.items():
            start = time.perf_counter()
            result = refine(
                scene.points, scene.T_base_flange, T0, cylinder0, config, radius_m=RADIUS
            )
            times[name].append(time.perf_counter() - start)
            errors[name].append(hand_eye_error(result.T_flange_sensor, scene.T_flange_sensor))
    print(f"\n## Accuracy over {seeds} seeds (50 poses x 800 points, paper noise)\n")
    print("| method | RMS rotation (deg) | RMS translation (mm) | median time (s) |")
    print("|---|---|---|---|")
    for name in errors:
        rot, trans = _rms(errors[name])
        print(f"| {name} | {rot:.4f} | {trans:.4f} | {np.median(times[name]):.3f} |")


def subsampling(seeds: int) -> None:
    print(f"\n## Points per profile over {seeds} seeds (ML, 50 poses)\n")
    print("| points per profile | RMS rotation (deg) | RMS translation (mm) | median time (s) |")
    print("|---|---|---|---|")
    for limit in (25, 50, 100, 200, 400, 0):
        runs = [_run(seed, RefineConfig(max_points_per_profile=limit)) for seed in range(seeds)]
        rot, trans = _rms(
            [hand_eye_error(r.T_flange_sensor, s.T_flange_sensor) for s, r, _ in runs]
        )
        label = limit if limit else "800 (all)"
        print(f"| {label} | {rot:.4f} | {trans:.4f} | {np.median([t for *_, t in runs]):.3f} |")


def calibration(seeds: int) -> None:
    inside, sigmas, errors, chi2_dof = [], [], [], []
    for seed in range(seeds):
        scene, result, _ = _run(seed, RefineConfig())
        error = hand_eye_error(result.T_flange_sensor, scene.T_flange_sensor)
        sigma = np.concatenate([result.sigma_rotation_rad, result.sigma_translation_m])
        inside.append(np.abs(error) <= sigma)
        sigmas.append(sigma)
        errors.append(error)
        chi2_dof.append(result.chi2_dof)
    share = np.mean(inside, axis=0)
    ratio = np.std(errors, axis=0) / np.sqrt(np.mean(np.square(sigmas), axis=0))
    labels = ["θx", "θy", "θz", "ρx", "ρy", "ρz"]
    print(f"\n## 1σ calibration over {seeds} seeds (ML default; 68 % expected)\n")
    print("| axis | within 1σ | empirical std / predicted σ |")
    print("|---|---|---|")
    for label, s, r in zip(labels, share, ratio, strict=True):
        print(f"| {label} | {100 * s:.0f} % | {r:.2f} |")
    print(f"| all | {100 * np.mean(inside):.1f} % | median χ²/dof {np.median(chi2_dof):.3f} |")


def scaling(seeds: int) -> None:
    print("\n## Time per solve against profiles (ML default, 800 points per profile given)\n")
    print("| profiles | median time (s) | iterations |")
    print("|---|---|---|")
    for n_poses in (20, 50, 100, 200, 500):
        runs = [_run(seed, RefineConfig(), n_poses) for seed in range(max(1, seeds // 4))]
        its = np.median([r.iterations for _, r, _ in runs])
        print(f"| {n_poses} | {np.median([t for *_, t in runs]):.3f} | {its:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "study", choices=["accuracy", "subsampling", "calibration", "scaling", "all"]
    )
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    studies = {
        "accuracy": accuracy,
        "subsampling": subsampling,
        "calibration": calibration,
        "scaling": scaling,
    }
    for name, study in studies.items():
        if args.study in (name, "all"):
            study(args.seeds)


if __name__ == "__main__":
    main()
