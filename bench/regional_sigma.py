"""The cylinder's and sphere's 1σ where the robot errs by region, as the line presets draw it.

Each seed simulates a small cylinder (``ur_scancontrol``, 40 poses of 320 points) or sphere
(``sphere``, 30 views) recording and gives its profiles' true flange poses a regional error
in place of the rig's per-view one, as ``bench/known_point_regional.py`` does: the profiles
are ordered as a robot program would visit them (a nearest-neighbour tour of their flange
poses), the rig's error (its σ_t and σ_r per axis) is drawn at every ``--views-per-anchor``-th
profile of the tour and blended linearly between, so that neighbouring views share most of
it; ``independent`` gives each profile its own (the control). The default method
calibrates the samples with the pipeline three times: without the self-check, with the
per-view 1σ (each view's error alone, :mod:`linelaser_calib.core.shared_pose` switched off)
and with the 1σ that counts the error the views share; then with the self-check (as a user
runs it).

Per scene and error: the largest |error| / 1σ per axis over the seeds (and which seed) and
the RMS of error / 1σ of each, the seeds beyond 3 after the self-check, and the median
translation 1σ (length, mm) of each.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/regional_sigma.py [--seeds 10]
[--views-per-anchor 4] [--only cylinder|sphere]`` (a few seconds a seed and scene; without
the variable OpenBLAS's threads make it ten times slower on a loaded machine).
"""

from __future__ import annotations

import argparse
import math
from contextlib import nullcontext
from dataclasses import replace
from typing import Any
from unittest import mock

import numpy as np
from known_point_regional import regional_errors

from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix
from linelaser_calib.core.pipeline import Method, calibrate_samples
from linelaser_calib.core.targets.cylinder import target as cylinder_target
from linelaser_calib.core.targets.sphere import target as sphere_target
from linelaser_calib.core.types import Sample
from linelaser_calib.settings import Front, pipeline_config
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import simulate_sphere, sphere_scenario_from_preset

ERRORS = ("regional", "independent")
#: The 1σ compared: per-view and shared without the self-check, then with it.
SIGMAS = ("per-view", "shared", "after")


def scene(target: str, seed: int) -> Any:
    """The simulated recording of ``target``'s scene."""
    if target == "cylinder":
        return simulate(scenario_from_preset("ur_scancontrol", n_poses=40, resolution=320), seed)
    return simulate_sphere(sphere_scenario_from_preset("sphere", n_poses=30), seed)


def _per_view(target: str) -> Any:
    """A patch that leaves the robot's shared error out of ``target``'s 1σ."""
    if target == "cylinder":
        return mock.patch.object(
            cylinder_target, "with_shared", lambda refined, _=None: (refined, None, None)
        )
    return mock.patch.object(sphere_target, "shared_pose_error", lambda *_: None)


def calibrated(target: str, data: Any, seed: int, per_anchor: int) -> dict[str, FloatArray]:
    """|error| / 1σ (6,) of one recording with the regional robot error (``per_anchor`` 1:
    each profile's own), per :data:`SIGMAS`, and the 1σ itself (``sigma <name>``)."""
    truth = data.truth
    T = truth.T_base_flange_true
    rig = truth.scenario if target == "cylinder" else truth.scenario.rig
    T = T @ regional_errors(T, np.random.default_rng(seed), rig, per_anchor)
    samples = [Sample(k, p.stamp_ns, T[k], p.points) for k, p in enumerate(data.profiles)]
    config = pipeline_config(target, Method.DEFAULT, {}, Front.CLI, seed=0)
    out = {}
    for name in SIGMAS:
        with _per_view(target) if name == "per-view" else nullcontext():
            result = calibrate_samples(
                samples, config if name == "after" else replace(config, self_check_folds=0)
            )
        X, X_true = result.T_flange_sensor, truth.T_flange_sensor
        error = np.r_[rotvec_from_matrix(X_true[:3, :3].T @ X[:3, :3]), X[:3, 3] - X_true[:3, 3]]
        assert result.uncertainty_rotation_rad is not None
        assert result.uncertainty_translation_m is not None
        sigma = np.r_[result.uncertainty_rotation_rad, result.uncertainty_translation_m]
        out[name], out[f"sigma {name}"] = np.abs(error / sigma), sigma
    return out


def run(targets: list[str], seeds: int, per_anchor: int) -> None:
    print(
        f"{'scene':<10}{'error':<13}"
        + "".join(f"{f'max |e|/σ {name}':>20}" for name in SIGMAS)
        + "".join(f"{f'RMS {name}':>13}" for name in SIGMAS)
        + f"{'> 3 after':>10}"
        + "".join(f"{f'1σ t mm {name}':>17}" for name in SIGMAS)
    )
    for target in targets:
        for kind in ERRORS:
            rows = [
                calibrated(
                    target, scene(target, seed), seed, per_anchor if kind == "regional" else 1
                )
                for seed in range(seeds)
            ]
            z = {name: np.array([row[name] for row in rows]) for name in SIGMAS}
            worst = {name: z[name].max(axis=1) for name in SIGMAS}
            sigma_t = {
                name: float(np.median([np.linalg.norm(row[f"sigma {name}"][3:]) for row in rows]))
                for name in SIGMAS
            }
            print(
                f"{target:<10}{kind:<13}"
                + "".join(
                    f"{f'{worst[n].max():.2f} ({int(worst[n].argmax())})':>20}" for n in SIGMAS
                )
                + "".join(f"{math.sqrt(float(np.mean(z[n] ** 2))):>13.2f}" for n in SIGMAS)
                + f"{int(np.sum(worst['after'] > 3.0)):>10}"
                + "".join(f"{sigma_t[n] * 1e3:>17.3f}" for n in SIGMAS),
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--views-per-anchor", type=int, default=4)
    parser.add_argument("--only", choices=("cylinder", "sphere"))
    args = parser.parse_args()
    run([args.only] if args.only else ["cylinder", "sphere"], args.seeds, args.views_per_anchor)


if __name__ == "__main__":
    main()
