"""Pair each profile with the flange pose at its stamp.

One implementation serves the offline path (a whole bag at once) and the collector node
(profiles arriving live against a rolling pose buffer): both go through :class:`PoseBuffer`.

For a profile stamped ``t`` (shifted by ``clock_offset_s`` onto the pose clock):

1. If poses bracket ``t`` and both are within ``sync_tolerance_s``, the pose is
   interpolated: lerp on position, slerp on rotation.
2. Else, if one pose is within ``sync_tolerance_s``, the nearest pose is used.
3. Else the profile is rejected, with the distance to the nearest pose in the reason.

The robot's speed at ``t`` is measured over ``t +- speed_window_s`` from the interpolated
stream; a profile taken faster than ``max_linear_speed_m_s`` or ``max_angular_speed_rad_s``
is rejected (the pose is then unreliable by latency times speed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .geometry import FloatArray, rotation_angles
from .pose_track import PoseTrack
from .types import BoolArray, FlangePose, Profile, Rejection, Sample

NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class PairingConfig:
    """Pairing parameters (SI units).

    Attributes
    ----------
    sync_tolerance_s : float
        Largest gap between a profile stamp and a pose stamp used for it, s.
    clock_offset_s : float
        Added to every profile stamp to put it on the pose clock, s.
    max_linear_speed_m_s : float
        Profiles taken while the flange moved faster are rejected, m/s. 0 disables.
    max_angular_speed_rad_s : float
        Same for the rotation speed, rad/s. 0 disables.
    speed_window_s : float
        Half-width of the window over which the speed is measured, s.
    """

    sync_tolerance_s: float = 0.02
    clock_offset_s: float = 0.0
    max_linear_speed_m_s: float = 0.005
    max_angular_speed_rad_s: float = 0.01
    speed_window_s: float = 0.02

    def __post_init__(self) -> None:
        if not self.sync_tolerance_s > 0.0:
            raise ValueError(f"sync_tolerance_s must be > 0 s, got {self.sync_tolerance_s}")
        if self.max_linear_speed_m_s < 0.0 or self.max_angular_speed_rad_s < 0.0:
            raise ValueError("speed bounds must be >= 0 (0 disables the check)")
        if self.speed_window_s < 0.0:
            raise ValueError(f"speed_window_s must be >= 0 s, got {self.speed_window_s}")


@dataclass(frozen=True)
class ClockOffsetDiagnosis:
    """What a calibration's residual says about the clock offset it was paired with
    (:func:`~.latency.diagnose_clock_offset`).

    Attributes
    ----------
    offset_s : float
        The clock offset the residual points to, s: the one used plus the correction.
    correction_s, sigma_s : float
        The correction to the offset used and its 1σ, s.
    moving : int
        Profiles taken while the flange moved (the test's evidence).
    significant : bool
        The correction differs from zero at :data:`~.latency.LATENCY_FALSE_ALARM`.
    """

    offset_s: float
    correction_s: float
    sigma_s: float
    moving: int
    significant: bool


@dataclass
class PairingResult:
    """Outcome of pairing a batch of profiles.

    Attributes
    ----------
    samples : list of Sample
        Paired profiles, in profile-stamp order.
    rejected : list of Rejection
        Profiles that could not be paired, with reasons.
    notes : list of str
        Things fixed on the way (unsorted or duplicate pose stamps).
    median_offset_s : float or None
        Median of (nearest pose stamp - profile stamp) over all profiles, s.
    span_offset_s : float or None
        Centre of the pose stream's time span minus the centre of the profiles' span, s:
        the clock offset estimate when the two streams do not overlap at all.
    """

    samples: list[Sample]
    rejected: list[Rejection]
    notes: list[str] = field(default_factory=list)
    median_offset_s: float | None = None
    span_offset_s: float | None = None

    def explain_nothing_paired(self, config: PairingConfig) -> str:
        """A paragraph telling the user why nothing paired and what to try."""
        reasons = sorted({r.reason.split(" (")[0] for r in self.rejected})
        text = f"No profile could be paired with a flange pose ({len(self.rejected)} rejected"
        text += f": {'; '.join(reasons[:3])})." if reasons else ")."
        if self.median_offset_s is not None:
            text += (
                f" The median offset from a profile stamp to its nearest pose stamp is "
                f"{self.median_offset_s * 1e3:.1f} ms against a sync tolerance of "
                f"{config.sync_tolerance_s * 1e3:.1f} ms."
            )
            if abs(self.median_offset_s) > config.sync_tolerance_s:
                guess = self.median_offset_s
                if self.span_offset_s is not None and abs(self.span_offset_s) > abs(guess):
                    guess = self.span_offset_s
                    text += (
                        " The two streams do not overlap in time; their centres are "
                        f"{guess:.3f} s apart."
                    )
                text += (
                    f" If the two clocks differ by a constant, set the clock offset to about "
                    f"{guess:.3f} s; otherwise raise the sync tolerance or record the flange "
                    "pose at a higher rate."
                )
        return text


class PoseBuffer:
    """Flange poses sorted by stamp, queried at profile stamps.

    Poses may arrive unsorted or duplicated; the buffer keeps them sorted (a
    :class:`~.pose_track.PoseTrack`) and keeps the first of any duplicate stamp.
    ``max_age_s`` bounds the buffer for live use.
    """

    def __init__(self, max_age_s: float | None = None) -> None:
        self.track = PoseTrack.empty()
        self._max_age_ns = None if max_age_s is None else int(max_age_s * NS_PER_S)
        self.duplicates = 0
        self.out_of_order = 0

    def __len__(self) -> int:
        return len(self.track)

    @property
    def latest_stamp_ns(self) -> int | None:
        """Stamp of the newest pose, or None when empty."""
        return int(self.track.stamps_ns[-1]) if len(self.track) else None

    @property
    def stamps_ns(self) -> list[int]:
        """Stamps of the poses held, ns, sorted (a copy)."""
        return [int(s) for s in self.track.stamps_ns]

    def add(self, pose: FlangePose) -> None:
        """Insert one pose in stamp order (duplicates of an existing stamp are ignored)."""
        stamps = self.track.stamps_ns
        i = int(np.searchsorted(stamps, pose.stamp_ns))
        if i < len(stamps) and stamps[i] == pose.stamp_ns:
            self.duplicates += 1
            return
        if i < len(stamps):
            self.out_of_order += 1
        one = PoseTrack.from_transforms([pose.stamp_ns], pose.T_base_flange, pose.frame_id)
        track = self.track
        self.track = PoseTrack(
            np.insert(stamps, i, one.stamps_ns),
            np.insert(track.translation, i, one.translation, axis=0),
            np.insert(track.rotation_xyzw, i, one.rotation_xyzw, axis=0),
            track.frame_id if len(track) else pose.frame_id,
        )
        if self._max_age_ns is not None:
            stamps = self.track.stamps_ns
            cut = int(np.searchsorted(stamps, stamps[-1] - self._max_age_ns))
            if cut > 0:
                self.track = self.track.take(slice(cut, None))

    def extend(self, poses: PoseTrack | Sequence[FlangePose]) -> None:
        """Insert many poses (sorted once, much faster than repeated :meth:`add`)."""
        new = PoseTrack.of(poses)
        if not len(new):
            return
        held = self.track
        frame = held.frame_id if len(held) else new.frame_id
        self.out_of_order += int(np.count_nonzero(np.diff(new.stamps_ns) < 0))
        joined = PoseTrack.concatenate([new, held], frame) if len(held) else new
        self.track, duplicates = joined.sorted()  # a sorted stream is held as it is: no copy
        self.duplicates += duplicates

    def ready_for(self, stamp_ns: int, config: PairingConfig) -> bool:
        """True when no later pose can still change the pairing of ``stamp_ns``."""
        latest = self.latest_stamp_ns
        horizon = max(config.sync_tolerance_s, config.speed_window_s)
        t = stamp_ns + round(config.clock_offset_s * NS_PER_S)
        return latest is not None and latest >= t + round(horizon * NS_PER_S)

    def nearest_offset_ns(self, stamp_ns: int) -> int | None:
        """Signed offset from ``stamp_ns`` to the nearest pose stamp, ns."""
        offsets = self.nearest_offsets_ns(np.array([stamp_ns], dtype=np.int64))
        return None if offsets is None else int(offsets[0])

    def nearest_offsets_ns(self, stamps_ns: NDArray[np.int64]) -> NDArray[np.int64] | None:
        """:meth:`nearest_offset_ns` of each stamp (K,) (the earlier pose where two are
        as near), ns; None without poses."""
        stamps = self.track.stamps_ns
        if not len(stamps):
            return None
        i = np.searchsorted(stamps, stamps_ns)
        before = stamps[np.maximum(i - 1, 0)] - stamps_ns
        after = stamps[np.minimum(i, len(stamps) - 1)] - stamps_ns
        earlier = (i > 0) & ((i == len(stamps)) | (np.abs(before) <= np.abs(after)))
        offsets: NDArray[np.int64] = np.where(earlier, before, after)
        return offsets

    def pose_at(self, stamp_ns: int, tolerance_ns: int) -> FloatArray | str:
        """Flange pose at ``stamp_ns``, or the reason there is none.

        Returns
        -------
        T_base_flange : ndarray, shape (4, 4), or str
            Interpolated when two poses within the tolerance bracket the stamp, the nearest
            pose when only one is within it, else a reason (:meth:`PoseTrack.at`).
        """
        if not len(self.track):
            return "no flange pose received"
        T, found = self.track.at([stamp_ns], tolerance_ns)
        if found[0]:
            pose: FloatArray = T[0]
            return pose
        offset = self.nearest_offset_ns(stamp_ns)
        assert offset is not None
        return (
            f"no flange pose within {tolerance_ns / 1e6:.1f} ms of the profile stamp "
            f"(nearest is {offset / 1e6:+.1f} ms away)"
        )

    def speed_at(self, stamp_ns: int, window_ns: int) -> tuple[float, float] | None:
        """Linear (m/s) and angular (rad/s) flange speed around ``stamp_ns``.

        Measured between the poses interpolated at ``stamp_ns -+ window_ns``; None when
        the buffer does not cover that window.
        """
        linear, angular, known = self.speeds_at(np.array([stamp_ns]), window_ns)
        return (float(linear[0]), float(angular[0])) if known[0] else None

    def speeds_at(
        self, stamps_ns: NDArray[np.int64], window_ns: int
    ) -> tuple[FloatArray, FloatArray, BoolArray]:
        """:meth:`speed_at` at every stamp (K,): linear (m/s) and angular (rad/s) speeds, and
        where the buffer covers the window (elsewhere the speeds are 0)."""
        stamps = self.track.stamps_ns
        linear, angular = np.zeros(len(stamps_ns)), np.zeros(len(stamps_ns))
        if window_ns <= 0 or not len(stamps):
            return linear, angular, np.zeros(len(stamps_ns), dtype=bool)
        lo, hi = stamps_ns - window_ns, stamps_ns + window_ns
        A, found_a = self.track.at(lo, 10 * window_ns)
        B, found_b = self.track.at(hi, 10 * window_ns)
        known = (lo >= stamps[0]) & (hi <= stamps[-1]) & found_a & found_b
        dt = 2 * window_ns / NS_PER_S
        linear[known] = np.linalg.norm(B[known, :3, 3] - A[known, :3, 3], axis=1) / dt
        relative = np.einsum("kji,kjl->kil", A[known, :3, :3], B[known, :3, :3])
        angular[known] = rotation_angles(relative) / dt
        return linear, angular, known

    def pair(self, profile: Profile, index: int, config: PairingConfig) -> Sample | Rejection:
        """Pair one profile, or say why it cannot be paired."""
        return self.pair_many([profile], [index], config)[0]

    def pair_many(
        self, profiles: Sequence[Profile], indices: Sequence[int], config: PairingConfig
    ) -> list[Sample | Rejection]:
        """Pair each profile (its index in the input stream given), or say why it cannot be
        paired: the poses and speeds of all of them are looked up at once."""
        shift = round(config.clock_offset_s * NS_PER_S)
        t = np.array([p.stamp_ns for p in profiles], dtype=np.int64) + shift
        T, found = self.track.at(t, round(config.sync_tolerance_s * NS_PER_S))
        linear, angular, known = self.speeds_at(t, round(config.speed_window_s * NS_PER_S))
        out: list[Sample | Rejection] = []
        for k, (profile, index) in enumerate(zip(profiles, indices, strict=True)):
            reason = None
            if not found[k]:
                reason = self.pose_at(int(t[k]), round(config.sync_tolerance_s * NS_PER_S))
            elif known[k] and 0.0 < config.max_linear_speed_m_s < linear[k]:
                reason = (
                    f"robot moving at {linear[k] * 1e3:.1f} mm/s during the profile "
                    f"(limit {config.max_linear_speed_m_s * 1e3:.1f} mm/s)"
                )
            elif known[k] and 0.0 < config.max_angular_speed_rad_s < angular[k]:
                reason = (
                    f"robot rotating at {np.degrees(angular[k]):.2f} deg/s during the profile "
                    f"(limit {np.degrees(config.max_angular_speed_rad_s):.2f} deg/s)"
                )
            if isinstance(reason, str):
                out.append(Rejection(index, profile.stamp_ns, "pairing", reason))
            else:
                out.append(Sample(index, profile.stamp_ns, T[k], profile.points))
        return out


def pair_profiles(
    profiles: list[Profile], poses: PoseTrack | Sequence[FlangePose], config: PairingConfig
) -> PairingResult:
    """Pair every profile with the flange pose at its stamp.

    Parameters
    ----------
    profiles : list of Profile
        In any order; a profile whose stamp repeats an earlier one is rejected.
    poses : PoseTrack or sequence of FlangePose
        The flange pose stream, in any order; duplicate stamps keep the first pose.
    config : PairingConfig

    Returns
    -------
    PairingResult
        Samples in stamp order; ``samples[i].index`` is the profile's position in
        ``profiles``.
    """
    buffer = PoseBuffer()
    buffer.extend(poses)
    notes = []
    if buffer.out_of_order:
        notes.append(f"{buffer.out_of_order} flange poses arrived out of stamp order; sorted")
    if buffer.duplicates:
        notes.append(f"{buffer.duplicates} flange poses repeated a stamp; kept the first")
    samples: list[Sample] = []
    rejected: list[Rejection] = []
    seen: set[int] = set()
    order = sorted(range(len(profiles)), key=lambda k: profiles[k].stamp_ns)
    first: list[int] = []
    for k in order:
        profile = profiles[k]
        if profile.stamp_ns in seen:
            rejected.append(
                Rejection(k, profile.stamp_ns, "pairing", "duplicate profile stamp; kept first")
            )
            continue
        seen.add(profile.stamp_ns)
        first.append(k)
    offsets = buffer.nearest_offsets_ns(
        np.array([profiles[k].stamp_ns for k in first], dtype=np.int64)
    )
    for outcome in buffer.pair_many([profiles[k] for k in first], first, config):
        if isinstance(outcome, Sample):
            samples.append(outcome)
        else:
            rejected.append(outcome)
    median = float(np.median(offsets)) / NS_PER_S if offsets is not None and first else None
    span = None
    pose_stamps = buffer.track.stamps_ns
    if profiles and len(pose_stamps):
        profile_stamps = [p.stamp_ns for p in profiles]
        span = (
            (int(pose_stamps[0]) + int(pose_stamps[-1]))
            - (min(profile_stamps) + max(profile_stamps))
        ) / (2 * NS_PER_S)
    return PairingResult(samples, rejected, notes, median, span)
