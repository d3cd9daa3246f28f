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

Numbers may be separated by spaces or commas. Values are checked as every hand-eye is
(:mod:`~linelaser_calib.io.hand_eye`: near-unit rotations normalised with a warning,
millimetres refused); angles over 2 pi are refused as degrees.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import matrix_from_rpy, transform_from_rotation_translation
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.hand_eye import check_translation, rotation_from_quaternion
from linelaser_calib.io.results import hand_eye_transform
from linelaser_calib.io.yaml_file import load_fields

FloatArray = NDArray[np.float64]

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


def _checked(T: FloatArray, warnings: list[str]) -> InitialHandEye:
    check_translation(T[:3, 3])
    return InitialHandEye(T, warnings)


def _from_numbers(values: list[float]) -> InitialHandEye:
    """The hand-eye from 7 numbers (x y z qx qy qz qw) or 6 (x y z roll pitch yaw)."""
    warnings: list[str] = []
    if len(values) == 7:
        R = rotation_from_quaternion(np.array(values[3:]), warnings, "the quaternion qx qy qz qw")
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
    """The hand-eye of a YAML file, read and checked as every result file is."""
    path, fields = load_fields(path)
    T, warnings = hand_eye_transform(fields)
    return InitialHandEye(T, warnings)


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
