"""The quantiles and rotation conversions written on numpy and the standard library agree with
scipy (which the calibration no longer imports: see test_startup) to the last digits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import chdtri, ndtri, stdtrit

from linelaser_calib.core import geometry
from linelaser_calib.core.quantiles import (
    chi2_upper_quantile,
    normal_quantile,
    student_t_quantile,
)

DOFS = [0.7, 1, 2, 2.5, 3, 4, 5, 6, 9, 20, 100, 500]
PROBABILITIES = [1e-12, 1e-9, 1e-6, 0.0027, 0.05, 0.3, 0.5, 0.7, 0.99]


@pytest.mark.parametrize("dof", DOFS)
def test_chi2_and_t_quantiles_agree_with_scipy(dof: float) -> None:
    for p in PROBABILITIES:
        assert chi2_upper_quantile(dof, p) == pytest.approx(chdtri(dof, p), rel=1e-11)
        for q in (p, 1.0 - p):
            expected = stdtrit(dof, q)
            assert student_t_quantile(dof, q) == pytest.approx(expected, rel=1e-11, abs=1e-12)


def test_normal_quantile_agrees_with_scipy() -> None:
    for p in [1e-9, 0.00135, 0.1, 0.5, 0.9, 0.99865]:
        assert normal_quantile(p) == pytest.approx(ndtri(p), rel=1e-13, abs=1e-15)


def test_quantiles_refuse_probabilities_outside_zero_one() -> None:
    for bad in (0.0, 1.0, -0.1, float("nan")):
        with pytest.raises(ValueError):
            chi2_upper_quantile(3, bad)
        with pytest.raises(ValueError):
            student_t_quantile(3, bad)


def test_rotation_conversions_agree_with_scipy() -> None:
    rotations = Rotation.random(300, random_state=7)
    matrices = rotations.as_matrix()
    quaternions = rotations.as_quat()
    np.testing.assert_allclose(
        geometry.matrices_from_quaternions_xyzw(quaternions), matrices, atol=1e-14
    )
    for k in range(len(matrices)):
        q = quaternions[k] if quaternions[k, 3] >= 0 else -quaternions[k]
        np.testing.assert_allclose(geometry.quaternion_xyzw_from_matrix(matrices[k]), q, atol=1e-14)
        np.testing.assert_allclose(
            geometry.rotvec_from_matrix(matrices[k]), rotations[k].as_rotvec(), atol=1e-14
        )
        np.testing.assert_allclose(
            geometry.rpy_from_matrix(matrices[k]), rotations[k].as_euler("xyz"), atol=1e-13
        )
        np.testing.assert_allclose(
            geometry.matrix_from_rpy(rotations[k].as_euler("xyz")), matrices[k], atol=1e-14
        )


def test_rotation_vectors_round_trip_from_tiny_angles_to_pi() -> None:
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(60, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    angles = np.geomspace(1e-12, np.pi - 1e-9, 60)
    rotvecs = directions * angles[:, None]
    np.testing.assert_allclose(
        geometry.exp_so3(rotvecs), Rotation.from_rotvec(rotvecs).as_matrix(), atol=1e-15
    )
    for v in rotvecs:
        back = geometry.rotvec_from_matrix(geometry.matrix_from_rotvec(v))
        np.testing.assert_allclose(back, v, rtol=1e-9, atol=1e-15)


def test_roll_pitch_yaw_at_gimbal_lock_rebuild_the_rotation() -> None:
    for pitch in (np.pi / 2, -np.pi / 2):
        R = geometry.matrix_from_rpy([0.3, pitch, -0.7])
        rpy = geometry.rpy_from_matrix(R)
        assert abs(rpy[2]) < 1e-15  # yaw set to zero at the lock
        np.testing.assert_allclose(geometry.matrix_from_rpy(rpy), R, atol=1e-12)


def test_rotation_vector_conversions_take_stacks_like_single_ones() -> None:
    rotvecs = Rotation.random(40, random_state=11).as_rotvec().reshape(2, 20, 3)
    matrices = geometry.matrix_from_rotvec(rotvecs)
    assert matrices.shape == (2, 20, 3, 3)
    np.testing.assert_allclose(
        matrices,
        Rotation.from_rotvec(rotvecs.reshape(-1, 3)).as_matrix().reshape(2, 20, 3, 3),
        atol=1e-14,
    )
    np.testing.assert_allclose(geometry.rotvec_from_matrix(matrices), rotvecs, atol=1e-13)
    for k in range(20):
        np.testing.assert_allclose(
            geometry.matrix_from_rotvec(rotvecs[1, k]), matrices[1, k], atol=1e-15
        )
        np.testing.assert_allclose(
            geometry.rotvec_from_matrix(matrices[1, k]), rotvecs[1, k], atol=1e-13
        )
