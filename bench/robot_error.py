"""Hand-eye error against the reported 1σ, on independent and on systematic robot error.

Over ``--seeds`` seeds of each preset (independent per-pose robot noise: ``paper``,
``ur_scancontrol``; systematic, from kinematic errors: ``ur5e_kinematic``; region-dependent,
with a coarse sensor and clutter: ``cluttered_camera``), each recording is simulated and
calibrated with the default method (its self-check included). Per preset the
table gives, as median [max] over the seeds:

- the hand-eye error (mm, deg) against the simulator's truth. With an arm's kinematics
  (``ur5e_kinematic``) the truth is the hand-eye the nominal flange poses can see
  (:func:`~linelaser_calib.core.robot.kinematics.effective_hand_eye`: the true one with the arm's
  error after its last joint's motion, a constant transform in the flange frame that no scan
  separates from the hand-eye and that a user's scans with nominal kinematics need);
  ``phys_mm`` is the error against the physical hand-eye, for comparison;
- the reported 1σ (largest axis; mm, deg) and the model's own 1σ before any widening;
- the largest |error| / 1σ over the six axes, with the reported and with the model's 1σ, and
  the share of axes within 1σ and 2σ of the reported one;
- the accuracy in use (held-out point-to-surface RMS, µm; regions of the workspace held out,
  bench/accuracy_in_use.py sets it against the simulator's truth);
- the two statistics that decide whether the error is systematic, as min / max over the
  seeds beside their limits: the neighbour correlation of the held-out offsets and the region
  dispersion (the hand-eye's jackknife 1σ over regions of the workspace left out, over what
  the noise model predicts for it);
- the even/odd halves' disagreement in combined (reported) σ;
- how many recordings warned that the robot's error looks systematic, and the CPU time the
  self-check adds (s).

Run: ``.venv/bin/python bench/robot_error.py [--seeds N] [--presets a,b] [--verbose]``
(default 20 seeds; 3-5 s of CPU per recording, 20 s on cluttered_camera; ``--verbose`` prints
each recording's largest |error|/σ and statistics).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.pipeline import PipelineConfig, run_pipeline
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import effective_hand_eye
from linelaser_calib.core.selfcheck import SelfCheck, neighbour_limit, region_limit
from linelaser_calib.sim import SimulatedData, scenario_from_preset, simulate
from linelaser_calib.summary import TruthError, truth_error

PRESETS = ("paper", "ur_scancontrol", "ur5e_kinematic", "cluttered_camera")
SYSTEMATIC_WORDS = "looks systematic"


@dataclass(frozen=True)
class CheckedRun:
    """One simulated recording calibrated twice: without the self-check (for its cost) and
    with it; the error against the hand-eye the recorded poses can see."""

    data: SimulatedData
    result: CalibrationResult
    check: SelfCheck
    plain_s: float
    checked_s: float
    error: TruthError
    abs_error: np.ndarray  # (6,): rotation about the sensor axes (rad), translation (m)


def checked_run(preset: str, seed: int) -> CheckedRun:
    """Simulate ``preset`` with ``seed`` and calibrate it (CPU seconds of both runs)."""
    data = simulate(scenario_from_preset(preset), seed)
    start = time.process_time()
    run_pipeline(data.profiles, data.poses, PipelineConfig(seed=seed, self_check_folds=0))
    plain = time.process_time() - start
    start = time.process_time()
    result = run_pipeline(data.profiles, data.poses, PipelineConfig(seed=seed))
    checked = time.process_time() - start
    check = result.self_check
    assert check is not None, f"{preset} seed {seed}: no self-check"
    arm = data.truth.arm
    T_truth = (
        data.truth.T_flange_sensor
        if arm is None
        else effective_hand_eye(arm.nominal, arm.true, data.truth.T_flange_sensor)
    )
    error = truth_error(result.T_flange_sensor, T_truth)
    e = np.abs(np.concatenate([error.rotation_axes_rad, error.translation_axes_m]))
    return CheckedRun(data, result, check, plain, checked, error, e)


def run(preset: str, seed: int) -> dict[str, float]:
    """One recording: the numbers of one table row's columns."""
    done = checked_run(preset, seed)
    data, result, check, error, e = done.data, done.result, done.check, done.error, done.abs_error
    plain, checked = done.plain_s, done.checked_s
    physical = truth_error(result.T_flange_sensor, data.truth.T_flange_sensor)
    z = e / check.sigma_honest
    return {
        "err_mm": error.translation_m * 1e3,
        "phys_mm": physical.translation_m * 1e3,
        "err_deg": float(np.degrees(error.rotation_rad)),
        "sigma_mm": float(check.sigma_honest[3:].max() * 1e3),
        "sigma_deg": float(np.degrees(check.sigma_honest[:3].max())),
        "model_mm": float(check.sigma_model[3:].max() * 1e3),
        "z": float(z.max()),
        "z_model": float((e / check.sigma_model).max()),
        "in1": float(np.mean(z <= 1.0)),
        "in2": float(np.mean(z <= 2.0)),
        "acc_um": float("nan")
        if check.accuracy_in_use_m is None
        else check.accuracy_in_use_m * 1e6,
        "corr": check.neighbour_correlation,
        "corr_limit": neighbour_limit(len(check.indices)),
        "region": float("nan") if check.region_ratio is None else check.region_ratio,
        "region_limit": region_limit(check.regions - 1) if check.regions else float("nan"),
        "halves": float("nan") if check.halves_sigmas is None else float(check.halves_sigmas.max()),
        "warned": float(any(SYSTEMATIC_WORDS in w for w in result.warnings)),
        "added_s": checked - plain,
    }


def cell(rows: list[dict[str, float]], key: str) -> str:
    """``median [max]`` of one column over the seeds."""
    values = np.array([r[key] for r in rows])
    return f"{np.nanmedian(values):>7.3f} [{np.nanmax(values):>5.2f}]"


def span(rows: list[dict[str, float]], key: str, limit: str) -> str:
    """``min / max (limit)`` of one statistic over the seeds."""
    values = np.array([r[key] for r in rows])
    return f"{values.min():.2f} / {values.max():.2f} ({np.median([r[limit] for r in rows]):.2f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--presets", default=",".join(PRESETS))
    parser.add_argument("--verbose", action="store_true", help="print each recording too")
    args = parser.parse_args()
    columns = ("err_mm", "phys_mm", "err_deg", "sigma_mm", "sigma_deg", "model_mm", "z", "z_model")
    columns += ("acc_um", "halves", "added_s")
    print(
        f"{'preset':<15} {'n':>3} "
        + " ".join(f"{c:>15}" for c in columns)
        + f" {'in 1σ':>6} {'in 2σ':>6} {'warned':>6}"
        + f" {'neighbour corr (limit)':>24} {'region dispersion (limit)':>26}"
    )
    for preset in args.presets.split(","):
        rows = []
        for seed in range(1, args.seeds + 1):
            rows.append(run(preset, seed))
            if args.verbose:
                print(
                    f"  {preset} seed {seed}: max |e|/σ {rows[-1]['z']:.2f}, warned "
                    f"{bool(rows[-1]['warned'])}, neighbour correlation {rows[-1]['corr']:.2f}, "
                    f"region dispersion {rows[-1]['region']:.2f}",
                    flush=True,
                )
        print(
            f"{preset:<15} {len(rows):>3} "
            + " ".join(f"{cell(rows, c):>15}" for c in columns)
            + f" {np.mean([r['in1'] for r in rows]):>6.0%}"
            + f" {np.mean([r['in2'] for r in rows]):>6.0%}"
            + f" {int(sum(r['warned'] for r in rows)):>6}"
            + f" {span(rows, 'corr', 'corr_limit'):>24}"
            + f" {span(rows, 'region', 'region_limit'):>26}",
            flush=True,
        )


if __name__ == "__main__":
    main()
