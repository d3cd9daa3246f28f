"""The known point's 1σ where the robot errs by region, as the line presets draw its error.

Each seed simulates a weld-seam run (``bench/weld_seam.py``'s three pose patterns, 20 views
of one taught point) and gives its true flange poses a regional error in place of the rig's
per-view one, as :mod:`linelaser_calib.sim.line` does along its
sweep: the views are ordered as a robot program would visit them (a nearest-neighbour tour
of their flange poses, :func:`~linelaser_calib.core.shared_pose.pose_separations`, from the
first view), the rig's error (0.05 mm and 0.002 deg per axis, 1σ) is drawn at every
``--views-per-anchor``-th view of the tour and blended linearly between
(:func:`~linelaser_calib.sim.robot.error_transforms`), so that neighbouring views share most
of it; ``--views-per-anchor 1`` gives each view its own (the rig's model). The default
method corrects a bumped hand-eye against the taught point (as ``bench/weld_seam.py``)
twice: with the per-view 1σ (each view's error alone) and with the 1σ that counts the error
the views share (:mod:`linelaser_calib.core.shared_pose`).

Per pattern: the largest |error| / 1σ per axis over the seeds (and which seed), the RMS of
error / 1σ, the seeds beyond 3, the median translation 1σ (mm) and the views used.

Run: ``.venv/bin/python bench/known_point_regional.py [--seeds 10] [--views-per-anchor 4]``
(about 1 s a seed and pattern).
"""

from __future__ import annotations

import argparse
import math
from contextlib import nullcontext
from unittest import mock

import numpy as np
from weld_seam import PATTERNS, bumped

from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix
from linelaser_calib.core.shared_pose import pose_separations
from linelaser_calib.core.targets.known_point import (
    KnownPointConfig,
    calibrate_known_point,
)
from linelaser_calib.core.targets.known_point import target as known_point_target
from linelaser_calib.core.types import Sample
from linelaser_calib.sim.robot import draw_errors, error_transforms
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset

MODELS = ("per-view", "shared")


def tour(T: FloatArray) -> list[int]:
    """A nearest-neighbour tour of flange poses (M, 4, 4) from the first: view indices."""
    D = pose_separations(T, T)
    order, left = [0], set(range(1, len(T)))
    while left:
        nearest = min(left, key=lambda j: D[order[-1], j])
        order.append(nearest)
        left.remove(nearest)
    return order


def regional_errors(
    T: FloatArray, rng: np.random.Generator, rig: Scenario, per_anchor: int
) -> FloatArray:
    """Error transforms (M, 4, 4) of views with flange poses T: the rig's robot error drawn
    at every ``per_anchor``-th view of the :func:`tour` and blended linearly between (1: each
    view's own)."""
    position = np.argsort(tour(T))
    errors = draw_errors(rng, rig, len(T) // per_anchor + 2)
    return error_transforms(rig, errors, position // per_anchor, position % per_anchor / per_anchor)


def run(seeds: int, per_anchor: int) -> None:
    config = KnownPointConfig(robot_sigma_r_rad=math.radians(0.002))
    print(
        f"{'pattern':<16}{'1σ model':<10}{'max |e|/σ (seed)':>18}{'RMS e/σ':>9}{'> 3':>5}"
        f"{'1σ t mm':>9}{'used':>8}"
    )
    for pattern, (preset, overrides) in PATTERNS.items():
        z: dict[str, list[FloatArray]] = {m: [] for m in MODELS}
        sigma_t: dict[str, list[float]] = {m: [] for m in MODELS}
        used = []
        for seed in range(seeds):
            data = simulate_weld(weld_scenario_from_preset(preset, **overrides), seed)
            truth = data.truth
            T = truth.T_base_flange_true
            T = T @ regional_errors(T, np.random.default_rng(seed), truth.scenario.rig, per_anchor)
            samples = [Sample(k, p.stamp_ns, T[k], p.points) for k, p in enumerate(data.profiles)]
            initial = bumped(truth.T_flange_sensor, np.random.default_rng(seed))
            for model in MODELS:
                patch = (
                    mock.patch.object(known_point_target, "shared_pose_error", lambda *_: None)
                    if model == "per-view"
                    else nullcontext()
                )
                with patch:
                    result = calibrate_known_point(
                        samples, initial, truth.taught_point_m, config, "default", seed
                    )
                X, X_true = result.T_flange_sensor, truth.T_flange_sensor
                error = np.r_[
                    rotvec_from_matrix(X_true[:3, :3].T @ X[:3, :3]), X[:3, 3] - X_true[:3, 3]
                ]
                assert result.uncertainty_rotation_rad is not None
                assert result.uncertainty_translation_m is not None
                sigma = np.r_[result.uncertainty_rotation_rad, result.uncertainty_translation_m]
                z[model].append(error / sigma)
                sigma_t[model].append(float(np.linalg.norm(sigma[3:])) * 1e3)
            used.append(f"{len(result.samples_used)}/{len(samples)}")
        for model in MODELS:
            a = np.abs(np.array(z[model]))
            worst = a.max(axis=1)
            print(
                f"{pattern:<16}{model:<10}"
                f"{f'{worst.max():.2f} ({int(worst.argmax())})':>18}"
                f"{math.sqrt(float(np.mean(a**2))):>9.2f}{int(np.sum(worst > 3.0)):>5}"
                f"{float(np.median(sigma_t[model])):>9.3f}{min(used):>8}",
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--views-per-anchor", type=int, default=4)
    args = parser.parse_args()
    run(args.seeds, args.views_per_anchor)


if __name__ == "__main__":
    main()
