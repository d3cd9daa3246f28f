"""Typed records shared by every stage of the pipeline.

All arrays are float64 in SI units (metres, radians), but points kept for later, which may be
float32 (:func:`stored_points`); stamps are integer nanoseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: Points as :func:`stored_points` keeps them: float32 where exact, else float64.
StoredArray = NDArray[np.floating[Any]]


@dataclass(frozen=True, slots=True)
class Profile:
    """One laser profile as received.

    Attributes
    ----------
    stamp_ns : int
        Acquisition stamp, ns.
    points : ndarray, shape (N, 3)
        Points in the sensor frame, m. The laser plane is x-z, so y is ~0.
        May still hold NaN/Inf (REP 117); cleaning drops them.
        float32 where a recording's are kept (:func:`stored_points`): convert before
        computing with them.
    frame_id : str
        Sensor frame id from the message header.
    """

    stamp_ns: int
    points: StoredArray
    frame_id: str = "laser"


@dataclass(frozen=True, slots=True)
class FlangePose:
    """One flange pose sample from the robot.

    Attributes
    ----------
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
        Pose of the flange in the base frame (translation in m).
    frame_id : str
        Base frame id from the message header.
    """

    stamp_ns: int
    T_base_flange: FloatArray
    frame_id: str = "base_link"


@dataclass(frozen=True, slots=True)
class Sample:
    """A profile paired with the flange pose interpolated at its stamp.

    Attributes
    ----------
    index : int
        Index of the profile in the input stream (stable across stages, for reports).
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
    points : ndarray, shape (N, 3)
        Sensor-frame points, m (float32 where its profile's are, :class:`Profile`).
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    points: StoredArray


@dataclass(frozen=True)
class Rejection:
    """Why a profile or sample was not used.

    Attributes
    ----------
    index : int
        Profile index in the input stream.
    stamp_ns : int
    stage : str
        ``pairing``, ``cleaning``, ``outlier`` or the target's feature stage (``ellipse``,
        ``corner``, ...).
    reason : str
        Human-readable reason, with units.
    """

    index: int
    stamp_ns: int
    stage: str
    reason: str


def stored_points(points: StoredArray) -> StoredArray:
    """``points`` to keep for later (a feature's, held through a whole calibration): as
    float32 where that holds them exactly (a profiler's float32 coordinates, read as
    float64), else as they are. Half the memory, the same numbers: a user converts them
    back to float64 before computing with them (``np.asarray(p, dtype=np.float64)``)."""
    if points.dtype == np.float32:
        return points
    narrow = points.astype(np.float32)
    return narrow if np.array_equal(narrow, points, equal_nan=True) else points


@dataclass(frozen=True)
class SampleFit:
    """What the solve used of one sample, kept for reports and markers.

    Attributes
    ----------
    index : int
        Profile index in the input stream.
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
        Flange pose as paired (recorded, not corrected).
    stored : ndarray, shape (K, 3)
        The points the target's model used, sensor frame, m (e.g. the ellipse inliers, the
        points of the two V lines), kept as :func:`stored_points` keeps them (a result holds
        every used profile's); :attr:`points` gives them as float64.
    feature_xz : ndarray, shape (2,)
        The profile's feature point in the sensor x-z plane, m: the point of the profile that
        the target's paper method uses (e.g. the ellipse centre, the V corner).
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    stored: StoredArray
    feature_xz: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "stored", stored_points(np.asarray(self.stored)))

    @property
    def points(self) -> FloatArray:
        """The points (K, 3) the target's model used, sensor frame, m, as float64."""
        return np.asarray(self.stored, dtype=np.float64)


class Level(str, Enum):
    """How far a result can be trusted, best first."""

    GOOD = "good"
    USE_WITH_CARE = "use_with_care"
    DO_NOT_USE = "do_not_use"

    @property
    def words(self) -> str:
        """The level in words (``use with care``)."""
        return self.value.replace("_", " ")


@dataclass(frozen=True)
class Verdict:
    """The verdict on a calibration (the result file's ``quality.verdict``).

    Attributes
    ----------
    level : Level
    reason : str
        The one reason that decides it.
    next_step : str
        The one thing to do next.
    accuracy_in_use_m : float or None
        The self-check's accuracy in use, m, beside the verdict; None when not measured.
    not_measured_because : str
        Why there is no accuracy in use (empty when there is one).
    warning_ids : tuple of str
        The stable id of each of the result's warnings, in their order.
    """

    level: Level
    reason: str
    next_step: str
    accuracy_in_use_m: float | None = None
    not_measured_because: str = ""
    warning_ids: tuple[str, ...] = ()
