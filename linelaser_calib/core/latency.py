"""Whether a calibration's residual follows the flange's velocity: a clock offset left out.

A profile stamped τ late is paired with the pose the flange had τ after the profile was
taken, so each profile lands off the target by about τ times the velocity of its points.
The per-pose robot-error model absorbs much of that as pose corrections, and the self-check
then calls the robot's error systematic; the cause is the clock.

The test (:func:`diagnose_clock_offset`), for any target, through its result section only:
each used profile's points are mapped into the base frame with the flange pose at its stamp
(shifted by the clock offset the calibration used) and with the poses ``step_s`` before and
after; their signed distances ``d`` from the fitted target and the derivative ``g = ∂d/∂τ``
(central difference) give the least-squares offset that the residual points to,
τ̂ = −Σ d g / Σ g². Its standard error is cluster-robust with the profile as the cluster
(the points of a profile share one pose error), and the offset is reported when it
differs from zero at :data:`LATENCY_FALSE_ALARM` (two-sided), the 3σ convention of
:mod:`.selfcheck`. Where the flange stands still at the profiles (step-and-shoot) ``g`` is
zero and there is nothing to test: the test runs only when at least
:data:`MIN_MOVING_PROFILES` profiles were taken while the flange moved faster than the
pairing's default speed gate.

All times in s, lengths in m.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from .geometry import FloatArray
from .pairing import NS_PER_S, ClockOffsetDiagnosis, PairingConfig, PoseBuffer
from .pose_track import PoseTrack
from .result import CalibrationResult
from .types import BoolArray, FlangePose

#: Warning code of the diagnosis (the result file's ``quality.pairing.clock_offset_diagnosis``):
#: the residual follows the flange's velocity, so the clocks look offset.
CLOCK_OFFSET_CODE = "clock_offset"
#: False-alarm probability of the test under no offset (two-sided; the 3σ convention).
LATENCY_FALSE_ALARM = 0.0027
#: Profiles taken while the flange moved that the test needs (the poses stream).
MIN_MOVING_PROFILES = 10
#: Half-step of the central difference in the offset, s.
STEP_S = 0.005


def clock_offset_warning(diagnosis: ClockOffsetDiagnosis) -> str:
    """The warning that names the cause and the next step (ms in text)."""
    return (
        f"the clocks look offset by about {diagnosis.offset_s * 1e3:.1f} ms: the residual "
        f"follows the flange's velocity ({diagnosis.moving} profiles taken while moving point "
        f"to {diagnosis.correction_s * 1e3:+.1f} ms +- {diagnosis.sigma_s * 1e3:.1f} ms on "
        "the clock offset used), and a clock offset left out looks like a robot error: read "
        "any robot-error warning below as this one's. Give {setting:clock_offset_s} auto and "
        "calibrate again"
    )


@dataclass(frozen=True)
class ClockProbe:
    """What the test reads of the flange pose stream, looked up once at the paired profiles'
    stamps (shifted by the clock offset): the poses ``step_s`` before, at and after each, and
    the flange's speeds there. Built before the solve, it lets the caller release the pose
    stream (141,912 poses, 9 MB, on a 1,600-profile ``ur_scancontrol`` recording) while the
    calibration runs; the test then reads the rows of the profiles the calibration used.

    Attributes
    ----------
    stamps_ns : ndarray, shape (N,), int64
        The profiles' own stamps, sorted, without repeats, ns.
    T_base_flange : ndarray, shape (3, N, 4, 4)
        The poses at each stamp shifted by the clock offset, ``-step_s``, 0 and ``+step_s``
        from it (m).
    found : ndarray, shape (3, N), bool
        Where each of them was within the pairing's sync tolerance.
    linear, angular : ndarray, shape (N,)
        The flange's speeds at the shifted stamps (m/s, rad/s), over the default pairing's
        speed window; ``known`` (N,) where the stream covers that window.
    step_s : float
        Half-step of the central difference in the offset, s.
    """

    stamps_ns: NDArray[np.int64]
    T_base_flange: FloatArray
    found: BoolArray
    linear: FloatArray
    angular: FloatArray
    known: BoolArray
    step_s: float

    @classmethod
    def of(
        cls,
        stamps_ns: Sequence[int],
        poses: PoseTrack | Sequence[FlangePose],
        pairing: PairingConfig,
        step_s: float = STEP_S,
    ) -> ClockProbe:
        """The probe of profiles stamped ``stamps_ns`` (ns) paired from ``poses`` with
        ``pairing`` (its clock offset and sync tolerance)."""
        buffer = PoseBuffer()
        buffer.extend(poses)
        stamps = np.unique(np.asarray(stamps_ns, dtype=np.int64))
        tolerance_ns = round(pairing.sync_tolerance_s * NS_PER_S)
        step_ns = round(step_s * NS_PER_S)
        t = stamps + round(pairing.clock_offset_s * NS_PER_S)
        looked_up = [buffer.track.at(t + k * step_ns, tolerance_ns) for k in (-1, 0, 1)]
        window_ns = round(PairingConfig().speed_window_s * NS_PER_S)
        linear, angular, known = buffer.speeds_at(t, window_ns)
        return cls(
            stamps,
            np.stack([T for T, _ in looked_up]),
            np.stack([found for _, found in looked_up]),
            linear,
            angular,
            known,
            step_s,
        )

    def rows(self, stamps_ns: Sequence[int]) -> NDArray[np.intp]:
        """The probe's row of each of ``stamps_ns`` (ns; each one of the probe's stamps)."""
        t = np.asarray(stamps_ns, dtype=np.int64)
        rows = np.searchsorted(self.stamps_ns, t)
        if not np.array_equal(self.stamps_ns[np.minimum(rows, len(self.stamps_ns) - 1)], t):
            raise ValueError("the clock probe was built without some of the profiles asked for")
        return rows


def diagnose_clock_offset(
    result: CalibrationResult,
    poses: ClockProbe | PoseTrack | Sequence[FlangePose],
    pairing: PairingConfig,
    step_s: float = STEP_S,
) -> ClockOffsetDiagnosis | None:
    """Test whether the residual follows the flange's velocity (see the module docstring).

    Parameters
    ----------
    result : CalibrationResult
        A calibration with its ``sample_fits``.
    poses : ClockProbe, PoseTrack or sequence of FlangePose
        The flange pose stream the profiles were paired with, or its probe at the profiles'
        stamps (:class:`ClockProbe`, built with ``pairing``; its own ``step_s`` holds).
    pairing : PairingConfig
        The pairing the calibration used (its clock offset and sync tolerance).
    step_s : float
        Half-step of the central difference in the offset, s.

    Returns
    -------
    ClockOffsetDiagnosis or None
        None when fewer than :data:`MIN_MOVING_PROFILES` profiles were taken while moving.
    """
    stamps = [fit.stamp_ns for fit in result.sample_fits]
    probe = (
        poses if isinstance(poses, ClockProbe) else ClockProbe.of(stamps, poses, pairing, step_s)
    )
    step_s = probe.step_s
    gate = PairingConfig()
    T_fs = result.T_flange_sensor
    scores, curvatures, profiles = [], [], []
    rows = probe.rows(stamps)
    looked_up = [(probe.T_base_flange[k, rows], probe.found[k, rows]) for k in range(3)]
    everywhere = np.logical_and.reduce([found for _, found in looked_up])
    linear, angular, known = probe.linear[rows], probe.angular[rows], probe.known[rows]
    moving = int(
        np.count_nonzero(
            everywhere
            & known
            & ((linear > gate.max_linear_speed_m_s) | (angular > gate.max_angular_speed_rad_s))
        )
    )
    for j in np.flatnonzero(everywhere).tolist():
        fit = result.sample_fits[j]
        before, at, after = (T[j] @ T_fs for T, _ in looked_up)
        d = result.target.surface_distances(fit, at)
        g = (
            result.target.surface_distances(fit, after)
            - result.target.surface_distances(fit, before)
        ) / (2.0 * step_s)
        profiles.append((d, g))
        scores.append(float(g @ d))
        curvatures.append(float(g @ g))
    total = float(np.sum(curvatures))
    if moving < MIN_MOVING_PROFILES or not total > 0.0:
        return None
    correction = -float(np.sum(scores)) / total
    clusters = np.array([float(g @ (d + correction * g)) for d, g in profiles])
    n = len(clusters)
    sigma = float(np.sqrt(n / (n - 1) * np.sum(clusters**2))) / total
    limit = float(norm.isf(LATENCY_FALSE_ALARM / 2.0))
    return ClockOffsetDiagnosis(
        offset_s=pairing.clock_offset_s + correction,
        correction_s=correction,
        sigma_s=sigma,
        moving=moving,
        significant=abs(correction) > limit * sigma,
    )


def add_clock_diagnosis(
    result: CalibrationResult,
    poses: ClockProbe | PoseTrack | Sequence[FlangePose],
    pairing: PairingConfig,
) -> None:
    """Run :func:`diagnose_clock_offset` on a result paired with ``pairing`` and keep it as
    ``result.clock_diagnosis``; a significant offset puts its warning first, before any
    robot-error warning it explains."""
    result.clock_diagnosis = diagnose_clock_offset(result, poses, pairing)
    if result.clock_diagnosis is not None and result.clock_diagnosis.significant:
        result.warnings.insert(0, clock_offset_warning(result.clock_diagnosis))
