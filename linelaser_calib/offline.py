"""Offline calibration of a rosbag2 recording: read the bag, run the one pipeline."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from linelaser_calib.core.errors import DegenerateError, InputError, PairingError
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, estimate_clock_offset, run_pipeline
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.joint_calibration import JointCalibrationConfig, KinematicSetup
from linelaser_calib.core.robot.kinematics import JointStates, KinematicModel, forward_kinematics
from linelaser_calib.core.targets.base import Progress, rejection_digest
from linelaser_calib.core.targets.cylinder.advice import placement_advice, thinned
from linelaser_calib.core.targets.cylinder.identifiability import CylinderScan
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FloatArray, Profile, Rejection, Sample
from linelaser_calib.io.bags import BagContents, read_bag
from linelaser_calib.io.pose_sources import (
    POSE_SOURCES,
    FlangePoses,
    PoseRequest,
    refuse_pose_topic,
)


@dataclass
class OfflineRun:
    """A calibration of one bag: the result, what was read and where the poses came from."""

    result: CalibrationResult
    bag: BagContents
    poses: FlangePoses


def _silent(stage: str, done: int, total: int) -> None:
    """No progress output."""


def calibrate_bag(
    path: str | Path,
    config: PipelineConfig,
    *,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
    flange_frame: str = "tool0",
    estimate_offset: bool = False,
    progress: Progress = _silent,
    pose_source: PoseSource = PoseSource.POSE,
    base_frame: str = "base_link",
    invalid_values_m: tuple[float, ...] = (),
    joint_state_topic: str | None = None,
    model: KinematicModel | None = None,
    kinematic_calibration: JointCalibrationConfig | None = None,
    placements: Sequence[str | Path] = (),
) -> OfflineRun:
    """Calibrate from a bag holding profiles (PointCloud2) and flange poses (any source).

    Parameters
    ----------
    path : str or Path
        Bag directory, its .mcap file, or a collector session directory.
    config : PipelineConfig
    profile_topic, pose_topic : str, optional
        Auto-detected by message type when there is exactly one topic of each type.
    flange_frame : str
        Frame id of the flange (PoseStamped does not carry it; the end of the TF chain).
    estimate_offset : bool
        Estimate the clock offset between profile and pose stamps (continuous scanning,
        :func:`~linelaser_calib.core.pipeline.estimate_clock_offset`), starting from the
        configured one.
    progress : callable, optional
        Called as ``progress(stage, done, total)``.
    pose_source : PoseSource
        Where the flange poses come from (:data:`~linelaser_calib.io.pose_sources.POSE_SOURCES`).
    base_frame : str
        The robot base frame: the start of the TF chain; with PoseStamped poses in another
        frame (UR's ``base``) a warning says what that means.
    invalid_values_m : tuple of float
        Depths z, m, that the profiler sends for no return, besides NaN and +-Inf.
    joint_state_topic : str, optional
    model : KinematicModel, optional
        The robot model of the ``joint_states`` source.
    kinematic_calibration : JointCalibrationConfig, optional
        With the ``joint_states`` source: estimate the identifiable kinematic corrections
        together with the hand-eye (the result's ``kinematics``); None keeps the model
        nominal.
    placements : sequence of str or Path
        Further recordings of the same arm and sensor, each of another placement of the
        target, read and paired like ``path``, for a joint calibration from all of them
        (``model`` and ``kinematic_calibration`` given): one hand-eye and one set of
        kinematic corrections. The result's target section and statistics are those of
        ``path``.

    Raises
    ------
    CalibrationError
        Bag, pairing, data or solver problems (e.g. every profile empty), with a message
        saying what to do.
    """
    if placements and (model is None or kinematic_calibration is None):
        raise InputError(
            f"{len(placements) + 1} recordings are calibrated together only by the joint "
            "kinematic calibration (--kinematics MODEL, without --nominal-kinematics): give "
            "one recording, or the robot model"
        )
    request = PoseRequest(
        base_frame, flange_frame, config.pairing.sync_tolerance_s, model, joint_state_topic
    )
    reading = _Reading(profile_topic, pose_topic, pose_source, invalid_values_m, request)
    bag, flange_poses = reading.read(path, progress)
    if estimate_offset:
        progress("clock offset", 0, 1)
        offset = estimate_clock_offset(bag.profiles, flange_poses.poses, config)
        config = replace(config, pairing=replace(config.pairing, clock_offset_s=offset))
        progress("clock offset", 1, 1)
    others = []
    unpaired = []
    if kinematic_calibration is not None and model is not None:
        setup = _setup(flange_poses, model, config, kinematic_calibration)
        config = replace(config, kinematics=setup)
        for k, more in enumerate(placements, start=2):
            samples, more_setup, rejected = reading.placement(
                more, bag, config, kinematic_calibration
            )
            others.append((samples, more_setup))
            if rejected:
                unpaired.append(
                    f"recording {k} ({more}): {len(rejected)} of its "
                    f"{len(samples) + len(rejected)} profiles did not pair with a flange pose "
                    f"and were left out. {rejection_digest(rejected)}".rstrip()
                )
    result = run_pipeline(bag.profiles, flange_poses.poses, config, progress, others)
    result.warnings.extend(unpaired)
    result.clock_offset_estimated = estimate_offset
    result.parent_frame = flange_frame
    result.child_frame = bag.sensor_frame
    result.base_frame = flange_poses.base_frame
    result.warnings.extend(flange_poses.warnings)
    joint = config.kinematics
    section, corrections = result.target, result.kinematics
    if joint is not None and corrections is not None:
        # Imported here: other commands need no target loaded.
        from linelaser_calib.core.targets.cylinder import CylinderSection

        placed = [s for s in result.placement_sections if isinstance(s, CylinderSection)]
        if isinstance(section, CylinderSection) and len(placed) == len(others):
            result.warnings.append(
                advise_placements(
                    [bag.profiles[i] for i in result.samples_used],
                    joint.states,
                    corrections.apply(joint.model),
                    result.T_flange_sensor,
                    section.cylinder,
                    joint.clock_offset_s,
                    more=[
                        (samples, setup.states, p.cylinder)
                        for (samples, setup), p in zip(others, placed, strict=True)
                    ],
                )
            )
    if bag.skipped:
        reasons = sorted({s.reason for s in bag.skipped})
        result.warnings.append(
            f"{len(bag.skipped)} malformed messages were skipped: {'; '.join(reasons[:3])}"
        )
    return OfflineRun(result, bag, flange_poses)


def advise_placements(
    profiles: Sequence[Profile | Sample],
    states: JointStates,
    model: KinematicModel,
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
    clock_offset_s: float = 0.0,
    more: Sequence[tuple[Sequence[Profile | Sample], JointStates, Cylinder]] = (),
) -> str:
    """Whether another placement of the cylinder would determine more of the robot's
    kinematics, in words (:func:`~linelaser_calib.core.targets.cylinder.advice.placement_advice` on
    up to 30 points of each profile within 0.5 mm of the cylinder).

    Parameters
    ----------
    profiles : sequence of Profile or Sample
        The scans of one placement (stamps, sensor-frame points in m).
    states : JointStates
        The recording's joint states.
    model : KinematicModel
        The robot model (corrected where a joint calibration gave corrections).
    T_flange_sensor : ndarray, shape (4, 4)
    cylinder : Cylinder
        In the base frame, m.
    clock_offset_s : float
        Added to the profile stamps to pair them with the joint states, s.
    more : sequence of (profiles, JointStates, Cylinder)
        The placements scanned besides (a joint calibration of several recordings): each
        one's scans, joint states and cylinder; the advice is then whether one more adds.

    Raises
    ------
    InputError
        A model joint the states do not name, or a profile outside the joint-state stream.
    """
    setup = KinematicSetup(model, states, clock_offset_s)
    scans = [
        _advice_scan(
            scanned,
            KinematicSetup(model, scanned_states, clock_offset_s),
            T_flange_sensor,
            placed,
        )
        for scanned, scanned_states, placed in [(profiles, states, cylinder), *more]
    ]
    return placement_advice(model, scans, T_flange_sensor, setup.config).text()


def _advice_scan(
    profiles: Sequence[Profile | Sample],
    setup: KinematicSetup,
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
) -> CylinderScan:
    """One placement for the advice: its joint vectors and up to 30 points of each profile
    within 0.5 mm of its cylinder (mapped with ``setup``'s model)."""
    q = setup.joint_positions([p.stamp_ns for p in profiles])
    T = forward_kinematics(setup.model, q) @ T_flange_sensor
    points = []
    for profile, T_bs in zip(profiles, T, strict=True):
        x = profile.points[np.all(np.isfinite(profile.points), axis=1)]
        v = x @ T_bs[:3, :3].T + T_bs[:3, 3] - cylinder.point
        radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
        points.append(x[np.abs(np.linalg.norm(radial, axis=1) - cylinder.radius) < 5e-4])
    return thinned(CylinderScan(q, points, cylinder), 30)


def _setup(
    flange_poses: FlangePoses,
    model: KinematicModel,
    config: PipelineConfig,
    kinematic_calibration: JointCalibrationConfig,
) -> KinematicSetup:
    """The joint calibration's model and joint states of one recording."""
    states = flange_poses.joint_states
    if states is None:
        raise InputError(
            "the kinematic calibration needs the joint states: use --pose-source joint_states"
        )
    return KinematicSetup(model, states, config.pairing.clock_offset_s, kinematic_calibration)


@dataclass(frozen=True)
class _Reading:
    """How the recordings of one calibration are read (the same for each)."""

    profile_topic: str | None
    pose_topic: str | None
    pose_source: PoseSource
    invalid_values_m: tuple[float, ...]
    request: PoseRequest

    def read(self, path: str | Path, progress: Progress) -> tuple[BagContents, FlangePoses]:
        """The bag's profiles and flange poses; refuses a bag without a valid point."""
        refuse_pose_topic(self.pose_source, self.pose_topic)
        bag = read_bag(
            path,
            profile_topic=self.profile_topic,
            pose_topic=self.pose_topic,
            progress=lambda done, total: progress("reading", done, total),
            read_poses=self.pose_source is PoseSource.POSE,
            invalid_values_m=self.invalid_values_m,
        )
        flange_poses = POSE_SOURCES[self.pose_source](bag, self.request)
        if all(len(p.points) == 0 for p in bag.profiles):
            raise InputError(
                f"all {len(bag.profiles)} profiles on {bag.profile_topic} in {bag.path} are "
                "empty (no valid point, every return NaN/Inf): the sensor saw nothing. Check "
                "that the cylinder is within the sensor's measuring range and the laser is on, "
                "then record again"
            )
        return bag, flange_poses

    def placement(
        self,
        path: str | Path,
        first: BagContents,
        config: PipelineConfig,
        kinematic_calibration: JointCalibrationConfig,
    ) -> tuple[list[Sample], KinematicSetup, list[Rejection]]:
        """Another placement's paired samples, joint states and pairing rejections, checked
        against the first recording (same sensor frame and robot model)."""
        bag, flange_poses = self.read(path, _silent)
        if bag.sensor_frame != first.sensor_frame:
            raise InputError(
                f"{bag.path} holds profiles of the sensor frame {bag.sensor_frame!r} and "
                f"{first.path} of {first.sensor_frame!r}: recordings calibrated together must "
                "come from the same sensor on the same arm"
            )
        assert self.request.model is not None
        setup = _setup(flange_poses, self.request.model, config, kinematic_calibration)
        paired = pair_profiles(bag.profiles, flange_poses.poses, config.pairing)
        if not paired.samples:
            raise PairingError(f"{bag.path}: " + paired.explain_nothing_paired(config.pairing))
        return paired.samples, setup, paired.rejected


def bag_samples(
    path: str | Path,
    pairing: PairingConfig,
    *,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
) -> list[Sample]:
    """The paired samples of a bag or session (e.g. exploratory scans to plan from).

    Raises
    ------
    CalibrationError
        Bag problems, or no profile pairs with a pose.
    """
    bag = read_bag(path, profile_topic=profile_topic, pose_topic=pose_topic)
    paired = pair_profiles(bag.profiles, bag.poses, pairing)
    if not paired.samples:
        raise DegenerateError(
            f"no profile of {bag.path} pairs with a flange pose: "
            + paired.explain_nothing_paired(pairing)
        )
    return paired.samples
