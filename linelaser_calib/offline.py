"""Offline calibration of a rosbag2 recording: read the bag, run the one pipeline."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from linelaser_calib.core.errors import DegenerateError, InputError, PairingError
from linelaser_calib.core.latency import ClockProbe
from linelaser_calib.core.offset_search import OFFSET_COSTS, OFFSET_TRIALS, search_clock_offset
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import (
    Extracted,
    PipelineConfig,
    calibrate_paired,
    pair_recording,
)
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.pose_track import PoseTrack
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.joint_calibration import JointCalibrationConfig, KinematicSetup
from linelaser_calib.core.robot.kinematics import KinematicModel
from linelaser_calib.core.targets.base import (
    AdviceScan,
    Progress,
    placement_adviser,
    rejection_digest,
)
from linelaser_calib.core.types import Rejection, Sample
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


@dataclass(frozen=True)
class Recording:
    """A recording to calibrate from and how to read it.

    Attributes
    ----------
    path : str or Path
        Bag directory, its .mcap file, or a collector session directory.
    profile_topic, pose_topic : str, optional
        Auto-detected by message type when there is exactly one topic of each type.
    pose_source : PoseSource
        Where the flange poses come from (:data:`~linelaser_calib.io.pose_sources.POSE_SOURCES`).
    base_frame : str
        The robot base frame: the start of the TF chain; with PoseStamped poses in another
        frame (UR's ``base``) a warning says what that means.
    flange_frame : str
        Frame id of the flange (PoseStamped does not carry it; the end of the TF chain).
    joint_state_topic : str, optional
    model : KinematicModel, optional
        The robot model of the ``joint_states`` source.
    invalid_values_m : tuple of float
        Depths z, m, that the profiler sends for no return, besides NaN and +-Inf.
    """

    path: str | Path
    profile_topic: str | None = None
    pose_topic: str | None = None
    pose_source: PoseSource = PoseSource.POSE
    base_frame: str = "base_link"
    flange_frame: str = "tool0"
    joint_state_topic: str | None = None
    model: KinematicModel | None = None
    invalid_values_m: tuple[float, ...] = ()

    def read(self, sync_tolerance_s: float, progress: Progress) -> tuple[BagContents, FlangePoses]:
        """The bag's profiles and flange poses (a joint-state source looks poses up within
        ``sync_tolerance_s``, s); refuses a bag without a valid point."""
        refuse_pose_topic(self.pose_source, self.pose_topic)
        bag = read_bag(
            self.path,
            profile_topic=self.profile_topic,
            pose_topic=self.pose_topic,
            progress=lambda done, total: progress("reading", done, total),
            read_poses=self.pose_source is PoseSource.POSE,
            invalid_values_m=self.invalid_values_m,
        )
        request = PoseRequest(
            self.base_frame,
            self.flange_frame,
            sync_tolerance_s,
            self.model,
            self.joint_state_topic,
        )
        flange_poses = POSE_SOURCES[self.pose_source](bag, request)
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
        """Another placement's paired samples, joint states and pairing rejections (the
        recording at ``path``, read like this one), checked against the first recording
        (same sensor frame and robot model)."""
        bag, flange_poses = replace(self, path=path).read(config.pairing.sync_tolerance_s, _silent)
        if bag.sensor_frame != first.sensor_frame:
            raise InputError(
                f"{bag.path} holds profiles of the sensor frame {bag.sensor_frame!r} and "
                f"{first.path} of {first.sensor_frame!r}: recordings calibrated together must "
                "come from the same sensor on the same arm"
            )
        assert self.model is not None
        setup = _setup(flange_poses, self.model, config, kinematic_calibration)
        paired = pair_profiles(bag.profiles, flange_poses.poses, config.pairing)
        if not paired.samples:
            raise PairingError(f"{bag.path}: " + paired.explain_nothing_paired(config.pairing))
        return paired.samples, setup, paired.rejected


def calibrate_bag(
    recording: Recording | str | Path,
    config: PipelineConfig,
    *,
    estimate_offset: bool = False,
    progress: Progress = _silent,
    kinematic_calibration: JointCalibrationConfig | None = None,
    placements: Sequence[str | Path] = (),
) -> OfflineRun:
    """Calibrate from a bag holding profiles (PointCloud2) and flange poses (any source).

    Parameters
    ----------
    recording : Recording, or str or Path
        The recording and how to read it; a path alone reads it with the defaults.
    config : PipelineConfig
    estimate_offset : bool
        Estimate the clock offset between profile and pose stamps (continuous scanning,
        :func:`~linelaser_calib.core.offset_search.search_clock_offset`), starting from the
        configured one.
    progress : callable, optional
        Called as ``progress(stage, done, total)``.
    kinematic_calibration : JointCalibrationConfig, optional
        With the ``joint_states`` source: estimate the identifiable kinematic corrections
        together with the hand-eye (the result's ``kinematics``); None keeps the model
        nominal.
    placements : sequence of str or Path
        Further recordings of the same arm and sensor, each of another placement of the
        target, read and paired like ``recording``, for a joint calibration from all of them
        (the recording's ``model`` and ``kinematic_calibration`` given): one hand-eye and one
        set of kinematic corrections. The result's target section and statistics are those
        of ``recording``.

    Raises
    ------
    CalibrationError
        Bag, pairing, data or solver problems (e.g. every profile empty), with a message
        saying what to do.
    """
    reading = recording if isinstance(recording, Recording) else Recording(recording)
    if placements and (reading.model is None or kinematic_calibration is None):
        raise InputError(
            f"{len(placements) + 1} recordings are calibrated together only by the joint "
            "kinematic calibration ({setting:kinematics} MODEL, without "
            "{setting:nominal_kinematics}): give one recording, or the robot model"
        )
    bag, flange_poses = reading.read(config.pairing.sync_tolerance_s, progress)
    trace: list[tuple[float, float]] = []
    extracted: Extracted | None = None
    if estimate_offset:
        offset, extracted = search_clock_offset(
            bag.profiles, flange_poses.poses, config, progress=progress, trace=trace
        )
        config = replace(config, pairing=replace(config.pairing, clock_offset_s=offset))
    others = []
    unpaired = []
    if kinematic_calibration is not None and reading.model is not None:
        setup = _setup(flange_poses, reading.model, config, kinematic_calibration)
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
    paired = pair_recording(bag.profiles, flange_poses.poses, config, progress)
    probe = ClockProbe.of([s.stamp_ns for s in paired.samples], flange_poses.poses, config.pairing)
    # The pose stream is read no more: released before the solve (9 MB on a 1,600-profile
    # ur_scancontrol recording of 141,912 poses), the run keeps its description.
    bag = replace(bag, poses=PoseTrack.empty(bag.base_frame))
    flange_poses = replace(flange_poses, poses=PoseTrack.empty(flange_poses.base_frame))
    result = calibrate_paired(
        paired.samples,
        probe,
        config,
        paired.rejected,
        paired.notes,
        progress,
        others,
        extracted,
        diagnose_clock=not estimate_offset,
    )
    result.warnings.extend(unpaired)
    result.clock_offset_estimated = estimate_offset
    finite = sorted((t, c) for t, c in trace if math.isfinite(c))
    if finite:
        result.history[OFFSET_TRIALS] = [t for t, _ in finite]
        result.history[OFFSET_COSTS] = [c for _, c in finite]
    result.parent_frame = reading.flange_frame
    result.child_frame = bag.sensor_frame
    result.base_frame = flange_poses.base_frame
    result.warnings.extend(flange_poses.warnings)
    joint = config.kinematics
    adviser = placement_adviser(config.target_impl)
    if joint is not None and result.kinematics is not None and adviser is not None:
        placed = [adviser.placement_of(s) for s in [result.target, *result.placement_sections]]
        if None not in placed and len(placed) == len(others) + 1:
            scans: list[AdviceScan] = [
                ([bag.profiles[i] for i in result.samples_used], joint.states, placed[0]),
                *(
                    (samples, setup.states, p)
                    for (samples, setup), p in zip(others, placed[1:], strict=True)
                ),
            ]
            result.warnings.append(
                adviser.advise(
                    scans,
                    result.kinematics.apply(joint.model),
                    result.T_flange_sensor,
                    joint.clock_offset_s,
                )
            )
    if bag.skipped:
        reasons = sorted({s.reason for s in bag.skipped})
        result.warnings.append(
            f"{len(bag.skipped)} malformed messages were skipped: {'; '.join(reasons[:3])}"
        )
    return OfflineRun(result, bag, flange_poses)


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
            "the kinematic calibration needs the joint states: use {setting:pose_source} "
            "joint_states"
        )
    return KinematicSetup(model, states, config.pairing.clock_offset_s, kinematic_calibration)


def bag_samples(
    path: str | Path,
    pairing: PairingConfig,
    *,
    profile_topic: str | None = None,
    pose_topic: str | None = None,
    rejected: list[Rejection] | None = None,
) -> list[Sample]:
    """The paired samples of a bag or session (e.g. exploratory scans to plan from); the
    profiles that did not pair are appended to ``rejected`` (when given).

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
    if rejected is not None:
        rejected.extend(paired.rejected)
    return paired.samples
