"""Joint kinematic + hand-eye calibration: the flange poses from joint states and a corrected model.

Pose model
----------
A target's problem in the shared solver's block form (:mod:`.solver`) takes each sample's
flange pose ``T_j`` as data and estimates a per-sample correction δ_j = (ω_j, τ_j) (flange
frame, ``T_j · D(δ_j)``) with a Gaussian prior. Where the joint vector q_j of every sample
is known, the flange pose becomes

    T_j(Δ) = FK(q_j; p + E·Δ) · D(δ_j),

p the nominal kinematic parameters and Δ the corrections of the free ones (E embeds them),
which join the global parameters. δ_j is then the arm's repeatability (σ 0.02-0.05 mm),
no longer its absolute error. :class:`JointProblem` wraps any target problem that can take
other flange poses (:class:`PoseDrivenProblem`); the target's problem is not copied.

Chain rule
----------
A change of Δ moves FK(q_j) by a base-frame twist ``(v, w) = J_j dΔ``
(:func:`~.kinematics.parameter_jacobian`): ``R ← Exp(w) R``, ``t ← t + w × t + v``. Held
at the same corrected pose, this is a change of the sample's correction

    dω = J_l(ω)⁻¹ Rᵀ w,     dτ = Rᵀ (v + w × (t + R τ)),

R, t the model pose and J_l the left Jacobian of SO(3). The residuals' derivatives with
respect to Δ are the target's local Jacobian (with respect to ω, τ) times these.

Identifiability and gauge
-------------------------
Not every correction can be determined: a rigid change of the robot base is absorbed by the
target's placement, one of the flange by the hand-eye, and one target placement leaves
more free (e.g. parallel joint axes' offsets that only their sum affects). At the start
state, the information of the global parameters with every pose correction marginalised is
reduced to the kinematic block (hand-eye and target marginalised), its columns scaled by the
prior 1σ of each parameter, and the column-pivoted QR of its square root orders the
parameters from best to worst determined (:func:`kinematic_identifiability`). The
parameters whose pivot is below ``rtol`` of the largest stay at their nominal values (that
fixes the gauge: the base and flange frames stay the nominal ones, and the hand-eye stays
the physical one up to the flange-side errors it absorbs); the others are estimated with a
zero-mean Gaussian prior (global prior rows Δ / σ) that keeps weakly determined
combinations near nominal.

Several placements
------------------
:class:`MultiScanProblem` stacks the problems of several target placements scanned by the
same arm and sensor into one (shared hand-eye, a target per placement); wrapped like a
single problem, it estimates one set of corrections from all of them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Generic, Protocol, Self, TypeVar

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, SolverError
from ..geometry import FloatArray, right_jacobian_so3
from ..solver import (
    N_HAND_EYE,
    Linearisation,
    Residuals,
    Solution,
    SolverConfig,
    normal_equations,
    solve,
)
from .kinematics import (
    JointStates,
    KinematicCorrections,
    KinematicModel,
    forward_kinematics,
    parameter_jacobian,
)

State = TypeVar("State")


class PoseDrivenProblem(Protocol[State]):
    """A target problem (:class:`~.solver.BlockProblem`) whose flange poses can be replaced.

    Its per-sample corrections must follow the solver's convention: (ω, τ) in the flange
    frame, true pose ``T · D(δ)`` with ``D(δ) = [[Exp(ω), τ], [0, 1]]``, and its
    ``J_local`` columns the derivatives with respect to additive steps of (ω, τ).
    """

    @property
    def n_global(self) -> int: ...

    @property
    def n_samples(self) -> int: ...

    @property
    def step_scale(self) -> FloatArray: ...

    def residuals(self, state: State) -> Residuals: ...

    def linearise(self, state: State) -> Linearisation: ...

    def retract(self, state: State, step_global: FloatArray, step_local: FloatArray) -> State: ...

    def with_flange_poses(self, T_base_flange: FloatArray) -> Self:
        """The same problem at other flange poses (M, 4, 4)."""
        ...

    def pose_corrections(self, state: State) -> FloatArray:
        """The per-sample corrections ``[ω (rad), τ (m)]`` (M, 6) of ``state``."""
        ...


@dataclass(frozen=True)
class JointCalibrationConfig:
    """Settings of the joint kinematic + hand-eye solve.

    Attributes
    ----------
    repeatability_t_m, repeatability_r_rad : float
        1σ per axis of the arm's repeatability, the per-sample corrections' prior (m, rad).
        Default 0.03 mm and 0.003° (UR e-series: ±0.03 mm).
    prior_length_m, prior_angle_rad : float
        1σ of the zero-mean prior on every estimated correction: lengths (m), angles (rad).
        Default 1 mm and 0.1°: several times a serial arm's typical deviation from its
        nominal table, so that the data decide where they can.
    rtol : float
        A kinematic parameter whose QR pivot is below ``rtol`` times the largest stays
        nominal. Default 1e-3 (in units of the prior 1σ: a combination the data know
        a thousand times worse than the best one).
    """

    repeatability_t_m: float = 3e-5
    repeatability_r_rad: float = float(np.deg2rad(0.003))
    prior_length_m: float = 1e-3
    prior_angle_rad: float = float(np.deg2rad(0.1))
    rtol: float = 1e-3

    def __post_init__(self) -> None:
        for name in (
            "repeatability_t_m",
            "repeatability_r_rad",
            "prior_length_m",
            "prior_angle_rad",
            "rtol",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(
                    f"JointCalibrationConfig.{name} must be positive and finite, got {value}"
                )

    def prior_sigma(self, model: KinematicModel) -> FloatArray:
        """Prior 1σ (P,) of every parameter of ``model`` (m or rad)."""
        return np.where(model.parameter_is_length, self.prior_length_m, self.prior_angle_rad)


@dataclass(frozen=True)
class KinematicSetup:
    """What the joint solve needs besides the target's data: the model and the joint states.

    Attributes
    ----------
    model : KinematicModel
        The nominal model (the corrections apply to it).
    states : JointStates
        The recording's joint-state stream.
    clock_offset_s : float
        Offset added to the profile stamps to pair them with the joint states, s.
    config : JointCalibrationConfig
    """

    model: KinematicModel
    states: JointStates
    clock_offset_s: float = 0.0
    config: JointCalibrationConfig = JointCalibrationConfig()

    def outside(self, stamps_ns: ArrayLike) -> NDArray[np.bool_]:
        """Which profile stamps (M,) ns fall before the first or after the last joint state
        (with the clock offset): their joint vectors cannot be interpolated."""
        t = np.asarray(stamps_ns, dtype=np.int64) + round(self.clock_offset_s * 1e9)
        s = self.states.stamps_ns
        if len(s) == 0:
            return np.ones(t.shape, dtype=bool)
        return np.asarray((t < s[0]) | (t > s[-1]))

    def outside_reason(self, stamp_ns: int) -> str:
        """Why a profile stamped ``stamp_ns`` (outside the stream) has no joint vector."""
        t = stamp_ns + round(self.clock_offset_s * 1e9)
        s = self.states.stamps_ns
        if len(s) == 0:
            return "no joint states"
        if t < s[0]:
            return f"before the joint-state stream (it starts {(s[0] - t) / 1e6:.1f} ms later)"
        return f"after the joint-state stream (it ends {(t - s[-1]) / 1e6:.1f} ms earlier)"

    def joint_positions(self, stamps_ns: ArrayLike) -> FloatArray:
        """Joint vectors (M, n) at profile stamps (M,) ns, interpolated linearly.

        Raises
        ------
        InputError
            A model joint the states do not name, or a stamp outside the stream.
        """
        names = self.states.names
        missing = [j for j in self.model.joint_names if j not in names]
        if missing:
            raise InputError(
                f"the joint states do not name the joints {missing} of the kinematic model "
                f"{self.model.name!r} (they name {list(names)})"
            )
        t = np.asarray(stamps_ns, dtype=np.int64) + round(self.clock_offset_s * 1e9)
        s = self.states.stamps_ns
        if np.any(self.outside(stamps_ns)):
            raise InputError(
                "some profiles lie outside the joint-state stream; record /joint_states for "
                "the whole scan"
            )
        base = s[0]
        x = (s - base).astype(np.float64)
        tq = (t - base).astype(np.float64)
        columns = [names.index(j) for j in self.model.joint_names]
        return np.column_stack([np.interp(tq, x, self.states.positions[:, c]) for c in columns])


@dataclass(frozen=True)
class KinematicIdentifiability:
    """Which kinematic corrections one recording determines.

    Attributes
    ----------
    names : tuple of str
        Every kinematic parameter of the model.
    identifiable : tuple of str
        Those the data determine, best first (pivot order).
    unidentifiable : tuple of str
        The others (kept nominal), in pivot order.
    free_combinations : list of dict of str to float
        For each direction the data leave free (numerically zero singular value of the
        prior-scaled square-root information), its unit combination in prior-σ units, the
        entries above 0.1 only, largest first.
    singular_values : ndarray, shape (P,)
        Of the prior-scaled square-root information, descending.
    """

    names: tuple[str, ...]
    identifiable: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    free_combinations: list[dict[str, float]]
    singular_values: FloatArray

    def describe(self) -> str:
        """Human text: how many are identifiable and what is left free (three examples)."""
        examples = []
        for combination in self.free_combinations[:3]:
            terms = [f"{w:+.2f} {n}" for n, w in list(combination.items())[:4]]
            examples.append(" ".join(terms))
        text = (
            f"{len(self.identifiable)} of {len(self.names)} kinematic parameters are "
            "identifiable from these scans"
        )
        if self.free_combinations:
            text += (
                f"; {len(self.free_combinations)} combinations are not (absorbed by the base "
                "placement of the target, by the hand-eye at the flange, or left free by the "
                "poses), e.g. " + "; ".join(examples)
            )
        return text


def kinematic_identifiability(
    information: FloatArray,
    n_other: int,
    names: tuple[str, ...],
    prior_sigma: FloatArray,
    rtol: float,
) -> KinematicIdentifiability:
    """The identifiable kinematic parameters from the information of all global parameters.

    Parameters
    ----------
    information : ndarray, shape (G + P, G + P)
        Information of the global parameters (pose corrections marginalised): the target's
        G first (hand-eye, target), then the P kinematic parameters.
    n_other : int
        G.
    names : tuple of str, length P
    prior_sigma : ndarray, shape (P,)
        Column scales (m or rad).
    rtol : float
        Relative pivot threshold.
    """
    H = np.asarray(information, dtype=np.float64)
    G = n_other
    H_gg, H_gk, H_kk = H[:G, :G], H[:G, G:], H[G:, G:]
    S = H_kk - H_gk.T @ np.linalg.pinv(H_gg, rcond=1e-12, hermitian=True) @ H_gk
    S = 0.5 * (S + S.T) * np.outer(prior_sigma, prior_sigma)
    eigenvalues, vectors = np.linalg.eigh(S)
    root = np.sqrt(np.clip(eigenvalues, 0.0, None))[:, None] * vectors.T

    _, R, pivots = scipy.linalg.qr(root, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(R))
    rank = int(np.sum(diagonal > rtol * diagonal[0]))
    order = [names[i] for i in pivots]
    singular = np.sqrt(np.clip(eigenvalues[::-1], 0.0, None))
    free = []
    for vector in vectors[:, ::-1].T[rank:]:
        big = np.flatnonzero(np.abs(vector) > 0.1)
        free.append({names[i]: float(vector[i]) for i in big[np.argsort(-np.abs(vector[big]))]})
    return KinematicIdentifiability(
        tuple(names), tuple(order[:rank]), tuple(order[rank:]), free, singular
    )


@dataclass(frozen=True, eq=False)
class KinematicPoseModel:
    """Flange poses FK(q_j; p + E·Δ) of the samples' joint vectors, Δ the free corrections.

    Attributes
    ----------
    model : KinematicModel
        Nominal.
    q : ndarray, shape (M, n)
        Joint vector of each sample.
    free : ndarray of int, shape (F,)
        Indices of the estimated parameters.
    prior_sigma : ndarray, shape (F,)
        1σ of their zero-mean prior (m or rad).
    """

    model: KinematicModel
    q: FloatArray
    free: np.ndarray
    prior_sigma: FloatArray

    def parameters(self, delta: FloatArray) -> FloatArray:
        """All parameters (P,) with the corrections Δ (F,) added."""
        p = self.model.parameters.copy()
        p[self.free] += delta
        return p

    def poses(self, delta: FloatArray) -> FloatArray:
        """``T_base_flange`` (M, 4, 4) at corrections Δ."""
        return forward_kinematics(self.model.with_parameters(self.parameters(delta)), self.q)

    def twists(self, delta: FloatArray) -> FloatArray:
        """Base twists (M, 6, F) ``(v, w)`` of the flange per unit of each free correction."""
        model = self.model.with_parameters(self.parameters(delta))
        return parameter_jacobian(model, self.q)[:, :, self.free]

    def corrections(self, delta: FloatArray) -> KinematicCorrections:
        """Δ as named corrections of the model (the free ones only)."""
        names = self.model.parameter_names
        return KinematicCorrections(
            self.model.name,
            {names[i]: float(d) for i, d in zip(self.free, delta, strict=True)},
        )


@dataclass(frozen=True)
class JointState(Generic[State]):
    """The target's state and the kinematic corrections Δ (F,)."""

    inner: State
    delta: FloatArray


def correction_change(
    T: FloatArray, omega: FloatArray, tau: FloatArray, twists: FloatArray
) -> FloatArray:
    """d(ω, τ) (M, 6, F) of the corrections per unit base twist of the model pose.

    Parameters
    ----------
    T : ndarray, shape (M, 4, 4)
        Model poses FK(q_j).
    omega, tau : ndarray, shape (M, 3)
        The samples' corrections (rad, m).
    twists : ndarray, shape (M, 6, F)
        Base twists ``(v, w)`` of the model poses per unit parameter.
    """
    R, t = T[:, :3, :3], T[:, :3, 3]
    v, w = twists[:, :3, :], twists[:, 3:, :]
    Rt = np.swapaxes(R, 1, 2)
    Jl_inv = np.linalg.inv(right_jacobian_so3(-omega))
    d_omega = Jl_inv @ Rt @ w
    position = t + np.einsum("mij,mj->mi", R, tau)
    moved = v + np.cross(np.swapaxes(w, 1, 2), position[:, None, :]).swapaxes(1, 2)
    return np.concatenate([d_omega, Rt @ moved], axis=1)


@dataclass(frozen=True, eq=False)
class JointProblem(Generic[State]):
    """A target problem with its flange poses from a :class:`KinematicPoseModel`.

    Global parameters: the target's (hand-eye first), then Δ. The corrections Δ have the
    prior rows Δ / σ after the target's own global priors.
    """

    target: PoseDrivenProblem[State]
    pose_model: KinematicPoseModel

    @property
    def n_free(self) -> int:
        return len(self.pose_model.free)

    @property
    def n_global(self) -> int:
        return self.target.n_global + self.n_free

    @property
    def step_scale(self) -> FloatArray:
        """The target's, then 1 for lengths and the reach (mean flange distance, m) for angles."""
        reach = float(
            np.mean(np.linalg.norm(self.pose_model.poses(np.zeros(self.n_free))[:, :3, 3], axis=1))
        )
        lengths = self.pose_model.model.parameter_is_length[self.pose_model.free]
        return np.concatenate([self.target.step_scale, np.where(lengths, 1.0, reach)])

    def at(self, delta: FloatArray) -> PoseDrivenProblem[State]:
        """The target problem at the flange poses of corrections Δ."""
        return self.target.with_flange_poses(self.pose_model.poses(delta))

    def _prior(self, inner: Residuals, delta: FloatArray) -> Residuals:
        rows = delta / self.pose_model.prior_sigma
        return Residuals(inner.points, inner.pose_prior, np.concatenate([inner.global_prior, rows]))

    def residuals(self, state: JointState[State]) -> Residuals:
        return self._prior(self.at(state.delta).residuals(state.inner), state.delta)

    def linearise(self, state: JointState[State]) -> Linearisation:
        problem = self.at(state.delta)
        lin = problem.linearise(state.inner)
        T = self.pose_model.poses(state.delta)
        corrections = problem.pose_corrections(state.inner)
        change = correction_change(
            T, corrections[:, :3], corrections[:, 3:], self.pose_model.twists(state.delta)
        )
        J_kin = lin.J_local @ change
        G, F = self.target.n_global, self.n_free
        inner_prior = lin.global_prior_jacobian
        blocks = (
            []
            if inner_prior is None
            else [np.hstack([inner_prior, np.zeros((len(inner_prior), F))])]
        )
        blocks.append(np.hstack([np.zeros((F, G)), np.diag(1.0 / self.pose_model.prior_sigma)]))
        return Linearisation(
            residuals=self._prior(lin.residuals, state.delta),
            J_global=np.concatenate([lin.J_global, J_kin], axis=2),
            J_local=lin.J_local,
            pose_prior_sqrt_information=lin.pose_prior_sqrt_information,
            global_prior_jacobian=np.vstack(blocks),
        )

    def retract(
        self, state: JointState[State], step_global: FloatArray, step_local: FloatArray
    ) -> JointState[State]:
        G = self.target.n_global
        inner = self.at(state.delta).retract(state.inner, step_global[:G], step_local)
        return JointState(inner, state.delta + step_global[G:])


@dataclass(frozen=True)
class JointOutcome(Generic[State]):
    """Outcome of :func:`solve_joint`.

    Attributes
    ----------
    solution : Solution
        Of the :class:`JointProblem` (state: :class:`JointState`); its information is that
        of the target's global parameters and Δ, pose corrections marginalised.
    pose_model : KinematicPoseModel
    identifiability : KinematicIdentifiability
    """

    solution: Solution[JointState[State]]
    pose_model: KinematicPoseModel
    identifiability: KinematicIdentifiability

    @property
    def state(self) -> State:
        """The target's state at the solution."""
        return self.solution.state.inner

    @property
    def corrections(self) -> KinematicCorrections:
        """The estimated corrections, with the parameters kept nominal named."""
        found = self.pose_model.corrections(self.solution.state.delta)
        return replace(found, kept_nominal=self.identifiability.unidentifiable)

    @property
    def covariance(self) -> FloatArray:
        """Covariance (G + F, G + F) of the target's global parameters and Δ."""
        return np.asarray(np.linalg.inv(self.solution.information))


def solve_joint(
    problem: PoseDrivenProblem[State],
    state: State,
    model: KinematicModel,
    q: FloatArray,
    joint_config: JointCalibrationConfig,
    config: SolverConfig,
) -> JointOutcome[State]:
    """Estimate the identifiable kinematic corrections with the target's parameters.

    Parameters
    ----------
    problem : PoseDrivenProblem
        The target's problem (or several placements', :class:`MultiScanProblem`); its
        flange poses are replaced by the nominal model's forward kinematics of ``q``. Its
        per-sample pose prior should be the arm's repeatability
        (:class:`JointCalibrationConfig`).
    state : State
        Start: the target's solution with the nominal (or recorded) poses.
    model : KinematicModel
        Nominal.
    q : ndarray, shape (M, n)
        Joint vector of each sample (:meth:`KinematicSetup.joint_positions`).
    joint_config : JointCalibrationConfig
    config : SolverConfig

    Raises
    ------
    SolverError
        Non-finite values.
    """
    sigma = joint_config.prior_sigma(model)
    every = KinematicPoseModel(model, q, np.arange(len(sigma)), sigma)
    start = JointProblem(problem.with_flange_poses(every.poses(np.zeros(len(sigma)))), every)
    zero = JointState(state, np.zeros(len(sigma)))
    geometric = normal_equations(start.linearise(zero), config, None)
    prior_information = np.zeros(start.n_global)
    prior_information[problem.n_global :] = 1.0 / sigma**2
    identifiability = kinematic_identifiability(
        geometric.schur_information() - np.diag(prior_information),
        problem.n_global,
        model.parameter_names,
        sigma,
        joint_config.rtol,
    )
    names = model.parameter_names
    free = np.array(sorted(names.index(n) for n in identifiability.identifiable), dtype=int)
    pose_model = KinematicPoseModel(model, q, free, sigma[free])
    joint = JointProblem(start.target, pose_model)
    solution = solve(joint, JointState(state, np.zeros(len(free))), config)
    if not (np.all(np.isfinite(solution.state.delta)) and np.isfinite(solution.cost_history[-1])):
        raise SolverError("the joint kinematic calibration produced non-finite values")
    return JointOutcome(solution, pose_model, identifiability)


@dataclass(frozen=True, eq=False)
class MultiScanProblem(Generic[State]):
    """Several target placements scanned by one arm with one sensor, as one problem.

    The placements share the hand-eye (the first :data:`~.solver.N_HAND_EYE` global
    parameters of each); each keeps its own other global parameters (its target), after the
    hand-eye in placement order. Samples are stacked in placement order, point rows padded
    to the longest. The state is the tuple of the placements' states (their hand-eyes move
    together).
    """

    scans: tuple[PoseDrivenProblem[State], ...]

    def _rows(self) -> list[int]:
        return [int(p.step_scale.shape[0]) - N_HAND_EYE for p in self.scans]

    def _offsets(self) -> list[int]:
        return list(N_HAND_EYE + np.concatenate([[0], np.cumsum(self._rows())[:-1]]).astype(int))

    @property
    def n_global(self) -> int:
        return N_HAND_EYE + sum(self._rows())

    @property
    def step_scale(self) -> FloatArray:
        scales = [self.scans[0].step_scale[:N_HAND_EYE]]
        scales += [p.step_scale[N_HAND_EYE:] for p in self.scans]
        return np.concatenate(scales)

    def _columns(self, i: int) -> FloatArray:
        """Global columns (G_i,) of placement i in the joint global vector."""
        start = self._offsets()[i]
        own = np.arange(start, start + self._rows()[i])
        return np.concatenate([np.arange(N_HAND_EYE), own])

    @property
    def n_samples(self) -> int:
        return sum(p.n_samples for p in self.scans)

    def _bounds(self) -> FloatArray:
        """Sample index where each placement starts, and the total (len(scans) + 1,)."""
        return np.cumsum([0, *(p.n_samples for p in self.scans)])

    def _stack(self, blocks: list[FloatArray]) -> FloatArray:
        """Per-placement (M_i, K_i, ...) arrays stacked into (M, K, ...), zero-padded."""
        K = max(b.shape[1] for b in blocks)
        padded = [
            np.concatenate([b, np.zeros((b.shape[0], K - b.shape[1], *b.shape[2:]))], axis=1)
            for b in blocks
        ]
        return np.concatenate(padded, axis=0)

    def _join(self, parts: list[Residuals]) -> Residuals:
        return Residuals(
            self._stack([r.points for r in parts]),
            np.concatenate([r.pose_prior for r in parts]),
            np.concatenate([r.global_prior for r in parts]),
        )

    def residuals(self, state: tuple[State, ...]) -> Residuals:
        return self._join([p.residuals(s) for p, s in zip(self.scans, state, strict=True)])

    def linearise(self, state: tuple[State, ...]) -> Linearisation:
        parts = [p.linearise(s) for p, s in zip(self.scans, state, strict=True)]
        G = self.n_global
        J_global, priors = [], []
        for i, lin in enumerate(parts):
            columns = self._columns(i)
            J = np.zeros((*lin.J_global.shape[:2], G))
            J[:, :, columns] = lin.J_global
            J_global.append(J)
            if lin.global_prior_jacobian is not None and len(lin.global_prior_jacobian):
                rows = np.zeros((len(lin.global_prior_jacobian), G))
                rows[:, columns] = lin.global_prior_jacobian
                priors.append(rows)
        return Linearisation(
            residuals=self._join([lin.residuals for lin in parts]),
            J_global=self._stack(J_global),
            J_local=self._stack([lin.J_local for lin in parts]),
            pose_prior_sqrt_information=parts[0].pose_prior_sqrt_information,
            global_prior_jacobian=np.vstack(priors) if priors else None,
        )

    def retract(
        self, state: tuple[State, ...], step_global: FloatArray, step_local: FloatArray
    ) -> tuple[State, ...]:
        bounds = self._bounds()
        return tuple(
            p.retract(s, step_global[self._columns(i)], step_local[bounds[i] : bounds[i + 1]])
            for i, (p, s) in enumerate(zip(self.scans, state, strict=True))
        )

    def with_flange_poses(self, T_base_flange: FloatArray) -> MultiScanProblem[State]:
        bounds = self._bounds()
        return MultiScanProblem(
            tuple(
                p.with_flange_poses(T_base_flange[bounds[i] : bounds[i + 1]])
                for i, p in enumerate(self.scans)
            )
        )

    def pose_corrections(self, state: tuple[State, ...]) -> FloatArray:
        return np.concatenate(
            [p.pose_corrections(s) for p, s in zip(self.scans, state, strict=True)]
        )
