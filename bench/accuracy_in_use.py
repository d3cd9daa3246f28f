"""Accuracy in use held out by region, against the error a user really meets (simulator truth).

A user calibrates once and scans elsewhere in the cell. For each region of the workspace the
self-check held out (:mod:`linelaser_calib.core.regions`), the **user's error** is taken from
the simulator's truth: the held-out region's profile points (those the fit would use: the
arc's inliers), mapped into the base frame with the recorded flange poses (the robot's error
included, as a user's scans are) and the hand-eye calibrated *without* that region (its
along-line scale correction applied), measured against the TRUE cylinder surface; RMS over all
held-out points. The self-check's figure (``quality.accuracy_in_use_m``) measures the same
points against the cylinder fitted without the region, which is all a user has, plus how far
that cylinder moves at them when the region joins the fit (its own error there). The part of
the arm's error common to the whole scanned workspace moves every scan alike and no
held-out check can see it, so the user's error is also given against the cylinder where the
recorded poses put it (``rel_um``: fitted to all points mapped with the recorded poses and the
TRUE hand-eye): the error a self-check can in principle measure.

Per preset, over ``--seeds`` seeds, the table gives median [max]:

- ``blocked_um``: the self-check's accuracy in use, µm; ``truth_um``: the user's error, µm;
  ``ratio``: blocked / truth (goal: within 25 %, 0.75-1.25); ``rel_um`` and ``ratio_rel``:
  the same against the cylinder where the recorded poses put it;
- ``interleaved_um``: the pose-interleaved held-out RMS (the consistency check);
- ``z``: the largest |error| / 1σ over the six hand-eye axes (goal ≤ 3; the truth is the
  hand-eye the nominal flange poses can see where the arm's kinematics err,
  :func:`~linelaser_calib.core.robot.kinematics.effective_hand_eye`), and the share of axes
  within 1σ;
- ``centre_mm``: the reported 1σ at the measuring centre (largest flange axis, mm);
- how many recordings warned of a systematic robot error, chose the plain model, and the
  regions held out; the CPU time of the solve and the time the self-check adds.

Run: ``.venv/bin/python bench/accuracy_in_use.py [--seeds N] [--presets a,b] [--verbose]``
(default 20 seeds of ``cluttered_camera`` and ``ur5e_kinematic``; about 30 s of CPU per
``cluttered_camera`` recording).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from robot_error import SYSTEMATIC_WORDS, checked_run
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from linelaser_calib.core.regions import PLAIN
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.selfcheck import sigma_at_point
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.section import CylinderSection
from linelaser_calib.sim import SimulatedData

PRESETS = ("cluttered_camera", "ur5e_kinematic")


def arm_frame_cylinder(result: CalibrationResult, data: SimulatedData) -> Cylinder:
    """The true cylinder as the arm's recorded poses place it: fitted (radius the true one)
    to all used points mapped with the recorded poses and the TRUE hand-eye (the estimate's
    scale correction applied). It differs from the true one by the arm's error common to the
    scanned workspace, which no self-check can see."""
    T_true = data.truth.T_flange_sensor
    points = np.concatenate(
        [
            result.target.sensor_points(fit.points) @ (fit.T_base_flange @ T_true)[:3, :3].T
            + (fit.T_base_flange @ T_true)[:3, 3]
            for fit in result.sample_fits
        ]
    )
    truth = data.truth.cylinder

    def cylinder(x: np.ndarray) -> Cylinder:
        direction = Rotation.from_rotvec([x[3], x[4], 0.0]).apply(truth.direction)
        return Cylinder(truth.point + x[:3], direction, truth.radius)

    def residual(x: np.ndarray) -> np.ndarray:
        c = cylinder(x)
        v = points - c.point
        radial = v - np.outer(v @ c.direction, c.direction)
        return np.asarray(np.linalg.norm(radial, axis=1) - c.radius)

    return cylinder(least_squares(residual, np.zeros(5)).x)


def user_error(result: CalibrationResult, data: SimulatedData, surface: Cylinder) -> float:
    """RMS distance (m) from ``surface`` of each held-out region's points mapped with the
    recorded poses and the hand-eye solved without the region; NaN without regions."""
    check = result.self_check
    assert check is not None
    true_surface = CylinderSection(surface, False)
    fits = {fit.index: fit for fit in result.sample_fits}
    squares, count = 0.0, 0
    for indices, solution in zip(check.region_indices, check.region_solutions, strict=True):
        if solution is None:
            continue
        for index in indices:
            fit = fits[index]
            corrected = replace(fit, points=solution.section.sensor_points(fit.points))
            d = true_surface.surface_distances(
                corrected, fit.T_base_flange @ solution.T_flange_sensor
            )
            squares += float(np.sum(d**2))
            count += d.size
    return float(np.sqrt(squares / count)) if count else float("nan")


def run(preset: str, seed: int) -> dict[str, float]:
    """One recording: the numbers of one table row's columns."""
    done = checked_run(preset, seed)
    data, result, check = done.data, done.result, done.check
    solve_s, checked_s = done.plain_s, done.checked_s
    z = done.abs_error / check.sigma_honest
    blocked = float("nan") if check.accuracy_in_use_m is None else check.accuracy_in_use_m
    truth = user_error(result, data, data.truth.cylinder)
    relative = user_error(result, data, arm_frame_cylinder(result, data))
    assert result.measuring_centre_depth_m is not None
    centre = sigma_at_point(
        result.T_flange_sensor,
        check.sigma_honest[:3],
        check.sigma_honest[3:],
        np.array([0.0, 0.0, result.measuring_centre_depth_m]),
    )
    return {
        "blocked_um": blocked * 1e6,
        "truth_um": truth * 1e6,
        "ratio": blocked / truth,
        "rel_um": relative * 1e6,
        "ratio_rel": blocked / relative,
        "interleaved_um": check.interleaved_rms_m * 1e6,
        "z": float(z.max()),
        "in1": float(np.mean(z <= 1.0)),
        "centre_mm": float(centre.max() * 1e3),
        "warned": float(any(SYSTEMATIC_WORDS in w for w in result.warnings)),
        "plain": float(check.model is not None and check.model.chosen == PLAIN),
        "regions": float(check.regions),
        "solve_s": solve_s,
        "added_s": checked_s - solve_s,
    }


def cell(rows: list[dict[str, float]], key: str) -> str:
    """``median [max]`` of one column over the seeds."""
    values = np.array([r[key] for r in rows])
    return f"{np.nanmedian(values):>8.3f} [{np.nanmax(values):>7.2f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--presets", default=",".join(PRESETS))
    parser.add_argument("--verbose", action="store_true", help="print each recording too")
    args = parser.parse_args()
    columns = ("blocked_um", "truth_um", "ratio", "rel_um", "ratio_rel", "interleaved_um")
    columns += ("z", "centre_mm")
    columns += ("solve_s", "added_s")
    print(
        f"{'preset':<17} {'n':>3} "
        + " ".join(f"{c:>18}" for c in columns)
        + f" {'ratio in 0.75-1.25':>19} {'rel in 0.75-1.25':>17} {'in 1σ':>6} {'z ≤ 3':>6}"
        + f" {'warned':>6} {'plain':>6}"
        + f" {'regions':>8}"
    )
    for preset in args.presets.split(","):
        rows = []
        for seed in range(1, args.seeds + 1):
            rows.append(run(preset, seed))
            if args.verbose:
                print(
                    f"  {preset} seed {seed}: "
                    + ", ".join(f"{k} {v:.3f}" for k, v in rows[-1].items()),
                    flush=True,
                )
        ratio = np.array([r["ratio"] for r in rows])
        ratio_rel = np.array([r["ratio_rel"] for r in rows])
        print(
            f"{preset:<17} {len(rows):>3} "
            + " ".join(f"{cell(rows, c):>18}" for c in columns)
            + f" {int(np.sum((ratio >= 0.75) & (ratio <= 1.25))):>19}"
            + f" {int(np.sum((ratio_rel >= 0.75) & (ratio_rel <= 1.25))):>17}"
            + f" {np.mean([r['in1'] for r in rows]):>6.0%}"
            + f" {int(sum(r['z'] <= 3.0 for r in rows)):>6}"
            + f" {int(sum(r['warned'] for r in rows)):>6}"
            + f" {int(sum(r['plain'] for r in rows)):>6}"
            + f" {np.median([r['regions'] for r in rows]):>8.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
