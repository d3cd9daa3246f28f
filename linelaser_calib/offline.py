"""Offline calibration of a rosbag2 recording: read the bag, run the one pipeline."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.pipeline import PipelineConfig, estimate_clock_offset, run_pipeline
from linelaser_calib.core.targets.base import Progress
from linelaser_calib.core.types import CalibrationResult
from linelaser_calib.io.bags import BagContents, read_bag


@dataclass
class OfflineRun:
    """A calibration of one bag: the result and what was read."""

    result: CalibrationResult
    bag: BagContents


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
) -> OfflineRun:
    """Calibrate from a bag holding profiles (PointCloud2) and flange poses (PoseStamped).

    Parameters
    ----------
    path : str or Path
        Bag directory, its .mcap file, or a collector session directory.
    config : PipelineConfig
    profile_topic, pose_topic : str, optional
        Auto-detected by message type when there is exactly one topic of each type.
    flange_frame : str
        Frame id of the flange (PoseStamped does not carry it).
    estimate_offset : bool
        Estimate the clock offset between profile and pose stamps (continuous scanning,
        :func:`~linelaser_calib.core.pipeline.estimate_clock_offset`), starting from the
        configured one.
    progress : callable, optional
        Called as ``progress(stage, done, total)``.

    Raises
    ------
    CalibrationError
        Bag, pairing, data or solver problems (e.g. every profile empty), with a message
        saying what to do.
    """
    bag = read_bag(
        path,
        profile_topic=profile_topic,
        pose_topic=pose_topic,
        progress=lambda done, total: progress("reading", done, total),
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
        offset = estimate_clock_offset(bag.profiles, bag.poses, config)
        config = replace(config, pairing=replace(config.pairing, clock_offset_s=offset))
        progress("clock offset", 1, 1)
    result = run_pipeline(bag.profiles, bag.poses, config, progress)
    result.clock_offset_estimated = estimate_offset
    result.parent_frame = flange_frame
    result.child_frame = bag.sensor_frame
    result.base_frame = bag.base_frame
    if bag.skipped:
        reasons = sorted({s.reason for s in bag.skipped})
        result.warnings.append(
            f"{len(bag.skipped)} malformed messages were skipped: {'; '.join(reasons[:3])}"
        )
    return OfflineRun(result, bag)
