"""The cylinder's joint kinematic and hand-eye calibration: the refinement with the flange poses
from joint states and the robot model's identifiable corrections estimated with it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import ModelMismatch
from ...geometry import FloatArray
from ...robot.joint_calibration import JointOutcome, KinematicSetup, MultiScanProblem, solve_joint
from ...robot.kinematics import forward_kinematics
from ...solver import N_HAND_EYE, Solution, normal_equations
from .config import RefineConfig
from .model import Cylinder
from .problem import (
    CylinderProblem,
    CylinderState,
    build_problem,
    data_centroid,
    initial_state,
    recentred,
)
from .refine import RefineResult, summarise

#: The pose corrections of a joint solve may be at most this multiple of the repeatability
#: (re-estimated robot σ): 0.6-0.7 on simulated UR5e arms with the right model, 7 with the
#: UR10e model on a UR5e.
MAX_REPEATABILITY_SCALE = 3.0


#: A kinematic correction may be at most this multiple of its prior 1σ (m or rad).
MAX_CORRECTION_PRIOR_SIGMAS = 10.0


def _check_kinematic_fit(scale: float, outcome: JointOutcome[Any], setup: KinematicSetup) -> None:
    """Refuse a joint solve whose kinematic model does not explain the robot's error (the
    re-estimated robot σ ``scale``, a multiple of the repeatability)."""
    delta = outcome.solution.state.delta
    ratio = np.abs(delta) / outcome.pose_model.prior_sigma
    if scale <= MAX_REPEATABILITY_SCALE and float(np.max(ratio, initial=0.0)) <= (
        MAX_CORRECTION_PRIOR_SIGMAS
    ):
        return
    worst = setup.model.parameter_names[int(outcome.pose_model.free[int(np.argmax(ratio))])]
    raise ModelMismatch(
        f"the {setup.model.name} kinematic model does not explain the robot's error: the "
        f"per-pose corrections are {scale:.1f} times the arm's repeatability of "
        f"{setup.config.repeatability_t_m * 1e3:.3f} mm and "
        f"{np.rad2deg(setup.config.repeatability_r_rad):.4f} deg, and the largest kinematic "
        f"correction ({worst}) is {float(np.max(ratio)):.0f} times its prior 1 sigma. "
        "Likely causes: the model is not the recorded robot's ({setting:kinematics}), the joint "
        "states are not the robot's encoders, or the arm's error is not kinematic "
        "(elasticity, heat). Calibrate with {setting:nominal_kinematics} to keep the model "
        "nominal. No result was written."
    )


def kinematic_problem(
    samples_points: list[FloatArray],
    q: FloatArray,
    setup: KinematicSetup,
    T_flange_sensor0: ArrayLike,
    cylinder0: Cylinder,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
) -> tuple[CylinderProblem, CylinderState]:
    """The cylinder problem at the nominal forward kinematics of joint vectors q (M, n), with
    the arm's repeatability as the pose corrections' prior, and its start state."""
    cfg = RefineConfig() if config is None else config
    cfg = replace(
        cfg,
        robot_sigma_t_m=setup.config.repeatability_t_m,
        robot_sigma_r_rad=setup.config.repeatability_r_rad,
    )
    estimate_radius = radius_m is None or cfg.estimate_radius
    problem = build_problem(
        samples_points, forward_kinematics(setup.model, q), cfg, estimate_radius
    )
    state = initial_state(
        problem, T_flange_sensor0, cylinder0, cylinder0.radius if radius_m is None else radius_m
    )
    centroid = data_centroid(problem, state)
    return replace(problem, centroid=centroid), recentred(state, centroid)


@dataclass(frozen=True)
class JointScan:
    """One recording of a joint calibration: a cylinder placement's samples and joint states.

    Attributes
    ----------
    samples_points : list of ndarray, shape (N_j, 3)
        Inlier profile points of each sample in the sensor frame, m.
    stamps_ns : ndarray of int64, shape (M,)
        Profile stamps, ns (the joint states are interpolated there).
    cylinder0 : Cylinder
        Start, e.g. :func:`.refine.refine_with_outlier_rejection` on the nominal poses.
    setup : KinematicSetup
        The model (the same for every scan) and this recording's joint states.
    """

    samples_points: list[FloatArray]
    stamps_ns: NDArray[np.int64]
    cylinder0: Cylinder
    setup: KinematicSetup


def refine_kinematics(
    scans: Sequence[JointScan],
    T_flange_sensor0: ArrayLike,
    config: RefineConfig | None = None,
    radius_m: float | None = None,
) -> tuple[list[RefineResult], JointOutcome[Any]]:
    """The refinement with the flange poses from joint states and a corrected robot model.

    The same cylinder problem, its flange poses the forward kinematics of each sample's
    joint vector with the identifiable kinematic corrections estimated
    (:func:`~linelaser_calib.core.robot.joint_calibration.solve_joint`); the per-sample pose
    corrections have the arm's repeatability as prior (``setup.config``). Several scans
    (cylinder placements scanned by the same arm) are solved together
    (:class:`~linelaser_calib.core.robot.joint_calibration.MultiScanProblem`: one hand-eye, one
    set of corrections, a cylinder per scan).

    Parameters
    ----------
    scans : sequence of JointScan
        At least one; the first one's model and settings apply to all.
    T_flange_sensor0 : array_like, shape (4, 4)
        Start.
    config : RefineConfig, optional
    radius_m : float, optional
        Known radius, m; None estimates it (per scan).

    Returns
    -------
    list of RefineResult
        Per scan, at the corrected poses; the 1σ are the hand-eye's, marginal over the
        kinematic corrections and every scan's cylinder.
    JointOutcome
        Its state is the first scan's state (one scan) or the tuple of the scans' states.
    """
    setup = scans[0].setup
    problems, states, qs = [], [], []
    for scan in scans:
        q = scan.setup.joint_positions(scan.stamps_ns)
        problem, state = kinematic_problem(
            scan.samples_points, q, scan.setup, T_flange_sensor0, scan.cylinder0, config, radius_m
        )
        problems.append(problem)
        states.append(state)
        qs.append(q)
    cfg = problems[0].config
    together: Any = problems[0] if len(scans) == 1 else MultiScanProblem(tuple(problems))
    start: Any = states[0] if len(scans) == 1 else tuple(states)
    outcome = solve_joint(together, start, setup.model, np.vstack(qs), setup.config, cfg.solver)
    joint = outcome.solution
    poses = outcome.pose_model.poses(joint.state.delta)
    found = [outcome.state] if len(scans) == 1 else list(outcome.state)
    bounds = np.cumsum([0, *(p.n_samples for p in problems)])
    results = []
    for i, (problem, state) in enumerate(zip(problems, found, strict=True)):
        corrected = problem.with_flange_poses(poses[bounds[i] : bounds[i + 1]])
        linearisation = corrected.linearise(state)
        inner = Solution(
            state=state,
            residuals=linearisation.residuals,
            normal=normal_equations(linearisation, cfg.solver),
            cost_history=joint.cost_history,
            iterations=joint.iterations,
            converged=joint.converged,
        )
        results.append(summarise(corrected, inner))
    _check_kinematic_fit(max(r.robot_sigma_scale for r in results), outcome, setup)
    sigma = np.sqrt(np.diag(outcome.covariance)[:N_HAND_EYE])
    for result in results:
        result.sigma_rotation_rad, result.sigma_translation_m = sigma[:3], sigma[3:]
        result.covariance_hand_eye = outcome.covariance[:N_HAND_EYE, :N_HAND_EYE]
        result.sample_dispersion = None  # the joint covariance is not widened
    return results, outcome
