"""The calibration service's logic without ROS: match samples by stamp, bound them, summarise.

The collector publishes each sample as a profile and a flange pose with identical stamps on
two topics. :class:`SampleStore` joins the halves by exact stamp, ignores repeats (a
transient_local topic replays its history to a restarted service), and holds at most
``max_samples`` samples. :func:`points_in_base` feeds the RViz markers.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.geometry import FloatArray, apply_transform
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.types import Sample


@dataclass(frozen=True)
class _Half:
    """One of the two messages of a sample: profile points (N, 3) or ``T_base_flange``."""

    value: FloatArray
    frame_id: str


class SampleStore:
    """Samples joined by exact stamp from the profile and flange-pose sample topics.

    Thread-safe: subscriptions add while ``/calibrate`` takes a snapshot.

    Parameters
    ----------
    max_samples : int
        Most samples kept; later ones are ignored (and :meth:`add_profile`/:meth:`add_pose`
        return a warning, once). Unmatched halves are bounded by the same number.
    """

    def __init__(self, max_samples: int) -> None:
        if max_samples < 1:
            raise ValueError(f"max_samples must be >= 1, got {max_samples}")
        self.max_samples = max_samples
        self.session: str | None = None
        self.ignored_full = 0
        self.repeated = 0
        self.dropped_unmatched = 0
        self._lock = threading.Lock()
        self._samples: dict[int, tuple[_Half, _Half]] = {}
        self._profiles: dict[int, _Half] = {}
        self._poses: dict[int, _Half] = {}
        self._warned_full = False

    def __len__(self) -> int:
        with self._lock:
            return len(self._samples)

    def add_profile(self, stamp_ns: int, points: FloatArray, frame_id: str) -> str | None:
        """Add the profile half of a sample; returns a warning to log, if any."""
        return self._add(stamp_ns, _Half(points, frame_id), is_profile=True)

    def add_pose(self, stamp_ns: int, T_base_flange: FloatArray, frame_id: str) -> str | None:
        """Add the flange-pose half of a sample; returns a warning to log, if any."""
        return self._add(stamp_ns, _Half(T_base_flange, frame_id), is_profile=False)

    def _add(self, stamp_ns: int, half: _Half, *, is_profile: bool) -> str | None:
        with self._lock:
            if stamp_ns in self._samples:
                self.repeated += 1
                return None
            mine, other = (
                (self._profiles, self._poses) if is_profile else (self._poses, self._profiles)
            )
            partner = other.pop(stamp_ns, None)
            if partner is None:
                if stamp_ns in mine:
                    self.repeated += 1
                    return None
                mine[stamp_ns] = half
                if len(mine) > self.max_samples:
                    del mine[min(mine)]
                    self.dropped_unmatched += 1
                return None
            if len(self._samples) >= self.max_samples:
                self.ignored_full += 1
                if self._warned_full:
                    return None
                self._warned_full = True
                return (
                    f"max_samples ({self.max_samples}) reached: further samples are ignored. "
                    "Calibrate now, clear the collector's session (~/clear) to start over, or "
                    "raise max_samples"
                )
            profile, pose = (half, partner) if is_profile else (partner, half)
            self._samples[stamp_ns] = (profile, pose)
            return None

    def samples(self) -> list[Sample]:
        """Snapshot of the complete samples in stamp order; ``index`` is the position."""
        with self._lock:
            items = sorted(self._samples.items())
        return [
            Sample(index=k, stamp_ns=stamp, T_base_flange=pose.value, points=profile.value)
            for k, (stamp, (profile, pose)) in enumerate(items)
        ]

    def set_session(self, session: str) -> int:
        """Follow the collector's session; a change of session drops the stored samples.

        Returns
        -------
        int
            Number of samples dropped (0 on the first session seen or the same session).
        """
        with self._lock:
            previous, self.session = self.session, session
            if previous is None or previous == session:
                return 0
            dropped = len(self._samples)
            self._samples.clear()
            self._profiles.clear()
            self._poses.clear()
            self._warned_full = False
            return dropped


def points_in_base(result: CalibrationResult, max_points: int) -> FloatArray:
    """The ellipse inlier points of the samples the solve used, mapped into the base frame.

    Uses ``result.sample_fits`` and the calibrated hand-eye; each sample contributes an evenly
    strided subset so that the total stays within ``max_points``.

    Returns
    -------
    ndarray, shape (M, 3), M <= max_points
        Points in the base frame, m.
    """
    fits = result.sample_fits
    if not fits or max_points < 1:
        return np.zeros((0, 3))
    per_sample = max(1, max_points // len(fits))
    parts = []
    for fit in fits:
        stride = max(1, int(np.ceil(len(fit.points) / per_sample)))
        T_base_sensor = fit.T_base_flange @ result.T_flange_sensor
        parts.append(apply_transform(T_base_sensor, fit.points[::stride]))
    return np.concatenate(parts)[:max_points]
