"""The cylinder paper's seed solver: PSO fused with the generalized Lagrange multiplier method.

Faithful parts (the cylinder paper, §3.3, Fig. 4):

- :func:`~.galm.galm` is the generalized Lagrange multiplier method of §3.3.1: BFGS minimises
  φ(x, λ, σ) = f(x) − λᵀh(x) + σ/2 ‖h(x)‖² (eq. 14); stop when ‖h‖ ≤ ε; σ ← ησ when
  ‖h_k‖ > α‖h_{k−1}‖; λ ← λ − σ_k h(x_k).
- :func:`~.pso.pso` is plain PSO with the update of eq. 15.
- :func:`solve_pso_galm` is the 7-step hybrid of §3.3.3: particles are GALM initial points,
  g_best and f_best are initialised from the first swarm; each generation the best and the
  worst particle are found; if the generation's best beats f_best it becomes g_best,
  otherwise GALM runs from the worst particle and its result replaces g_best if its φ is
  lower; stop when n ≥ n_max or f_best < ψ; move the particles by eq. 15 towards g_best.

Choices where the paper is silent (documented defaults):

- PSO constants w = 0.729, c1 = c2 = 1.494 (the constriction-equivalent values of Clerc and
  Kennedy); velocities are clamped to a fraction of the box width and positions are clamped
  to the box (the velocity component that hit the wall is zeroed).
- Particle fitness is φ(x, λ0 = 0, σ0), i.e. f + σ0/2‖h‖²; a GALM result is compared by
  φ at its own final (λ_k, σ_k), as in Fig. 4.
- GALM parameters σ0, η, α, ε and the BFGS tolerances (below).

Departures, each with its switch in :class:`HybridConfig`:

1. ``normalised=True`` (default): the bounded cost with N/|N|
   (:mod:`~linelaser_calib.core.targets.cylinder.model`, departure 1); ``False`` is the literal
   eq. 12, whose GALM runs diverge. A GALM run flagged as diverged never becomes g_best.
2. ``PsoConfig.stagnation_generations`` (default 6, 0 disables): the hybrid also stops after
   that many generations without improvement of f_best (the paper only has n_max and ψ,
   and ψ is below the noise floor of noisy data).
3. ``box="data"`` (default): search box from the data. The paper's Table 2 box (t and the
   axis point in [0, 300] mm) only fits its own scene. The data box keeps a_ij, m, l, n in
   [−1, 1], takes t ∈ [−b, b]³ (b = ``translation_bound_m``) and the axis point in the
   bounding box of the flange positions grown by b plus the largest centre norm, which
   holds every centre O_j and so a stretch of the axis. ``box="paper"`` gives Table 2.
4. ``faithful=False`` (default) adds two steps after the hybrid:

   - Polish: g_best seeds a Levenberg-Marquardt least-squares fit on a minimal
     parametrisation (rotation vector, t, two direction components, two axis offsets) of
     the centre-to-axis residuals, so that the rotation is exactly orthonormal (the paper
     has no a1 ⊥ a3 constraint) and the unit norms hold exactly.
   - Restarts: if the polished RMS centre-to-axis distance exceeds ``accept_rms_m``, the
     hybrid runs again from a new swarm, up to ``max_restarts`` times, keeping the best.
     They stop early when a swarm ends on the best solution again (polished RMS equal to
     within ``same_minimum_rtol``): two independent swarms agreeing is the sign of the
     global minimum of data that cannot reach ``accept_rms_m``, e.g. noisy centres or one
     wrong centre, where more swarms only cost time (~0.5 s each).
   - Early acceptance (``accept_early=True``, off by default): g_best is polished whenever
     it changes, and the swarm stops as soon as the polished RMS distance is at most
     ``accept_rms_m``. A seed for the maximum-likelihood refinement only has to land in its
     basin, and on the paper's data the polished best particle of the first swarm usually
     does: one or two polishes (~10 ms) instead of the full hybrid (0.3-0.7 s).

The paper's algorithm is ``HybridConfig(faithful=True, box="paper")`` (with the bounded cost;
add ``normalised=False`` for the literal one).

Units: configs are SI (ψ in m²); inside, the problem's length unit applies
(:class:`~linelaser_calib.core.targets.cylinder.model.CentreAxisProblem`). GALM works on f in that
unit: σ0 and the divergence bound are in unit², which with the default unit (the RMS centre
norm) makes them scale-free.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from linelaser_calib.core.errors import DegenerateError, InputError, SolverError
from linelaser_calib.core.geometry import matrix_from_rotvec, orthonormal_basis
from linelaser_calib.core.targets.cylinder.galm import GalmConfig, galm
from linelaser_calib.core.targets.cylinder.model import (
    DIRECTION,
    N_PARAMS,
    POINT,
    TRANS,
    CentreAxisProblem,
    Cylinder,
    calibration_from_x,
    x_from_calibration,
)
from linelaser_calib.core.targets.cylinder.pso import PsoConfig, Stagnation, Swarm
from linelaser_calib.core.types import FloatArray

#: Table 2 box: a_ij, m, l, n in [-1, 1]; t and the axis point in [0, 300] mm.
PAPER_BOX_MM = (
    np.array([-1.0] * 6 + [0.0] * 6 + [-1.0] * 3),
    np.array([1.0] * 6 + [300.0] * 6 + [1.0] * 3),
)


@dataclass(frozen=True)
class HybridConfig:
    """PSO + GALM hybrid (Fig. 4) and this package's departures (see the module docstring).

    Attributes
    ----------
    pso : PsoConfig
        ``psi`` in m².
    galm : GalmConfig
        In the problem's internal unit.
    faithful : bool
        True runs the paper's algorithm only: no polish, no restarts.
    normalised : bool
        Bounded cost with N/|N| (default) or the paper-literal eq. 9.
    box : {"data", "paper"}
        Search box derived from the data, or the paper's Table 2 box.
    translation_bound_m : float
        Half-width b of the hand-eye translation box, m (``box="data"``).
    length_unit_m : float or None
        Internal length unit, m; None takes the RMS norm of the centres.
    accept_rms_m : float
        Largest polished RMS centre-to-axis distance that ends the restarts, m.
    max_restarts : int
        Extra swarms tried when a run is not accepted.
    same_minimum_rtol : float
        Restarts stop when a swarm's polished RMS distance equals the best one to this
        relative tolerance (the same minimum found twice); 0 disables.
    accept_early : bool
        Polish g_best whenever it changes and end the swarm once the polished RMS distance
        is at most ``accept_rms_m`` (module docstring, departure 4). Not with ``faithful``.
    """

    pso: PsoConfig = field(default_factory=PsoConfig)
    galm: GalmConfig = field(default_factory=GalmConfig)
    faithful: bool = False
    normalised: bool = True
    box: Literal["data", "paper"] = "data"
    translation_bound_m: float = 0.5
    length_unit_m: float | None = None
    accept_rms_m: float = 5e-4
    max_restarts: int = 8
    same_minimum_rtol: float = 1e-3
    accept_early: bool = False

    def __post_init__(self) -> None:
        if self.box not in ("data", "paper"):
            raise InputError(f"box must be 'data' or 'paper', got {self.box!r}")
        if self.faithful and self.accept_early:
            raise InputError(
                "accept_early polishes the swarm's best, which the faithful algorithm does not "
                "do: use faithful=False with accept_early=True"
            )
        if self.translation_bound_m <= 0.0 or self.accept_rms_m <= 0.0 or self.max_restarts < 0:
            raise InputError(
                "translation_bound_m and accept_rms_m must be positive and max_restarts >= 0"
            )
        if not self.same_minimum_rtol >= 0.0:
            raise InputError(f"same_minimum_rtol must be >= 0, got {self.same_minimum_rtol}")


@dataclass(frozen=True)
class PaperSolution:
    """Result of :func:`solve_pso_galm`, SI units.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        Hand-eye; rotation completed with a2 = a3 × a1 and projected onto SO(3).
    cylinder : Cylinder
        Axis in the base frame (point closest to the origin, unit direction). The radius is
        not estimated by this method: NaN, to be set by the caller.
    x : ndarray, shape (15,)
        The raw vector of eq. 10 (t and the axis point in m) the solver ended with.
    f_m2 : float
        f(x) in m² (in the configured cost form).
    rms_m : float
        RMS centre-to-axis distance of the returned transform and axis, m.
    h_norm : float
        ‖h(x)‖ of the raw vector.
    accepted : bool
        Faithful mode: f_best < ψ was reached. Otherwise: the polished RMS distance is at
        most ``accept_rms_m``.
    generations : int
        PSO generations run, summed over restarts (the paper's "iterations").
    galm_runs, galm_iterations : int
        GALM runs and their outer iterations, summed.
    restarts : int
        Extra swarms used.
    history : dict of str to list of float
        ``pso_best``: f_best after each generation (m²); ``galm_phi`` and ``galm_f``:
        φ and f after each GALM outer iteration (m²), runs concatenated (paper Figs. 5-6);
        ``galm_h``: the constraint violation ‖h‖ (dimensionless, eq. 11) with them.
    time_s : float
        Wall-clock time of the solve, s.
    """

    T_flange_sensor: FloatArray
    cylinder: Cylinder
    x: FloatArray
    f_m2: float
    rms_m: float
    h_norm: float
    accepted: bool
    generations: int
    galm_runs: int
    galm_iterations: int
    restarts: int
    history: dict[str, list[float]]
    time_s: float


@dataclass
class _Run:
    """Mutable bookkeeping of one hybrid solve."""

    generations: int = 0
    galm_runs: int = 0
    galm_iterations: int = 0
    history: dict[str, list[float]] = field(
        default_factory=lambda: {"pso_best": [], "galm_phi": [], "galm_f": [], "galm_h": []}
    )


def search_box(problem: CentreAxisProblem, config: HybridConfig) -> tuple[FloatArray, FloatArray]:
    """The PSO search box in the problem's unit, shape (15,) each (module docstring, item 3)."""
    if config.box == "paper":
        scale = np.where(np.arange(N_PARAMS) < 6, 1.0, 1e-3 / problem.unit_m)
        scale[DIRECTION] = 1.0
        return PAPER_BOX_MM[0] * scale, PAPER_BOX_MM[1] * scale
    b = config.translation_bound_m / problem.unit_m
    grow = b + float(np.max(np.linalg.norm(problem.centres_xz, axis=1)))
    lower = -np.ones(N_PARAMS)
    upper = np.ones(N_PARAMS)
    lower[TRANS], upper[TRANS] = -b, b
    lower[POINT] = problem.positions.min(axis=0) - grow
    upper[POINT] = problem.positions.max(axis=0) + grow
    return lower, upper


def solve_pso_galm(
    centres_xz: ArrayLike,
    T_base_flange: ArrayLike,
    config: HybridConfig = HybridConfig(),
    rng: np.random.Generator | None = None,
) -> PaperSolution:
    """Hand-eye and cylinder axis from ellipse centres, with no initial guess (§3.3.3).

    Parameters
    ----------
    centres_xz : array-like, shape (M, 2)
        Ellipse centres in the sensor x-z plane, m.
    T_base_flange : array-like, shape (M, 4, 4)
        Flange pose of each centre, m.
    config : HybridConfig
    rng : numpy.random.Generator, optional
        Source of all randomness; ``default_rng(0)`` if omitted.

    Returns
    -------
    PaperSolution

    Raises
    ------
    InputError, DegenerateError
        Bad data (see :meth:`CentreAxisProblem.from_data`).
    SolverError
        The faithful solver ended on a vector that is no hand-eye (a1 ∥ a3). A solve that
        merely misses ψ or ``accept_rms_m`` does not raise: see ``accepted``.
    """
    start = time.perf_counter()
    rng = np.random.default_rng(0) if rng is None else rng
    problem = CentreAxisProblem.from_data(
        centres_xz, T_base_flange, normalised=config.normalised, unit_m=config.length_unit_m
    )
    area = problem.unit_m**2
    psi = config.pso.psi / area
    lower, upper = search_box(problem, config)
    run = _Run()
    best_x, f_best, polished = _hybrid(problem, lower, upper, psi, config, rng, run)
    accepted = f_best < psi
    restarts = 0
    if not config.faithful:
        best_x, best_rms = polished or _polish(problem, best_x)
        while best_rms > config.accept_rms_m and restarts < config.max_restarts:
            restarts += 1
            x, _, polished = _hybrid(problem, lower, upper, psi, config, rng, run)
            x, rms = polished or _polish(problem, x)
            if abs(rms - best_rms) < config.same_minimum_rtol * best_rms:
                break
            if rms < best_rms:
                best_x, best_rms = x, rms
        accepted = best_rms <= config.accept_rms_m
    try:
        T_flange_sensor, cylinder = calibration_from_x(best_x, problem.unit_m)
    except DegenerateError as err:
        raise SolverError(
            f"the PSO+GALM solver ended on a point that is no hand-eye ({err}); "
            "use the default (non-faithful) mode or more varied flange poses"
        ) from err
    x_si = best_x.copy()
    x_si[TRANS] *= problem.unit_m
    x_si[POINT] *= problem.unit_m
    return PaperSolution(
        T_flange_sensor=T_flange_sensor,
        cylinder=cylinder,
        x=x_si,
        f_m2=float(problem.cost(best_x[None])[0]) * area,
        rms_m=_rms(problem, x_from_calibration(T_flange_sensor, cylinder, problem.unit_m)),
        h_norm=float(np.linalg.norm(problem.constraints(best_x))),
        accepted=accepted,
        generations=run.generations,
        galm_runs=run.galm_runs,
        galm_iterations=run.galm_iterations,
        restarts=restarts,
        history=run.history,
        time_s=time.perf_counter() - start,
    )


def _rms(problem: CentreAxisProblem, x: FloatArray) -> float:
    """RMS centre-to-axis distance of x (internal units), m."""
    return float(np.sqrt(np.mean(problem.distances_m(x) ** 2)))


def _hybrid(
    problem: CentreAxisProblem,
    lower: FloatArray,
    upper: FloatArray,
    psi: float,
    config: HybridConfig,
    rng: np.random.Generator,
    run: _Run,
) -> tuple[FloatArray, float, tuple[FloatArray, float] | None]:
    """One swarm of the 7-step hybrid (Fig. 4).

    Returns g_best and f_best (internal units), and with ``config.accept_early`` the
    polished g_best and its RMS distance (m) when that was accepted, else None.
    """
    area = problem.unit_m**2
    sigma0 = config.galm.sigma0

    def fitness(X: FloatArray) -> FloatArray:
        H = problem.constraints(X)
        return np.asarray(problem.cost(X) + 0.5 * sigma0 * np.sum(H**2, axis=1))

    def polished_if_accepted(x: FloatArray) -> tuple[FloatArray, float] | None:
        if not config.accept_early:
            return None
        polished = _polish(problem, x)
        return polished if polished[1] <= config.accept_rms_m else None

    swarm = Swarm(lower, upper, config.pso, rng)
    stagnation = Stagnation(config.pso.stagnation_generations, config.pso.stagnation_tol)
    F = fitness(swarm.x)  # step 1: g_best and f_best from the initial swarm
    swarm.record(F)
    g_best, f_best = swarm.x[int(np.argmin(F))].copy(), float(np.min(F))
    early = polished_if_accepted(g_best)
    for n in range(1, config.pso.max_generations + 1):
        if early is not None:
            break
        if n > 1:  # step 2 (the first generation is the initial swarm)
            F = fitness(swarm.x)
            swarm.record(F)
        best, worst = int(np.argmin(F)), int(np.argmax(F))
        if F[best] < f_best:  # step 3
            g_best, f_best = swarm.x[best].copy(), float(F[best])
            early = polished_if_accepted(g_best)
        else:  # step 4
            result = galm(swarm.x[worst], problem, config.galm)
            run.galm_runs += 1
            run.galm_iterations += result.iterations
            run.history["galm_phi"].extend(v * area for v in result.history_phi)
            run.history["galm_f"].extend(v * area for v in result.history_f)
            run.history["galm_h"].extend(result.history_h)
            if not result.diverged and result.phi < f_best:
                g_best, f_best = result.x.copy(), result.phi
                early = polished_if_accepted(g_best)
        run.generations += 1
        run.history["pso_best"].append(f_best * area)
        if early is not None or f_best < psi or stagnation.stalled(f_best):  # step 5
            break
        swarm.step(g_best)  # step 6
    return g_best, f_best, early


def _polish(problem: CentreAxisProblem, x: FloatArray) -> tuple[FloatArray, float]:
    """Levenberg-Marquardt on a minimal parametrisation from x (departure 4).

    Parameters are a rotation vector applied on the left of the SO(3)-projected hand-eye
    rotation, t, two tangent components of the axis direction and two offsets of the axis
    point in the plane through the start point perpendicular to the start direction.

    Returns
    -------
    x : ndarray, shape (15,)
        Polished vector, internal units (x itself if it is no hand-eye).
    rms_m : float
        Its RMS centre-to-axis distance, m (inf if x is no hand-eye).
    """
    try:
        T0, cyl0 = calibration_from_x(x)  # unit_m = 1: internal units throughout
    except DegenerateError:
        return x, np.inf
    R0, n0 = T0[:3, :3], cyl0.direction
    P0 = x[POINT] - float((x[POINT] - cyl0.point) @ n0) * n0
    b1, b2 = orthonormal_basis(n0)
    c = np.zeros((problem.n_centres, 3))
    c[:, [0, 2]] = problem.centres_xz

    def unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        R = matrix_from_rotvec(p[0:3]) @ R0
        n = n0 + p[6] * b1 + p[7] * b2
        return R, p[3:6], n / np.linalg.norm(n), P0 + p[8] * b1 + p[9] * b2

    def residuals(p: FloatArray) -> FloatArray:
        R, t, n, point = unpack(p)
        W = np.einsum("mij,mj->mi", problem.rotations, c @ R.T + t) + problem.positions - point
        return np.asarray((W - np.outer(W @ n, n)).ravel())

    p0 = np.concatenate([np.zeros(3), T0[:3, 3], np.zeros(4)])
    solution = least_squares(residuals, p0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    R, t, n, point = unpack(solution.x)
    polished = np.concatenate([R[:, 0], R[:, 2], t, point, n])
    return polished, _rms(problem, polished)
