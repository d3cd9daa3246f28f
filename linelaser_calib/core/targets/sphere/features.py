"""The sphere target's feature of one profile: its circle, the points it holds and what
they are worth."""

from __future__ import annotations

from dataclasses import dataclass

from linelaser_calib.core.model_check import Comparison
from linelaser_calib.core.targets.sphere.circle import CircleFit
from linelaser_calib.core.types import FloatArray, SampleFit


@dataclass(frozen=True)
class SphereFeature:
    """One profile's circle.

    Attributes
    ----------
    index : int
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
    circle : CircleFit
    points : ndarray, shape (N, 3)
        The circle's inlier points, sensor frame, m, in scan order.
    n_effective : float
        Independent points the circle's inlier residuals are worth
        (:func:`~linelaser_calib.core.model_check.effective_count`): what its RMS residual
        is an estimate over, when the recording judges it (:func:`.shape.set_aside_outliers`).
    rival : Comparison or None
        The comparison with the rival shapes when a rival fits this one profile clearly
        better than its circle (a real profiler's smooth shape error makes a conic do so on
        most profiles): it never rejects the profile, and only a majority of such profiles
        puts the sphere in doubt (:meth:`.target.SphereTarget.model_doubt`).
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    circle: CircleFit
    points: FloatArray
    n_effective: float
    rival: Comparison | None = None

    def record(self) -> SampleFit:
        """The plain record kept in the result."""
        return SampleFit(
            self.index, self.stamp_ns, self.T_base_flange, self.points, self.circle.centre_xz
        )
