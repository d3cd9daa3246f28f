"""Block-sparse Levenberg–Marquardt with per-sample flange-pose corrections.

Problem
-------
Sample j (one profile at one recorded flange pose) contributes K residuals e_jk, already
divided by their 1σ (K may be padded: a padded row has e = 0 and a zero Jacobian row). Each
depends on the G global parameters (the hand-eye first, ``[θ (3, rad), ρ (3, m)]``, then the
target's own: an axis, a radius, a point, ...) and on the sample's own pose correction
δ_j = (ω_j, τ_j) (6 numbers: rad, m; flange frame). The corrections have the zero-mean
Gaussian prior δ_j / σ (σ_r three times, σ_t three times); the global parameters may have
Gaussian priors of any shape (rows r = J_p·x + r₀, already normalised). The cost is

    ½ Σ_jk ρ(e_jk²) + ½ Σ_j |δ_j / σ|² + ½ |r|²,

with ρ a robust loss (``huber``, ``soft_l1`` or ``linear``) of scale ``loss_scale``.

A target states its problem through :class:`BlockProblem`: the residuals at a state, their
Jacobians in local coordinates (:class:`Linearisation`), and the retraction that applies a
step in those coordinates (e.g. R ← R·Exp(θ) for a rotation, normalisation for a direction).
The state is the target's own object; the solver only passes it back.

Solver
------
Gauss–Newton normal equations with iteratively re-weighted robust weights, in block form
(A: G×G, B_j: G×6, C_j: 6×6): each sample's 6×6 block is inverted on its own and eliminated
(Schur complement), leaving a G×G system, so cost and time grow linearly with the samples.
Levenberg–Marquardt with Marquardt scaling (damping times the diagonal) and Nielsen's damping
update from the gain ratio (actual over predicted decrease). It stops when an accepted step
lowers the cost by less than ``tolerance`` of it, when no global parameter moves by more than
``step_tolerance_m`` (a step times the problem's ``step_scale``: the lever for rotations, 1
for lengths), when the steps tell that the optimum is within ``step_sigmas`` of each
global parameter's 1σ (solves whose figures need to be right to a small fraction of their
1σ only: warm re-solves, and a solve that only starts a later one; off by default), or when
no damping lowers the cost any more (a minimum to machine precision).

Information and covariance
--------------------------
:attr:`Solution.normal` holds the normal equations at the estimate (robust weights at the
solution). :meth:`BlockNormal.schur_information` is the information of the global parameters
with every pose correction marginalised; its inverse is their covariance. With the noise
levels re-estimated (:func:`variance_factors`, variance-component estimation) the point and
prior information are divided by the sensor and robot variance factors first.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, Protocol, TypeVar, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, SolverError
from ..geometry import FloatArray

#: Robust losses: ρ(s) of the squared normalised residual s = (e / scale)².
LOSSES = ("huber", "soft_l1", "linear")
#: Hand-eye parameters at the head of every global vector: θ (3, rad), ρ (3, m).
N_HAND_EYE = 6
#: Parameters of one pose correction (ω, τ).
N_LOCAL = 6
#: Initial damping, relative to the diagonal of the information.
INITIAL_DAMPING = 1e-7
#: Damping beyond which no step lowers the cost any more: a minimum to machine precision.
MAX_DAMPING = 1e16
#: Floor of the re-estimated variance factors: a σ is never taken as below 0.1 of the
#: configured one (noise-free data would otherwise make the information singular).
MIN_VARIANCE_FACTOR = 0.01
#: Samples beyond the global parameters that :func:`sample_dispersion` needs: fewer give a
#: jackknife too noisy to widen a 1σ by.
MIN_DISPERSION_REDUNDANCY = 5
#: Dispersion ratio of a hand-eye axis (observed over expected variance) beyond which a
#: solve warns that its noise model understates the profiles' errors: its 1σ doubled.
#: With 30 profiles the ratio scatters by about ±0.3 where the model holds.
DISPERSION_WARNING = 4.0
#: Points per chunk of samples :func:`normal_equations` sums over: its weighted copies of the
#: Jacobians stay a few MB however long the recording.
CHUNK_POINTS = 1 << 15
#: Samples :func:`sample_dispersion` takes at a time: its dozen per-sample (G, G) arrays
#: stay well under a MB each however long the recording.
DISPERSION_CHUNK_SAMPLES = 512
#: Names of the hand-eye parameters, for messages.
HAND_EYE_AXES = (
    "rotation about x",
    "rotation about y",
    "rotation about z",
    "translation along x",
    "translation along y",
    "translation along z",
)

State = TypeVar("State")


@dataclass(frozen=True)
class SolverConfig:
    """Settings of :func:`solve`.

    Attributes
    ----------
    loss : str
        ``huber``, ``soft_l1`` or ``linear`` (least squares).
    loss_scale : float
        Where the robust loss turns from quadratic to linear, in units of the residuals' σ.
    max_iterations : int
        Linearisations.
    tolerance : float
        Stop when an accepted step lowers the cost by less than this fraction.
    step_tolerance_m : float
        Stop when no global parameter moves by more than this, m (after ``step_scale``).
    step_sigmas : float
        Stop when the optimum is within this fraction of each global parameter's 1σ (the
        inverse of the Schur information at the current linearisation, :meth:`BlockNormal.
        schur_information` with ``variance_factors``), as the steps tell: the first step of
        each linearisation, largest in units of that 1σ, shrinks by a ratio r where the
        robust loss makes the solve converge linearly, so the optimum is the step over
        (1 − r) away. The state is then that linearisation's, so no further linearisation
        is needed. 0 (default): not used.
    variance_factors : tuple of float, or None
        Sensor and robot variance factors of that 1σ (:func:`variance_factors`): those of an
        earlier solve of the problem, or None to learn them at each linearisation from its
        own residuals, for a problem that counts its measurements (:class:`CountedProblem`).
        Far from the optimum the misfit inflates them (and the 1σ with them), but the stop
        needs two linearisations whose steps shrink, by when the residuals are nearly the
        optimum's.
    """

    loss: str = "linear"
    loss_scale: float = 3.0
    max_iterations: int = 50
    tolerance: float = 1e-10
    step_tolerance_m: float = 1e-12
    step_sigmas: float = 0.0
    variance_factors: tuple[float, float] | None = (1.0, 1.0)

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise InputError(f"the loss must be one of {LOSSES}, got {self.loss!r}")
        for name in ("loss_scale", "tolerance", "step_tolerance_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"SolverConfig.{name} must be positive and finite, got {value}")
        if self.max_iterations < 1:
            raise InputError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not (np.isfinite(self.step_sigmas) and self.step_sigmas >= 0.0):
            raise InputError(f"step_sigmas must be >= 0 and finite, got {self.step_sigmas}")
        factors = self.variance_factors
        if factors is not None and not all(np.isfinite(f) and f > 0.0 for f in factors):
            raise InputError(f"variance_factors must be positive, got {factors}")


@dataclass(frozen=True)
class Residuals:
    """Normalised residuals at one state.

    Attributes
    ----------
    points : ndarray, shape (M, K)
        Per-sample measurement residuals (zero on padding), in units of their σ.
    pose_prior : ndarray, shape (M, 6)
        ``[ω / σ_r, τ / σ_t]`` of each pose correction.
    global_prior : ndarray, shape (R,)
        Prior residuals on the global parameters (R may be 0).
    """

    points: FloatArray
    pose_prior: FloatArray
    global_prior: FloatArray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class Linearisation:
    """Residuals and their Jacobians in the local coordinates of the retraction.

    Attributes
    ----------
    residuals : Residuals
    J_global : ndarray, shape (M, K, G)
        d points / d global step; zero rows on padding.
    J_local : ndarray, shape (M, K, 6)
        d points / d (ω, τ) of the row's own sample; zero rows on padding.
    pose_prior_sqrt_information : ndarray, shape (6,)
        ``[1/σ_r] * 3 + [1/σ_t] * 3``: d pose_prior / d (ω, τ) (diagonal).
    global_prior_jacobian : ndarray, shape (R, G)
        d global_prior / d global step.
    """

    residuals: Residuals
    J_global: FloatArray
    J_local: FloatArray
    pose_prior_sqrt_information: FloatArray
    global_prior_jacobian: FloatArray | None = None


class BlockProblem(Protocol[State]):
    """A least-squares problem in the solver's block form (see the module docstring)."""

    @property
    def n_global(self) -> int:
        """G, the number of global parameters (hand-eye first)."""
        ...

    @property
    def step_scale(self) -> FloatArray:
        """(G,) factors that turn a global step into metres (lever for rotations)."""
        ...

    def residuals(self, state: State) -> Residuals:
        """Normalised residuals at ``state``."""
        ...

    def linearise(self, state: State) -> Linearisation:
        """Residuals and Jacobians at ``state``."""
        ...

    def retract(self, state: State, step_global: FloatArray, step_local: FloatArray) -> State:
        """``state`` moved by a global step (G,) and per-sample steps (M, 6)."""
        ...


@runtime_checkable
class CountedProblem(Protocol):
    """A :class:`BlockProblem` that counts its measurement residuals (padding excluded), as
    :func:`variance_factors` needs."""

    @property
    def n_measurements(self) -> int:
        """Measurement residuals, padding excluded."""
        ...


@runtime_checkable
class ChunkedProblem(Protocol):
    """A :class:`BlockProblem` that also linearises a chunk of its samples at a time."""

    def linearise_chunks(self, state: Any) -> Iterator[Linearisation]:
        """Residuals and Jacobians at ``state`` of consecutive chunks of the samples, in
        order (each chunk's ``pose_prior`` its samples' rows)."""
        ...


def evaluate_loss(e: FloatArray, config: SolverConfig) -> tuple[FloatArray, FloatArray]:
    """Robust cost terms c²·ρ(s) (twice the cost) and IRLS weights ρ'(s), shaped like ``e``."""
    c = config.loss_scale
    if config.loss == "linear":
        return e**2, np.ones_like(e)
    s = (e / c) ** 2
    if config.loss == "huber":
        root = np.sqrt(s)
        inside = s <= 1.0
        rho = np.where(inside, s, 2.0 * root - 1.0)
        weight = np.where(inside, 1.0, 1.0 / np.maximum(root, 1.0))
        return c**2 * rho, weight
    root = np.sqrt(1.0 + s)
    return c**2 * 2.0 * (root - 1.0), 1.0 / root


def robust_costs(e: FloatArray, config: SolverConfig) -> FloatArray:
    """The robust cost terms c²·ρ(s) of :func:`evaluate_loss` (twice the cost), shaped like
    ``e`` (M, K), computed a chunk of :data:`CHUNK_POINTS` points at a time: the loss's
    intermediates and its weights never span the whole recording."""
    out = np.empty_like(e)
    step = max(1, CHUNK_POINTS // max(e.shape[1], 1)) if e.ndim == 2 else max(len(e), 1)
    for start in range(0, len(e), step):
        out[start : start + step] = evaluate_loss(e[start : start + step], config)[0]
    return out


def cost(residuals: Residuals, config: SolverConfig) -> float:
    """½ Σ robust point cost + ½ Σ pose prior² + ½ Σ global prior², dimensionless."""
    return 0.5 * float(
        np.sum(robust_costs(residuals.points, config))
        + np.sum(residuals.pose_prior**2)
        + np.sum(residuals.global_prior**2)
    )


@dataclass(frozen=True)
class BlockNormal:
    """Gauss–Newton normal equations H·δ = −g in block form (A, B_j, C_j).

    Attributes
    ----------
    A : ndarray, shape (G, G)
        Global-global information, global priors included.
    B : ndarray, shape (M, G, 6)
        Global-local information per sample.
    C_data : ndarray, shape (M, 6, 6)
        Local-local information per sample from the measurements only.
    prior_precision : ndarray, shape (6,)
        Diagonal prior information of a pose correction.
    g_global : ndarray, shape (G,)
    g_local : ndarray, shape (M, 6)
        Pose priors included.
    A_sample : ndarray, shape (M, G, G)
        Each sample's share of A from its measurements (what :func:`sample_dispersion`
        needs; A is their sum plus the global priors).
    g_sample : ndarray, shape (M, G)
        Each sample's share of g_global from its measurements.
    global_prior : tuple of ndarray (G, G) and (G,), or None
        The global priors' share of A and of g_global (None: no global prior).
    """

    A: FloatArray
    B: FloatArray
    C_data: FloatArray
    prior_precision: FloatArray
    g_global: FloatArray
    g_local: FloatArray
    A_sample: FloatArray
    g_sample: FloatArray
    global_prior: tuple[FloatArray, FloatArray] | None = None

    def take(self, rows: NDArray[np.intp]) -> BlockNormal:
        """The normal equations of the samples ``rows`` (indices, in that order) at the same
        state: what linearising those samples alone there gives (the per-sample blocks are
        each sample's own; A and g_global their sums plus the global priors)."""
        A_sample, g_sample = self.A_sample[rows], self.g_sample[rows]
        return _assembled(
            A_sample,
            g_sample,
            self.B[rows],
            self.C_data[rows],
            self.prior_precision,
            self.g_local[rows],
            self.global_prior,
        )

    def C(self, sensor_factor: float = 1.0, robot_factor: float = 1.0) -> FloatArray:
        """Local blocks (M, 6, 6) with the measurement and prior information divided by the
        sensor and robot variance factors."""
        return np.asarray(
            self.C_data / sensor_factor + np.diag(self.prior_precision / robot_factor)
        )

    def schur_information(
        self,
        sensor_factor: float = 1.0,
        robot_factor: float = 1.0,
        remove: FloatArray | None = None,
    ) -> FloatArray:
        """Information (G, G) of the global parameters with the pose corrections marginalised.

        Parameters
        ----------
        sensor_factor, robot_factor : float
            Variance factors the measurement and pose-prior information are divided by.
        remove : ndarray, shape (G, G), optional
            Information taken out of A first (e.g. a global prior's, to get the data's own).
        """
        A = self.A if remove is None else self.A - remove
        B = self.B / sensor_factor
        BC = B @ np.linalg.inv(self.C(sensor_factor, robot_factor))
        S = A / sensor_factor - np.einsum("mgk,mhk->gh", BC, B)
        return np.asarray(0.5 * (S + S.T))


def normal_equations(
    linearisation: Linearisation | Iterable[Linearisation],
    config: SolverConfig,
    weights: FloatArray | None = None,
) -> BlockNormal:
    """Weighted normal equations; ``weights`` (M, K) None uses the robust IRLS weights.

    ``linearisation`` is the whole problem's, or its consecutive chunks of samples in order
    (:meth:`ChunkedProblem.linearise_chunks`: the Jacobians of the whole recording are
    then never held at once; global priors and the pose prior's information are the first
    chunk's). Summed over chunks of at most :data:`CHUNK_POINTS` points, so the weighted
    copies of the Jacobians never span the whole recording either.
    """
    return _accumulated(linearisation, config, weights)[0]


def _accumulated(
    linearisation: Linearisation | Iterable[Linearisation],
    config: SolverConfig,
    weights: FloatArray | None = None,
) -> tuple[BlockNormal, Residuals]:
    """:func:`normal_equations` and the residuals (the chunks' joined)."""
    chunks = [linearisation] if isinstance(linearisation, Linearisation) else linearisation
    # Per block (A_sample, g_sample, B, C_data, g_local, residuals, pose prior), each chunk's.
    parts: list[list[FloatArray]] = [[] for _ in range(7)]
    first: tuple[FloatArray, FloatArray | None, FloatArray] | None = None  # its priors
    row = 0
    for lin in chunks:
        if first is None:
            first = (
                lin.residuals.global_prior,
                lin.global_prior_jacobian,
                lin.pose_prior_sqrt_information,
            )
        M = lin.J_global.shape[0]
        for blocks in _blocks(lin, config, None if weights is None else weights[row : row + M]):
            for part, block in zip(parts, blocks, strict=True):
                part.append(block)
        row += M
        del lin  # this chunk's Jacobians are let go before the next chunk's are built
    if first is None:
        raise InputError("the normal equations need at least one sample")
    A_sample, g_sample, B, C_data, g_local, points, pose_prior = (_joined(part) for part in parts)
    global_residual, Jp, sqrt_info = first
    prior = None if Jp is None or not len(Jp) else (Jp.T @ Jp, Jp.T @ global_residual)
    normal = _assembled(
        A_sample, g_sample, B, C_data, sqrt_info**2, g_local + pose_prior * sqrt_info, prior
    )
    return normal, Residuals(points, pose_prior, global_residual)


def _assembled(
    A_sample: FloatArray,
    g_sample: FloatArray,
    B: FloatArray,
    C_data: FloatArray,
    prior_precision: FloatArray,
    g_local: FloatArray,
    global_prior: tuple[FloatArray, FloatArray] | None,
) -> BlockNormal:
    """The block normal equations from the per-sample blocks and the global priors' share
    (:class:`BlockNormal`)."""
    A, g_global = A_sample.sum(axis=0), g_sample.sum(axis=0)
    if global_prior is not None:
        A = A + global_prior[0]
        g_global = g_global + global_prior[1]
    return BlockNormal(
        A=0.5 * (A + A.T),
        B=B,
        C_data=C_data,
        prior_precision=prior_precision,
        g_global=g_global,
        g_local=g_local,
        A_sample=A_sample,
        g_sample=g_sample,
        global_prior=global_prior,
    )


def _blocks(
    lin: Linearisation, config: SolverConfig, weights: FloatArray | None
) -> Iterator[tuple[FloatArray, ...]]:
    """The normal equations' blocks of one chunk's samples (A_sample, g_sample, B, C_data,
    g_local) with its residuals and pose prior, :data:`CHUNK_POINTS` points at a time;
    ``weights`` (M, K) None uses the robust IRLS weights."""
    M, K = lin.J_global.shape[:2]
    step = max(1, CHUNK_POINTS // max(K, 1))
    for start in range(0, M, step):
        rows = slice(start, start + step)
        e = lin.residuals.points[rows]
        w = evaluate_loss(e, config)[1] if weights is None else weights[rows]
        # Each sample's blocks apart (no stacked copy of the Jacobian): one small product
        # per sample for its share of A, B and C.
        J_global, J_local = lin.J_global[rows], lin.J_local[rows]
        WJ_global = J_global * w[..., None]
        WJ_local = J_local * w[..., None]
        yield (
            WJ_global.transpose(0, 2, 1) @ J_global,
            np.einsum("mkg,mk->mg", WJ_global, e),
            WJ_global.transpose(0, 2, 1) @ J_local,
            WJ_local.transpose(0, 2, 1) @ J_local,
            np.einsum("mkl,mk->ml", WJ_local, e),
            e,
            lin.residuals.pose_prior[rows],
        )


def _joined(chunks: list[FloatArray]) -> FloatArray:
    """The chunks of one block joined, the list emptied as it goes: each block of the normal
    equations is held twice (its chunks and the whole) only while it is joined."""
    whole = np.concatenate(chunks)
    chunks.clear()
    return whole


def linearised(
    problem: BlockProblem[State], state: State, config: SolverConfig
) -> tuple[BlockNormal, Residuals]:
    """The normal equations (robust weights) and the residuals of ``problem`` at ``state``: a
    chunk of samples at a time where the problem linearises by chunks
    (:class:`ChunkedProblem`), so its whole Jacobians are never held."""
    if isinstance(problem, ChunkedProblem):
        return _accumulated(problem.linearise_chunks(state), config)
    return _accumulated(problem.linearise(state), config)


def solve_damped(normal: BlockNormal, damping: float) -> tuple[FloatArray, FloatArray]:
    """Solve (H + damping·diag H)·δ = −g by eliminating each sample's block (Schur).

    Returns
    -------
    step_global : ndarray, shape (G,)
    step_local : ndarray, shape (M, 6)

    Raises
    ------
    SolverError
        Where a global parameter has no information at all (damping scales each diagonal,
        so it cannot help): a state the solve ran away to, such as a sphere fitted to a
        cylinder's profiles shrinking its along-line scale without bound.
    """
    A = normal.A + damping * np.diag(np.diag(normal.A))
    C = normal.C()
    C = C + damping * np.einsum("mii->mi", C)[:, :, None] * np.eye(N_LOCAL)
    C_inv = np.linalg.inv(C)
    BC = normal.B @ C_inv
    S = A - np.einsum("mgk,mhk->gh", BC, normal.B)
    rhs = -normal.g_global + np.einsum("mgk,mk->g", BC, normal.g_local)
    try:
        step_global = np.linalg.solve(S, rhs)
    except np.linalg.LinAlgError as singular:
        raise SolverError(
            "the solve reached a state where the profiles no longer determine one of the "
            "estimated numbers (its information is zero): the model does not fit this "
            "recording there"
        ) from singular
    step_local = -np.einsum(
        "mkl,ml->mk", C_inv, normal.g_local + np.einsum("mgk,g->mk", normal.B, step_global)
    )
    return step_global, step_local


def variance_factors(
    normal: BlockNormal, point_cost: float, prior_cost: float, n_points: int, n_global: int
) -> tuple[float, float]:
    """Sensor and robot variance factors (s_s², s_r²) from the residuals and redundancies.

    The pose corrections keep the redundancy r_prior = Σ_j (6 − tr(P·C_j⁻¹)) (P the prior
    precision), the measurements r_points = n_points − n_global − r_prior; s_s² = point_cost /
    r_points and s_r² = prior_cost / r_prior, each 1 where its group keeps less than one
    degree of freedom and never below :data:`MIN_VARIANCE_FACTOR`.

    Parameters
    ----------
    normal : BlockNormal
        At the solution.
    point_cost : float
        Σ robust point cost terms c²·ρ (twice the cost).
    prior_cost : float
        Σ pose prior residual².
    n_points, n_global : int
        Measurement residuals (padding excluded) and global parameters.
    """
    C_inv = np.linalg.inv(normal.C())
    r_prior = float(np.sum(N_LOCAL - np.einsum("mii,i->m", C_inv, normal.prior_precision)))
    r_points = n_points - n_global - r_prior
    sensor = point_cost / r_points if r_points >= 1.0 else 1.0
    robot = prior_cost / r_prior if r_prior >= 1.0 else 1.0
    return max(sensor, MIN_VARIANCE_FACTOR), max(robot, MIN_VARIANCE_FACTOR)


@dataclass(frozen=True)
class Solution(Generic[State]):
    """Outcome of :func:`solve`.

    Attributes
    ----------
    state : State
        The estimate.
    residuals : Residuals
        At the estimate.
    normal : BlockNormal
        Normal equations at the estimate (robust weights there); see
        :meth:`BlockNormal.schur_information`.
    cost_history : list of float
        Cost after each accepted step, starting with the initial cost.
    iterations : int
        Linearisations performed during the search.
    converged : bool
    """

    state: State
    residuals: Residuals
    normal: BlockNormal
    cost_history: list[float]
    iterations: int
    converged: bool

    @property
    def information(self) -> FloatArray:
        """Information (G, G) of the global parameters, pose corrections marginalised."""
        return self.normal.schur_information()


def sample_dispersion(
    solution: Solution[Any], sensor_factor: float, robot_factor: float
) -> FloatArray | None:
    """How much more the estimate moves from sample to sample than the noise model says.

    The delete-one-sample jackknife in one Newton step: without sample j the global
    parameters move by d_j = (S − S_j)⁻¹ u_j, S the Schur information, S_j sample j's share
    of it and u_j its share of the gradient (its pose correction re-fitted, so the gradient
    of its profiled cost). Under the noise model (point and pose-prior variances scaled by
    the variance factors) each u_j has the covariance V_j and the refitted u_j(x̂) =
    u_j − S_j S⁻¹ Σ u_k the covariance V_j − H_j V_j − V_j H_jᵀ + H_j V H_jᵀ (H_j = S_j S⁻¹,
    V = Σ V_j), which gives the expected Σ d_j d_jᵀ. The ratio of the observed to the
    expected, per global parameter, is about 1 when the model holds (whatever the
    jackknife's own bias); above 1 when each sample's points err more, or more alike, than
    the model of the point noise says (a profiler's short-range correlation, lateral noise
    on steep flanks), which the covariance then does not see.

    Returns
    -------
    ndarray, shape (G,), or None
        Observed over expected variance per global parameter; None with fewer than
        :data:`MIN_DISPERSION_REDUNDANCY` samples beyond the global parameters.
    """
    normal = solution.normal
    M, G, _ = normal.B.shape
    if M - G < MIN_DISPERSION_REDUNDANCY:
        return None
    S = normal.schur_information()
    step = DISPERSION_CHUNK_SAMPLES
    chunks = [slice(start, start + step) for start in range(0, M, step)]
    V = sum(
        _score_terms(normal, rows, sensor_factor, robot_factor)[1].sum(axis=0) for rows in chunks
    )
    observed, expected = np.zeros(G), np.zeros(G)
    for rows in chunks:
        S_j, V_j = _score_terms(normal, rows, sensor_factor, robot_factor)
        H = np.linalg.solve(S, S_j.transpose(0, 2, 1)).transpose(0, 2, 1)  # S_j S⁻¹
        E_j = V_j - H @ V_j - V_j @ H.transpose(0, 2, 1) + H @ V @ H.transpose(0, 2, 1)
        leave_out = np.linalg.inv(S[None] - S_j)
        d = np.einsum("mgh,mh->mg", leave_out, normal.g_sample[rows])
        observed += np.sum(d * d, axis=0)
        expected += np.einsum("mgg->g", leave_out @ E_j @ leave_out)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = observed / expected
    return np.asarray(np.where(expected > 0.0, ratio, 1.0))


def _score_terms(
    normal: BlockNormal, rows: slice, sensor_factor: float, robot_factor: float
) -> tuple[FloatArray, FloatArray]:
    """Of the samples ``rows``: each one's share S_j of the Schur information (m, G, G) and
    the covariance V_j of its score under the noise model (m, G, G): the points' part
    (residuals minus the pose correction's fit of them) and the pose prior's
    (:func:`sample_dispersion`)."""
    A, B, C_data = normal.A_sample[rows], normal.B[rows], normal.C_data[rows]
    BC = B @ np.linalg.inv(C_data + np.diag(normal.prior_precision))
    BCB = np.einsum("mgk,mhk->mgh", BC, B)
    V_j = sensor_factor * (
        A - 2.0 * BCB + np.einsum("mgk,mkl,mhl->mgh", BC, C_data, BC)
    ) + robot_factor * np.einsum("mgk,k,mhk->mgh", BC, normal.prior_precision, BC)
    return A - BCB, V_j


def dispersion_warning(ratio: FloatArray | None) -> str | None:
    """A warning when a hand-eye axis scatters beyond :data:`DISPERSION_WARNING` (``ratio``
    from :func:`sample_dispersion`), else None."""
    if ratio is None:
        return None
    hand_eye = np.asarray(ratio, dtype=np.float64)[:N_HAND_EYE]
    worst = int(np.argmax(hand_eye))
    if hand_eye[worst] <= DISPERSION_WARNING:
        return None
    return (
        f"the hand-eye moves from profile to profile {math.sqrt(hand_eye[worst]):.1f} times "
        f"more than the noise model predicts ({HAND_EYE_AXES[worst]}): the points of a "
        "profile err more, or more alike along the line, than the model weighs them. The "
        "1 sigma is widened by that factor"
    )


def widening(ratio: FloatArray | None) -> FloatArray | None:
    """Factors (>= 1) by which each 1σ is widened for a dispersion ``ratio``
    (:func:`sample_dispersion`): √ratio where it exceeds 1."""
    if ratio is None:
        return None
    return np.asarray(np.sqrt(np.maximum(np.asarray(ratio, dtype=np.float64), 1.0)))


def widen_covariance(covariance: FloatArray, ratio: FloatArray | None) -> FloatArray:
    """``covariance`` (G, G) with each parameter's 1σ times :func:`widening` of ``ratio``;
    correlations kept."""
    scale = widening(ratio)
    if scale is None:
        return covariance
    return np.asarray(covariance * np.outer(scale, scale))


def _sigma(
    problem: BlockProblem[Any], normal: BlockNormal, residuals: Residuals, config: SolverConfig
) -> FloatArray | None:
    """1σ (G,) of the global parameters at a linearisation (``config.variance_factors``, or
    learned from its ``residuals``); None where the information is singular."""
    factors = config.variance_factors
    if factors is None:
        if not isinstance(problem, CountedProblem):
            raise InputError("variance factors learned in the solve need a CountedProblem")
        factors = variance_factors(
            normal,
            float(np.sum(robust_costs(residuals.points, config))),
            float(np.sum(residuals.pose_prior**2)),
            problem.n_measurements,
            problem.n_global,
        )
    try:
        covariance = np.linalg.inv(normal.schur_information(*factors))
    except np.linalg.LinAlgError:
        return None
    return np.asarray(np.sqrt(np.maximum(np.diag(covariance), 0.0)))


def _left(size: float, last_size: float) -> float:
    """How far the optimum still is, in the units of the step sizes, when a linearly
    converging solve's step shrank from ``last_size`` to ``size`` (< ``last_size``): the
    rest of the geometric series, size / (1 − size / last_size)."""
    return size / (1.0 - size / last_size)


def solve(
    problem: BlockProblem[State],
    state: State,
    config: SolverConfig,
    start: Callable[[], tuple[BlockNormal, Residuals]] | None = None,
) -> Solution[State]:
    """Minimise the problem's cost from ``state`` (see the module docstring).

    ``start``: where the caller has them cheaper than a linearisation (a subset of a solved
    problem's samples at its solution, :meth:`BlockNormal.take`), a function giving the
    normal equations and residuals of ``problem`` at ``state``, called once instead of the
    first linearisation: a function, so that no caller holds them while later
    linearisations are built (5 MB of a subset of 1,600 profiles). The first linearisation
    gives the starting cost too."""
    first = linearised(problem, state, config) if start is None else start()
    cost_now = cost(first[1], config)
    pending: tuple[BlockNormal, Residuals] | None = first
    del first  # held by ``pending`` until the loop takes it, then let go
    history = [cost_now]
    damping, growth = INITIAL_DAMPING, 2.0
    scale = problem.step_scale
    converged = False
    iterations = 0
    normal: BlockNormal | None = None
    residuals: Residuals | None = None
    last_size = math.inf  # the first step of the last linearisation, in 1σ (step_sigmas)
    while iterations < config.max_iterations:
        sigma = None
        if normal is None:
            normal, residuals = linearised(problem, state, config) if pending is None else pending
            pending = None
            iterations += 1
            if config.step_sigmas > 0.0:
                assert residuals is not None
                sigma = _sigma(problem, normal, residuals, config)
        step_global, step_local = solve_damped(normal, damping)
        if float(np.max(np.abs(step_global * scale))) < config.step_tolerance_m:
            converged = True
            break
        if sigma is not None:
            size = float(np.max(np.abs(step_global) / sigma))
            if size < last_size and _left(size, last_size) < config.step_sigmas:
                converged = True
                break
            last_size = size
        candidate = problem.retract(state, step_global, step_local)
        # Linearised, not only its residuals: an accepted step (most are) is the next
        # linearisation's state, whose geometry is then formed once, not twice.
        trial = linearised(problem, candidate, config)
        new_cost = cost(trial[1], config)
        diag_step = np.concatenate(
            [
                np.diag(normal.A) * step_global,
                np.einsum("mii->mi", normal.C()).ravel() * step_local.ravel(),
            ]
        )
        step = np.concatenate([step_global, step_local.ravel()])
        gradient = np.concatenate([normal.g_global, normal.g_local.ravel()])
        predicted = 0.5 * float(damping * step @ diag_step - gradient @ step)
        gain = (cost_now - new_cost) / predicted if predicted > 0.0 else -1.0
        if gain > 0.0:
            decrease = cost_now - new_cost
            state, cost_now = candidate, new_cost
            history.append(cost_now)
            normal, residuals, pending = None, None, trial  # the old state's let go
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            growth = 2.0
            if decrease <= config.tolerance * max(cost_now, 1e-300):
                converged = True
                break
        else:
            del trial
            damping *= growth
            growth *= 2.0
            if damping > MAX_DAMPING:
                converged = True
                break
    if normal is None or residuals is None:  # the state moved since the last one
        normal, residuals = linearised(problem, state, config) if pending is None else pending
    return Solution(
        state=state,
        residuals=residuals,
        normal=normal,
        cost_history=history,
        iterations=iterations,
        converged=converged,
    )
