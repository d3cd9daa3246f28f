"""What a bag holds, for ``linelaser-calib info``."""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from linelaser_calib.io.bags.read import bag_parts, read_bag, summarise
from linelaser_calib.io.bags.records import BagContents, TopicSummary
from linelaser_calib.io.errors import BagError


class PointCount(NamedTuple):
    """Valid points per profile: minimum, median and maximum over the profiles."""

    min: int
    median: float
    max: int


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds, for ``linelaser-calib info``.

    Attributes
    ----------
    path : Path
    topics : list of TopicSummary
    start_ns, end_ns : int or None
        Log times of the first and last message, ns; None for an empty bag.
    contents : BagContents or None
        The decoded profiles and poses; None when they could not be read (see ``problem``).
    problem : str or None
        Why the profiles and poses could not be read (e.g. ambiguous topics).
    points_per_profile : PointCount or None
        Valid points per profile; None without profiles.
    """

    path: Path
    topics: list[TopicSummary]
    start_ns: int | None
    end_ns: int | None
    contents: BagContents | None
    problem: str | None
    points_per_profile: PointCount | None


def bag_info(
    path: str | Path, *, profile_topic: str | None = None, pose_topic: str | None = None
) -> BagInfo:
    """Summarise a bag: topics, time span, profiles, poses and points per profile.

    A bag whose topics cannot be chosen (ambiguous, missing) still gets its topic list, with
    the reason in ``problem``.

    Raises
    ------
    BagError
        If the bag does not exist or cannot be opened at all.
    """
    bag = Path(path)
    summary = summarise(bag, bag_parts(bag))
    try:
        contents: BagContents | None = read_bag(
            bag, profile_topic=profile_topic, pose_topic=pose_topic
        )
        problem = None
    except BagError as err:
        contents, problem = None, str(err)
    counts = None
    if contents is not None:
        sizes = [len(p.points) for p in contents.profiles]
        counts = PointCount(min(sizes), float(np.median(sizes)), max(sizes))
    return BagInfo(bag, summary.topics, summary.start_ns, summary.end_ns, contents, problem, counts)


def _utc(stamp_ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(stamp_ns / 1e9, tz=datetime.timezone.utc)
    return moment.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


def format_bag_info(info: BagInfo) -> str:
    """Human-readable text of :func:`bag_info`'s result (times in UTC and s, labelled)."""
    lines = [f"bag: {info.path}"]
    if info.start_ns is None or info.end_ns is None:
        lines.append("time: empty bag (no messages)")
    else:
        duration_s = (info.end_ns - info.start_ns) / 1e9
        lines.append(
            f"time: {_utc(info.start_ns)} to {_utc(info.end_ns)} UTC, duration {duration_s:.3f} s"
        )
    lines.append("topics:")
    width = max((len(t.topic) for t in info.topics), default=0)
    lines += [f"  {t.topic:<{width}}  {t.msgtype}  {t.msgcount} msgs" for t in info.topics]
    contents = info.contents
    if contents is None:
        lines.append(f"profiles and poses: not readable: {info.problem}")
        return "\n".join(lines)
    lines.append(
        f"profiles: {len(contents.profiles)} on {contents.profile_topic} "
        f"(frame {contents.sensor_frame})"
    )
    if info.points_per_profile is not None:
        n = info.points_per_profile
        lines.append(f"valid points per profile: min {n.min}, median {n.median:g}, max {n.max}")
    lines.append(
        f"flange poses: {len(contents.poses)} on {contents.pose_topic} "
        f"(frame {contents.base_frame})"
    )
    if contents.skipped:
        first = contents.skipped[0]
        lines.append(
            f"skipped messages: {len(contents.skipped)} (first: {first.topic} at "
            f"{first.stamp_ns} ns: {first.reason})"
        )
    return "\n".join(lines)
