"""What the report draws and states, computed once from a result (no matplotlib here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.geometry import FloatArray, apply_transform
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.base import SurfaceMap, feature_residuals, surface_map

IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class ReportData:
    """A result and its residuals with the recorded flange poses.

    Attributes
    ----------
    result : CalibrationResult
    indices : ndarray of int, shape (M,)
        Profile index of each fitted sample the solve used.
    points_base : list of ndarray, shape (K_j, 3)
        Each sample's points in the base frame, m.
    distances_m : list of ndarray, shape (D_j,)
        Each sample's distances from the fitted target
        (:meth:`~linelaser_calib.core.targets.base.ResultSection.surface_distances`, recorded
        poses), m: one per point (signed, + outside) or one per sample (its feature point).
    feature_distances_m : ndarray, shape (M,), or None
        The paper's feature residual of each sample, m, where the target has one apart from
        ``distances_m``.
    surface : SurfaceMap or None
        All points (N = sum K_j) on the target's unrolled surface, where it has one.
    """

    result: CalibrationResult
    indices: IntArray
    points_base: list[FloatArray]
    distances_m: list[FloatArray]
    feature_distances_m: FloatArray | None
    surface: SurfaceMap | None

    @property
    def per_point(self) -> bool:
        """True when the distances are of the points (a surface), False when one per sample."""
        return any(len(d) > 1 for d in self.distances_m)

    @property
    def all_points_base(self) -> FloatArray:
        """Every sample's points (N, 3), base frame, m."""
        return np.concatenate(self.points_base) if self.points_base else np.zeros((0, 3))

    @property
    def all_distances_m(self) -> FloatArray:
        """Every distance (sum D_j,), m."""
        return np.concatenate(self.distances_m) if self.distances_m else np.zeros(0)

    @property
    def recorded_pose_rms_m(self) -> float:
        """RMS of all distances with the recorded poses, m (NaN without samples)."""
        values = self.all_distances_m
        return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def report_data(result: CalibrationResult) -> ReportData:
    """Map the result's sample fits into the base frame and measure their distances from the
    fitted target through its result section."""
    section = result.target
    fits = result.sample_fits
    T = result.T_flange_sensor
    points = [apply_transform(f.T_base_flange @ T, section.sensor_points(f.points)) for f in fits]
    stacked = np.concatenate(points) if points else np.zeros((0, 3))
    features = feature_residuals(section)
    return ReportData(
        result=result,
        indices=np.array([f.index for f in fits], dtype=np.intp),
        points_base=points,
        distances_m=[
            np.atleast_1d(section.surface_distances(f, f.T_base_flange @ T)) for f in fits
        ],
        feature_distances_m=None if features is None else features.feature_distances(fits, T),
        surface=surface_map(section, stacked) if len(stacked) else None,
    )
