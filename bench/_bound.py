"""The Cramér–Rao bound of the cylinder hand-eye under the simulator's sensor model.

For one recording, the profiles and flange poses the calibration used are linearised at the
true hand-eye and cylinder (the default method's own residuals and Jacobians,
:class:`~linelaser_calib.core.targets.cylinder.problem.CylinderProblem`, radius estimated).
Each profile's point residuals get the covariance the simulator's error model gives them
(:mod:`linelaser_calib.sim.sensor_models`), mapped onto the surface normal n (sensor frame):

    C = σ_x² n_x² + σ_y² n_y² (diagonal) + n_z n_zᵀ ∘ K_z,
    K_z = (σ_z² + q_z²/12) I + σ_shape² exp(−Δx² / (2 ℓ²)) + σ_speckle² exp(−Δray² / (4 w²)),

with the quantisation steps q as uniform noise, the smooth shape error's Gaussian kernel
along the true x (here: the measured x), and the speckle's Gaussian smoothing of w rays (the
correlation of white noise smoothed twice by a Gaussian of width w). The pose corrections
have the simulator's robot σ as their prior. The information ``Σ_j Jᵀ C_j⁻¹ J`` with every
sample's pose correction eliminated (Schur complement) inverts to the bound on the hand-eye
of any unbiased estimator that sees these points (the oracle: generalised least squares
with the true covariance). The fixed linearity bow is a systematic error shared by every
profile, not noise: it is left out (set ``linearity_m`` to 0 to compare like with like).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from linelaser_calib.core.geometry import FloatArray
from linelaser_calib.core.targets.cylinder.config import RefineConfig
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.problem import build_problem, initial_state
from linelaser_calib.core.types import SampleFit
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.sensor_models import SensorModel


def _depth_covariance(scenario: Scenario, model: SensorModel, points: FloatArray) -> FloatArray:
    """Covariance (N, N) of the depth errors of a profile's points (N, 3), m²."""
    x, z = points[:, 0], points[:, 2]
    ray = (x / z / math.tan(scenario.fan_half_angle_rad) + 1.0) / 2.0 * (scenario.resolution - 1)
    K = np.eye(len(x)) * (scenario.sigma_depth_m**2 + model.z_step_m**2 / 12.0)
    if model.shape_sigma_m > 0.0:
        dx = x[:, None] - x[None, :]
        K += model.shape_sigma_m**2 * np.exp(-(dx**2) / (2.0 * model.shape_length_m**2))
    if model.speckle_sigma_m > 0.0:
        dr = ray[:, None] - ray[None, :]
        K += model.speckle_sigma_m**2 * np.exp(-(dr**2) / (4.0 * model.speckle_points**2))
    return np.asarray(K)


def hand_eye_bound(
    scenario: Scenario,
    model: SensorModel,
    fits: list[SampleFit],
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
    max_points: int = 200,
) -> FloatArray:
    """The Cramér–Rao bound (6, 6) of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.

    Parameters
    ----------
    scenario : Scenario
        The simulated scene (white noise, fan, resolution, robot σ).
    model : SensorModel
        The sensor's error terms (the bow is ignored, see the module docstring).
    fits : list of SampleFit
        The profiles (inlier points, sensor frame, m) and recorded flange poses used.
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    cylinder : Cylinder
        The true cylinder (base frame, m).
    max_points : int
        Points per profile, evenly spaced (the default method's subsampling; 0 all).
    """
    config = RefineConfig(
        sensor_sigma_m=1.0,
        robot_sigma_t_m=scenario.robot_sigma_translation_m,
        robot_sigma_r_rad=scenario.robot_sigma_rotation_rad,
        max_points_per_profile=max_points,
    )
    T_base_flange = np.stack([f.T_base_flange for f in fits])
    problem = build_problem([f.points for f in fits], T_base_flange, config, True)
    state = initial_state(problem, T_flange_sensor, cylinder, cylinder.radius)
    linear = problem.linearise(state)
    normal_sensor = linear.J_global[..., 3:6] @ state.R_fs  # rows: unit normals, sensor frame
    prior = np.diag(linear.pose_prior_sqrt_information**2)
    lateral = scenario.sigma_lateral_m**2 + model.x_step_m**2 / 12.0
    G = linear.J_global.shape[2]
    information = np.zeros((G, G))
    for j in range(problem.n_samples):
        k = int(problem.counts[j])
        n = normal_sensor[j, :k]
        C = n[:, 2:3] * _depth_covariance(scenario, model, problem.points[j, :k]) * n[None, :, 2]
        C += np.diag(n[:, 0] ** 2 * lateral + n[:, 1] ** 2 * scenario.sigma_y_m**2)
        factor = cho_factor(C)
        J_g, J_l = linear.J_global[j, :k], linear.J_local[j, :k]
        W_g, W_l = cho_solve(factor, J_g), cho_solve(factor, J_l)
        B = J_g.T @ W_l
        information += J_g.T @ W_g - B @ np.linalg.solve(J_l.T @ W_l + prior, B.T)
    return np.asarray(np.linalg.inv(information)[:6, :6])


def rms_of(covariance: FloatArray) -> tuple[float, float]:
    """Expected RMS of the rotation (deg) and translation (mm) errors of a (6, 6) covariance."""
    rotation = math.degrees(math.sqrt(float(np.trace(covariance[:3, :3]))))
    return rotation, 1e3 * math.sqrt(float(np.trace(covariance[3:, 3:])))
