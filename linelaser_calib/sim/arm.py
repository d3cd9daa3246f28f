"""An arm with kinematics: joint motion, a true and a nominal model, joint states.

With ``scenario.robot_model`` set (``ur5e``, ``ur10e``), the robot is a serial arm:

- Joint vectors: each sampled sensor pose gives a wanted flange pose, solved by inverse
  kinematics under the nominal model from a home configuration; poses the arm cannot reach
  are left out (the sampler is asked for three times as many as needed and the first
  reachable ``n_poses`` are kept, in visiting order).
- The true model is the nominal one with every parameter off by a Gaussian error: lengths
  (m) by ``kinematic_sigma_length_m``, angles (joint zero offsets and twists, rad) by
  ``kinematic_sigma_angle_rad``, drawn with the run's seed or with ``kinematic_seed`` (the
  same arm in runs of other seeds).
- The joints move linearly between the waypoints with the motion's blend weight (quintic
  in step-and-shoot), so they rest during each dwell.
- The controller reports what its encoders and nominal model say: the flange pose
  ``FK_nominal(q)`` (plus per-message jitter) and the joint states q. The flange truly is
  at ``FK_true(q) · E``, E the per-waypoint repeatability error blended like the joints
  (:func:`~linelaser_calib.sim.robot.error_transforms`); this pose makes the scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import invert_transform
from linelaser_calib.core.robot.kinematics import (
    KinematicCorrections,
    KinematicModel,
    forward_kinematics,
    inverse_kinematics,
    model_from_preset,
)
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim.poses import SensorPoses, sample_sensor_poses
from linelaser_calib.sim.robot import Motion, error_transforms
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Scene

#: Home joint vector of UR arms (rad): elbow up, tool pointing down; the IK starts here.
UR_HOME_RAD = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)
_EXTRA_SEEDS = 12
_SAMPLE_FACTOR = 3


@dataclass(frozen=True, eq=False)
class Arm:
    """The simulated arm of one run.

    Attributes
    ----------
    nominal, true : KinematicModel
        The model the controller uses and the arm's real kinematics.
    q_waypoints : ndarray, shape (M, n)
        Joint vector at each waypoint (rad).
    sampled : SensorPoses
        The reachable sensor poses that the waypoints aim at (the scan is made from the true
        poses, off by the kinematic error).
    """

    nominal: KinematicModel
    true: KinematicModel
    q_waypoints: FloatArray
    sampled: SensorPoses

    @property
    def errors(self) -> KinematicCorrections:
        """The true kinematics as corrections to the nominal model (m, rad)."""
        delta = self.true.parameters - self.nominal.parameters
        names = self.nominal.parameter_names
        return KinematicCorrections(
            self.nominal.name, {n: float(v) for n, v in zip(names, delta, strict=True)}
        )

    def joint_positions(self, motion: Motion, t: FloatArray) -> FloatArray:
        """Joint vectors (K, n) at times t (K,) s."""
        index, weight = motion.locate(t)
        nxt = np.minimum(index + 1, len(self.q_waypoints) - 1)
        q0, q1 = self.q_waypoints[index], self.q_waypoints[nxt]
        return np.asarray(q0 + weight[:, None] * (q1 - q0))

    def true_flange(
        self, motion: Motion, scenario: Scenario, errors: FloatArray, t: FloatArray
    ) -> FloatArray:
        """True ``T_base_flange`` (K, 4, 4) at times t: ``FK_true(q) · E``."""
        index, weight = motion.locate(t)
        E = error_transforms(scenario, errors, index, weight)
        return np.asarray(forward_kinematics(self.true, self.joint_positions(motion, t)) @ E)

    def reported_flange(self, motion: Motion, t: FloatArray) -> FloatArray:
        """Reported ``T_base_flange`` (K, 4, 4) without jitter: ``FK_nominal(q)``."""
        return forward_kinematics(self.nominal, self.joint_positions(motion, t))


def _home(model: KinematicModel) -> FloatArray:
    if len(model.joint_names) == len(UR_HOME_RAD):
        return np.asarray(UR_HOME_RAD)
    return np.zeros(len(model.joint_names))


def plan_arm(rng: np.random.Generator, scenario: Scenario, scene: Scene) -> Arm:
    """Sample reachable sensor poses, solve their joint vectors, draw the true model.

    Raises
    ------
    InputError
        If fewer than ``scenario.n_poses`` sampled poses are reachable.
    """
    nominal = model_from_preset(scenario.robot_model)
    wanted = scenario.n_poses
    sampled = sample_sensor_poses(rng, replace(scenario, n_poses=_SAMPLE_FACTOR * wanted), scene)
    T_sensor_flange = invert_transform(scenario.T_flange_sensor)
    home = _home(nominal)
    seeds = np.vstack(
        [home, home + rng.uniform(-math.pi / 2, math.pi / 2, (_EXTRA_SEEDS, len(home)))]
    )
    solved = inverse_kinematics(nominal, sampled.T_base_sensor @ T_sensor_flange, seeds)
    reachable = np.flatnonzero(solved.converged)[:wanted]
    if len(reachable) < wanted:
        raise InputError(
            f"scenario {scenario.name!r}: the {scenario.robot_model} reaches only "
            f"{len(reachable)} of {len(sampled.T_base_sensor)} sampled sensor poses, fewer than "
            f"n_poses = {wanted}; move the cylinder within reach or ask for fewer poses"
        )
    sigma = np.where(
        nominal.parameter_is_length,
        scenario.kinematic_sigma_length_m,
        scenario.kinematic_sigma_angle_rad,
    )
    draw = rng if scenario.kinematic_seed < 0 else np.random.default_rng(scenario.kinematic_seed)
    true = nominal.with_parameters(nominal.parameters + draw.normal(size=len(sigma)) * sigma)
    kept = SensorPoses(
        sampled.T_base_sensor[reachable],
        tuple(sampled.kinds[i] for i in reachable),
        sampled.cut_angles_rad[reachable],
    )
    return Arm(nominal, true, solved.q[reachable], kept)
