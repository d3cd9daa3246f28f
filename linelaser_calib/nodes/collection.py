"""The collector's logic without ROS: pair live profiles with buffered flange poses, and count.

The ``collector`` node decodes messages and hands them to a :class:`LiveCollector`, which

1. buffers flange poses (:class:`~linelaser_calib.core.pairing.PoseBuffer`, ``pose_window_s``
   deep, reset when the pose clock jumps back further than that) and follows the flange's
   standstills (:class:`StandstillDetector`);
2. keeps each profile in a small waiting queue until the buffer holds every pose that can
   still change its pairing (``PoseBuffer.ready_for``), or until the pose stream has been
   silent for ``pose_window_s`` of wall time, then pairs it (``PoseBuffer.pair``);
3. decides by the collection mode what becomes of each paired profile:

   - ``continuous``: it is a sample at once (store first; the node checks samples against
     the target beside the storing, as fast as it can, and never holds one back for it),
     unless ``max_rate_hz`` decimates it on purpose;
   - ``stop_and_go``: the first profile of each standstill (the flange slower than the
     pairing's speed bounds for ``standstill_s``) that passes validation is the sample of
     that standstill (its profiles queue for validation in turn); profiles taken while the
     flange moves or settles, and the rest of a standstill once it has its sample, are
     skipped;
   - ``on_demand``: the first profile that passes validation after each capture request;

4. hands the samples to the node to store and publish (:meth:`LiveCollector.take_to_store`).

Every profile that reaches the collector ends up counted exactly once: ``received ==
accepted + rejected + skipped + pending``. Rejections (bad data) and skips (collector
policy) are counted per reason; a reason's key has its numbers replaced by ``#`` so that one
kind of problem has one key, and ``on_new_reason`` is called the first time a key appears,
so the node logs it once instead of once per profile. Profiles that never reach it (lost by
a best-effort transport) are counted from the gaps in the publisher's sequence numbers
(:class:`SequenceGaps`).
"""

from __future__ import annotations

import math
import re
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from linelaser_calib.core.geometry import rotation_angle
from linelaser_calib.core.pairing import NS_PER_S, PairingConfig, PoseBuffer
from linelaser_calib.core.types import FlangePose, Profile, Rejection, Sample

#: Called with (reason key, full first message) the first time a reason key is counted.
ReasonLogger = Callable[[str, str], None]


_NUMBER = re.compile(r"(?<![A-Za-z_\d])[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


#: The collector's /diagnostics status is named ``"<node name>: collection"``.
COLLECTION_STATUS = "collection"
#: Its value saying why no profile was accepted (:meth:`LiveCollector.nothing_accepted`),
#: present only then; the calibration service answers /calibrate with it.
KEY_NOTHING_ACCEPTED = "why no sample"

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


KEY_PROFILES_LOST = "profiles lost in transport"


KEY_PROFILES_BEFORE = "profiles published before the first one received"


KEY_POSES_LOST = "poses lost in transport"


KEY_CHECKED = "samples checked live"


KEY_CHECK_FAILED = "samples failing the live check"


SKIP_NOT_CAPTURED = "not captured (on_demand mode and no capture request pending)"


SKIP_RATE = "decimated to max_rate_hz on purpose"


SKIP_BACKLOG = "validation queue full (the collector cannot validate profiles this fast)"


SKIP_CLEARED = "received before the session was cleared"


SKIP_MOVING = "robot moving or settling (stop_and_go: one sample per standstill)"


SKIP_SAMPLED = "this standstill has its sample already (stop_and_go)"


SKIP_CANDIDATE = "validation queue full of this standstill's profiles (stop_and_go)"


class Mode(str, Enum):
    """Collection modes (the ``mode`` parameter)."""

    STOP_AND_GO = "stop_and_go"
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
        Flange poses older than this behind the newest one are dropped, s; a profile waits for
        the poses around its stamp until the pose stream has been silent this long (wall
        time; a busy receiver still working through queued poses is not silent).
    mode : Mode
        ``stop_and_go``: one valid sample per standstill; ``continuous``: every paired
        profile; ``on_demand``: the first valid one after each capture request.
    max_rate_hz : float
        ``continuous``: paired profiles stamped less than 1/``max_rate_hz`` after the
        previous sample are skipped (decimation on purpose), Hz; 0 takes every one.
    standstill_s : float
        ``stop_and_go``: how long the flange must have been slower than the pairing's speed
        bounds before a profile is taken, s.
    validation_queue_size : int
        Profiles waiting for validation (``stop_and_go``, ``on_demand``); more are skipped
        (counted), never queued without bound.
    max_waiting_profiles : int
        Profiles waiting for poses; the oldest is paired early (and most likely rejected)
        when more arrive.
    """

    pairing: PairingConfig = field(default_factory=PairingConfig)
    pose_window_s: float = 2.0
    mode: Mode = Mode.STOP_AND_GO
    max_rate_hz: float = 0.0
    standstill_s: float = 0.1
    validation_queue_size: int = 20
    max_waiting_profiles: int = 1000

    def __post_init__(self) -> None:
        horizon = max(self.pairing.sync_tolerance_s, self.pairing.speed_window_s)
        if not self.pose_window_s > horizon + self.standstill_s:
            raise ValueError(
                f"pose_window_s ({self.pose_window_s} s) must exceed standstill_s "
                f"({self.standstill_s} s) plus the pairing horizon ({horizon} s, the larger "
                "of sync_tolerance_s and speed_window_s)"
            )
        if self.max_rate_hz < 0.0 or self.standstill_s < 0.0:
            raise ValueError("max_rate_hz and standstill_s must be >= 0")
        if self.mode is Mode.STOP_AND_GO and not (
            self.pairing.max_linear_speed_m_s > 0.0 and self.pairing.max_angular_speed_rad_s > 0.0
        ):
            raise ValueError(
                "mode stop_and_go detects standstills with max_linear_speed_m_s and "
                "max_angular_speed_rad_s: both must be > 0"
            )
        if self.validation_queue_size < 1 or self.max_waiting_profiles < 1:
            raise ValueError("validation_queue_size and max_waiting_profiles must be >= 1")


class StandstillDetector:
    """The flange's standstills, followed pose by pose.

    Each pose is compared with the latest earlier pose at least ``speed_window_s`` before
    it: the flange is moving at that pose when the linear or angular speed between the two
    exceeds the pairing's bounds. A standstill is a run of poses without motion; it is
    known by the stamp of its first pose. Poses that arrive out of stamp order are ignored.

    Parameters
    ----------
    pairing : PairingConfig
        Speed bounds (m/s, rad/s) and ``speed_window_s``.
    memory_s : float
        How far back standstills are remembered, s.
    """

    def __init__(self, pairing: PairingConfig, memory_s: float) -> None:
        self._pairing = pairing
        self._window_ns = round(pairing.speed_window_s * NS_PER_S)
        self._memory_ns = round(memory_s * NS_PER_S)
        self._recent: deque[FlangePose] = deque()
        #: [start, end] stamps of each standstill, oldest first; the last may be open.
        self._spans: deque[list[int]] = deque()
        self._open = False

    def reset(self) -> None:
        """Forget everything (the pose clock jumped back)."""
        self._recent.clear()
        self._spans.clear()
        self._open = False

    def add(self, pose: FlangePose) -> None:
        """Follow one more pose."""
        recent = self._recent
        if recent and pose.stamp_ns <= recent[-1].stamp_ns:
            return
        while len(recent) > 1 and recent[1].stamp_ns <= pose.stamp_ns - self._window_ns:
            recent.popleft()
        moving = False
        if recent and recent[0].stamp_ns <= pose.stamp_ns - self._window_ns:
            before = recent[0]
            dt = (pose.stamp_ns - before.stamp_ns) / NS_PER_S
            A, B = before.T_base_flange, pose.T_base_flange
            linear = float(np.linalg.norm(B[:3, 3] - A[:3, 3])) / dt
            angular = rotation_angle(A[:3, :3].T @ B[:3, :3]) / dt
            moving = (
                linear > self._pairing.max_linear_speed_m_s
                or angular > self._pairing.max_angular_speed_rad_s
            )
        recent.append(pose)
        if moving:
            self._open = False
        elif self._open:
            self._spans[-1][1] = pose.stamp_ns
        else:
            self._spans.append([pose.stamp_ns, pose.stamp_ns])
            self._open = True
        while self._spans and self._spans[0][1] < pose.stamp_ns - self._memory_ns:
            self._spans.popleft()

    def standstill_at(self, stamp_ns: int, settle_ns: int, after_ns: int) -> int | None:
        """The standstill that holds ``stamp_ns`` (pose clock), or None.

        The flange must have stood still from ``settle_ns`` before ``stamp_ns`` until
        ``after_ns`` after it.

        Returns
        -------
        int or None
            The standstill's first pose stamp, ns, which names it.
        """
        for start, end in reversed(self._spans):
            if start <= stamp_ns - settle_ns and stamp_ns + after_ns <= end:
                return start
            if end < stamp_ns:
                return None
        return None


class SequenceGaps:
    """Messages lost before they reached a subscription, from the publisher's sequence numbers.

    Each message carries its publisher's sequence number (1, 2, ... per publisher). A jump
    forward by more than one means lost messages (a best-effort transport drops them under
    load, or before the subscription has matched the publisher); the first number received
    tells how many were published before it. With several publishers on one topic the
    numbers interleave: only forward jumps of the largest number seen are counted.
    """

    def __init__(self) -> None:
        self.lost = 0
        self.before_first = 0
        self._last: int | None = None

    def add(self, sequence: int | None) -> None:
        """Note one received message's sequence number (None when the middleware has none)."""
        if sequence is None or sequence <= 0:
            return
        if self._last is None:
            self.before_first = sequence - 1
        elif sequence > self._last + 1:
            self.lost += sequence - self._last - 1
        self._last = sequence if self._last is None else max(self._last, sequence)


@dataclass(frozen=True)
class PendingSample:
    """A paired profile on its way to the session.

    Attributes
    ----------
    sample : Sample
        ``index`` is the profile's receive count (0-based).
    sensor_frame, base_frame : str
        Header frames of the profile and of the flange pose.
    generation : int
        Session generation at receive time (see :meth:`LiveCollector.clear`).
    standstill : int or None
        ``stop_and_go``: the standstill it was taken in (its first pose stamp, ns).
    """

    sample: Sample
    sensor_frame: str
    base_frame: str
    generation: int
    standstill: int | None = None


@dataclass
class _Waiting:
    profile: Profile
    index: int
    received_s: float
    generation: int


class LiveCollector:
    """Pair live profiles with flange poses, choose the samples, and account for every profile.

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
        self.standstills = StandstillDetector(config.pairing, config.pose_window_s)
        # stop_and_go leaves moving profiles to the standstill detector (a skip, not a
        # rejection); the other modes reject them while pairing.
        self._pair_config = (
            replace(config.pairing, max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
            if config.mode is Mode.STOP_AND_GO
            else config.pairing
        )
        self.rejected = ReasonCounter(on_new_reason)
        self.skipped = ReasonCounter(on_new_reason)
        #: The pose source's word on why it gave no flange pose at a stamp (pose clock, ns),
        #: added to a profile's reason when no pose was near it (e.g. which /tf link is stale).
        self.explain_no_pose: Callable[[int], str | None] | None = None
        self.pose_rejected = ReasonCounter(on_new_reason)
        self.check_failed = ReasonCounter(on_new_reason)
        self.profile_gaps = SequenceGaps()
        self.pose_gaps = SequenceGaps()
        self.received = 0
        self.poses_received = 0
        self.paired = 0
        self.accepted = 0
        self.checked = 0
        self.session_samples = 0
        self.generation = 0
        self.last_rejection = ""
        #: Receive index of the profile that fulfilled the last capture request.
        self.captured: int | None = None
        self._base_frame = ""
        self._last_pose_s = -math.inf  # wall time of the newest pose
        self._waiting: deque[_Waiting] = deque()
        self._to_validate: deque[PendingSample] = deque()
        self._to_store: deque[PendingSample] = deque()
        self._validating = 0
        self._last_profile_stamp: int | None = None
        self._last_sample_stamp: int | None = None
        self._capture_from: int | None = None
        self._sampled_standstill: int | None = None
        self._candidates: int | None = None  # standstill of the newest candidate queued

    # -- input ---------------------------------------------------------------------------

    def add_pose(self, pose: FlangePose, now_s: float, sequence: int | None = None) -> None:
        """Buffer one flange pose and pair the profiles it makes ready.

        ``sequence`` is the publisher's sequence number of the message, where known.
        """
        self.poses_received += 1
        self.pose_gaps.add(sequence)
        latest = self.poses.latest_stamp_ns
        window_ns = round(self.config.pose_window_s * NS_PER_S)
        if latest is not None and pose.stamp_ns < latest - window_ns:
            self.pose_rejected.add(
                "pose",
                f"flange pose stamp jumped back by {(latest - pose.stamp_ns) / NS_PER_S:.3f} s "
                "(clock reset or replay restarted); pose buffer emptied",
            )
            self.poses = PoseBuffer(self.config.pose_window_s)
            self.standstills.reset()
        self.poses.add(pose)
        if self.config.mode is Mode.STOP_AND_GO:
            self.standstills.add(pose)
        self._base_frame = pose.frame_id
        self._last_pose_s = now_s
        self.release(now_s)

    def reject_pose(self, reason: str) -> None:
        """Count a flange pose message that could not be decoded."""
        self.poses_received += 1
        self.pose_rejected.add("pose", reason)

    def add_profile(self, profile: Profile, now_s: float, sequence: int | None = None) -> None:
        """Queue one decoded profile until the poses around its stamp have arrived.

        ``sequence`` is the publisher's sequence number of the message, where known.
        """
        index = self.received
        self.received += 1
        self.profile_gaps.add(sequence)
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

    def reject_profile(self, reason: str, sequence: int | None = None) -> None:
        """Count a profile message that could not be decoded."""
        self.received += 1
        self.profile_gaps.add(sequence)
        self._reject("message", reason)

    def release(self, now_s: float) -> None:
        """Pair every waiting profile that is ready, has waited too long, or overflows."""
        waiting = self._waiting
        pairing = self.config.pairing
        while waiting:
            head = waiting[0]
            if not (
                self.poses.ready_for(head.profile.stamp_ns, pairing)
                or now_s - max(head.received_s, self._last_pose_s) > self.config.pose_window_s
                or len(waiting) > self.config.max_waiting_profiles
            ):
                break
            waiting.popleft()
            outcome = self.poses.pair(head.profile, head.index, self._pair_config)
            if isinstance(outcome, Rejection):
                self._reject(outcome.stage, self._explained(outcome))
                continue
            self.paired += 1
            standstill = None
            if self.config.mode is Mode.STOP_AND_GO:
                standstill = self.standstills.standstill_at(
                    head.profile.stamp_ns + round(pairing.clock_offset_s * NS_PER_S),
                    round(self.config.standstill_s * NS_PER_S),
                    round(max(pairing.sync_tolerance_s, pairing.speed_window_s) * NS_PER_S),
                )
                if standstill is None:
                    self.skipped.add("skipped", SKIP_MOVING)
                    continue
            self._offer(
                PendingSample(
                    outcome, head.profile.frame_id, self._base_frame, head.generation, standstill
                )
            )

    def _explained(self, rejection: Rejection) -> str:
        """The pairing's reason, with the pose source's explanation when no pose was near."""
        if self.explain_no_pose is None:
            return rejection.reason
        pairing = self.config.pairing
        t = rejection.stamp_ns + round(pairing.clock_offset_s * NS_PER_S)
        if not isinstance(self.poses.pose_at(t, round(pairing.sync_tolerance_s * NS_PER_S)), str):
            return rejection.reason  # a pose was near: rejected for another reason
        why = self.explain_no_pose(t)
        return rejection.reason if why is None else f"{rejection.reason}: {why}"

    def _offer(self, pending: PendingSample) -> None:
        mode = self.config.mode
        if pending.generation != self.generation:
            self.skipped.add("skipped", SKIP_CLEARED)
        elif mode is Mode.CONTINUOUS:
            stamp, last = pending.sample.stamp_ns, self._last_sample_stamp
            rate = self.config.max_rate_hz
            if rate > 0.0 and last is not None and 0 <= stamp - last < NS_PER_S / rate:
                self.skipped.add("skipped", SKIP_RATE)
            else:
                self._last_sample_stamp = stamp
                self._take(pending)
        elif mode is Mode.ON_DEMAND and not self._capturing(pending):
            self.skipped.add("skipped", SKIP_NOT_CAPTURED)
        elif mode is Mode.STOP_AND_GO and pending.standstill == self._sampled_standstill:
            self.skipped.add("skipped", SKIP_SAMPLED)
        elif len(self._to_validate) >= self.config.validation_queue_size:
            full_of_it = mode is Mode.STOP_AND_GO and pending.standstill == self._candidates
            self.skipped.add("skipped", SKIP_CANDIDATE if full_of_it else SKIP_BACKLOG)
        else:
            self._to_validate.append(pending)
            self._candidates = pending.standstill

    def _take(self, pending: PendingSample) -> None:
        """Count a sample as accepted, queue it for storing, fulfil a capture request."""
        if self._capturing(pending):
            self._capture_from = None
            self.captured = pending.sample.index
        self.accepted += 1
        self.session_samples += 1
        self._to_store.append(pending)

    def _reject(self, stage: str, reason: str) -> None:
        self.rejected.add(stage, reason)
        self.last_rejection = f"{stage}: {reason}"

    # -- validation (stop_and_go and on_demand) ------------------------------------------

    def next_to_validate(self) -> PendingSample | None:
        """The oldest candidate awaiting validation (now counted as being validated).

        ``stop_and_go``: candidates of a standstill that has its sample meanwhile are
        skipped on the way.
        """
        while self._to_validate:
            pending = self._to_validate.popleft()
            if (
                self.config.mode is Mode.STOP_AND_GO
                and pending.standstill == self._sampled_standstill
            ):
                self.skipped.add("skipped", SKIP_SAMPLED)
                continue
            self._validating += 1
            return pending
        return None

    def reject_validated(self, rejection: Rejection) -> None:
        """Count a candidate that failed validation (its standstill's next one is tried)."""
        self._validating -= 1
        self._reject(rejection.stage, rejection.reason)

    def admit(self, pending: PendingSample) -> bool:
        """Whether a valid candidate becomes a sample now; counts it either way.

        A candidate is skipped when the session was cleared since it was received, or in
        ``on_demand`` mode when no capture request is pending any more. Otherwise it is
        accepted, queued for storing (:meth:`take_to_store`), and a pending capture request
        is fulfilled.
        """
        self._validating -= 1
        if pending.generation != self.generation:
            self.skipped.add("skipped", SKIP_CLEARED)
            return False
        if self.config.mode is Mode.ON_DEMAND and not self._capturing(pending):
            self.skipped.add("skipped", SKIP_NOT_CAPTURED)
            return False
        self._sampled_standstill = pending.standstill
        self._take(pending)
        return True

    # -- storing -------------------------------------------------------------------------

    def take_to_store(self) -> list[PendingSample]:
        """Every accepted sample not yet handed out for storing, oldest first.

        Samples accepted before the session was cleared are skipped instead.
        """
        batch = [p for p in self._to_store if p.generation == self.generation]
        for _ in range(len(self._to_store) - len(batch)):
            self.accepted -= 1
            self.skipped.add("skipped", SKIP_CLEARED)
        self._to_store.clear()
        return batch

    def revoke(self, stage: str, reason: str) -> None:
        """Turn an accepted sample into a rejection (it could not be stored)."""
        self.accepted -= 1
        self.session_samples -= 1
        self._reject(stage, reason)

    def note_check(self, rejection: Rejection | None) -> None:
        """Count the live check of a stored sample (``continuous``; None: it passed)."""
        self.checked += 1
        if rejection is not None:
            self.check_failed.add(rejection.stage, rejection.reason)

    @property
    def has_work(self) -> bool:
        """True when candidates wait for validation or samples for storing."""
        return bool(self._to_validate or self._to_store)

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
        self._last_sample_stamp = None
        self._sampled_standstill = None

    # -- reporting -----------------------------------------------------------------------

    def nothing_accepted(self) -> str | None:
        """Why no profile has joined the session though some were received, with the fix;
        None when the session has samples or nothing was received.

        The most common reasons are counted, e.g. ``received 50 profiles and set every one
        aside (50 x skipped: robot moving or settling ...)``. When ``stop_and_go`` could not
        confirm a standstill for most of them, the advice names the modes that need none.
        """
        if self.session_samples or self.accepted or not self.received or self.pending:
            return None
        counts = {**self.rejected.counts(), **self.skipped.counts()}
        ordered = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))[:3]
        reasons = "; ".join(f"{n} x {key}" for key, n in ordered)
        text = f"received {self.received} profiles and set every one aside ({reasons})"
        if self.last_rejection:
            text += f"; the last rejected: {self.last_rejection}"
        moving = self.skipped.counts().get(reason_key("skipped", SKIP_MOVING), 0)
        if moving * 2 > self.received:
            text += (
                f". In stop_and_go mode a profile is taken only when the flange poses show the "
                f"flange standing still for standstill_s ({self.config.standstill_s:g} s) "
                "before it; a pose stream that is published only around each shot cannot show "
                "that: set the collector's mode:=on_demand (call ~/capture at each stop) or "
                "mode:=continuous"
            )
        elif self.skipped.counts().get(reason_key("skipped", SKIP_NOT_CAPTURED), 0):
            text += ". In on_demand mode a profile is taken only after a ~/capture call"
        return text

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
            KEY_PROFILES_LOST: self.profile_gaps.lost,
            KEY_PROFILES_BEFORE: self.profile_gaps.before_first,
            KEY_POSES_RECEIVED: self.poses_received,
            KEY_POSES_REJECTED: self.pose_rejected.total,
            KEY_POSES_LOST: self.pose_gaps.lost,
        }
        if self.config.mode is Mode.CONTINUOUS:
            values.update({KEY_CHECKED: self.checked, KEY_CHECK_FAILED: self.check_failed.total})
        out = {key: str(value) for key, value in values.items()}
        for counter, prefix in (
            (self.rejected, "rejected "),
            (self.pose_rejected, "rejected "),
            (self.check_failed, "live check failed "),
        ):
            out.update({prefix + key: str(n) for key, n in counter.counts().items()})
        out.update({key: str(n) for key, n in self.skipped.counts().items()})
        return out
