"""Robot motion and pose reporting: where the flange truly is, and what the robot reports.

Two motions pass through the sampled sensor poses (waypoints); both move the sensor
(the tool point), and the flange follows rigidly, ``T_base_flange = T_base_sensor ·
inv(T_flange_sensor)``. Times are seconds from the first streamed pose.

- :class:`StepMotion` (step-and-shoot): rest at each waypoint for ``dwell_s`` (the first
  rest is ``margin_s`` longer, the last is followed by ``margin_s``); move between them
  with quintic time scaling (at rest at both ends), translation interpolated linearly and
  rotation by slerp. A profile is taken mid-dwell.
- :class:`ContinuousMotion`: a C2 spline through all waypoints (cubic on translation,
  :class:`scipy.spatial.transform.RotationSpline` on rotation), parametrised by cumulative
  move cost, run with quintic ease-in/out after ``margin_s`` of rest; profiles every
  1/``profile_rate_hz`` along the way.

Pose errors (:func:`draw_errors`, :func:`reported_flange`): reported = true · E_sys · E(t) ·
J, all in the flange frame. E_sys is the scenario's fixed systematic error. E(t) blends the
per-waypoint random errors E_i (translation and rotation vector interpolated linearly) with
the motion's blend weight, so during a dwell it is exactly E_i. J is per-message jitter.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from linelaser_calib.core.geometry import (
    invert_transform,
    rotation_angle,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Int64Array


def quintic(tau: FloatArray) -> FloatArray:
    """Quintic time scaling 10τ³ - 15τ⁴ + 6τ⁵ of τ clipped to [0, 1].

    Rate and acceleration are zero at both ends.
    """
    t = np.clip(tau, 0.0, 1.0)
    return np.asarray(t**3 * (10.0 - 15.0 * t + 6.0 * t * t))


def _compose(R: FloatArray, p: FloatArray) -> FloatArray:
    T = np.zeros((len(p), 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return T


def _move_cost(T_base_sensor: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Translation (m) and turn (rad) between consecutive waypoints, shape (M-1,) each."""
    dp = np.linalg.norm(np.diff(T_base_sensor[:, :3, 3], axis=0), axis=1)
    turn = np.array([rotation_angle(a[:3, :3].T @ b[:3, :3]) for a, b in pairwise(T_base_sensor)])
    return dp, turn


@dataclass(frozen=True, eq=False)
class StepMotion:
    """Step-and-shoot through waypoints (see the module docstring).

    Attributes
    ----------
    waypoints : ndarray, shape (M, 4, 4)
        Sensor poses in the base frame.
    dwell_start_s, dwell_end_s : ndarray, shape (M,)
        Rest interval at each waypoint, s.
    duration_s : float
        End of the stream (last dwell end + margin), s.
    """

    waypoints: FloatArray
    dwell_start_s: FloatArray
    dwell_end_s: FloatArray
    duration_s: float

    @classmethod
    def plan(cls, T_base_sensor: FloatArray, scenario: Scenario) -> StepMotion:
        """Time the moves from the scenario's speeds."""
        dp, turn = _move_cost(T_base_sensor)
        moves = np.maximum.reduce(
            [
                np.full(len(dp), scenario.min_move_s),
                dp / scenario.move_speed_m_s,
                turn / scenario.move_angular_speed_rad_s,
            ]
        )
        starts = scenario.margin_s + np.concatenate([[0.0], np.cumsum(scenario.dwell_s + moves)])
        ends = starts + scenario.dwell_s
        return cls(T_base_sensor, starts, ends, float(ends[-1] + scenario.margin_s))

    def shot_times_s(self) -> FloatArray:
        """True acquisition times, mid-dwell, shape (M,)."""
        return np.asarray(0.5 * (self.dwell_start_s + self.dwell_end_s))

    def locate(self, t: FloatArray) -> tuple[Int64Array, FloatArray]:
        """Segment index i (M,) and blend weight s ∈ [0, 1] towards waypoint i+1 at times t."""
        i = np.clip(np.searchsorted(self.dwell_start_s, t, side="right") - 1, 0, None)
        nxt = np.minimum(i + 1, len(self.waypoints) - 1)
        span = np.where(nxt > i, self.dwell_start_s[nxt] - self.dwell_end_s[i], 1.0)
        s = np.where(nxt > i, quintic((t - self.dwell_end_s[i]) / span), 0.0)
        return i.astype(np.int64), np.asarray(s)

    def T_base_sensor(self, t: FloatArray) -> FloatArray:
        """True sensor poses (K, 4, 4) at times t (K,); exactly the waypoint during a dwell."""
        i, s = self.locate(t)
        nxt = np.minimum(i + 1, len(self.waypoints) - 1)
        A, B = self.waypoints[i], self.waypoints[nxt]
        delta = Rotation.from_matrix(np.einsum("kji,kjl->kil", A[:, :3, :3], B[:, :3, :3]))
        step = Rotation.from_rotvec(s[:, None] * delta.as_rotvec()).as_matrix()
        R = np.where((s > 0.0)[:, None, None], A[:, :3, :3] @ step, A[:, :3, :3])
        p = A[:, :3, 3] + s[:, None] * (B[:, :3, 3] - A[:, :3, 3])
        return _compose(R, p)


@dataclass(frozen=True, eq=False)
class ContinuousMotion:
    """Continuous spline motion through waypoints (see the module docstring).

    Attributes
    ----------
    waypoints : ndarray, shape (M, 4, 4)
    knots : ndarray, shape (M,)
        Spline parameter of each waypoint: cumulative move cost, m (turns weighted by
        ``move_speed_m_s / move_angular_speed_rad_s``).
    start_s, path_s : float
        Start time and length in time of the motion, s.
    duration_s : float
        End of the stream, s.
    """

    waypoints: FloatArray
    knots: FloatArray
    start_s: float
    path_s: float
    duration_s: float
    profile_rate_hz: float

    @classmethod
    def plan(cls, T_base_sensor: FloatArray, scenario: Scenario) -> ContinuousMotion:
        """Parametrise the path and time it from the scenario's average speed."""
        dp, turn = _move_cost(T_base_sensor)
        cost = dp + turn * scenario.move_speed_m_s / scenario.move_angular_speed_rad_s
        knots = np.concatenate([[0.0], np.cumsum(np.maximum(cost, 1e-6))])
        path_s = float(knots[-1] / scenario.move_speed_m_s)
        return cls(
            T_base_sensor,
            knots,
            scenario.margin_s,
            path_s,
            scenario.margin_s * 2.0 + path_s,
            scenario.profile_rate_hz,
        )

    def shot_times_s(self) -> FloatArray:
        """True acquisition times along the path at the profile rate, shape (K,)."""
        count = int(np.floor(self.path_s * self.profile_rate_hz))
        return np.asarray(self.start_s + (np.arange(count) + 0.5) / self.profile_rate_hz)

    def _parameter(self, t: FloatArray) -> FloatArray:
        return np.asarray(self.knots[-1] * quintic((t - self.start_s) / self.path_s))

    def locate(self, t: FloatArray) -> tuple[Int64Array, FloatArray]:
        """Segment index i and linear weight s ∈ [0, 1] between waypoints i and i+1."""
        u = self._parameter(t)
        i = np.clip(np.searchsorted(self.knots, u, side="right") - 1, 0, len(self.knots) - 2)
        s = np.clip((u - self.knots[i]) / (self.knots[i + 1] - self.knots[i]), 0.0, 1.0)
        return i.astype(np.int64), np.asarray(s)

    def T_base_sensor(self, t: FloatArray) -> FloatArray:
        """True sensor poses (K, 4, 4) at times t (K,)."""
        u = self._parameter(t)
        p = CubicSpline(self.knots, self.waypoints[:, :3, 3], bc_type="clamped")(u)
        R = RotationSpline(self.knots, Rotation.from_matrix(self.waypoints[:, :3, :3]))(u)
        return _compose(R.as_matrix(), np.asarray(p))


Motion = StepMotion | ContinuousMotion


def plan_motion(T_base_sensor: FloatArray, scenario: Scenario) -> Motion:
    """The scenario's motion (``step`` or ``continuous``) through the waypoints."""
    if scenario.motion == "continuous":
        return ContinuousMotion.plan(T_base_sensor, scenario)
    return StepMotion.plan(T_base_sensor, scenario)


def draw_errors(rng: np.random.Generator, scenario: Scenario, count: int) -> FloatArray:
    """Per-waypoint random pose errors, shape (count, 6): translation (m), rotation vector (rad)."""
    sigma = np.repeat([scenario.robot_sigma_translation_m, scenario.robot_sigma_rotation_rad], 3)
    return np.asarray(rng.normal(size=(count, 6)) * sigma)


def error_transforms(
    scenario: Scenario, errors: FloatArray, index: Int64Array, weight: FloatArray
) -> FloatArray:
    """E_sys · E(t) (K, 4, 4) from per-waypoint errors (M, 6) blended at (index, weight)."""
    nxt = np.minimum(index + 1, len(errors) - 1)
    e = errors[index] + weight[:, None] * (errors[nxt] - errors[index])
    E = _compose(Rotation.from_rotvec(e[:, 3:]).as_matrix(), e[:, :3])
    E_sys = transform_from_rotvec_translation(
        scenario.robot_systematic_rotvec_rad, scenario.robot_systematic_translation_m
    )
    return np.asarray(E_sys @ E)


def jitter_transforms(rng: np.random.Generator, scenario: Scenario, count: int) -> FloatArray:
    """Per-message jitter transforms J, shape (count, 4, 4)."""
    sigma = np.repeat([scenario.pose_jitter_translation_m, scenario.pose_jitter_rotation_rad], 3)
    e = rng.normal(size=(count, 6)) * sigma
    return _compose(Rotation.from_rotvec(e[:, 3:]).as_matrix(), e[:, :3])


def true_flange(motion: Motion, scenario: Scenario, t: FloatArray) -> FloatArray:
    """True ``T_base_flange`` (K, 4, 4) at times t (K,)."""
    return np.asarray(motion.T_base_sensor(t) @ invert_transform(scenario.T_flange_sensor))


def reported_flange(
    motion: Motion, scenario: Scenario, errors: FloatArray, t: FloatArray
) -> FloatArray:
    """Reported ``T_base_flange`` without jitter, true · E_sys · E(t), shape (K, 4, 4)."""
    index, weight = motion.locate(t)
    return np.asarray(
        true_flange(motion, scenario, t) @ error_transforms(scenario, errors, index, weight)
    )
