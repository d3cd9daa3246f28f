"""Plain particle swarm optimisation with the update of the cylinder paper's eq. 15.

Where the paper is silent: w = 0.729, c1 = c2 = 1.494 (the constriction-equivalent values of
Clerc and Kennedy); velocities are clamped to a fraction of the box width and positions to
the box (the velocity component that hit the wall is zeroed). The hybrid that uses the
swarm is :mod:`.pso_alm`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.types import FloatArray

#: The paper's ψ for the noisy simulation (0.5 mm²), in m².
PAPER_PSI_M2 = 0.5e-6


@dataclass(frozen=True)
class PsoConfig:
    """Particle swarm (eq. 15) and the hybrid's generation loop.

    Attributes
    ----------
    n_particles : int
        Swarm size (the paper uses 20).
    inertia : float
        w (not given by the paper).
    c1, c2 : float
        Cognitive and social acceleration (not given by the paper).
    max_generations : int
        n_max.
    psi : float
        Stop when the best fitness is below ψ, in the fitness's units; m² for
        :func:`.pso_alm.solve_pso_galm` (the paper's 0.5 mm² by default).
    stagnation_generations : int
        Stop after this many generations without a relative improvement of the best
        fitness larger than ``stagnation_tol`` (0 disables).
    stagnation_tol : float
        Relative improvement that counts as progress.
    velocity_clamp : float
        Largest velocity component as a fraction of the box width.
    """

    n_particles: int = 20
    inertia: float = 0.729
    c1: float = 1.494
    c2: float = 1.494
    max_generations: int = 30
    psi: float = PAPER_PSI_M2
    stagnation_generations: int = 6
    stagnation_tol: float = 1e-6
    velocity_clamp: float = 0.2

    def __post_init__(self) -> None:
        if self.n_particles < 2 or self.max_generations < 1:
            raise InputError("PSO needs at least 2 particles and 1 generation")
        if not 0.0 < self.velocity_clamp <= 1.0:
            raise InputError(f"velocity_clamp must be in (0, 1], got {self.velocity_clamp}")


@dataclass(frozen=True)
class PsoResult:
    """Outcome of :func:`pso`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Global best position.
    fitness : float
    generations : int
    history : list of float
        Best fitness after each generation (the initial swarm first).
    """

    x: FloatArray
    fitness: float
    generations: int
    history: list[float]


class Swarm:
    """Positions, velocities and personal bests of a swarm in a box (eq. 15)."""

    def __init__(
        self,
        lower: FloatArray,
        upper: FloatArray,
        config: PsoConfig,
        rng: np.random.Generator,
    ) -> None:
        self.lower, self.upper, self.config, self.rng = lower, upper, config, rng
        shape = (config.n_particles, lower.size)
        self.v_max = config.velocity_clamp * (upper - lower)
        self.x = rng.uniform(lower, upper, shape)
        self.v = rng.uniform(-self.v_max, self.v_max, shape)
        self.p_best = self.x.copy()
        self.p_fitness = np.full(config.n_particles, np.inf)

    def record(self, fitness: FloatArray) -> None:
        """Update the personal bests with the fitness (K,) of the current positions."""
        better = fitness < self.p_fitness
        self.p_best[better] = self.x[better]
        self.p_fitness[better] = fitness[better]

    def step(self, g_best: FloatArray) -> None:
        """Move every particle by eq. 15 towards its own best and the global best."""
        c = self.config
        r1 = self.rng.uniform(size=self.x.shape)
        r2 = self.rng.uniform(size=self.x.shape)
        self.v = (
            c.inertia * self.v
            + c.c1 * r1 * (self.p_best - self.x)
            + c.c2 * r2 * (g_best[None] - self.x)
        )
        self.v = np.clip(self.v, -self.v_max, self.v_max)
        x = self.x + self.v
        hit = (x < self.lower) | (x > self.upper)
        self.x = np.clip(x, self.lower, self.upper)
        self.v[hit] = 0.0


class Stagnation:
    """Counts consecutive generations without relative progress of the best fitness."""

    def __init__(self, generations: int, tol: float) -> None:
        self.generations, self.tol, self.count = generations, tol, 0
        self.last = np.inf

    def stalled(self, best: float) -> bool:
        if self.last - best > self.tol * abs(self.last) or not np.isfinite(self.last):
            self.count = 0
        else:
            self.count += 1
        self.last = min(self.last, best)
        return 0 < self.generations <= self.count


def pso(
    fitness: Callable[[FloatArray], FloatArray],
    lower: ArrayLike,
    upper: ArrayLike,
    config: PsoConfig,
    rng: np.random.Generator,
) -> PsoResult:
    """Minimise a function over a box with plain PSO (eq. 15).

    Parameters
    ----------
    fitness : callable
        Maps positions (K, n) to fitness (K,).
    lower, upper : array-like, shape (n,)
        Search box.
    config : PsoConfig
        ``psi`` is in the fitness's units.
    rng : numpy.random.Generator

    Returns
    -------
    PsoResult
    """
    lo, hi = _check_box(lower, upper)
    swarm = Swarm(lo, hi, config, rng)
    stagnation = Stagnation(config.stagnation_generations, config.stagnation_tol)
    F = fitness(swarm.x)
    swarm.record(F)
    g = int(np.argmin(F))
    g_best, f_best = swarm.x[g].copy(), float(F[g])
    history = [f_best]
    while len(history) <= config.max_generations:
        if f_best < config.psi or stagnation.stalled(f_best):
            break
        swarm.step(g_best)
        F = fitness(swarm.x)
        swarm.record(F)
        g = int(np.argmin(F))
        if F[g] < f_best:
            g_best, f_best = swarm.x[g].copy(), float(F[g])
        history.append(f_best)
    return PsoResult(x=g_best, fitness=f_best, generations=len(history) - 1, history=history)


def _check_box(lower: ArrayLike, upper: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate a search box: finite 1-D bounds of equal shape with lower < upper."""
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    if lo.ndim != 1 or lo.shape != hi.shape or not np.all(np.isfinite(lo) & np.isfinite(hi)):
        raise InputError(f"search box bounds must be finite vectors of equal length: {lo}, {hi}")
    if not np.all(lo < hi):
        raise InputError(f"search box lower bounds must be below the upper ones: {lo}, {hi}")
    return lo, hi
