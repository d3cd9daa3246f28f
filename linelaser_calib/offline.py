"""Offline calibration of a rosbag2 recording: read the bag, run the one pipeline."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.kinematics import KinematicModel
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, estimate_clock_offset, run_pipeline
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.targets.base import Progress
from linelaser_calib.core.types import CalibrationResult, Sample
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

    Raises
    ------
    CalibrationError
        Bag, pairing, data or solver problems (e.g. every profile empty), with a message
        saying what to do.
    """
    refuse_pose_topic(pose_source, pose_topic)
    bag = read_bag(
        path,
        profile_topic=profile_topic,
        pose_topic=pose_topic,
        progress=lambda done, total: progress("reading", done, total),
        read_poses=pose_source is PoseSource.POSE,
        invalid_values_m=invalid_values_m,
    )
    flange_poses = POSE_SOURCES[pose_source](
        bag,
        PoseRequest(
            base_frame, flange_frame, config.pairing.sync_tolerance_s, model, joint_state_topic
        ),
    )
    if all(len(p.points) == 0 for p in bag.profiles):
        raise InputError(
            f"all {len(bag.profiles)} profiles on {bag.profile_topic} in {bag.path} are empty "
            "(no valid point, every return NaN/Inf): the sensor saw nothing. Check that the "
            "cylinder is within the sensor's measuring range and the laser is on, then record "
            "again"
        )
    if estimate_offset:
        progress("clock offset", 0, 1)
        offset = estimate_clock_offset(bag.profiles, flange_poses.poses, config)
        config = replace(config, pairing=replace(config.pairing, clock_offset_s=offset))
        progress("clock offset", 1, 1)
    result = run_pipeline(bag.profiles, flange_poses.poses, config, progress)
    result.clock_offset_estimated = estimate_offset
    result.parent_frame = flange_frame
    result.child_frame = bag.sensor_frame
    result.base_frame = flange_poses.base_frame
    result.warnings.extend(flange_poses.warnings)
    if bag.skipped:
        reasons = sorted({s.reason for s in bag.skipped})
        result.warnings.append(
            f"{len(bag.skipped)} malformed messages were skipped: {'; '.join(reasons[:3])}"
        )
    return OfflineRun(result, bag, flange_poses)


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
