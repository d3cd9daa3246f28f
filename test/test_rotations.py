"""The rotation conversions of core.geometry agree with scipy.spatial.transform to the last
digits, from tiny angles to pi and at gimbal lock."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core import geometry


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
