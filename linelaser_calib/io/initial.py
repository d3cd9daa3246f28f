"""The initial hand-eye ``T_flange_sensor`` as a user gives it: a file, or the numbers.

One reader for ``calibrate --initial`` and the ``initial_hand_eye_path`` parameter of
``calibration_service``. Accepted forms:

- A YAML file: a result file, or one holding only ``hand_eye`` with ``translation`` (m) and
  ``rotation_xyzw``, or with a 4 x 4 ``matrix`` (translation in m); other keys are ignored.
- Seven numbers ``x y z qx qy qz qw``: translation in m, quaternion xyzw, the order of
  ``static_transform_publisher``.
- Six numbers ``x y z roll pitch yaw``: translation in m, angles in rad about the fixed
  x, y, z axes, R = Rz(yaw) Ry(pitch) Rx(roll), the ROS convention. (The positional form of
  ``static_transform_publisher`` lists the same angles as yaw pitch roll.)
- The named arguments of the Jazzy ``static_transform_publisher``: ``--x --y --z`` with
  ``--qx --qy --qz --qw`` or ``--roll --pitch --yaw`` (an absent one is 0, ``--qw`` 1).

Numbers may be separated by spaces or commas. Hand-written values are checked: a quaternion
or rotation matrix a little off unit is normalised with a warning and refused when far off;
a translation over :data:`MAX_TRANSLATION_M` or angles over 2 pi are refused as millimetres
or degrees.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    matrices_from_quaternions_xyzw,
    matrix_from_rpy,
    project_to_so3,
    transform_from_rotation_translation,
)
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.results import MATRIX_TOLERANCE, _load

FloatArray = NDArray[np.float64]

#: Largest hand-eye translation accepted, m: a sensor on a flange is well within 2 m of it.
MAX_TRANSLATION_M = 2.0
#: A quaternion whose norm, or a matrix whose orthonormality, is off by more than this is
#: normalised with a warning; by more than :data:`FAR_OFF_UNIT` it is refused.
NEAR_UNIT = 1e-6
FAR_OFF_UNIT = 0.05

FORMS = (
    "a result YAML or a YAML with a hand_eye section (translation in m and rotation_xyzw, or "
    "a 4x4 matrix), or the numbers 'x y z qx qy qz qw' (m, quaternion xyzw) or "
    "'x y z roll pitch yaw' (m, rad), or static_transform_publisher's named arguments "
    "'--x X --y Y --z Z --qx .. --qw ..' or '--roll .. --pitch .. --yaw ..'"
)


class InitialHandEye(NamedTuple):
    """An initial hand-eye and what was corrected in it.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        Translation in m.
    warnings : list of str
        One line per value that was normalised (a quaternion or matrix a little off unit).
    """

    T_flange_sensor: FloatArray
    warnings: list[str]


def _rotation_from_quaternion(q_xyzw: FloatArray, warnings: list[str]) -> FloatArray:
    norm = float(np.linalg.norm(q_xyzw))
    if not abs(norm - 1.0) <= FAR_OFF_UNIT:
        raise InputError(
            f"the quaternion {q_xyzw.tolist()} (xyzw) has norm {norm:.4f}, not 1: check the "
            "order (x y z w, scalar last) and the digits"
        )
    if abs(norm - 1.0) > NEAR_UNIT:
        warnings.append(f"the quaternion {q_xyzw.tolist()} (xyzw) has norm {norm:.6f}; normalised")
    return matrices_from_quaternions_xyzw(q_xyzw)


def _rotation_from_matrix(M: FloatArray, warnings: list[str]) -> FloatArray:
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


def _checked(T: FloatArray, warnings: list[str]) -> InitialHandEye:
    t = T[:3, 3]
    if not np.linalg.norm(t) <= MAX_TRANSLATION_M:
        raise InputError(
            f"the translation {t.tolist()} is {np.linalg.norm(t):.1f} m from the flange: are "
            f"these millimetres? Give metres, e.g. {(t / 1000.0).round(6).tolist()}"
        )
    return InitialHandEye(T, warnings)


def _from_numbers(values: list[float]) -> InitialHandEye:
    """The hand-eye from 7 numbers (x y z qx qy qz qw) or 6 (x y z roll pitch yaw)."""
    warnings: list[str] = []
    if len(values) == 7:
        R = _rotation_from_quaternion(np.array(values[3:]), warnings)
    elif len(values) == 6:
        angles = np.array(values[3:])
        if np.max(np.abs(angles)) > 2.0 * math.pi:
            raise InputError(
                f"roll pitch yaw {angles.tolist()} exceed 2 pi: are these degrees? Give "
                f"radians, e.g. {np.radians(angles).round(6).tolist()}"
            )
        R = matrix_from_rpy(angles)
    else:
        raise InputError(
            f"expected 7 numbers 'x y z qx qy qz qw' or 6 numbers 'x y z roll pitch yaw', got "
            f"{len(values)}: {values}"
        )
    return _checked(transform_from_rotation_translation(R, values[:3]), warnings)


def _named_values(words: list[str]) -> list[float]:
    """``--x X --y Y ...`` as the 7 or 6 positional numbers (absent: 0, and 1 for qw)."""
    names = dict(zip(words[::2], words[1::2], strict=False))
    quaternion = bool({"--qx", "--qy", "--qz", "--qw"} & set(names))
    rotation = ("qx", "qy", "qz", "qw") if quaternion else ("roll", "pitch", "yaw")
    allowed = {f"--{k}" for k in ("x", "y", "z", *rotation)}
    if len(words) % 2 or len(names) != len(words) // 2 or not set(names) <= allowed:
        raise InputError(
            f"cannot read {' '.join(words)!r} as named arguments: give each of --x --y --z "
            "at most once, with --qx --qy --qz --qw or with --roll --pitch --yaw"
        )
    try:
        return [
            float(names.get(f"--{k}", "1" if k == "qw" else "0"))
            for k in ("x", "y", "z", *rotation)
        ]
    except ValueError:
        raise InputError(
            f"named arguments need numbers as values, got {' '.join(words)!r}"
        ) from None


def _parse_numbers(spec: str) -> InitialHandEye | None:
    """The hand-eye if ``spec`` is numbers (positional or named); None if it is not."""
    words = [w for w in re.split(r"[\s,]+", spec.strip()) if w]
    if words and words[0].startswith("--"):
        return _from_numbers(_named_values(words))
    try:
        values = [float(w) for w in words]
    except ValueError:
        return None
    if not values or not all(math.isfinite(v) for v in values):
        return None
    return _from_numbers(values)


def _from_file(path: Path) -> InitialHandEye:
    path, fields = _load(path)
    hand_eye = fields.section("hand_eye")
    warnings: list[str] = []
    has_pose = hand_eye.has("translation") or hand_eye.has("rotation_xyzw")
    if not has_pose and not hand_eye.has("matrix"):
        raise ResultFileError(
            f"{path}: hand_eye needs translation and rotation_xyzw, or matrix; it has "
            f"{sorted(hand_eye.data)}"
        )
    try:
        if has_pose:
            R = _rotation_from_quaternion(hand_eye.array("rotation_xyzw", (4,)), warnings)
            T = transform_from_rotation_translation(R, hand_eye.array("translation", (3,)))
            if (
                hand_eye.has("matrix")
                and np.max(np.abs(hand_eye.array("matrix", (4, 4)) - T)) > MATRIX_TOLERANCE
            ):
                raise ResultFileError(
                    f"{path}: hand_eye.matrix disagrees with hand_eye.translation and "
                    "hand_eye.rotation_xyzw; fix or delete one of them"
                )
        else:
            M = hand_eye.array("matrix", (4, 4))
            if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > MATRIX_TOLERANCE:
                raise ResultFileError(f"{path}: the last row of hand_eye.matrix must be 0 0 0 1")
            R = _rotation_from_matrix(M[:3, :3], warnings)
            T = transform_from_rotation_translation(R, M[:3, 3])
        return _checked(T, warnings)
    except InputError as err:
        raise ResultFileError(f"{path}: {err}") from None


def read_initial_hand_eye(spec: str) -> InitialHandEye:
    """Read an initial hand-eye from a file name or from numbers (see the module docstring).

    Parameters
    ----------
    spec : str
        A YAML file name (``~`` expanded), or the numbers as one string.

    Returns
    -------
    InitialHandEye

    Raises
    ------
    InputError
        Numbers of the wrong count, a quaternion or matrix far from a rotation, a translation
        in mm or angles in degrees, or text that is neither a file nor numbers.
    ResultFileError
        A file that cannot be read or has no usable ``hand_eye`` section.
    """
    numbers = _parse_numbers(spec)
    if numbers is not None:
        return numbers
    path = Path(spec).expanduser()
    if not path.exists():
        raise ResultFileError(f"{path} does not exist (nor is it numbers); give {FORMS}")
    return _from_file(path)
