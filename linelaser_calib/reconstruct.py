"""Apply a calibration: every profile of a recording mapped into the base frame.

Each profile is paired with the flange pose at its stamp by the same pairing as
calibration (:func:`~linelaser_calib.core.pairing.pair_profiles`, same options), and its
valid points go to ``T_base_flange · T_flange_sensor · p``, with their intensity where the
profiles carry one; p corrected by what the calibration estimated of the sensor itself (the
along-line scale of a cylinder calibration). When the calibration holds
kinematic corrections, the flange poses come from the recording's joint states through
the corrected robot model instead of the recorded flange poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from linelaser_calib.core.errors import InputError, PairingError
from linelaser_calib.core.geometry import apply_transform
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import KinematicCorrections, KinematicModel
from linelaser_calib.core.types import FloatArray, Rejection
from linelaser_calib.io.bags import BagContents, read_bag, read_profile_intensities
from linelaser_calib.io.kinematics import load_model
from linelaser_calib.io.pose_sources import (
    POSE_SOURCES,
    FlangePoses,
    PoseRequest,
    refuse_pose_topic,
)


@dataclass(frozen=True)
class Reconstruction:
    """Profiles of a recording in the base frame.

    Attributes
    ----------
    clouds : list of (int, ndarray (N, 3))
        Per paired profile, in stamp order: its stamp (ns) and its points in the base frame
        (m).
    base_frame : str
    intensities : list of ndarray (N,), or None
        Per cloud, the intensity of each point; None when the profiles carry none.
    rejected : list of Rejection
        Profiles that could not be paired, with reasons.
    bag : BagContents
        What was read.
    pose_source : PoseSource
    poses : FlangePoses
        The flange poses used and where they came from.
    """

    clouds: list[tuple[int, FloatArray]]
    intensities: list[FloatArray] | None
    base_frame: str
    rejected: list[Rejection]
    bag: BagContents
    pose_source: PoseSource
    poses: FlangePoses

    @property
    def points(self) -> FloatArray:
        """Every point, shape (N, 3), m."""
        if not self.clouds:
            return np.zeros((0, 3))
        return np.concatenate([c for _, c in self.clouds])

    @property
    def intensity(self) -> FloatArray | None:
        """Every point's intensity, shape (N,), or None."""
        if self.intensities is None:
            return None
        return np.concatenate(self.intensities) if self.intensities else np.zeros(0)


def _check_frames(
    calibration: CalibrationResult, sensor: str, base: str, flange: str, path: Path
) -> None:
    pairs = [
        ("sensor", calibration.child_frame, sensor, "the profiles' header frame"),
        ("base", calibration.base_frame, base, "the flange poses' frame"),
        ("flange", calibration.parent_frame, flange, "the flange frame"),
    ]
    for what, expected, found, where in pairs:
        if expected and found and expected != found:
            raise InputError(
                f"the calibration's {what} frame is {expected!r} but {where} in {path} is "
                f"{found!r}: the calibration belongs to another setup. Use the calibration of "
                "this sensor and robot, or the matching frame option"
            )


def reconstruct_bag(
    path: str | Path,
    calibration: CalibrationResult,
    pairing: PairingConfig,
    *,
    kinematics: KinematicCorrections | None = None,
    pose_source: PoseSource = PoseSource.POSE,
    model: KinematicModel | None = None,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
    joint_state_topic: str | None = None,
    base_frame: str = "base_link",
    flange_frame: str = "tool0",
    invalid_values_m: tuple[float, ...] = (),
) -> Reconstruction:
    """Map every profile of a recording into the base frame with a calibration.

    Parameters
    ----------
    path : str or Path
        Bag directory, its .mcap file, or a collector session directory.
    calibration : CalibrationResult
        Its ``T_flange_sensor`` and frames are used.
    pairing : PairingConfig
    kinematics : KinematicCorrections, optional
        The calibration's kinematic corrections; the flange poses then come from the joint
        states through the corrected model (which ``model`` must not contradict).
    pose_source : PoseSource
        Without corrections: where the flange poses come from.
    model : KinematicModel, optional
        The robot model of the ``joint_states`` source.
    profile_topic, pose_topic, joint_state_topic : str, optional
    base_frame, flange_frame : str
        The ends of the ``tf`` chain; with ``tf`` or joint states the flange frame is
        checked against the calibration's.
    invalid_values_m : tuple of float
        Depths z, m, that the profiler sends for no return, besides NaN and +-Inf.

    Raises
    ------
    CalibrationError
        Bag problems, frames that differ from the calibration's, or no profile paired.
    """
    if kinematics is not None:
        if model is not None and model.name != kinematics.model:
            raise InputError(
                f"the calibration's kinematic corrections are for the model "
                f"{kinematics.model!r}, not {model.name!r} (--kinematics); leave --kinematics "
                "out or give the calibration's model"
            )
        base = model if model is not None else load_model(kinematics.model)
        model, pose_source = kinematics.apply(base), PoseSource.JOINT_STATES
    refuse_pose_topic(pose_source, pose_topic)
    bag = read_bag(
        path,
        profile_topic=profile_topic,
        pose_topic=pose_topic,
        read_poses=pose_source is PoseSource.POSE,
        invalid_values_m=invalid_values_m,
    )
    request = PoseRequest(
        base_frame, flange_frame, pairing.sync_tolerance_s, model, joint_state_topic
    )
    poses = POSE_SOURCES[pose_source](bag, request)
    flange = ""  # a PoseStamped does not name the flange
    if pose_source is PoseSource.TF:
        flange = flange_frame
    elif pose_source is PoseSource.JOINT_STATES and model is not None:
        flange = model.flange_frame
    _check_frames(calibration, bag.sensor_frame, poses.base_frame, flange, bag.path)
    paired = pair_profiles(bag.profiles, poses.poses, pairing)
    if not paired.samples:
        raise PairingError(paired.explain_nothing_paired(pairing))
    clouds = []
    for sample in paired.samples:
        T_base_sensor = sample.T_base_flange @ calibration.T_flange_sensor
        points = calibration.target.sensor_points(np.asarray(sample.points, dtype=np.float64))
        clouds.append((sample.stamp_ns, apply_transform(T_base_sensor, points)))
    by_stamp = read_profile_intensities(path, bag.profile_topic)
    intensities = None
    if by_stamp and all(
        s.stamp_ns in by_stamp and len(by_stamp[s.stamp_ns]) == len(s.points)
        for s in paired.samples
    ):
        intensities = [by_stamp[s.stamp_ns] for s in paired.samples]
    return Reconstruction(
        clouds, intensities, poses.base_frame, paired.rejected, bag, pose_source, poses
    )
