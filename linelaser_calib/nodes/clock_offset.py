"""The live profile-to-pose clock offset of the collector's ``continuous`` mode, without ROS.

:class:`ClockOffsetTracker` gathers batches of stored samples with the flange poses around
them, the node estimates the offset of each batch outside the receive path, and the tracker
keeps the mean, its 1σ and whether it drifts; :func:`offset_values` are its diagnostic
values.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.offset_search import search_clock_offset
from linelaser_calib.core.pairing import NS_PER_S, PairingConfig
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.settings import Front, render

#: 1σ of one batch estimate's rounding (its search stops at 0.1 ms), s: the least scatter.
OFFSET_RESOLUTION_S = 1e-4 / np.sqrt(12.0)


#: A clock offset step smaller than this is never called a drift, s.
DRIFT_FLOOR_S = 0.5e-3


@dataclass(frozen=True)
class OffsetEstimate:
    """The live profile-to-pose clock offset: what is added to profile stamps, s.

    Attributes
    ----------
    offset_s : float
        Mean of the batch estimates, s.
    sigma_s : float or None
        1σ of that mean (batch scatter, at least the search's resolution, over the square
        root of their count), s; None before two batches.
    batches : int
        Batch estimates so far.
    latest_s : float
        The newest batch estimate, s.
    """

    offset_s: float
    sigma_s: float | None
    batches: int
    latest_s: float


class ClockOffsetTracker:
    """Estimate the profile-to-pose clock offset live, batch by batch (``continuous`` mode).

    Samples are kept at most ``samples_per_batch`` per ``period_s`` of stamps, evenly
    spaced, with the flange poses around them. When the pose stream has passed the end of a
    period, :meth:`take_batch` hands out the batch; the node runs
    :func:`~linelaser_calib.core.offset_search.search_clock_offset` on it (seconds of CPU,
    outside the receive path) and reports the result with :meth:`add_estimate`, which
    tells when the offset drifts.

    Parameters
    ----------
    config : PipelineConfig
        The pipeline settings; ``pairing.clock_offset_s`` is the search's centre.
    period_s : float
        Stamp span of each batch, s.
    samples_per_batch : int
    half_range_s : float
        Half-width of the offset search, s (as
        :func:`~linelaser_calib.core.offset_search.search_clock_offset`).
    delay_s : float
        Longest delay from a sample's stamp to its :meth:`add_sample` (pairing, storing), s:
        the poses that far back are kept before the first batch starts.
    """

    def __init__(
        self,
        config: PipelineConfig,
        period_s: float,
        samples_per_batch: int = 30,
        half_range_s: float = 0.05,
        delay_s: float = 2.0,
    ) -> None:
        self.config = config
        self.half_range_s = half_range_s
        self.estimates: list[float] = []
        self.drifting = False
        self.failures = 0
        self.last_failure = ""
        self._period_ns = round(period_s * NS_PER_S)
        self._spacing_ns = self._period_ns // samples_per_batch
        self._margin_ns = round(
            (half_range_s + config.pairing.sync_tolerance_s + abs(config.pairing.clock_offset_s))
            * NS_PER_S
        )
        self._delay_ns = round(delay_s * NS_PER_S)
        self._start: int | None = None
        self._profiles: list[Profile] = []
        self._poses: deque[FlangePose] = deque()

    def add_pose(self, pose: FlangePose) -> None:
        """Keep a flange pose (those that the current or a coming batch may need)."""
        poses = self._poses
        if poses and pose.stamp_ns <= poses[-1].stamp_ns:
            return
        poses.append(pose)
        if self._start is None:
            cut = pose.stamp_ns - self._delay_ns - self._margin_ns
        else:
            cut = self._start - self._margin_ns
        while poses[0].stamp_ns < cut:
            poses.popleft()

    def add_sample(self, profile: Profile) -> None:
        """Offer a stored sample's profile (stamped on the profile clock)."""
        stamp = profile.stamp_ns
        if self._start is None:
            self._start = stamp
        if stamp >= self._start + self._period_ns:
            return
        if not self._profiles or stamp >= self._profiles[-1].stamp_ns + self._spacing_ns:
            self._profiles.append(profile)

    def take_batch(self) -> tuple[list[Profile], list[FlangePose]] | None:
        """The batch of a finished period (and start the next), or None."""
        if self._start is None or not self._poses:
            return None
        end = self._start + self._period_ns
        if self._poses[-1].stamp_ns < end + self._margin_ns:
            return None
        batch = self._profiles, list(self._poses)
        self._start = end
        self._profiles = []
        while self._poses[0].stamp_ns < end - self._margin_ns:
            self._poses.popleft()
        return batch

    def estimate_batch(self, profiles: list[Profile], poses: list[FlangePose]) -> float | str:
        """Run the offline estimate on one batch; the offset (s), or why it failed."""
        if len(profiles) < self.config.target_config.min_samples:
            return f"only {len(profiles)} samples in the batch"
        try:
            return float(search_clock_offset(profiles, poses, self.config, self.half_range_s)[0])
        except CalibrationError as err:
            return render(str(err), Front.NODE)

    def add_estimate(self, outcome: float | str) -> str | None:
        """Record one batch's outcome; returns a warning when the offset drifts.

        The offset drifts when the new batch estimate is further from the mean of the
        earlier ones than three times their scatter (and more than ``DRIFT_FLOOR_S``).
        """
        if isinstance(outcome, str):
            self.failures += 1
            self.last_failure = outcome
            return None
        earlier = np.array(self.estimates)
        self.estimates.append(outcome)
        if len(earlier) < 2:
            return None
        scatter = float(np.std(earlier, ddof=1)) * np.sqrt(1.0 + 1.0 / len(earlier))
        step = outcome - float(np.mean(earlier))
        self.drifting = abs(step) > max(3.0 * scatter, DRIFT_FLOOR_S)
        if not self.drifting:
            return None
        return (
            f"the profile-to-pose clock offset drifts: the latest batch gives "
            f"{outcome * 1e3:+.2f} ms, the {len(earlier)} before it "
            f"{float(np.mean(earlier)) * 1e3:+.2f} ms (scatter {scatter * 1e3:.2f} ms); "
            "check the driver's time stamping (a clock that drifts needs a time sync)"
        )

    @property
    def estimate(self) -> OffsetEstimate | None:
        """The offset so far, or None before the first batch."""
        if not self.estimates:
            return None
        values = np.array(self.estimates)
        sigma = float(np.std(values, ddof=1) / np.sqrt(len(values))) if len(values) >= 2 else None
        return OffsetEstimate(float(np.mean(values)), sigma, len(values), float(values[-1]))


def offset_values(estimate: OffsetEstimate) -> dict[str, str]:
    """Diagnostic values of the live clock offset (ms, labelled)."""
    sigma = "n/a (needs 2 batches)" if estimate.sigma_s is None else f"{estimate.sigma_s * 1e3:.3f}"
    return {
        "clock offset (ms)": f"{estimate.offset_s * 1e3:+.3f}",
        "clock offset 1 sigma (ms)": sigma,
        "clock offset batches": str(estimate.batches),
        "clock offset latest batch (ms)": f"{estimate.latest_s * 1e3:+.3f}",
    }


def offset_message(pairing: PairingConfig, estimate: OffsetEstimate | None) -> list[float]:
    """The data of the collector's ``linelaser_calib/clock_offset`` message: the clock offset
    it pairs with, the live estimate, its 1σ (s; NaN where none yet) and the batches, then
    the rest of its pairing: sync tolerance (s), speed limits (m/s, rad/s), speed window (s)."""
    if estimate is None:
        head = [pairing.clock_offset_s, math.nan, math.nan, 0.0]
    else:
        sigma = math.nan if estimate.sigma_s is None else estimate.sigma_s
        head = [pairing.clock_offset_s, estimate.offset_s, sigma, float(estimate.batches)]
    return [
        *head,
        pairing.sync_tolerance_s,
        pairing.max_linear_speed_m_s,
        pairing.max_angular_speed_rad_s,
        pairing.speed_window_s,
    ]


def pairing_of_message(data: list[float]) -> PairingConfig | None:
    """The collector's pairing from the data of :func:`offset_message` (None before one
    arrived, or from a collector that does not send it)."""
    if len(data) != 8:
        return None
    offset, _, _, _, tolerance, linear, angular, window = data
    return PairingConfig(
        sync_tolerance_s=tolerance,
        clock_offset_s=offset,
        max_linear_speed_m_s=linear,
        max_angular_speed_rad_s=angular,
        speed_window_s=window,
    )
