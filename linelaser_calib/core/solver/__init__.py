"""One block-sparse Levenberg–Marquardt solver and one outlier-rejection loop for every target.

The solver knows no target. A target describes its least-squares problem through
:class:`~linelaser_calib.core.solver.lm.BlockProblem`: a state (any object), its retraction, and
at each state per-sample residual blocks with Jacobians on the G global parameters (hand-eye
first, then the target's own) and on the sample's 6 local flange-pose corrections, plus
Gaussian priors on the corrections and on the global parameters. :func:`solve` returns the
estimate, the block normal equations at it (whose Schur complement is the information of the
global parameters with every pose correction marginalised), the cost history and whether it
converged. :func:`solve_with_rejection` drops the samples a target flags and solves again.
"""

from __future__ import annotations

from .lm import (
    LOSSES,
    N_HAND_EYE,
    N_LOCAL,
    BlockNormal,
    BlockProblem,
    ChunkedProblem,
    CountedProblem,
    Linearisation,
    Residuals,
    Solution,
    SolverConfig,
    cost,
    dispersion_warning,
    evaluate_loss,
    normal_equations,
    robust_costs,
    sample_dispersion,
    solve,
    solve_damped,
    variance_factors,
    widen_covariance,
    widening,
)
from .rejection import (
    Flag,
    RejectionOutcome,
    recording_chi2_scale,
    recording_widening,
    solve_with_rejection,
)

__all__ = [
    "LOSSES",
    "N_HAND_EYE",
    "N_LOCAL",
    "BlockNormal",
    "BlockProblem",
    "ChunkedProblem",
    "CountedProblem",
    "Flag",
    "Linearisation",
    "RejectionOutcome",
    "Residuals",
    "Solution",
    "SolverConfig",
    "cost",
    "dispersion_warning",
    "evaluate_loss",
    "normal_equations",
    "recording_chi2_scale",
    "recording_widening",
    "robust_costs",
    "sample_dispersion",
    "solve",
    "solve_damped",
    "solve_with_rejection",
    "variance_factors",
    "widen_covariance",
    "widening",
]
