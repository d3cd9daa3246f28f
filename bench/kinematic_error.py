"""What today's default method makes of an arm whose kinematics differ from the nominal ones.

For every seed the ``ur5e_kinematic`` preset is simulated (a UR5e with lengths off by 1σ
0.15 mm and joint offsets and twists by 1σ 0.02°, repeatability 0.02 mm; 50 cylinder poses;
the flange poses it reports are nominal forward kinematics of its joints) and calibrated
with the default method. Printed per seed:

- the arm's absolute error at the shots: |true - reported| flange position, mean and max;
- the hand-eye error against the truth (mm, deg) and the reported 1σ (ranges over the axes);
- the largest |error| / 1σ over the six axes, against the true hand-eye and against the one
  the nominal flange poses can see (``seen``: moved by the arm's error after its last joint,
  :func:`~linelaser_calib.core.robot.kinematics.effective_hand_eye`, which no scan separates
  from the hand-eye);
- the residual, the number of warnings, and whether the robot's error was called
  systematic (``warned``: the self-check's systematic-error warning);
- the scan error: the median distance of the cylinder points, mapped into the base frame
  with the reported poses and the estimated hand-eye, from the true cylinder surface.

Last, the honesty figure: the share of seeds either warned or within 3σ of the seen hand-eye
on every axis. ``--length-sigma`` and ``--angle-sigma`` scale the arm's kinematic error (the
preset's 1σ 0.15 mm and 0.02°); each seed draws another arm.

Run: ``.venv/bin/python bench/kinematic_error.py [--seeds N]`` (default 3; ~10 s per seed).
"""

from __future__ import annotations

import argparse

import numpy as np

from linelaser_calib.core.geometry import apply_transform
from linelaser_calib.core.pipeline import PipelineConfig, run_pipeline
from linelaser_calib.core.robot.kinematics import effective_hand_eye
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim import SimulatedData, Surface, scenario_from_preset, simulate
from linelaser_calib.summary import truth_error


def scan_error_m(data: SimulatedData, T_flange_sensor: FloatArray) -> float:
    """Median distance (m) of the cylinder points, mapped with the reported flange poses and
    ``T_flange_sensor``, from the true cylinder surface."""
    truth = data.truth
    cylinder: Cylinder = truth.cylinder
    distances = []
    for k in range(len(data.profiles)):
        x = truth.points_true_sensor[k][truth.surface[k] == Surface.SIDE]
        X = apply_transform(truth.T_base_flange_recorded[k] @ T_flange_sensor, x)
        v = X - cylinder.point
        radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
        distances.append(np.abs(np.linalg.norm(radial, axis=1) - cylinder.radius))
    return float(np.median(np.concatenate(distances)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--length-sigma", type=float, default=1.5e-4, help="m, 1 sigma")
    parser.add_argument("--angle-sigma", type=float, default=np.radians(0.02), help="rad")
    args = parser.parse_args()
    print(
        f"{'seed':>4} {'arm mean mm':>11} {'arm max mm':>10} {'err mm':>7} {'err deg':>8} "
        f"{'1σ t mm':>11} {'1σ r deg':>13} {'max|e|/σ':>8} {'seen':>5} {'resid µm':>8} "
        f"{'warn':>4} {'warned':>6} {'scan mm':>7}"
    )
    honest = 0
    for seed in range(1, args.seeds + 1):
        scenario = scenario_from_preset(
            "ur5e_kinematic",
            kinematic_sigma_length_m=args.length_sigma,
            kinematic_sigma_angle_rad=args.angle_sigma,
        )
        data = simulate(scenario, seed)
        truth = data.truth
        arm = np.linalg.norm(
            truth.T_base_flange_true[:, :3, 3] - truth.T_base_flange_recorded[:, :3, 3], axis=1
        )
        result = run_pipeline(data.profiles, data.poses, PipelineConfig(seed=seed))
        error = truth_error(result.T_flange_sensor, truth.T_flange_sensor)
        sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
        assert sigma_t is not None and sigma_r is not None
        ratio = np.abs(
            np.concatenate([error.translation_axes_m / sigma_t, error.rotation_axes_rad / sigma_r])
        ).max()
        assert truth.arm is not None
        seen = truth_error(
            result.T_flange_sensor,
            effective_hand_eye(truth.arm.nominal, truth.arm.true, truth.T_flange_sensor),
        )
        seen_ratio = np.abs(
            np.concatenate([seen.translation_axes_m / sigma_t, seen.rotation_axes_rad / sigma_r])
        ).max()
        warned = result.self_check is not None and result.self_check.systematic
        honest += bool(warned or seen_ratio <= 3.0)
        print(
            f"{seed:>4} {arm.mean() * 1e3:>11.3f} {arm.max() * 1e3:>10.3f} "
            f"{error.translation_m * 1e3:>7.3f} {np.degrees(error.rotation_rad):>8.4f} "
            f"{sigma_t.min() * 1e3:>5.3f}-{sigma_t.max() * 1e3:<5.3f} "
            f"{np.degrees(sigma_r.min()):>6.4f}-{np.degrees(sigma_r.max()):<6.4f} "
            f"{ratio:>8.1f} {seen_ratio:>5.1f} {result.rms_residual_m * 1e6:>8.1f} "
            f"{len(result.warnings):>4} {'yes' if warned else 'no':>6} "
            f"{scan_error_m(data, result.T_flange_sensor) * 1e3:>7.3f}",
            flush=True,
        )
    print(
        f"warned or within 3 sigma of the seen hand-eye on every axis: {honest} of "
        f"{args.seeds} seeds ({100.0 * honest / args.seeds:.0f} %)"
    )


if __name__ == "__main__":
    main()
