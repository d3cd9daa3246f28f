"""Warm solves of a solved cylinder problem: some of its samples (the self-check's subsets,
the clock-offset search's features) or its samples at other flange poses, each started at
the full solution and stopped at looser tolerances than the full solve's."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from ...errors import DegenerateError, SolverError
from ...geometry import FloatArray
from ...solver import BlockNormal, Residuals, Solution, SolverConfig, solve
from .config import RefineConfig
from .problem import CylinderProblem, CylinderState
from .refine import RefineResult, SolvedProblem, outlier_rounds, screened, summarise

#: Step tolerance of :func:`refine_subset`, m: 10 nm, a thousandth of the smallest 1σ this
#: tool reports (a few µm); the full solve's 1e-12 m would cost it one or two more
#: linearisations.
SUBSET_STEP_TOLERANCE_M = 1e-8


#: Cost tolerance of :func:`refine_subset`: it stops when a step lowers the cost by less
#: than this fraction. With some 10⁴ points that step moved the hand-eye by under 1 % of
#: its 1σ, and what is left is smaller again. Where the robust loss slows convergence it
#: saves a few linearisations (cluttered_camera: 9-12 instead of 13-21; the jackknife's
#: statistics move by 1e-3 of themselves).
SUBSET_COST_TOLERANCE = 1e-8

#: Stopping rule of :func:`refine_subset`, before the two above: the step of the current
#: linearisation moves no global parameter (hand-eye, axis, radius, scales) by more than
#: this fraction of its 1σ (with the noise levels the solved problem learned). The
#: self-check reads a subset's hand-eye and axis against moves of about their 1σ, so what
#: is left is far below anything it can tell; and the solve ends at that linearisation,
#: where a stop on the cost's decrease takes the step and linearises once more. A
#: re-solve under a tighter robot prior (the plain model) converges only linearly where
#: the robust loss down-weights many points: this stop saves it two or three
#: linearisations of seven, the default model's subsets one of three.
SUBSET_STEP_SIGMAS = 0.01


def refine_subset(
    solved: SolvedProblem,
    rows: Sequence[int],
    prior: RefineConfig | None = None,
    final: bool = False,
    widen: bool = True,
) -> RefineResult:
    """The refinement of some samples of a solved problem, started at its solution.

    The samples keep their points as solved (trimmed, subsampled) and start at the full
    solution with their own pose corrections; no seed solve, no point trimming and no
    outlier rejection run again (the full solve screened these samples). Leaving samples out
    moves the optimum by about its 1σ, so the solve converges, to
    :data:`SUBSET_STEP_SIGMAS` of the 1σ, in two linearisations on clean data (a few more
    where the robust loss down-weights many points) instead of a dozen: the self-check's
    twelve subset solves (leave-some-out, halves, regions) go through here. One Gauss–Newton
    step is not enough: on cluttered data it moves the jackknife's dispersion by 20 %.

    Parameters
    ----------
    solved : SolvedProblem
        :attr:`RefineResult.solved` of the full solve.
    rows : sequence of int
        Positions of the samples in ``solved.problem``.
    prior : RefineConfig, optional
        Whose per-pose robot-error prior (``robot_sigma_t_m``, ``robot_sigma_r_rad``: the
        self-check's plain model) and scales estimated (``estimate_scale``,
        ``estimate_depth_scale``: ``--scale auto`` holding one) the solve takes instead of
        the solved problem's (:func:`_under`). None keeps the problem's.
    final : bool
        Solve to the problem's own tolerances, for a result reported rather than one read
        against moves of about its 1σ. The profile-scatter test
        (:func:`~linelaser_calib.core.solver.sample_dispersion`) reads each sample's share
        of the gradient, which the subsets' stop leaves too large (``ur_scancontrol``, the x
        scale held: the hand-eye's z seemed to scatter 3.2 times the noise model's, 1.0
        converged), and the subsets' cost tolerance moves the 1σ by 0.1 %.
    widen : bool
        False: no 1σ widened by the profiles' scatter
        (:func:`~linelaser_calib.core.solver.sample_dispersion`), for a solve whose 1σ is
        read as the noise model's (the self-check's subsets:
        :func:`~linelaser_calib.core.subsets.model_sigma` divides that widening out again;
        at their loose stop the scatter reads too large anyway, see ``final``). It saves a
        seventh of a subset's solve.

    Returns
    -------
    RefineResult
        ``used`` indexes ``rows``.

    Raises
    ------
    DegenerateError
        Fewer samples than ``min_samples``, or poses that leave a direction unobservable.
    SolverError
        The solve produced non-finite numbers.
    """
    full, at = solved.problem, solved.state
    keep = np.asarray(rows, dtype=np.intp)
    if len(keep) < full.config.min_samples:
        raise DegenerateError(
            f"{len(keep)} samples given, but the refinement needs at least "
            f"{full.config.min_samples}"
        )
    problem = full.take(keep)
    if not widen:
        problem = replace(problem, config=replace(problem.config, widen_by_dispersion=False))
    start = replace(at, omega=at.omega[keep], tau=at.tau[keep])
    # The solved problem's equations at its solution hold these samples' own: the first
    # linearisation, where the problem stays the same (its residuals, about a third of a
    # linearisation's cost, are formed again rather than kept beside every solved problem).
    normal = solved.normal if prior is None else None
    if prior is not None:
        problem, start = _under(prior, problem, start)

    def linearised() -> tuple[BlockNormal, Residuals]:
        assert normal is not None
        return normal.take(keep), problem.residuals(start)

    tolerances = (
        problem.config.solver
        if final
        else replace(
            _near(problem),
            step_sigmas=SUBSET_STEP_SIGMAS,
            variance_factors=solved.variance_factors,
        )
    )
    first = None if normal is None else linearised
    solution = _solve_near(problem, start, "of a subset", tolerances, first)
    return summarise(problem, solution, solved.noise)


def refine_screened(
    solved: SolvedProblem, rows: Sequence[int], prior: RefineConfig, final: bool = False
) -> RefineResult:
    """The refinement of some samples of a solved problem under another robot-error
    ``prior`` or scale model (:func:`refine_subset`, ``final`` as there), with the outlier
    rounds of :func:`.refine.refine_with_outlier_rejection` run again (another scale model
    is another fit of the same robot-error model; the self-check's solves keep the solved
    problem's samples instead, :attr:`~..base.SolveContext.screen_outliers`). Each
    round starts at the last one's solution. ``used`` and ``dropped`` index ``rows``.

    Raises
    ------
    DegenerateError, SolverError
        As :func:`refine_subset`.
    """
    last: list[int] = []  # the rows of the last round's solve, in its problem's order

    def solve_rows(keep: list[int], previous: RefineResult | None) -> RefineResult:
        if previous is None or previous.solved is None:
            result = refine_subset(solved, [rows[i] for i in keep], prior, final)
        else:
            at = {i: k for k, i in enumerate(last)}
            result = refine_subset(previous.solved, [at[i] for i in keep], final=final)
        last[:] = keep
        return result

    return screened(outlier_rounds(len(rows), solve_rows, prior), prior)


def _under(
    prior: RefineConfig, problem: CylinderProblem, start: CylinderState
) -> tuple[CylinderProblem, CylinderState]:
    """``problem`` under ``prior``'s robot-error prior and scale model, and its start: the
    pose corrections restart at zero under another robot prior, and a scale no longer
    estimated is held at its nominal 1."""
    config = replace(
        problem.config,
        robot_sigma_t_m=prior.robot_sigma_t_m,
        robot_sigma_r_rad=prior.robot_sigma_r_rad,
        estimate_scale=prior.estimate_scale,
        estimate_depth_scale=prior.estimate_depth_scale,
    )
    solved_prior = (problem.config.robot_sigma_t_m, problem.config.robot_sigma_r_rad)
    if solved_prior != (prior.robot_sigma_t_m, prior.robot_sigma_r_rad):
        start = replace(start, omega=np.zeros_like(start.omega), tau=np.zeros_like(start.tau))
    problem = replace(
        problem,
        config=config,
        estimate_scale=prior.estimate_scale,
        estimate_depth_scale=prior.estimate_depth_scale,
    )
    start = replace(
        start,
        scale=start.scale if prior.estimate_scale else 0.0,
        depth_scale=start.depth_scale if prior.estimate_depth_scale else 0.0,
    )
    return problem, start


def _near(problem: CylinderProblem, max_iterations: int | None = None) -> SolverConfig:
    """The problem's solver settings with the tolerances of a solve from near its optimum,
    :data:`SUBSET_STEP_TOLERANCE_M` and :data:`SUBSET_COST_TOLERANCE`, and at most
    ``max_iterations`` linearisations (None: the problem's solver's)."""
    return replace(
        problem.config.solver,
        step_tolerance_m=SUBSET_STEP_TOLERANCE_M,
        tolerance=SUBSET_COST_TOLERANCE,
        max_iterations=max_iterations or problem.config.solver.max_iterations,
    )


def _solve_near(
    problem: CylinderProblem,
    start: CylinderState,
    what: str,
    tolerances: SolverConfig,
    linearised: Callable[[], tuple[BlockNormal, Residuals]] | None = None,
) -> Solution[CylinderState]:
    """The solve of a problem from a state near its optimum with ``tolerances``
    (:func:`_near`), SolverError on non-finite numbers, naming ``what``; ``linearised`` gives
    its normal equations and residuals at ``start`` where known (``solve``'s ``start``)."""
    solution = solve(problem, start, tolerances, linearised)
    if not (np.all(np.isfinite(solution.state.R_fs)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError(f"the refinement {what} produced non-finite values")
    return solution


def refine_at_poses(
    solved: SolvedProblem, T_base_flange: FloatArray, max_iterations: int | None = None
) -> tuple[SolvedProblem, float]:
    """The refinement of a solved problem's samples at other flange poses (M, 4, 4), started
    at its solution, and its final cost (dimensionless, as :attr:`RefineResult.cost_history`).

    The clock-offset search re-pairs the same points with poses a few ms away, which moves
    the optimum little: from a nearby solution the solve converges (to
    :data:`SUBSET_STEP_TOLERANCE_M` and :data:`SUBSET_COST_TOLERANCE`: the search compares
    costs) without a new problem, seed or observability check;
    ``max_iterations`` bounds its linearisations (None: the solver's bound).

    Raises
    ------
    SolverError
        The solve produced non-finite numbers.
    """
    problem = solved.problem.with_flange_poses(np.asarray(T_base_flange, dtype=np.float64))
    solution = _solve_near(
        problem, solved.state, "at other flange poses", _near(problem, max_iterations)
    )
    # Without equations: no subset is solved from it, and they would hold memory.
    moved = replace(solved, problem=problem, state=solution.state, normal=None)
    return moved, solution.cost_history[-1]
