"""Rigid-body geometry on plain numpy arrays.

Conventions (those of the whole package):

- ``T_a_b`` is a (4, 4) homogeneous matrix, the pose of frame b in frame a; it maps
  b-coordinates into a-coordinates: ``p_a = T_a_b @ p_b``.
- Quaternions are ``xyzw`` (scalar last), as in ROS messages.
- Rotation vectors (axis * angle) are in radians; translations in metres.

Every ``check_*`` function validates its input at the entry and raises ``ValueError``
that shows the bad value.

The rotation conversions are written out here on numpy (Rodrigues' formula, Shepperd's
quaternion extraction) rather than taken from ``scipy.spatial.transform``: importing that
module costs a calibration about 0.3 s, as long as the whole solve.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

FloatArray = NDArray[np.float64]

#: Tolerance on |det R - 1| and |R^T R - I| accepted by :func:`check_rotation`.
ROTATION_TOLERANCE = 1e-6
#: Quaternions whose norm differs from 1 by more than this are called non-unit.
QUATERNION_NORM_TOLERANCE = 1e-3


def check_rotation(R: ArrayLike, tolerance: float = ROTATION_TOLERANCE) -> FloatArray:
    """Validate a rotation matrix.

    Parameters
    ----------
    R : array-like, shape (3, 3)
        Candidate rotation matrix.
    tolerance : float
        Largest accepted deviation from orthonormality and det = +1.

    Returns
    -------
    R : ndarray, shape (3, 3), float64
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"rotation matrix must have shape (3, 3), got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError(f"rotation matrix contains NaN or Inf:\n{R}")
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > tolerance or abs(np.linalg.det(R) - 1.0) > tolerance:
        raise ValueError(f"matrix is not a proper rotation (orthonormality error {err:.3g}):\n{R}")
    return R


def check_transform(T: ArrayLike, tolerance: float = ROTATION_TOLERANCE) -> FloatArray:
    """Validate a homogeneous rigid transform.

    Parameters
    ----------
    T : array-like, shape (4, 4)

    Returns
    -------
    T : ndarray, shape (4, 4), float64
    """
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"transform must have shape (4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"transform contains NaN or Inf:\n{T}")
    if np.max(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0])) > tolerance:
        raise ValueError(f"last row of a transform must be [0, 0, 0, 1], got {T[3]}")
    check_rotation(T[:3, :3], tolerance)
    return T


def check_quaternion_xyzw(q: ArrayLike) -> FloatArray:
    """Validate and normalise an ``xyzw`` quaternion.

    A quaternion is accepted if it is finite and its norm is within
    :data:`QUATERNION_NORM_TOLERANCE` of one; it is then normalised exactly.

    Raises
    ------
    ValueError
        For a wrong shape, NaN/Inf, a zero quaternion or a clearly non-unit one.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (4,):
        raise ValueError(f"quaternion must have shape (4,), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"quaternion contains NaN or Inf: {q}")
    norm = float(np.linalg.norm(q))
    if norm < 1e-12:
        raise ValueError(f"zero quaternion {q} (xyzw) is not a rotation")
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"quaternion {q} (xyzw) is not unit: norm {norm:.6f}")
    return q / norm


def matrices_from_quaternions_xyzw(q_xyzw: ArrayLike) -> FloatArray:
    """Rotation matrices (M, 3, 3) from ``xyzw`` quaternions (M, 4), each normalised first
    (not validated: see :func:`check_quaternion_xyzw`)."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[..., 0, 1] = 2.0 * (x * y - z * w)
    R[..., 0, 2] = 2.0 * (x * z + y * w)
    R[..., 1, 0] = 2.0 * (x * y + z * w)
    R[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[..., 1, 2] = 2.0 * (y * z - x * w)
    R[..., 2, 0] = 2.0 * (x * z - y * w)
    R[..., 2, 1] = 2.0 * (y * z + x * w)
    R[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


def matrix_from_quaternion_xyzw(q_xyzw: ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) from a unit ``xyzw`` quaternion (validated)."""
    return matrices_from_quaternions_xyzw(check_quaternion_xyzw(q_xyzw))


def _quaternion_xyzw_one(R: FloatArray) -> FloatArray:
    """:func:`_quaternion_xyzw` of one matrix (3, 3), in scalar arithmetic (several times
    faster than the masked array code for one)."""
    rows = R.tolist()
    diagonal = (rows[0][0], rows[1][1], rows[2][2])
    trace = diagonal[0] + diagonal[1] + diagonal[2]
    i = max(range(3), key=diagonal.__getitem__)
    if diagonal[i] >= trace:  # the choice of np.argmax over (diagonal, trace)
        j, k = (i + 1) % 3, (i + 2) % 3
        q = [0.0, 0.0, 0.0, rows[k][j] - rows[j][k]]
        q[i] = 1.0 + 2.0 * diagonal[i] - trace
        q[j] = rows[j][i] + rows[i][j]
        q[k] = rows[k][i] + rows[i][k]
    else:
        q = [
            rows[2][1] - rows[1][2],
            rows[0][2] - rows[2][0],
            rows[1][0] - rows[0][1],
            1.0 + trace,
        ]
    scale = (1.0 if q[3] >= 0.0 else -1.0) / math.sqrt(sum(v * v for v in q))
    return np.array([scale * v for v in q])


def _quaternion_xyzw(R: FloatArray) -> FloatArray:
    """Unit ``xyzw`` quaternions (..., 4) with w >= 0 of rotation matrices (..., 3, 3), by
    Shepperd's method: each from the largest of its trace and diagonal, so that no division
    is by a small number."""
    if R.shape == (3, 3):
        return _quaternion_xyzw_one(R)
    M = R.reshape(-1, 3, 3)
    diagonal = np.einsum("mii->mi", M)
    trace = np.sum(diagonal, axis=1)
    choice = np.argmax(np.column_stack([diagonal, trace]), axis=1)
    q = np.empty((len(M), 4))
    by_trace = choice == 3
    q[by_trace, 3] = 1.0 + trace[by_trace]
    q[by_trace, 0] = M[by_trace, 2, 1] - M[by_trace, 1, 2]
    q[by_trace, 1] = M[by_trace, 0, 2] - M[by_trace, 2, 0]
    q[by_trace, 2] = M[by_trace, 1, 0] - M[by_trace, 0, 1]
    for i in range(3):
        rows = choice == i
        j, k = (i + 1) % 3, (i + 2) % 3
        q[rows, i] = 1.0 + 2.0 * diagonal[rows, i] - trace[rows]
        q[rows, j] = M[rows, j, i] + M[rows, i, j]
        q[rows, k] = M[rows, k, i] + M[rows, i, k]
        q[rows, 3] = M[rows, k, j] - M[rows, j, k]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0.0] *= -1.0
    return q.reshape((*R.shape[:-2], 4))


def quaternion_xyzw_from_matrix(R: ArrayLike) -> FloatArray:
    """Unit ``xyzw`` quaternion with w >= 0 from a rotation matrix (3, 3)."""
    return _quaternion_xyzw(check_rotation(R, 1e-4))


def matrix_from_rotvec(rotvec: ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) from a rotation vector (3,) in radians (Rodrigues' formula in
    scalar arithmetic, its coefficients by their series below 1e-4 rad); matrices (..., 3, 3)
    from rotation vectors (..., 3) (:func:`exp_so3`)."""
    w = np.asarray(rotvec, dtype=np.float64)
    if w.shape != (3,):
        return exp_so3(w)
    x, y, z = w.tolist()
    theta2 = x * x + y * y + z * z
    if theta2 < 1e-8:
        a, b = 1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0
    else:
        theta = math.sqrt(theta2)
        a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta2
    return np.array(
        [
            [1.0 - b * (y * y + z * z), b * x * y - a * z, b * x * z + a * y],
            [b * x * y + a * z, 1.0 - b * (x * x + z * z), b * y * z - a * x],
            [b * x * z - a * y, b * y * z + a * x, 1.0 - b * (x * x + y * y)],
        ]
    )


def rotvec_from_matrix(R: ArrayLike) -> FloatArray:
    """Rotation vectors (..., 3) in radians, angles in [0, pi], of rotation matrices
    (..., 3, 3)."""
    q = _quaternion_xyzw(np.asarray(R, dtype=np.float64))
    if q.shape == (4,):
        x, y, z, w = q.tolist()
        half = math.atan2(math.sqrt(x * x + y * y + z * z), w)
        if half < 5e-4:
            one = 2.0 + half**2 / 3.0 + 7.0 * half**4 / 180.0
        else:
            one = 2.0 * half / math.sin(half)
        return np.array([one * x, one * y, one * z])
    angle = 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), q[..., 3])
    small = angle < 1e-3
    safe = np.where(small, 1.0, angle)
    # angle / sin(angle / 2), by its series for small angles
    factor = np.where(
        small, 2.0 + angle**2 / 12.0 + 7.0 * angle**4 / 2880.0, safe / np.sin(safe / 2.0)
    )
    return np.asarray(factor[..., None] * q[..., :3])


def transform_from_rotation_translation(R: ArrayLike, t: ArrayLike) -> FloatArray:
    """Homogeneous (4, 4) transform from a rotation (3, 3) and a translation (3,) in m."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def transform_from_translation_quaternion(t: ArrayLike, q_xyzw: ArrayLike) -> FloatArray:
    """Homogeneous (4, 4) transform from a translation (3,) in m and an ``xyzw`` quaternion."""
    return transform_from_rotation_translation(matrix_from_quaternion_xyzw(q_xyzw), t)


def translation_quaternion_from_transform(T: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Translation (3,) in m and ``xyzw`` quaternion (4,) of a (4, 4) transform."""
    T = np.asarray(T, dtype=np.float64)
    return T[:3, 3].copy(), quaternion_xyzw_from_matrix(T[:3, :3])


def transform_from_rotvec_translation(rotvec: ArrayLike, t: ArrayLike) -> FloatArray:
    """Homogeneous (4, 4) transform from a rotation vector (rad) and a translation (m)."""
    return transform_from_rotation_translation(matrix_from_rotvec(rotvec), t)


def invert_transform(T: ArrayLike) -> FloatArray:
    """Inverse of a rigid (4, 4) transform: ``T_b_a`` from ``T_a_b``."""
    T = np.asarray(T, dtype=np.float64)
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def apply_transform(T: ArrayLike, points: ArrayLike) -> FloatArray:
    """Map points (N, 3) from frame b into frame a with ``T_a_b`` (4, 4).

    ``T`` may also be a stack (K, 4, 4) applied to points (K, N, 3) or (K, 3).
    """
    T = np.asarray(T, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    if T.ndim == 2:
        return np.asarray(p @ T[:3, :3].T + T[:3, 3])
    if p.ndim == 2:
        return np.asarray(np.einsum("kij,kj->ki", T[:, :3, :3], p) + T[:, :3, 3])
    return np.asarray(np.einsum("kij,knj->kni", T[:, :3, :3], p) + T[:, None, :3, 3])


def project_to_so3(M: ArrayLike) -> FloatArray:
    """Nearest rotation matrix (Frobenius norm) to a (3, 3) matrix, by SVD."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt)) or 1.0)])
    return np.asarray(U @ D @ Vt)


def rotation_angles(R: ArrayLike) -> FloatArray:
    """Rotation angles (K,) (rad, in [0, pi]) of rotation matrices (K, 3, 3)."""
    R = np.asarray(R, dtype=np.float64)
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    vee = [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]]
    s = np.linalg.norm(np.stack(vee, axis=-1), axis=-1) / 2.0
    angles: FloatArray = np.arctan2(s, c)
    return angles


def rotation_angle(R: ArrayLike) -> float:
    """Rotation angle (rad, in [0, pi]) of a rotation matrix (3, 3)."""
    return float(rotation_angles(R))


def transform_error(T_estimate: ArrayLike, T_truth: ArrayLike) -> tuple[float, float]:
    """Rotation (rad) and translation (m) error between two (4, 4) transforms."""
    A = np.asarray(T_estimate, dtype=np.float64)
    B = np.asarray(T_truth, dtype=np.float64)
    return rotation_angle(A[:3, :3].T @ B[:3, :3]), float(np.linalg.norm(A[:3, 3] - B[:3, 3]))


def interpolate_transform(T0: ArrayLike, T1: ArrayLike, s: float) -> FloatArray:
    """Interpolate between two transforms: lerp on translation, slerp on rotation.

    Parameters
    ----------
    T0, T1 : array-like, shape (4, 4)
    s : float
        0 gives ``T0`` and 1 gives ``T1``.
    """
    A = np.asarray(T0, dtype=np.float64)
    B = np.asarray(T1, dtype=np.float64)
    R = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([A[:3, :3], B[:3, :3]])))(s)
    return transform_from_rotation_translation(R.as_matrix(), (1.0 - s) * A[:3, 3] + s * B[:3, 3])


def skew(v: ArrayLike) -> FloatArray:
    """Skew-symmetric (3, 3) matrix with ``skew(v) @ u == cross(v, u)``."""
    x, y, z = np.asarray(v, dtype=np.float64)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rpy_from_matrix(R: ArrayLike) -> FloatArray:
    """Roll, pitch, yaw (rad) of a rotation, ROS convention: fixed axes x-y-z, R = Rz Ry Rx.

    Pitch is in [-pi/2, pi/2], roll and yaw in (-pi, pi]; at pitch ±pi/2 (gimbal lock) only
    roll ∓ yaw is determined, and yaw is set to 0.
    """
    M = np.asarray(R, dtype=np.float64)
    cos_pitch = float(np.hypot(M[0, 0], M[1, 0]))
    pitch = float(np.arctan2(-M[2, 0], cos_pitch))
    if cos_pitch > 1e-9:
        roll = float(np.arctan2(M[2, 1], M[2, 2]))
        yaw = float(np.arctan2(M[1, 0], M[0, 0]))
    else:
        roll = float(np.arctan2(-M[1, 2], M[1, 1]))
        yaw = 0.0
    return np.array([roll, pitch, yaw])


def matrix_from_rpy(rpy: ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) of roll, pitch, yaw (rad), ROS convention: R = Rz Ry Rx."""
    roll, pitch, yaw = np.asarray(rpy, dtype=np.float64)
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def orthonormal_basis(direction: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors (3,) that with ``direction`` form a right-handed orthonormal basis."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    helper = np.eye(3)[int(np.argmin(np.abs(d)))]
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def exp_so3(omega: FloatArray) -> FloatArray:
    """Rotation matrices (M, 3, 3) of rotation vectors (M, 3), rad (Rodrigues' formula,
    its coefficients by their series below 1e-4 rad)."""
    w = np.asarray(omega, dtype=np.float64)
    theta2 = np.sum(w * w, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    K = skews(w.reshape(-1, 3)).reshape((*w.shape[:-1], 3, 3))
    return np.asarray(
        np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K), dtype=np.float64
    )


def skews(v: FloatArray) -> FloatArray:
    """Skew matrices (M, 3, 3) of vectors (M, 3): ``skews(v)[i] @ u == cross(v[i], u)``."""
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def right_jacobian_so3(omega: FloatArray) -> FloatArray:
    """Right Jacobians (M, 3, 3) of SO(3): Exp(ω + dω) ≈ Exp(ω)·Exp(J_r(ω)·dω)."""
    theta = np.linalg.norm(omega, axis=1)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    K = skews(omega)
    return np.asarray(np.eye(3) - a[:, None, None] * K + b[:, None, None] * (K @ K))
