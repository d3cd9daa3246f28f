"""Invariants of core.geometry, checked in seeded loops."""

from __future__ import annotations

import numpy as np
import pytest

from linelaser_calib.core import geometry as g


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return g.transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))


def test_quaternion_matrix_round_trip() -> None:
    rng = np.random.default_rng(1)
    for _ in range(50):
        T = random_transform(rng)
        t, q = g.translation_quaternion_from_transform(T)
        assert q[3] >= 0.0
        np.testing.assert_allclose(g.transform_from_translation_quaternion(t, q), T, atol=1e-12)


def test_quaternion_is_xyzw() -> None:
    # 90 deg about z: x, y, z, w = 0, 0, sin 45, cos 45
    R = g.matrix_from_quaternion_xyzw([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("q", [[0, 0, 0, 0], [np.nan, 0, 0, 1], [0, 0, 0, 2.0], [1, 0, 0]])
def test_bad_quaternion_rejected(q: list[float]) -> None:
    with pytest.raises(ValueError, match="quaternion"):
        g.check_quaternion_xyzw(q)


def test_slightly_non_unit_quaternion_normalised() -> None:
    q = g.check_quaternion_xyzw([0.0, 0.0, 0.0, 1.0004])
    assert np.linalg.norm(q) == pytest.approx(1.0)


def test_invert_and_apply() -> None:
    rng = np.random.default_rng(2)
    for _ in range(20):
        T = random_transform(rng)
        p = rng.normal(size=(7, 3))
        np.testing.assert_allclose(
            g.apply_transform(g.invert_transform(T), g.apply_transform(T, p)), p, atol=1e-12
        )
        np.testing.assert_allclose(g.invert_transform(T) @ T, np.eye(4), atol=1e-12)


def test_apply_transform_stacks() -> None:
    rng = np.random.default_rng(3)
    Ts = np.stack([random_transform(rng) for _ in range(4)])
    p = rng.normal(size=(4, 5, 3))
    expected = np.stack([g.apply_transform(T, q) for T, q in zip(Ts, p, strict=True)])
    np.testing.assert_allclose(g.apply_transform(Ts, p), expected, atol=1e-12)
    np.testing.assert_allclose(g.apply_transform(Ts, p[:, 0]), expected[:, 0], atol=1e-12)


def test_project_to_so3_recovers_perturbed_rotation() -> None:
    rng = np.random.default_rng(4)
    for _ in range(20):
        R = g.matrix_from_rotvec(rng.normal(size=3))
        P = g.project_to_so3(R + 1e-4 * rng.normal(size=(3, 3)))
        g.check_rotation(P, 1e-12)
        assert g.rotation_angle(P.T @ R) < 1e-3


def test_interpolate_transform_midpoint() -> None:
    A = np.eye(4)
    B = g.transform_from_rotvec_translation([0.0, 0.0, 1.0], [2.0, 0.0, 0.0])
    M = g.interpolate_transform(A, B, 0.5)
    np.testing.assert_allclose(M[:3, 3], [1.0, 0.0, 0.0])
    assert g.rotation_angle(M[:3, :3]) == pytest.approx(0.5)
    np.testing.assert_allclose(g.interpolate_transform(A, B, 1.0), B, atol=1e-12)


def test_transform_error() -> None:
    A = g.transform_from_rotvec_translation([0.0, 0.01, 0.0], [0.0, 0.0, 0.003])
    rot, trans = g.transform_error(A, np.eye(4))
    assert rot == pytest.approx(0.01)
    assert trans == pytest.approx(0.003)


def test_check_transform_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="shape"):
        g.check_transform(np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(ValueError, match="rotation"):
        g.check_transform(bad)


def test_orthonormal_basis() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        d = rng.normal(size=3)
        u, v = g.orthonormal_basis(d)
        B = np.column_stack([d / np.linalg.norm(d), u, v])
        np.testing.assert_allclose(B.T @ B, np.eye(3), atol=1e-12)
        assert np.linalg.det(B) == pytest.approx(1.0)
