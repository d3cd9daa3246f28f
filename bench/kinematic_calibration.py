"""Joint kinematic + hand-eye calibration: held-out reconstruction error against nominal kinematics.

For every seed one arm is drawn (``ur5e_kinematic``: a UR5e with lengths off by 1σ 0.15 mm,
joint offsets and twists by 1σ 0.02°, repeatability 0.02 mm) and scans two recordings with
it: a calibration recording (the preset's upright cylinder, 50 poses) and a held-out one
(another seed, the cylinder moved to (0.35, -0.25, 0) m and tilted by 17°, 20 poses). The
calibration recording is calibrated twice with the default method: with the reported
(nominal) flange poses, and with the joint states and the UR5e model (the identifiable
kinematic corrections estimated with the hand-eye). The held-out recording's true profile
points are then mapped into the base frame with each calibration from its joint vectors.

With ``--placements 2`` or ``3`` the arm also scans the cylinder at other placements
(moved and tilted, :data:`PLACEMENTS`), 50 poses each, and all of them are calibrated
together, as ``calibrate BAG1 BAG2 ... --kinematics ur5e`` does (the pipeline's
``placements``: one hand-eye, one set of kinematic corrections, a cylinder per placement);
the held-out placement is none of them.

Printed per seed:

- ``arm mm``: the arm's absolute error on the held-out poses, mean |true - nominal| flange
  position;
- ``ident``: kinematic parameters estimated (of 24);
- ``abs`` (nominal, joint): RMS distance of the mapped points from the true surface, mm;
- ``base`` (nominal, joint): the same after turning the points about the base z axis and
  shifting them along it (both fitted): the two base-frame freedoms that scans of a target
  of unknown placement cannot fix (the first joint's zero offset and the base height);
- ``shape`` (nominal, joint): the same after refitting the cylinder's placement (axis point
  and direction, radius known) to the mapped points, mm: the error that remains when the
  base frame's own placement is set aside.

Run: ``.venv/bin/python bench/kinematic_calibration.py [--seeds N] [--placements P]``
(default 5 seeds, 1 placement; ~15 s per seed and placement).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import least_squares

from linelaser_calib.core.geometry import (
    apply_transform,
    orthonormal_basis,
)
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, run_pipeline
from linelaser_calib.core.robot.joint_calibration import KinematicSetup
from linelaser_calib.core.robot.kinematics import (
    KinematicCorrections,
    KinematicModel,
    forward_kinematics,
)
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim import SimulatedData, Surface, scenario_from_preset, simulate

#: Calibration placements of the cylinder: (base point m, axis direction); the first is the
#: preset's.
PLACEMENTS = (
    ((0.45, 0.15, 0.0), (0.0, 0.0, 1.0)),
    ((0.3, -0.35, 0.0), (0.0, 0.5, 1.0)),
    ((0.55, -0.1, 0.0), (-0.5, 0.0, 1.0)),
)
HELD_OUT_BASE_M = (0.35, -0.25, 0.0)
HELD_OUT_AXIS = (0.3, 0.0, 1.0)


def mapped_points(
    data: SimulatedData, model: KinematicModel, T_flange_sensor: FloatArray
) -> FloatArray:
    """The recording's true cylinder points mapped into the base frame (N, 3), m."""
    truth = data.truth
    assert truth.joint_positions is not None
    T = forward_kinematics(model, truth.joint_positions)
    return np.concatenate(
        [
            apply_transform(T_bf @ T_flange_sensor, x[s == Surface.SIDE])
            for T_bf, x, s in zip(T, truth.points_true_sensor, truth.surface, strict=True)
        ]
    )


def surface_rms_m(data: SimulatedData, points: FloatArray) -> tuple[float, float, float]:
    """RMS distance (m) from the true surface; after turning the points about the base z axis
    and shifting them along it (fitted); after refitting the cylinder's axis."""
    cylinder = data.truth.cylinder
    u, w = orthonormal_basis(cylinder.direction)

    def gauged(p: FloatArray) -> FloatArray:
        c, s = np.cos(p[0]), np.sin(p[0])
        moved = points @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        v = moved + np.array([0.0, 0.0, p[1]]) - cylinder.point
        radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
        return np.asarray(np.linalg.norm(radial, axis=1) - cylinder.radius)

    def distances(p: FloatArray) -> FloatArray:
        d = cylinder.direction + p[0] * u + p[1] * w
        d = d / np.linalg.norm(d)
        v = points - (cylinder.point + p[2] * u + p[3] * w)
        return np.asarray(np.linalg.norm(v - np.outer(v @ d, d), axis=1) - cylinder.radius)

    absolute = float(np.sqrt(np.mean(distances(np.zeros(4)) ** 2)))
    base = float(np.sqrt(np.mean(least_squares(gauged, np.zeros(2)).fun ** 2)))
    shape = float(np.sqrt(np.mean(least_squares(distances, np.zeros(4)).fun ** 2)))
    return absolute, base, shape


def joint_calibration(
    scans: list[SimulatedData], seed: int
) -> tuple[KinematicCorrections, FloatArray, int]:
    """Corrections, hand-eye and the number of estimated parameters from one or several
    scans (the pipeline's joint calibration, the first scan's self-check included)."""
    setups = []
    for data in scans:
        assert data.truth.arm is not None and data.joint_states is not None
        setups.append(KinematicSetup(data.truth.arm.nominal, data.joint_states))
    placements = [
        (pair_profiles(data.profiles, data.poses, PairingConfig()).samples, setup)
        for data, setup in zip(scans[1:], setups[1:], strict=True)
    ]
    config = PipelineConfig(seed=seed, kinematics=setups[0])
    joint = run_pipeline(scans[0].profiles, scans[0].poses, config, placements=placements)
    assert joint.kinematics is not None and joint.identifiability is not None
    return joint.kinematics, joint.T_flange_sensor, len(joint.identifiability.identifiable)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--poses", type=int, default=50, help="poses of each calibration scan")
    parser.add_argument("--placements", type=int, default=1, choices=(1, 2, 3))
    args = parser.parse_args()
    print(
        f"{'seed':>4} {'arm mm':>6} {'ident':>5} {'abs nominal':>11} {'abs joint':>9} "
        f"{'base nominal':>12} {'base joint':>10} {'shape nominal':>13} {'shape joint':>11}"
    )
    rows = []
    for seed in range(1, args.seeds + 1):
        arm = {"kinematic_seed": 100 + seed}
        scans = [
            simulate(
                scenario_from_preset(
                    "ur5e_kinematic",
                    n_poses=args.poses,
                    cylinder_base_m=base,
                    axis_direction=axis,
                    **arm,
                ),
                seed + 100 * i,
            )
            for i, (base, axis) in enumerate(PLACEMENTS[: args.placements])
        ]
        calibration = scans[0]
        held_out = simulate(
            scenario_from_preset(
                "ur5e_kinematic",
                n_poses=20,
                cylinder_base_m=HELD_OUT_BASE_M,
                axis_direction=HELD_OUT_AXIS,
                **arm,
            ),
            1000 + seed,
        )
        truth = calibration.truth
        assert truth.arm is not None and calibration.joint_states is not None
        nominal = truth.arm.nominal
        plain = run_pipeline(calibration.profiles, calibration.poses, PipelineConfig(seed=seed))
        corrections, T_joint, estimated = joint_calibration(scans, seed)
        corrected = corrections.apply(nominal)
        ho = held_out.truth
        assert ho.joint_positions is not None
        arm_error = np.linalg.norm(
            ho.T_base_flange_true[:, :3, 3]
            - forward_kinematics(nominal, ho.joint_positions)[:, :3, 3],
            axis=1,
        )
        before = surface_rms_m(held_out, mapped_points(held_out, nominal, plain.T_flange_sensor))
        after = surface_rms_m(held_out, mapped_points(held_out, corrected, T_joint))
        rows.append([*before, *after])
        print(
            f"{seed:>4} {arm_error.mean() * 1e3:>6.3f} {estimated:>5} "
            f"{before[0] * 1e3:>11.3f} {after[0] * 1e3:>9.3f} {before[1] * 1e3:>12.3f} "
            f"{after[1] * 1e3:>10.3f} {before[2] * 1e3:>13.3f} {after[2] * 1e3:>11.3f}"
        )
    median = np.median(np.array(rows), axis=0) * 1e3
    print(
        f"median: abs {median[0]:.3f} -> {median[3]:.3f} mm, base {median[1]:.3f} -> "
        f"{median[4]:.3f} mm, shape {median[2]:.3f} -> {median[5]:.3f} mm"
    )


if __name__ == "__main__":
    main()
