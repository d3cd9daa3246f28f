"""The robot's error shared by neighbouring profiles, counted in the cylinder's 1σ.

The refinement's 1σ takes each profile's pose error as its own (an independent prior per
sample); a real arm errs by region. :mod:`...shared_pose` learns from the residuals how far
neighbouring views share the error and gives the 1σ of the same estimate under it; this
module hands it the refinement's views (:meth:`~...shared_pose.ViewsLinearised.from_points`:
each profile's points reduced to the directions its parameters move, with the robust
weights and the sensor and robot variance factors of the reported covariance), and
:func:`with_shared` reports the wider 1σ per axis. The estimate is left alone.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...geometry import FloatArray
from ...shared_pose import SharedPoseError, ViewsLinearised, shared_pose_error
from .refine import RefineResult, SolvedProblem


def _flange_poses(solved: SolvedProblem) -> FloatArray:
    """The solved problem's reported flange poses (M, 4, 4)."""
    problem = solved.problem
    T = np.zeros((problem.n_samples, 4, 4))
    T[:, :3, :3] = problem.R_bf
    T[:, :3, 3] = problem.t_bf
    T[:, 3, 3] = 1.0
    return T


def shared_error(
    solved: SolvedProblem, learned: SharedPoseError | None = None
) -> SharedPoseError | None:
    """:func:`~...shared_pose.shared_pose_error` of a solved refinement's views (``learned``
    on a superset of them: the self-check's subsets); None where too few views."""
    problem, state = solved.problem, solved.state
    views = ViewsLinearised.from_points(
        problem,
        state,
        np.concatenate([state.omega, state.tau], axis=1),
        problem.config.solver,
        problem.mask,
        _flange_poses(solved),
        solved.variance_factors,
    )
    return shared_pose_error(views, learned)


def shared_widening(
    solved: SolvedProblem, own: FloatArray, learned: SharedPoseError | None = None
) -> tuple[FloatArray, SharedPoseError, FloatArray] | None:
    """The hand-eye 1σ (6,), per axis the wider of ``own`` and the one under the robot's
    error as the solved refinement's views share it (:func:`shared_error`), that sharing
    and the factors (6,) it widened ``own`` by; None with too few views."""
    shared = shared_error(solved, learned)
    if shared is None:
        return None
    sigma = np.maximum(own, np.sqrt(np.diag(shared.covariance)[:6]))
    return sigma, shared, sigma / own


def with_shared(
    refined: RefineResult, learned: SharedPoseError | None = None
) -> tuple[RefineResult, SharedPoseError | None, FloatArray | None]:
    """``refined`` with its hand-eye 1σ widened by :func:`shared_widening`, that sharing and
    the factors (6,) (None without a solved problem or with too few views)."""
    if refined.solved is None:
        return refined, None, None
    own = np.r_[refined.sigma_rotation_rad, refined.sigma_translation_m]
    widened = shared_widening(refined.solved, own, learned)
    if widened is None:
        return refined, None, None
    sigma, shared, factors = widened
    return (
        replace(refined, sigma_rotation_rad=sigma[:3], sigma_translation_m=sigma[3:]),
        shared,
        factors,
    )
