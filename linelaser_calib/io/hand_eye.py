"""The checks every hand-eye a user gives goes through, from a file or as numbers.

A quaternion or rotation matrix a little off unit is normalised with a warning and refused
when far off; a translation over :data:`MAX_TRANSLATION_M` is refused as millimetres. Result
files, truth files and the initial hand-eye (:mod:`~linelaser_calib.io.initial`) are all
checked here, so a file one command refuses no other command takes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import matrices_from_quaternions_xyzw, project_to_so3

FloatArray = NDArray[np.float64]

#: Largest hand-eye translation accepted, m: a sensor on a flange is well within 2 m of it.
MAX_TRANSLATION_M = 2.0
#: A quaternion whose norm, or a matrix whose orthonormality, is off by more than this is
#: normalised with a warning; by more than :data:`FAR_OFF_UNIT` it is refused.
NEAR_UNIT = 1e-6
FAR_OFF_UNIT = 0.05


def rotation_from_quaternion(q_xyzw: FloatArray, warnings: list[str]) -> FloatArray:
    """The rotation (3, 3) of an ``xyzw`` quaternion (4,), normalised with a warning appended
    to ``warnings`` when a little off unit.

    Raises
    ------
    InputError
        A quaternion far from unit (or not finite).
    """
    norm = float(np.linalg.norm(q_xyzw))
    if not abs(norm - 1.0) <= FAR_OFF_UNIT:
        raise InputError(
            f"the quaternion {q_xyzw.tolist()} (xyzw) has norm {norm:.4f}, not 1: check the "
            "order (x y z w, scalar last) and the digits"
        )
    if abs(norm - 1.0) > NEAR_UNIT:
        warnings.append(f"the quaternion {q_xyzw.tolist()} (xyzw) has norm {norm:.6f}; normalised")
    return matrices_from_quaternions_xyzw(q_xyzw)


def rotation_from_matrix(M: FloatArray, warnings: list[str]) -> FloatArray:
    """The rotation (3, 3) nearest a matrix (3, 3) a little off orthonormal, with a warning.

    Raises
    ------
    InputError
        A matrix far from a rotation.
    """
    off = float(np.max(np.abs(M.T @ M - np.eye(3))))
    if not (off <= FAR_OFF_UNIT and np.linalg.det(M) > 0.0):
        raise InputError(
            f"the matrix's rotation {M.tolist()} is not a rotation (orthonormality off by "
            f"{off:.4f}, determinant {np.linalg.det(M):.4f})"
        )
    if off > NEAR_UNIT:
        warnings.append(
            f"the matrix's rotation is off orthonormal by {off:.2g}; the nearest rotation is used"
        )
        return project_to_so3(M)
    return M


def check_translation(t: FloatArray) -> None:
    """Refuse a hand-eye translation (3,), m, too long for a sensor on a flange.

    Raises
    ------
    InputError
        Farther than :data:`MAX_TRANSLATION_M`: most likely millimetres.
    """
    if not np.linalg.norm(t) <= MAX_TRANSLATION_M:
        raise InputError(
            f"the translation {t.tolist()} is {np.linalg.norm(t):.1f} m from the flange: are "
            f"these millimetres? Give metres, e.g. {(t / 1000.0).round(6).tolist()}"
        )
