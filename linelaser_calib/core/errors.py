"""Exceptions a user can cause. Each message says what was wrong and what to do.

The CLI and the nodes catch :class:`CalibrationError` and show its message; anything else
reaching the user as a traceback is a bug.
"""

from __future__ import annotations


class CalibrationError(Exception):
    """Base class of every error the package raises on bad input or bad data."""


class InputError(CalibrationError):
    """Malformed input: wrong shapes, NaN/Inf, non-unit quaternions, wrong units."""


class PairingError(CalibrationError):
    """No profile could be paired with a flange pose."""


class ProfileRejected(CalibrationError):
    """One profile is unusable (too few points, arc too short, fit failed).

    Raised per profile and turned into a :class:`~linelaser_calib.core.types.Rejection`
    by the pipeline; never fatal on its own.
    """


class DegenerateError(CalibrationError):
    """The poses cannot determine the transform; the message names the missing motion."""


class SolverError(CalibrationError):
    """The solver failed to converge to a usable solution."""


class ModelMismatch(CalibrationError):
    """The target's model does not fit the data (another target, units, clocks, motion)."""


class GrossMismatch(ModelMismatch):
    """A failed fit check that no comparison with the rivals may keep: a misfit beyond any
    robot or profiler error the target allows, or a recording of another kind that the
    target recognises itself (a target's ``soft_fit_check`` keeps the others' results where
    every rival is clearly worse)."""


class TooFewFeatures(DegenerateError):
    """Too few profiles show the target's feature (an arc, a circle, a V).

    The pipeline then asks whether another target's full model explains the recording
    (:func:`~linelaser_calib.core.targets.rivals.refuse_without_fit`) before this refusal
    stands.

    Attributes
    ----------
    found : int
        The profiles that show the feature.
    """

    def __init__(self, message: str, found: int) -> None:
        super().__init__(message)
        self.found = found

    def __reduce__(self) -> tuple[type[TooFewFeatures], tuple[str, int]]:
        return type(self), (str(self), self.found)
