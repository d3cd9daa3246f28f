"""The generalized Lagrange multiplier method (GALM) of the cylinder paper, §3.3.1.

BFGS minimises φ(x, λ, σ) = f(x) − λᵀh(x) + σ/2 ‖h(x)‖² (eq. 14); stop when ‖h‖ ≤ ε;
σ ← ησ when ‖h_k‖ > α‖h_{k−1}‖; λ ← λ − σ_k h(x_k). The parameters σ0, η, α, ε and the BFGS
tolerances, where the paper is silent, are documented defaults of :class:`GalmConfig`. The
hybrid that uses it is :mod:`.pso_alm`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.types import FloatArray


class ConstrainedProblem(Protocol):
    """An equality-constrained problem min f(x) s.t. h(x) = 0 (eq. 13), as GALM needs it."""

    def cost(self, x: ArrayLike) -> FloatArray:
        """f for a batch (K, n) -> (K,)."""
        ...

    def cost_and_gradient(self, x: ArrayLike) -> tuple[float, FloatArray]:
        """f and its gradient (n,) for one x (n,)."""
        ...

    def constraints(self, x: ArrayLike) -> FloatArray:
        """h, shape (l,) for x (n,) or (K, l) for (K, n)."""
        ...

    def constraints_jacobian(self, x: ArrayLike) -> FloatArray:
        """dh/dx, shape (l, n), for one x (n,)."""
        ...


@dataclass(frozen=True)
class GalmConfig:
    """Generalized Lagrange multiplier method (§3.3.1). Lengths in the problem's unit.

    Attributes
    ----------
    sigma0 : float
        Initial penalty σ0 > 0, in f units (unit²).
    eta : float
        Penalty growth η > 1.
    alpha : float
        Required constraint reduction ratio α ∈ (0, 1).
    epsilon : float
        Stop when ‖h(x_k)‖ ≤ ε (h is unitless).
    max_outer : int
        Most outer (multiplier) iterations.
    bfgs_gtol : float
        BFGS stop on the gradient's max-norm, f units per x unit.
    bfgs_max_iter : int
        Most BFGS iterations per inner solve.
    divergence_cost : float
        Abandon the run as diverged when φ or f falls below −divergence_cost (f units).
        On the constraint surface f ≥ 0, so only the unbounded literal cost gets there
        (the paper calls a result beyond 1e3 (mm²) diverged).
    divergence_x : float
        Abandon the run as diverged when max |x_i| exceeds this (x units): overflow guard.
    """

    sigma0: float = 10.0
    eta: float = 4.0
    alpha: float = 0.25
    epsilon: float = 1e-10
    max_outer: int = 30
    bfgs_gtol: float = 1e-8
    bfgs_max_iter: int = 400
    divergence_cost: float = 1e3
    divergence_x: float = 1e6

    def __post_init__(self) -> None:
        if not (self.sigma0 > 0.0 and self.eta > 1.0 and 0.0 < self.alpha < 1.0):
            raise InputError(
                f"GALM needs sigma0 > 0, eta > 1 and 0 < alpha < 1, got sigma0={self.sigma0}, "
                f"eta={self.eta}, alpha={self.alpha}"
            )
        if self.epsilon <= 0.0 or self.max_outer < 1 or self.bfgs_max_iter < 1:
            raise InputError("GALM needs epsilon > 0, max_outer >= 1 and bfgs_max_iter >= 1")


@dataclass(frozen=True)
class GalmResult:
    """Outcome of one GALM run (problem units).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Last iterate.
    f : float
        f(x).
    phi : float
        φ(x, λ_k, σ_k) with the multipliers and penalty the last inner solve used.
    h_norm : float
        ‖h(x)‖.
    iterations : int
        Outer iterations run.
    inner_iterations : int
        BFGS iterations summed over the outer ones.
    multipliers : ndarray, shape (l,)
        λ after the last update.
    sigma : float
        Penalty after the last update.
    converged : bool
        ‖h‖ ≤ ε was reached.
    diverged : bool
        f fell below −divergence_cost, x grew beyond divergence_x or became non-finite.
    history_phi, history_f : list of float
        φ and f after each outer iteration.
    history_h : list of float
        ‖h‖ after each outer iteration (the constraint violation).
    """

    x: FloatArray
    f: float
    phi: float
    h_norm: float
    iterations: int
    inner_iterations: int
    multipliers: FloatArray
    sigma: float
    converged: bool
    diverged: bool
    history_phi: list[float]
    history_f: list[float]
    history_h: list[float]


class _Diverged(Exception):
    """Raised inside the BFGS objective to abandon a run that is running away."""

    def __init__(self, x: FloatArray) -> None:
        super().__init__("diverged")
        self.x = x


def galm(
    x0: ArrayLike,
    problem: ConstrainedProblem,
    config: GalmConfig = GalmConfig(),
    multipliers0: ArrayLike | None = None,
) -> GalmResult:
    """Minimise f subject to h = 0 by the generalized Lagrange multiplier method (§3.3.1).

    Parameters
    ----------
    x0 : array-like, shape (n,)
        Initial point.
    problem : ConstrainedProblem
        For example a :class:`~linelaser_calib.core.targets.cylinder.model.CentreAxisProblem`.
    config : GalmConfig
    multipliers0 : array-like, shape (l,), optional
        λ0; zeros by default.

    Returns
    -------
    GalmResult
    """
    x = np.array(x0, dtype=np.float64)
    h = problem.constraints(x)
    lam = np.zeros(h.shape) if multipliers0 is None else np.array(multipliers0, dtype=float)
    sigma = config.sigma0
    h_prev = float(np.linalg.norm(h))
    history_phi: list[float] = []
    history_f: list[float] = []
    history_h: list[float] = []
    inner = 0
    converged = diverged = False
    k = 0
    while k < config.max_outer:
        k += 1
        lam_used, sigma_used = lam.copy(), sigma

        def phi_and_grad(
            z: FloatArray, lam_k: FloatArray = lam_used, sigma_k: float = sigma_used
        ) -> tuple[float, FloatArray]:
            f, g = problem.cost_and_gradient(z)
            hz = problem.constraints(z)
            J = problem.constraints_jacobian(z)
            phi = f - float(lam_k @ hz) + 0.5 * sigma_k * float(hz @ hz)
            if not np.isfinite(phi) or phi < -config.divergence_cost:
                raise _Diverged(z.copy())
            if np.max(np.abs(z)) > config.divergence_x:
                raise _Diverged(z.copy())
            return phi, g - J.T @ lam_k + sigma_k * (J.T @ hz)

        try:
            with np.errstate(over="ignore", invalid="ignore"):
                res = minimize(
                    phi_and_grad,
                    x,
                    jac=True,
                    method="BFGS",
                    options={"gtol": config.bfgs_gtol, "maxiter": config.bfgs_max_iter},
                )
            x = np.asarray(res.x, dtype=np.float64)
            inner += int(res.nit)
        except _Diverged as stop:
            x = stop.x
            diverged = True
        f = float(problem.cost(x[None])[0])
        h = problem.constraints(x)
        history_f.append(f)
        history_phi.append(f - float(lam_used @ h) + 0.5 * sigma_used * float(h @ h))
        h_norm = float(np.linalg.norm(h))
        history_h.append(h_norm)
        if diverged or not np.isfinite(f) or f < -config.divergence_cost:
            diverged = True
            break
        if h_norm <= config.epsilon:
            converged = True
            break
        if h_norm > config.alpha * h_prev:
            sigma *= config.eta
        lam = lam - sigma_used * h
        h_prev = h_norm
    return GalmResult(
        x=x,
        f=history_f[-1],
        phi=history_phi[-1],
        h_norm=float(np.linalg.norm(problem.constraints(x))),
        iterations=k,
        inner_iterations=inner,
        multipliers=lam,
        sigma=sigma,
        converged=converged,
        diverged=diverged,
        history_phi=history_phi,
        history_f=history_f,
        history_h=history_h,
    )
