"""The checks every hand-eye a user gives goes through, from a file or as numbers.

A quaternion (or rotation matrix) off unit (orthonormal) by no more than rounding its numbers
to the digits given can explain is normalised with a warning; one off by more is refused,
naming the field: a digit typed wrong (0.156664 for 0.056664 turns the rotation by 11 deg
and the norm by 1 %) is no rounding. The rounding of a number is half a unit of its last
decimal as written (``repr``: 0.7071 is rounded to 5e-5, a full-precision float to 1e-17),
never less than :data:`NEAR_UNIT` (float32 values). A translation over
:data:`MAX_TRANSLATION_M` is refused as millimetres. Result files, truth files and the
initial hand-eye (:mod:`~linelaser_calib.io.initial`) are all checked here, so a file one
command refuses no other command takes, and every command says what it normalised.
"""

from __future__ import annotations

from decimal import Decimal

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import matrices_from_quaternions_xyzw, project_to_so3

FloatArray = NDArray[np.float64]

#: Largest hand-eye translation accepted, m: a sensor on a flange is well within 2 m of it.
MAX_TRANSLATION_M = 2.0
#: Smallest tolerance on a quaternion's norm or a matrix's orthonormality: a float32 value
#: is off unit by about 1e-7.
NEAR_UNIT = 1e-6
#: A norm off unit by more than this is noted when normalised (a float64 one is off ~1e-16).
NOTED_OFF_UNIT = 1e-9


def rounding(values: FloatArray) -> FloatArray:
    """Half a unit of the last decimal of each value as written (shortest ``repr``), same
    shape as ``values``: how far rounding to those digits may have moved it."""
    return np.array(
        [0.5 * 10.0 ** int(Decimal(repr(float(v))).as_tuple().exponent) for v in values.flat]
    ).reshape(values.shape)


def rotation_from_quaternion(
    q_xyzw: FloatArray, warnings: list[str], field: str = "the quaternion"
) -> FloatArray:
    """The rotation (3, 3) of an ``xyzw`` quaternion (4,), normalised with a warning appended
    to ``warnings`` when off unit by no more than its rounding explains.

    Raises
    ------
    InputError
        A quaternion off unit by more than rounding explains (or not finite), naming
        ``field``.
    """
    norm = float(np.linalg.norm(q_xyzw))
    off = abs(norm - 1.0)
    tolerance = max(NEAR_UNIT, float(np.abs(q_xyzw) @ rounding(q_xyzw)))
    if not off <= tolerance:
        raise InputError(
            f"{field} {q_xyzw.tolist()} (xyzw) has norm {norm:.6f}, off unit by {off:.1e}, "
            f"more than rounding its digits explains ({tolerance:.1e}): a digit is likely "
            "wrong, or the order is not x y z w (scalar last); correct it"
        )
    if off > NOTED_OFF_UNIT:
        warnings.append(f"{field} {q_xyzw.tolist()} (xyzw) has norm {norm:.6f}; normalised")
    return matrices_from_quaternions_xyzw(q_xyzw)


def rotation_from_matrix(
    M: FloatArray, warnings: list[str], field: str = "the matrix's rotation"
) -> FloatArray:
    """The rotation (3, 3) nearest a matrix (3, 3) off orthonormal by no more than its
    rounding explains, with a warning.

    Raises
    ------
    InputError
        A matrix farther from a rotation, naming ``field``.
    """
    off = float(np.max(np.abs(M.T @ M - np.eye(3))))
    tolerance = max(NEAR_UNIT, 2.0 * float(np.max(np.abs(M).sum(axis=0) * rounding(M).max())))
    if not (off <= tolerance and np.linalg.det(M) > 0.0):
        raise InputError(
            f"{field} {M.tolist()} is not a rotation: orthonormality off by {off:.1e}, more "
            f"than rounding its digits explains ({tolerance:.1e}), determinant "
            f"{np.linalg.det(M):.4f}; a digit is likely wrong, correct it"
        )
    if off > NOTED_OFF_UNIT:
        warnings.append(f"{field} is off orthonormal by {off:.2g}; the nearest rotation is used")
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
