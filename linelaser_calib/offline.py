"""Offline calibration of a rosbag2 recording: read the bag, run the one pipeline."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.pipeline import PipelineConfig, Progress, run_pipeline
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
    result = run_pipeline(bag.profiles, bag.poses, config, progress)
    result.parent_frame = flange_frame
    result.child_frame = bag.sensor_frame
    result.base_frame = bag.base_frame
    if bag.skipped:
        reasons = sorted({s.reason for s in bag.skipped})
        result.warnings.append(
            f"{len(bag.skipped)} malformed messages were skipped: {'; '.join(reasons[:3])}"
        )
    return OfflineRun(result, bag)
