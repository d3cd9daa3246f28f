"""Typed records shared by every stage of the pipeline.

All arrays are float64 in SI units (metres, radians); stamps are integer nanoseconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .joint_calibration import KinematicIdentifiability
    from .kinematics import KinematicCorrections
    from .selfcheck import SelfCheck
    from .targets.base import ResultSection

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Profile:
    """One laser profile as received.

    Attributes
    ----------
    stamp_ns : int
        Acquisition stamp, ns.
    points : ndarray, shape (N, 3)
        Points in the sensor frame, m. The laser plane is x-z, so y is ~0.
        May still hold NaN/Inf (REP 117); cleaning drops them.
    frame_id : str
        Sensor frame id from the message header.
    """

    stamp_ns: int
    points: FloatArray
    frame_id: str = "laser"


@dataclass(frozen=True)
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


@dataclass(frozen=True)
class Sample:
    """A profile paired with the flange pose interpolated at its stamp.

    Attributes
    ----------
    index : int
        Index of the profile in the input stream (stable across stages, for reports).
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
    points : ndarray, shape (N, 3)
        Sensor-frame points, m.
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    points: FloatArray


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


@dataclass(frozen=True)
class EllipseFit:
    """A RANSAC ellipse fitted to one profile in the sensor x-z plane.

    Attributes
    ----------
    centre_xz : ndarray, shape (2,)
        Ellipse centre (x_c, z_c) in the sensor frame, m (paper eq. 5).
    conic : ndarray, shape (6,)
        (A, B, C, D, E, F) of A x^2 + B xz + C z^2 + D x + E z + F = 0, in m units,
        scaled so that F = 1 when F is not ~0 (paper eq. 4).
    semi_axes : ndarray, shape (2,)
        Semi-major and semi-minor axis lengths, m.
    inliers : ndarray of bool, shape (N,)
        Inlier mask over the cleaned points handed to the fit.
    coverage_rad : float
        Angular extent of the inlier arc in the ellipse's parametric angle, rad.
    rms_m : float
        RMS algebraic-to-geometric residual of the inliers, m.
    """

    centre_xz: FloatArray
    conic: FloatArray
    semi_axes: FloatArray
    inliers: BoolArray
    coverage_rad: float
    rms_m: float


@dataclass(frozen=True)
class Cylinder:
    """A cylinder in the base frame.

    Attributes
    ----------
    point : ndarray, shape (3,)
        A point on the axis, m (the one closest to the base origin).
    direction : ndarray, shape (3,)
        Unit axis direction.
    radius : float
        m.
    """

    point: FloatArray
    direction: FloatArray
    radius: float


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
    points : ndarray, shape (K, 3)
        The points the target's model used, sensor frame, m (e.g. the ellipse inliers, the
        points of the two V lines).
    feature_xz : ndarray, shape (2,)
        The profile's feature point in the sensor x-z plane, m: the point of the profile that
        the target's paper method uses (e.g. the ellipse centre, the V corner).
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    points: FloatArray
    feature_xz: FloatArray


@dataclass
class CalibrationResult:
    """The outcome of a calibration, written to files in one place (``linelaser_calib.io``).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        The hand-eye (the paper's T_EL).
    target : ResultSection
        The target's part of the result (e.g. the fitted cylinder, the known point), base
        frame; see :class:`linelaser_calib.core.targets.base.ResultSection`.
    method : str
        ``paper`` or ``default`` (maximum likelihood).
    samples_used : list of int
        Profile indices that entered the final solve.
    samples_rejected : list of Rejection
    rms_residual_m : float
        RMS residual of the final cost, m (what it measures: ``target.residual_kind``).
    sample_residuals_m : dict of int to float
        Per-sample RMS residual, m, keyed by profile index.
    uncertainty_translation_m, uncertainty_rotation_rad : ndarray, shape (3,) or None
        1-sigma of the hand-eye translation (m) and rotation (rad, small angles about the
        sensor-frame axes), when the method estimates it.
    warnings : list of str
    history : dict of str to list of float
        Convergence traces for reports (e.g. ``pso_best``, ``galm_phi``, ``refine_cost``).
    sample_fits : list of SampleFit
        The fitted samples the final solve used (not written to result files).
    clock_offset_s : float
        Offset added to the profile stamps to pair them with the poses, s.
    clock_offset_estimated : bool
        True when that offset was estimated from the data (continuous scanning).
    clock_offset_live_s, clock_offset_live_sigma_s : float or None
        The collector's live estimate of the clock offset and its 1σ, s (continuous
        scanning through the nodes); None when there is none.
    parent_frame, child_frame, base_frame : str
        Frame ids: flange, sensor and robot base.
    kinematics : KinematicCorrections or None
        The robot's kinematic corrections estimated with the hand-eye (joint calibration).
    identifiability : KinematicIdentifiability or None
        Which kinematic parameters the data determined (joint calibration).
    self_check : SelfCheck or None
        The default method's self-check (:mod:`linelaser_calib.core.selfcheck`): accuracy in
        use, halves, the model's and the widened 1σ; the uncertainty above is its widened one.
    placement_sections : list of ResultSection
        The target in each further recording of a joint calibration (same order as given),
        solved with the corrected poses (not written to result files).
    """

    T_flange_sensor: FloatArray
    target: ResultSection
    method: str
    samples_used: list[int]
    samples_rejected: list[Rejection]
    rms_residual_m: float
    sample_residuals_m: dict[int, float] = field(default_factory=dict)
    uncertainty_translation_m: FloatArray | None = None
    uncertainty_rotation_rad: FloatArray | None = None
    warnings: list[str] = field(default_factory=list)
    history: dict[str, list[float]] = field(default_factory=dict)
    sample_fits: list[SampleFit] = field(default_factory=list)
    clock_offset_s: float = 0.0
    clock_offset_estimated: bool = False
    clock_offset_live_s: float | None = None
    clock_offset_live_sigma_s: float | None = None
    parent_frame: str = "tool0"
    child_frame: str = "laser"
    base_frame: str = "base_link"
    kinematics: KinematicCorrections | None = None
    identifiability: KinematicIdentifiability | None = None
    self_check: SelfCheck | None = None
    placement_sections: list[ResultSection] = field(default_factory=list)
