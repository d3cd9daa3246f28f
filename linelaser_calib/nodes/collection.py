"""The collector's logic without ROS: pair live profiles with buffered flange poses, and count.

The ``collector`` node decodes messages and hands them to a :class:`LiveCollector`, which

1. buffers flange poses (:class:`~linelaser_calib.core.pairing.PoseBuffer`, ``pose_window_s``
   deep, reset when the pose clock jumps back further than that);
2. keeps each profile in a small waiting queue until the buffer holds every pose that can
   still change its pairing (``PoseBuffer.ready_for``), or until it has waited
   ``pose_window_s`` of wall time, then pairs it (``PoseBuffer.pair``);
3. offers each paired sample for validation (the node runs ``fit_sample``, the clean + ellipse
   stage, off the receive path), unless the collection mode, the ``min_sample_interval_s``
   rate limit or a full validation queue say to skip it;
4. decides whether a validated sample joins the session (:meth:`LiveCollector.admit`).

Every profile ends up counted exactly once: ``received == accepted + rejected + skipped +
pending``. Rejections (bad data) and skips (collector policy) are counted per reason; a
reason's key has its numbers replaced by ``#`` so that one kind of problem has one key, and
``on_new_reason`` is called the first time a key appears, so the node logs it once instead of
once per profile.
"""

from __future__ import annotations

import re
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from linelaser_calib.core.pairing import NS_PER_S, PairingConfig, PoseBuffer
from linelaser_calib.core.types import FlangePose, Profile, Rejection, Sample

#: Called with (reason key, full first message) the first time a reason key is counted.
ReasonLogger = Callable[[str, str], None]

_NUMBER = re.compile(r"(?<![A-Za-z_\d])[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")

#: Keys of the diagnostic values (see :meth:`LiveCollector.diagnostic_values`).
KEY_RECEIVED = "profiles received"
KEY_PAIRED = "profiles paired"
KEY_ACCEPTED = "samples accepted"
KEY_REJECTED = "profiles rejected"
KEY_SKIPPED = "profiles skipped"
KEY_PENDING = "profiles pending"
KEY_SESSION_SAMPLES = "session samples"
KEY_POSES_RECEIVED = "poses received"
KEY_POSES_REJECTED = "poses rejected"

SKIP_NOT_CAPTURED = "not captured (on_demand mode and no capture request pending)"
SKIP_INTERVAL = "within min_sample_interval_s of the previous sample"
SKIP_BACKLOG = "validation queue full (the collector cannot validate profiles this fast)"
SKIP_CLEARED = "received before the session was cleared"


class Mode(str, Enum):
    """Collection modes (the ``mode`` parameter)."""

    CONTINUOUS = "continuous"
    ON_DEMAND = "on_demand"


def reason_key(stage: str, reason: str) -> str:
    """``'stage: reason'`` with every number replaced by ``#``.

    ``reason_key('pairing', 'robot moving at 12.3 mm/s (limit 5.0 mm/s)')`` is
    ``'pairing: robot moving at # mm/s (limit # mm/s)'``; numbers inside names (``float32``,
    ``PointCloud2``) are kept.
    """
    return f"{stage}: {_NUMBER.sub('#', reason)}"


class ReasonCounter:
    """Counts per reason key, calling ``on_new_reason`` once per key."""

    def __init__(self, on_new_reason: ReasonLogger) -> None:
        self._counts: dict[str, int] = {}
        self._on_new_reason = on_new_reason

    def add(self, stage: str, reason: str) -> str:
        """Count one occurrence; returns its key."""
        key = reason_key(stage, reason)
        if key not in self._counts:
            self._counts[key] = 0
            self._on_new_reason(key, f"{stage}: {reason}")
        self._counts[key] += 1
        return key

    @property
    def total(self) -> int:
        """Occurrences of every reason."""
        return sum(self._counts.values())

    def counts(self) -> dict[str, int]:
        """Copy of the counts per key, most frequent first."""
        return dict(sorted(self._counts.items(), key=lambda kv: (-kv[1], kv[0])))


@dataclass(frozen=True)
class CollectorConfig:
    """Collector settings (SI units).

    Attributes
    ----------
    pairing : PairingConfig
        Sync tolerance, clock offset and speed limits of the pairing.
    pose_window_s : float
        Flange poses older than this behind the newest one are dropped, s; a profile waits at
        most this long (wall time) for the poses around its stamp.
    mode : Mode
        ``continuous``: every valid pair joins the session; ``on_demand``: only the first
        valid pair after each capture request.
    min_sample_interval_s : float
        A paired profile stamped less than this after the previous one offered for validation
        is skipped, s; 0 offers every paired profile.
    validation_queue_size : int
        Paired profiles waiting for validation; more are skipped (counted), never queued
        without bound.
    max_waiting_profiles : int
        Profiles waiting for poses; the oldest is paired early (and most likely rejected)
        when more arrive.
    """

    pairing: PairingConfig = field(default_factory=PairingConfig)
    pose_window_s: float = 2.0
    mode: Mode = Mode.CONTINUOUS
    min_sample_interval_s: float = 0.0
    validation_queue_size: int = 20
    max_waiting_profiles: int = 1000

    def __post_init__(self) -> None:
        horizon = max(self.pairing.sync_tolerance_s, self.pairing.speed_window_s)
        if not self.pose_window_s > horizon:
            raise ValueError(
                f"pose_window_s ({self.pose_window_s} s) must exceed the pairing horizon "
                f"({horizon} s, the larger of sync_tolerance_s and speed_window_s)"
            )
        if self.min_sample_interval_s < 0.0:
            raise ValueError(
                f"min_sample_interval_s must be >= 0 s, got {self.min_sample_interval_s}"
            )
        if self.validation_queue_size < 1 or self.max_waiting_profiles < 1:
            raise ValueError("validation_queue_size and max_waiting_profiles must be >= 1")


@dataclass(frozen=True)
class PendingSample:
    """A paired profile on its way through validation.

    Attributes
    ----------
    sample : Sample
        ``index`` is the profile's receive count (0-based).
    sensor_frame, base_frame : str
        Header frames of the profile and of the flange pose.
    generation : int
        Session generation at receive time (see :meth:`LiveCollector.clear`).
    """

    sample: Sample
    sensor_frame: str
    base_frame: str
    generation: int


@dataclass
class _Waiting:
    profile: Profile
    index: int
    received_s: float
    generation: int


class LiveCollector:
    """Pair live profiles with flange poses and account for every profile.

    Not thread-safe by itself: the node serialises calls with :attr:`lock`.

    Parameters
    ----------
    config : CollectorConfig
    on_new_reason : callable(key, message)
        Called the first time a rejection or skip reason appears (the node logs it).
    """

    def __init__(self, config: CollectorConfig, on_new_reason: ReasonLogger) -> None:
        self.config = config
        self.lock = threading.RLock()
        self.poses = PoseBuffer(config.pose_window_s)
        self.rejected = ReasonCounter(on_new_reason)
        self.skipped = ReasonCounter(on_new_reason)
        self.pose_rejected = ReasonCounter(on_new_reason)
        self.received = 0
        self.poses_received = 0
        self.paired = 0
        self.accepted = 0
        self.session_samples = 0
        self.generation = 0
        self.last_rejection = ""
        self._base_frame = ""
        self._waiting: deque[_Waiting] = deque()
        self._to_validate: deque[PendingSample] = deque()
        self._validating = 0
        self._last_profile_stamp: int | None = None
        self._last_offered_stamp: int | None = None
        self._capture_from: int | None = None

    # -- input ---------------------------------------------------------------------------

    def add_pose(self, pose: FlangePose, now_s: float) -> None:
        """Buffer one flange pose and pair the profiles it makes ready."""
        self.poses_received += 1
        latest = self.poses.latest_stamp_ns
        window_ns = round(self.config.pose_window_s * NS_PER_S)
        if latest is not None and pose.stamp_ns < latest - window_ns:
            self.pose_rejected.add(
                "pose",
                f"flange pose stamp jumped back by {(latest - pose.stamp_ns) / NS_PER_S:.3f} s "
                "(clock reset or replay restarted); pose buffer emptied",
            )
            self.poses = PoseBuffer(self.config.pose_window_s)
        self.poses.add(pose)
        self._base_frame = pose.frame_id
        self.release(now_s)

    def reject_pose(self, reason: str) -> None:
        """Count a flange pose message that could not be decoded."""
        self.poses_received += 1
        self.pose_rejected.add("pose", reason)

    def add_profile(self, profile: Profile, now_s: float) -> None:
        """Queue one decoded profile until the poses around its stamp have arrived."""
        index = self.received
        self.received += 1
        previous = self._last_profile_stamp
        self._last_profile_stamp = profile.stamp_ns
        if previous is not None and profile.stamp_ns <= previous:
            self._reject(
                "stamp",
                f"profile stamp is {(previous - profile.stamp_ns) / 1e6:.3f} ms before or at "
                "the previous profile's (stamps must increase)",
            )
        else:
            self._waiting.append(_Waiting(profile, index, now_s, self.generation))
        self.release(now_s)

    def reject_profile(self, reason: str) -> None:
        """Count a profile message that could not be decoded."""
        self.received += 1
        self._reject("message", reason)

    def release(self, now_s: float) -> None:
        """Pair every waiting profile that is ready, has waited too long, or overflows."""
        waiting = self._waiting
        while waiting:
            head = waiting[0]
            if not (
                self.poses.ready_for(head.profile.stamp_ns, self.config.pairing)
                or now_s - head.received_s > self.config.pose_window_s
                or len(waiting) > self.config.max_waiting_profiles
            ):
                break
            waiting.popleft()
            outcome = self.poses.pair(head.profile, head.index, self.config.pairing)
            if isinstance(outcome, Rejection):
                self._reject(outcome.stage, outcome.reason)
                continue
            self.paired += 1
            self._offer(
                PendingSample(outcome, head.profile.frame_id, self._base_frame, head.generation)
            )

    def _offer(self, pending: PendingSample) -> None:
        stamp = pending.sample.stamp_ns
        interval_ns = round(self.config.min_sample_interval_s * NS_PER_S)
        if pending.generation != self.generation:
            self.skipped.add("skipped", SKIP_CLEARED)
        elif self.config.mode is Mode.ON_DEMAND and not self._capturing(pending):
            self.skipped.add("skipped", SKIP_NOT_CAPTURED)
        elif (
            self._last_offered_stamp is not None
            and 0 <= stamp - self._last_offered_stamp < interval_ns
        ):
            self.skipped.add("skipped", SKIP_INTERVAL)
        elif len(self._to_validate) >= self.config.validation_queue_size:
            self.skipped.add("skipped", SKIP_BACKLOG)
        else:
            self._to_validate.append(pending)
            self._last_offered_stamp = stamp

    def _reject(self, stage: str, reason: str) -> None:
        self.rejected.add(stage, reason)
        self.last_rejection = f"{stage}: {reason}"

    # -- validation ----------------------------------------------------------------------

    def next_to_validate(self) -> PendingSample | None:
        """The oldest paired profile awaiting validation (now counted as being validated)."""
        if not self._to_validate:
            return None
        self._validating += 1
        return self._to_validate.popleft()

    def reject_validated(self, rejection: Rejection) -> None:
        """Count a sample that failed validation (or could not be stored)."""
        self._validating -= 1
        self._reject(rejection.stage, rejection.reason)

    def admit(self, pending: PendingSample) -> bool:
        """Whether a valid sample joins the session now; counts it either way.

        A sample is skipped when the session was cleared since it was received, or in
        ``on_demand`` mode when no capture request is pending any more. Otherwise it is
        counted as accepted and a pending capture request is fulfilled.
        """
        self._validating -= 1
        if pending.generation != self.generation:
            self.skipped.add("skipped", SKIP_CLEARED)
            return False
        capturing = self._capturing(pending)
        if self.config.mode is Mode.ON_DEMAND and not capturing:
            self.skipped.add("skipped", SKIP_NOT_CAPTURED)
            return False
        if capturing:
            self._capture_from = None
        self.accepted += 1
        self.session_samples += 1
        return True

    def revoke(self, stage: str, reason: str) -> None:
        """Turn an admitted sample into a rejection (it could not be stored)."""
        self.accepted -= 1
        self.session_samples -= 1
        self._reject(stage, reason)

    @property
    def has_work(self) -> bool:
        """True when paired profiles wait for validation."""
        return bool(self._to_validate)

    # -- requests ------------------------------------------------------------------------

    def arm_capture(self) -> None:
        """Request the next valid sample among the profiles received from now on."""
        self._capture_from = self.received

    def cancel_capture(self) -> None:
        """Withdraw a capture request (e.g. on timeout)."""
        self._capture_from = None

    @property
    def capture_pending(self) -> bool:
        """True while a capture request waits for a valid sample."""
        return self._capture_from is not None

    def _capturing(self, pending: PendingSample) -> bool:
        return self._capture_from is not None and pending.sample.index >= self._capture_from

    def clear(self, reloaded: int = 0) -> None:
        """Start a new session: samples received so far will not join it.

        Parameters
        ----------
        reloaded : int
            Samples the new session starts with (reloaded from an earlier session).
        """
        self.generation += 1
        self.session_samples = reloaded
        self._last_offered_stamp = None

    # -- reporting -----------------------------------------------------------------------

    @property
    def pending(self) -> int:
        """Profiles received but not yet accepted, rejected or skipped."""
        return len(self._waiting) + len(self._to_validate) + self._validating

    def diagnostic_values(self) -> dict[str, str]:
        """Counts for the ``/diagnostics`` status (keys are stable, values are decimal text)."""
        values = {
            KEY_RECEIVED: self.received,
            KEY_PAIRED: self.paired,
            KEY_ACCEPTED: self.accepted,
            KEY_REJECTED: self.rejected.total,
            KEY_SKIPPED: self.skipped.total,
            KEY_PENDING: self.pending,
            KEY_SESSION_SAMPLES: self.session_samples,
            KEY_POSES_RECEIVED: self.poses_received,
            KEY_POSES_REJECTED: self.pose_rejected.total,
        }
        out = {key: str(value) for key, value in values.items()}
        for counter, prefix in ((self.rejected, "rejected "), (self.pose_rejected, "rejected ")):
            out.update({prefix + key: str(n) for key, n in counter.counts().items()})
        out.update({key: str(n) for key, n in self.skipped.counts().items()})
        return out
