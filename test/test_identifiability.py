"""Identifiability of kinematic parameters, hand-eye and cylinder from one cylinder scan."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from linelaser_calib.core.geometry import orthonormal_basis, transform_from_rotvec_translation
from linelaser_calib.core.robot.kinematics import KinematicModel, forward_kinematics
from linelaser_calib.core.targets.cylinder.identifiability import (
    CYLINDER_NAMES,
    HAND_EYE_NAMES,
    CylinderScan,
    cylinder_identifiability,
    cylinder_scan_jacobian,
)
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim import SimulatedData, Surface, scenario_from_preset, simulate


@lru_cache(maxsize=1)
def scan(n_poses: int) -> SimulatedData:
    return simulate(scenario_from_preset("ur5e_kinematic", n_poses=n_poses), 2)


def cylinder_points(data: SimulatedData, step: int) -> list[FloatArray]:
    truth = data.truth
    return [
        truth.points_true_sensor[k][truth.surface[k] == Surface.SIDE][::step]
        for k in range(len(data.profiles))
    ]


def distances(
    model: KinematicModel,
    q: FloatArray,
    points: list[FloatArray],
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
) -> FloatArray:
    """Signed distance of every point to the cylinder surface, m (the residual)."""
    T = forward_kinematics(model, q) @ T_flange_sensor
    out = []
    for T_bs, x in zip(T, points, strict=True):
        v = x @ T_bs[:3, :3].T + T_bs[:3, 3] - cylinder.point
        a = cylinder.direction / np.linalg.norm(cylinder.direction)
        out.append(np.linalg.norm(v - np.outer(v @ a, a), axis=1) - cylinder.radius)
    return np.concatenate(out)


def test_jacobian_matches_finite_differences() -> None:
    data = scan(20)
    truth = data.truth
    assert truth.arm is not None and truth.joint_positions is not None
    model, q = truth.arm.nominal, truth.joint_positions[:4]
    points = cylinder_points(data, 40)[:4]
    T_fs, cyl = truth.T_flange_sensor, truth.cylinder
    J = cylinder_scan_jacobian(model, CylinderScan(q, points, cyl), T_fs)
    eps = 1e-6
    e1, e2 = orthonormal_basis(cyl.direction)
    p0 = model.parameters

    def moved(k: int, h: float) -> FloatArray:
        P = len(p0)
        if k < P:
            step = np.zeros(P)
            step[k] = h
            return distances(model.with_parameters(p0 + step), q, points, T_fs, cyl)
        if k < P + 6:
            delta = np.zeros(6)
            delta[k - P] = h
            T = T_fs @ transform_from_rotvec_translation(delta[3:], delta[:3])
            return distances(model, q, points, T, cyl)
        point, direction, radius = cyl.point, cyl.direction, cyl.radius
        which = k - P - 6
        if which < 2:
            point = point + h * (e1, e2)[which]
        elif which < 4:
            direction = direction + h * (e1, e2)[which - 2]
        else:
            radius = radius + h
        moved_cylinder = Cylinder(point, direction / np.linalg.norm(direction), radius)
        return distances(model, q, points, T_fs, moved_cylinder)

    for k in range(J.shape[1]):
        numeric = (moved(k, eps) - moved(k, -eps)) / (2 * eps)
        np.testing.assert_allclose(J[:, k], numeric, atol=2e-6, err_msg=f"column {k}")


def test_one_cylinder_leaves_the_gauge_and_the_parallel_axes_free() -> None:
    data = scan(20)
    truth = data.truth
    assert truth.arm is not None and truth.joint_positions is not None
    placed = CylinderScan(truth.joint_positions, cylinder_points(data, 5), truth.cylinder)
    found = cylinder_identifiability(truth.arm.nominal, [placed], truth.T_flange_sensor)
    assert len(found.names) == 24 + 6 + 5
    free = set(found.unidentifiable)
    # Lengths along the three parallel joint axes (shoulder lift, elbow, wrist 1): only
    # their sum moves the flange.
    parallel = {"shoulder_lift_joint.d", "elbow_joint.d", "wrist_1_joint.d"}
    assert len(parallel & free) == 2
    # The last link trades against the hand-eye (4 DH parameters of wrist 3), the base turn
    # and height against the upright cylinder's placement and its symmetry.
    assert len(free) == 8
    assert not free & {*HAND_EYE_NAMES, *CYLINDER_NAMES}
    assert len(found.kinematic_identifiable) == 16
    assert len(found.free_combinations) == 8
    gap = found.singular_values[len(found.identifiable) - 1] / found.singular_values[0]
    assert gap > 1e-5
    assert found.singular_values[len(found.identifiable)] < 1e-9 * found.singular_values[0]
