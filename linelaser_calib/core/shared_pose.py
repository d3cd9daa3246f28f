"""The robot's pose error shared by neighbouring views, learned from the recording.

A real arm errs by region: poses near each other share most of their error. A refinement
that gives each view its own pose correction with an independent prior (every target's,
through :mod:`.solver`) is a fair estimator when the sharing is unknown but
the wrong yardstick: where neighbouring views err alike, their residuals do not average the
robot's error away, and the hand-eye scatters more than the per-view covariance says. This
module knows no target: a target hands it its views linearised at the solution
(:meth:`ViewsLinearised.from_linearisation`, the solver's own record; a cylinder's or a
sphere's profile of many points reduced by :meth:`ViewsLinearised.from_points`) and reports
the 1σ of :func:`shared_pose_error` where it is wider than its own.

The model
---------
Linearised at the solution with every pose correction at zero, the whitened residuals (K per
view: a line's corner 2, a known point's 3) are y = X·Δx + Σ_j A_j e_j + n: X (KM, G) the
Jacobian of the global parameters (hand-eye first), A_j (K, 6) view j's pose Jacobian times
the robot's prior 1σ (σ_r, σ_t per axis), e_j its pose error in units of that prior, n the
measurement noise (whitened: unit covariance as fitted, times a variance factor s). The pose
errors are Gaussian with

    Cov(e_i, e_j) = exp(−d_ij / ℓ) · I₆,

d_ij the separation of the two flange poses (:func:`pose_separations`: position over 5 cm
plus the turn over 8 deg) and ℓ the separation over which they share their error. The
stated prior fixes each view's own error (d_ii = 0); the recording decides how far it is
shared. ℓ far below the poses' spacing is the refinement's own model (each view alone). An
error shared by every view is a hand-eye error the data cannot see, so ℓ stops at the poses'
largest separation, and the stated prior bounds what it adds.

(s, ℓ) are the restricted maximum-likelihood estimates (REML: the likelihood of the residuals
with the global parameters integrated out, a loose hand-eye prior included as
pseudo-observations): ℓ the best of :data:`LENGTHS` log-spaced lengths, s found at each, the
shortest unless a longer one is clearly likelier (:data:`SHARING_EVIDENCE`); on at most
:data:`MAX_FIT_VIEWS` views spread through the recording. Where the robot's prior is itself
an estimate (the cylinder's and the sphere's variance factor, judged over all six directions
while a profile sees three or four of them), its amplitude a ≤ 1 is learned with them
(V = s·I + a·exp(−d / ℓ) ∘ A Aᵀ): with a held at 1 a prior too large for the directions a
profile sees was taken for a shared error, since an error shared by all views is absorbed by
the hand-eye and leaves smaller residuals (``ur_scancontrol``, 40 poses, each erring alone:
ℓ at up to 4 times the poses' spacing chosen on 4 of 10 seeds, the 1σ up to 2.7 times the
per-view one; with a learned, 0.33-0.51 on every seed, 2 of 10 share over less than the
spacing and the 1σ stays within 9 %). On the line a learned a traded against ℓ (an error
shared by all views and a small one leave alike residuals) and took the worst of seed 6
back to 3.77: its stated prior stands. That rough model
(:data:`ROUGH`) bounds the robot's error by the stated prior, and a real arm errs by region
far more than its repeatability (issue 29's cell: 0.2 mm 1σ against a stated 0.03 mm). So the
line and the known point also fit a :data:`SMOOTH` model: each view's own error at the stated
prior (the floor, never less) plus a shared one of learned amplitude a ≥ 0,

    Cov(e_i, e_j) = δ_ij · I₆ + a · exp(−d_ij² / 2ℓ²) · I₆,

d_ij the Euclidean distance of :func:`pose_coordinates` (an arm's absolute-accuracy error is
a smooth function of where it is: link lengths, joint offsets), a = 0 unless clearly likelier
(:data:`SHARING_EVIDENCE`). The 1σ is the two models' covariances weighed by their REML
likelihoods (the law of total variance: the estimate is the same under both), so the
clearly likelier one decides and a tie counts both; each axis at least the rough model's
(correlations kept), so that it never narrows where the stated prior holds. On the recording 1 twin
(``bench/private_twins.py``, 12 seeds) the smooth model is the likelier on every seed (by
4-32 on 11, a tie on seed 10) and the worst |error| / 1σ goes 9.58 -> 3.06; on
``line_ridge`` (its arm's error near the prior) the rough one keeps its 1σ. A doubted view is judged
against its neighbours (:func:`neighbour_chi2`). The covariance
of the refinement's per-view estimate under that model is the sandwich

    H⁻¹ · (Xᵀ V₀⁻¹ V V₀⁻¹ X + prior) · H⁻¹,    H = Xᵀ V₀⁻¹ X + prior,

V₀ the per-view model the refinement solved (s = 1, each view alone) and V the learned one,
over all views. The estimate itself is left alone: its 1σ is what was wrong.

On ``line_ridge`` (the simulated arm's error drawn at 8 points of the sweep and blended, so
that about six neighbouring views share it) the per-view 1σ left the hand-eye off by up to
3.79 of it over seeds 0-9 (3.29 and 3.79 on seeds 3 and 6, mostly the robot's error: with
it made independent per view the worst was 2.43); with the sharing learned here 2.17 and
2.82, the worst of the ten. The sandwich with the simulator's own sharing (known only
there) gives about 1.9 and 2.4 on those two. The known point (20 views of a weld seam's
point, the paper's pattern, the arm's error drawn at every 4th view and blended;
``bench/known_point_regional.py``): the worst of 20 seeds 4.11 -> 2.47; where each view
errs alone its 1σ stays within 7 % of the per-view one. The cylinder and the sphere:
``bench/regional_sigma.py`` (docs/benchmarks.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import LinAlgError, cho_factor, cho_solve, qr
from scipy.optimize import minimize, minimize_scalar
from scipy.spatial.distance import cdist
from scipy.stats import chi2

from .geometry import FloatArray
from .regions import CLUSTER_ANGLE_RAD, CLUSTER_RADIUS_M, DISTANCE_BLOCK
from .solver import (
    BlockProblem,
    ChunkedProblem,
    Linearisation,
    SolverConfig,
    evaluate_loss,
    recording_chi2_scale,
)

#: Most views whose residuals the likelihood search uses (evenly spaced through the
#: recording); the sandwich uses all. Each evaluation factors a (KN, KN) matrix.
MAX_FIT_VIEWS = 100
#: Most rows (views times the rows each gives the search) the likelihood search uses: the
#: line's 100 views (2 rows) and the known point's (3), a cylinder's 75 (4 rows: on the
#: ``cluttered_camera`` twin 0.31 -> 0.18 s CPU a search, under load).
MAX_FIT_ROWS = 300
#: Fewest views for the search: fewer cannot tell a shared error from the corner noise.
MIN_FIT_VIEWS = 12
#: The shortest ℓ searched, as a fraction of the poses' median nearest-neighbour separation:
#: neighbours then share e⁻¹⁰ of their error, each view alone.
SHORTEST = 0.1
#: Lengths ℓ tried, log-spaced from the shortest to the longest (neighbouring ones about a
#: factor 2 apart on a sweep).
LENGTHS = 8
#: The negative log-likelihood by which the best length must beat the shortest for the views
#: to be taken as sharing their error: half the χ² 95 % point for one degree of freedom. On
#: a cylinder whose arm errs per pose (``ur_scancontrol``, 40 poses, seed 1) ℓ at 1.3 times
#: the poses' median spacing was 0.2 likelier than each view alone (the robot's amplitude
#: held at its prior), and its 1σ 1.3 times the per-view one along flange y; with the error
#: drawn at every 4th view and blended, 42 (22-38 over seeds 0-9, the amplitude learned).
#: The line's and the known point's figures below are unchanged by it.
SHARING_EVIDENCE = 0.5 * float(chi2.ppf(0.95, 1))
#: How closely log s is found at each length (the robot's amplitude a fixed).
NOISE_TOLERANCE = 0.02
#: How closely the negative log-likelihood is minimised over (log s, log a) at each length.
LEVELS_TOLERANCE = 1e-6
#: Bounds of the corner-noise variance factor s.
NOISE_FACTOR_BOUNDS = (1e-3, 1e4)
#: Models whose likelihood is below this share of the models' together add nothing to the
#: 1σ (the :data:`ROUGH` model's still floors it).
MIN_WEIGHT = 1e-4
#: Bounds of the robot error's variance factor a (:data:`ROUGH`): the stated prior bounds it.
AMPLITUDE_BOUNDS = (1e-3, 1.0)
#: Bounds of the shared error's variance factor a (:data:`SMOOTH`), over each view's own at the
#: stated prior: up to 100 times the prior's 1σ.
SHARED_BOUNDS = (1e-3, 1e4)
#: The two models of how the views share the robot's error (:attr:`SharedPoseError.kind`).
ROUGH, SMOOTH = "rough", "smooth"
#: A view's direction in its points' space (:meth:`ViewsLinearised.from_points`) carries
#: the Jacobians where its pivoted-QR diagonal exceeds this fraction of the view's first:
#: beyond it the columns are combinations of the others to rounding (a cylinder's rotation
#: about its axis, the same rigid motion as the hand-eye's and the pose's columns).
RANK_TOLERANCE = 1e-8


class ViewsLinearised(NamedTuple):
    """The views' residuals and Jacobians at the solution, every pose correction at zero.

    Attributes
    ----------
    residuals : ndarray, shape (M, K)
        Whitened residuals of each view.
    J_global : ndarray, shape (M, K, G)
        Their Jacobian of the global parameters.
    J_pose : ndarray, shape (M, K, 6)
        Their Jacobian of the view's pose correction [ω, τ], times the robot's prior 1σ.
    robot_sigma : ndarray, shape (6,)
        That prior 1σ ([σ_r] * 3 + [σ_t] * 3; rad, m).
    prior, J_prior : ndarray, shapes (R,) and (R, G)
        Whitened residuals and Jacobian of the global parameters' prior (R may be 0).
    T_base_flange : ndarray, shape (M, 4, 4)
        The views' flange poses.
    pose_rows : int or None
        The first rows of each view that the likelihood search learns from (those its pose
        correction moves, :meth:`from_points`), and the robot error's amplitude a with
        them; None for all rows and a = 1 (the stated prior). The 1σ uses all.
    """

    residuals: FloatArray
    J_global: FloatArray
    J_pose: FloatArray
    robot_sigma: FloatArray
    prior: FloatArray
    J_prior: FloatArray
    T_base_flange: FloatArray
    pose_rows: int | None = None

    @classmethod
    def from_linearisation(cls, lin: Linearisation, T_base_flange: FloatArray) -> ViewsLinearised:
        """The views of a refinement's linearisation (:class:`~.solver.Linearisation`) at its
        solution with every pose correction at zero, flange poses (M, 4, 4); its global prior
        is the one the reported covariance counts."""
        precision = lin.pose_prior_sqrt_information
        J_prior = lin.global_prior_jacobian
        return cls(
            lin.residuals.points,
            lin.J_global,
            lin.J_local / precision,
            1.0 / precision,
            lin.residuals.global_prior,
            np.zeros((0, lin.J_global.shape[2])) if J_prior is None else J_prior,
            T_base_flange,
        )

    @classmethod
    def from_points(
        cls,
        problem: BlockProblem[Any],
        solution: Any,
        corrections: FloatArray,
        config: SolverConfig,
        mask: NDArray[np.bool_],
        T_base_flange: FloatArray,
        factors: tuple[float, float] = (1.0, 1.0),
    ) -> ViewsLinearised:
        """The views of a refinement on many points per view (a cylinder's or a sphere's
        profile) at its ``solution``, pose corrections (M, 6) in the local coordinates of
        its retraction, reduced to what the model above can use of them.

        Linearised at the solution (the Jacobians and robust weights of the reported
        covariance), a view's K whitened point residuals with every pose correction at zero
        are y = e − J_pose·δ̂ to first order, and y = X·Δx + A·e + n with n white. In an
        orthonormal basis of the columns of A (the first :attr:`pose_rows`: the views'
        largest rank, :data:`RANK_TOLERANCE`, pivoted QR on the view's points, ``mask``
        (M, K)) and then of what X adds to them, the rows keep everything the pose error and
        the globals move, and their noise stays white; the points' space beyond is not used.
        The likelihood search learns (s, ℓ) from the first rows alone: where the globals
        alone move a view (a cylinder's radius against the along-line scale, nearly the same
        stretch of one arc), a real profile's shape error shows many times the white noise,
        which is the globals' concern and no sign of the robot's error. ``factors``: the
        refinement's sensor and robot variance factors (s_s², s_r²), whose model the
        per-view estimate's 1σ is (V₀ = s_s² + s_r²·A Aᵀ, in units of s_s² here: the pose
        Jacobian is times the stated prior and s_r, :attr:`robot_sigma` the stated prior, so
        that the self-check's subsets, whose s_r differs a little, take the sharing as
        learned)."""
        chunks = (
            problem.linearise_chunks(solution)
            if isinstance(problem, ChunkedProblem)
            else [problem.linearise(solution)]
        )
        sensor, robot = math.sqrt(factors[0]), math.sqrt(factors[1])
        views: list[tuple[FloatArray, FloatArray, FloatArray]] = []  # y, X, A of each view
        row, first = 0, None
        for lin in chunks:
            first = lin if first is None else first  # the global prior's, as the solver's
            e = lin.residuals.points
            weights = np.sqrt(evaluate_loss(e, config)[1]) / sensor
            y = e - np.einsum("mkl,ml->mk", lin.J_local, corrections[row : row + len(e)])
            sigma = robot / first.pose_prior_sqrt_information
            G = lin.J_global.shape[2]
            w = weights[..., None]
            block = np.concatenate([y[..., None], lin.J_global, lin.J_local * sigma], axis=2) * w
            block[~mask[row : row + len(e)]] = 0.0  # a padded row: no row
            # Each view's K rows by their triangular factor: an orthogonal map of its rows
            # (a zero row changes nothing), so every basis, rank and reduced row below is
            # the same, at the size of the columns, not of the points.
            for R in np.linalg.qr(block, mode="r"):
                views.append((R[:, 0], R[:, 1 : G + 1], R[:, G + 1 :]))
            row += len(e)
        assert first is not None
        pose = max(_rank(A) for _, _, A in views)
        bases = []
        for _, X, A in views:
            Q_A = qr(A, mode="economic", pivoting=True)[0][:, :pose]
            beyond = X - Q_A @ (Q_A.T @ X)
            bases.append((Q_A, qr(beyond, mode="economic", pivoting=True)[0], _rank(beyond)))
        rows_X = max(rank for _, _, rank in bases)
        reduced = [
            np.concatenate([Q_A, Q_X[:, :rows_X]], axis=1).T @ np.column_stack([y, X, A])
            for (y, X, A), (Q_A, Q_X, _) in zip(views, bases, strict=True)
        ]
        stacked = np.stack(reduced)
        G = stacked.shape[2] - 7
        J_prior = first.global_prior_jacobian
        return cls(
            stacked[:, :, 0],
            stacked[:, :, 1 : G + 1],
            stacked[:, :, G + 1 :],
            1.0 / first.pose_prior_sqrt_information,
            first.residuals.global_prior,
            np.zeros((0, G)) if J_prior is None else J_prior,
            T_base_flange,
            pose,
        )


def _rank(J: FloatArray) -> int:
    """Numerical rank of a view's Jacobian (K, P) by pivoted QR (:data:`RANK_TOLERANCE`)."""
    diagonal = np.abs(np.diag(qr(J, mode="r", pivoting=True)[0]))
    return int(np.sum(diagonal > RANK_TOLERANCE * diagonal[0])) if diagonal.size else 0


@dataclass(frozen=True)
class SharedPoseError:
    """How the robot's pose error is shared between views, and the 1σ it gives.

    Attributes
    ----------
    noise_factor : float
        s, the corners' variance over their fitted covariance.
    amplitude : float
        a, the robot's pose-error variance over the stated prior's (at most 1).
    length : float
        ℓ, the separation over which they share it, in the units of :func:`pose_separations`
        (1 is 5 cm of flange travel or 8 deg of flange turn).
    covariance : ndarray, shape (G, G)
        Of the refinement's estimate of the global parameters under the learned model.
    robot_sigma : ndarray, shape (6,)
        The robot's prior 1σ ([σ_r] * 3 + [σ_t] * 3; rad, m) the sharing was learned with:
        a solve with another prior (the self-check's plain model) learns its own.
    kind : str
        :data:`ROUGH` (a = the amplitude of the whole error, shared as exp(−d / ℓ)) or
        :data:`SMOOTH` (each view's own error at the stated prior plus a shared one of
        amplitude a, exp(−d² / 2ℓ²)).
    evidence : float
        For :data:`SMOOTH`: how much likelier (negative log-likelihood) the shared error makes
        the recording than each view's error alone at the stated prior and than the
        :data:`ROUGH` model; 0 otherwise.
    models : tuple of Sharing
        The models learned, weighed by their likelihood: the covariance is their weighted
        sum (the law of total variance: the estimate is one), each axis at least the
        :data:`ROUGH` model's; the fields above are the likeliest's.
    """

    noise_factor: float
    amplitude: float
    length: float
    covariance: FloatArray
    robot_sigma: FloatArray
    kind: str = "rough"
    evidence: float = 0.0
    models: tuple[Sharing, ...] = ()

    @property
    def robot_excess(self) -> float:
        """The robot's error at a view (its own and the shared part) over the stated prior,
        as a ratio of 1σ."""
        return math.sqrt(1.0 + self.amplitude) if self.kind == SMOOTH else 1.0

    def excess_note(self, threshold: float) -> str | None:
        """A warning where the learned robot error is clearly larger than the stated prior
        (over ``threshold`` times, and likelier than the prior alone by
        :data:`SHARING_EVIDENCE`), naming both; else None."""
        excess = self.robot_excess
        if excess <= threshold or self.evidence < SHARING_EVIDENCE:
            return None
        sigma_r, sigma_t = float(self.robot_sigma[0]), float(self.robot_sigma[3])
        return (
            f"the robot's pose error is about {excess:.1f} times the prior assumed: "
            f"{sigma_t * excess * 1e3:.3f} mm and {math.degrees(sigma_r) * excess:.4f} deg per "
            f"pose (1 sigma, learned from how the residuals vary with the poses; shared by poses "
            f"within about {self.length * CLUSTER_RADIUS_M * 1e3:.0f} mm or "
            f"{math.degrees(self.length * CLUSTER_ANGLE_RAD):.0f} deg of each other) against "
            f"{sigma_t * 1e3:.3f} mm and {math.degrees(sigma_r):.4f} deg "
            "({setting:robot_sigma_t_m}, {setting:robot_sigma_r_rad}); the 1 sigma above counts "
            "the larger error, and the arm is less accurate than assumed"
        )


def pose_separations(T_a: FloatArray, T_b: FloatArray) -> FloatArray:
    """(A, B) separations of flange poses (A, 4, 4) and (B, 4, 4): the position step over
    :data:`~.regions.CLUSTER_RADIUS_M` plus the turn over :data:`~.regions.
    CLUSTER_ANGLE_RAD`, the turn measured as the chord ‖R_a − R_b‖ / √2 (the angle, for small
    ones). Unlike :func:`~.regions.pose_distances` a turn about the flange axis counts (it
    moves the arm's wrist), and both parts are Euclidean distances, so exp(−d / ℓ) is a
    valid correlation for any ℓ."""
    step = cdist(T_a[:, :3, 3], T_b[:, :3, 3]) / CLUSTER_RADIUS_M
    chord = cdist(T_a[:, :3, :3].reshape(-1, 9), T_b[:, :3, :3].reshape(-1, 9))
    return np.asarray(step + chord / (math.sqrt(2.0) * CLUSTER_ANGLE_RAD))


def pose_coordinates(T: FloatArray) -> FloatArray:
    """Flange poses (M, 4, 4) as points (M, 12) whose Euclidean distances combine the
    position step and the turn of :func:`pose_separations` in quadrature (a valid distance
    for exp(−d² / 2ℓ²), which their sum is not)."""
    position = T[:, :3, 3] / CLUSTER_RADIUS_M
    turn = T[:, :3, :3].reshape(-1, 9) / (math.sqrt(2.0) * CLUSTER_ANGLE_RAD)
    return np.concatenate([position, turn], axis=1)


def correlation(separation: FloatArray, length: float) -> FloatArray:
    """The correlation exp(−d / ℓ) of two views' pose errors ``separation`` apart."""
    return np.asarray(np.exp(-separation / length))


class Sharing(NamedTuple):
    """One model of the views' pose errors, as learned: its kind, s, a, ℓ, its negative
    REML log-likelihood, (:data:`SMOOTH`) its evidence over each view's error alone and over
    the :data:`ROUGH` model, and its weight among the models learned (their REML
    likelihoods, normalised)."""

    kind: str
    noise: float
    amplitude: float
    length: float
    cost: float = 0.0
    evidence: float = 0.0
    weight: float = 1.0

    def weights(self, T_a: FloatArray, T_b: FloatArray, same: NDArray[np.bool_]) -> FloatArray:
        """(A, B) covariance of two sets of views' pose errors (flange poses (A, 4, 4) and
        (B, 4, 4); ``same`` where a pair is one view), in units of the stated prior."""
        if self.kind == ROUGH:
            return self.amplitude * correlation(pose_separations(T_a, T_b), self.length)
        d = cdist(pose_coordinates(T_a), pose_coordinates(T_b)) / self.length
        return np.asarray(same + self.amplitude * np.exp(-0.5 * d**2))


class _Likelihood:
    """The negative restricted log-likelihood of a :class:`Sharing`'s levels on some views."""

    def __init__(self, views: ViewsLinearised, rows: int | None = None) -> None:
        A = views.J_pose[:, :rows]
        M, K, _ = A.shape
        flat = A.reshape(M * K, 6)
        self.y = views.residuals[:, :rows].ravel()
        self.X = views.J_global[:, :rows].reshape(M * K, -1)
        self.pose = flat @ flat.T  # (MK, MK): A_i A_jᵀ
        self.expand = np.repeat(np.arange(M), K)  # the view of each row
        self.T = views.T_base_flange
        self.same = np.eye(M, dtype=bool)
        self.separation = pose_separations(self.T, self.T)
        self.distance = cdist(pose_coordinates(self.T), pose_coordinates(self.T))
        self.prior_information = views.J_prior.T @ views.J_prior
        self.prior_gradient = views.J_prior.T @ views.prior
        self.prior_square = float(views.prior @ views.prior)

    def matrix(self, sharing: Sharing) -> FloatArray:
        """V = s·I + W ∘ A Aᵀ (W the pose errors' covariance, :meth:`Sharing.weights`)."""
        if sharing.kind == ROUGH:
            W = sharing.amplitude * correlation(self.separation, sharing.length)
        else:
            W = self.same + sharing.amplitude * np.exp(-0.5 * (self.distance / sharing.length) ** 2)
        V = W[np.ix_(self.expand, self.expand)] * self.pose
        V[np.diag_indices_from(V)] += sharing.noise
        return V

    def fitted(self, sharing: Sharing) -> tuple[Any, FloatArray, FloatArray] | None:
        """V's Cholesky factor, V⁻¹ X and the residuals with the globals fitted (y − X H⁻¹ g,
        the global prior counted); None where V or H is not positive definite."""
        try:
            factor = cho_factor(self.matrix(sharing))
        except LinAlgError:
            return None
        Vi_X = cho_solve(factor, self.X)
        H = self.X.T @ Vi_X + self.prior_information
        g = Vi_X.T @ self.y + self.prior_gradient
        try:
            step = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            return None
        return factor, Vi_X, self.y - self.X @ step

    def __call__(self, kind: str, log_s: float, log_length: float, log_amplitude: float) -> float:
        sharing = Sharing(kind, math.exp(log_s), math.exp(log_amplitude), math.exp(log_length))
        try:
            factor = cho_factor(self.matrix(sharing))
        except LinAlgError:
            return math.inf
        Vi_X, Vi_y = cho_solve(factor, self.X), cho_solve(factor, self.y)
        H = self.X.T @ Vi_X + self.prior_information
        g = self.X.T @ Vi_y + self.prior_gradient
        sign, log_det_H = np.linalg.slogdet(H)
        if sign <= 0:
            return math.inf
        quadratic = float(self.y @ Vi_y) + self.prior_square - float(g @ np.linalg.solve(H, g))
        log_det_V = 2.0 * float(np.sum(np.log(np.diag(factor[0]))))
        return 0.5 * (log_det_V + float(log_det_H) + quadratic)


def _best_levels(
    likelihood: _Likelihood, kind: str, log_length: float, free_amplitude: bool, start: FloatArray
) -> tuple[FloatArray, float]:
    """The REML (log s, log a) of a kind at a given ℓ and its negative likelihood; a = 1 (the
    stated prior) for :data:`ROUGH` unless ``free_amplitude``, searched from ``start`` then
    (and always for :data:`SMOOTH`)."""
    bounds = (math.log(NOISE_FACTOR_BOUNDS[0]), math.log(NOISE_FACTOR_BOUNDS[1]))
    if kind == ROUGH and not free_amplitude:
        noise = minimize_scalar(
            lambda log_s: likelihood(kind, log_s, log_length, 0.0),
            bounds=bounds,
            method="bounded",
            options={"xatol": NOISE_TOLERANCE},
        )
        return np.array([float(noise.x), 0.0]), float(noise.fun)
    amplitude = AMPLITUDE_BOUNDS if kind == ROUGH else SHARED_BOUNDS
    found = minimize(
        lambda x: likelihood(kind, float(x[0]), log_length, float(x[1])),
        start,
        method="L-BFGS-B",
        bounds=[bounds, (math.log(amplitude[0]), math.log(amplitude[1]))],
        options={"ftol": LEVELS_TOLERANCE},
    )
    return np.asarray(found.x, dtype=np.float64), float(found.fun)


def _fit(
    likelihood: _Likelihood, kind: str, shortest: float, longest: float, free_amplitude: bool
) -> Sharing:
    """The REML model of a kind, ℓ on a grid of :data:`LENGTHS` log-spaced from ``shortest``
    to ``longest``. :data:`ROUGH`: the shortest (each view alone) unless a longer one is
    clearly likelier (:data:`SHARING_EVIDENCE`). :data:`SMOOTH`: no shared error (a = 0)
    unless it is clearly likelier than each view's error alone at the stated prior."""
    grid = np.linspace(math.log(shortest), math.log(longest), LENGTHS)
    fits: list[tuple[FloatArray, float, float]] = []
    start = np.array([0.0, math.log(0.5)])
    for log_ell in grid:  # each length's search starts at the shorter one's levels
        levels, cost = _best_levels(likelihood, kind, float(log_ell), free_amplitude, start)
        fits.append((levels, cost, float(log_ell)))
        start = levels
    levels, cost, log_length = min(fits, key=lambda fit: fit[1])
    if kind == SMOOTH:
        alone = minimize_scalar(
            lambda log_s: likelihood(kind, log_s, log_length, -math.inf),
            bounds=(math.log(NOISE_FACTOR_BOUNDS[0]), math.log(NOISE_FACTOR_BOUNDS[1])),
            method="bounded",
            options={"xatol": NOISE_TOLERANCE},
        )
        evidence = float(alone.fun) - cost
        if evidence < SHARING_EVIDENCE:
            noise = math.exp(float(alone.x))
            return Sharing(kind, noise, 0.0, math.exp(log_length), float(alone.fun), evidence)
        return Sharing(
            kind, math.exp(levels[0]), math.exp(levels[1]), math.exp(log_length), cost, evidence
        )
    if fits[0][1] - cost < SHARING_EVIDENCE:
        levels, cost, log_length = fits[0]
    return Sharing(kind, math.exp(levels[0]), math.exp(levels[1]), math.exp(log_length), cost)


def _picked(views: ViewsLinearised) -> NDArray[np.intp]:
    """At most :data:`MAX_FIT_VIEWS` views (and :data:`MAX_FIT_ROWS` rows) spread evenly
    through the recording, for the likelihood search."""
    M = len(views.residuals)
    per_view = views.residuals.shape[1] if views.pose_rows is None else views.pose_rows
    most = min(MAX_FIT_VIEWS, MAX_FIT_ROWS // max(int(per_view), 1))
    return np.unique(np.linspace(0, M - 1, min(M, most)).round().astype(int))


def _subset(views: ViewsLinearised, index: NDArray[np.intp]) -> ViewsLinearised:
    """The views at ``index``, with the same global prior."""
    return views._replace(
        residuals=views.residuals[index],
        J_global=views.J_global[index],
        J_pose=views.J_pose[index],
        T_base_flange=views.T_base_flange[index],
    )


def _lengths(distance: FloatArray) -> tuple[float, float] | None:
    """The shortest and longest ℓ searched over views ``distance`` (M, M) apart: a tenth of
    their median nearest-neighbour step (:data:`SHORTEST`) to their largest; None where the
    poses do not differ."""
    nearest = np.sort(distance, axis=1)[:, 1]
    positive = nearest[nearest > 0.0]
    longest = float(distance.max())
    if not positive.size or longest <= float(np.median(positive)):
        return None
    return SHORTEST * float(np.median(positive)), longest


def _learn(views: ViewsLinearised) -> list[Sharing]:
    """The models of the views' sharing worth a 1σ (see the module docstring), learned on
    :func:`_picked` views; none where too few views or poses that do not differ leave nothing
    to learn. Views of many points (:attr:`ViewsLinearised.pose_rows`): the :data:`ROUGH`
    model with its amplitude learned (at most the stated prior). Otherwise the :data:`ROUGH`
    (a = 1) and the :data:`SMOOTH` models: the clearly likelier one, or both where neither is
    (:data:`SHARING_EVIDENCE`)."""
    if len(views.residuals) < MIN_FIT_VIEWS:
        return []
    likelihood = _Likelihood(_subset(views, _picked(views)), views.pose_rows)
    rough = _lengths(likelihood.separation)
    if rough is None:
        return []
    if views.pose_rows is not None:
        return [_fit(likelihood, ROUGH, *rough, True)]
    fits = [_fit(likelihood, ROUGH, *rough, False)]
    lengths = _lengths(likelihood.distance)
    if lengths is not None:
        smooth = _fit(likelihood, SMOOTH, *lengths, False)
        fits.append(smooth._replace(evidence=min(smooth.evidence, fits[0].cost - smooth.cost)))
    best = min(fit.cost for fit in fits)
    weights = np.exp([best - fit.cost for fit in fits])
    return [
        fit._replace(weight=float(w / np.sum(weights)))
        for fit, w in zip(fits, weights, strict=True)
    ]


def _meat(Z: FloatArray, A: FloatArray, T: FloatArray, sharing: Sharing) -> FloatArray:
    """Xᵀ V₀⁻¹ V V₀⁻¹ X (G, G) from Z = V₀⁻¹ X per view (M, K, G): the views' pairs a block
    of rows at a time (no (M, M) array)."""
    Q = np.einsum("mkg,mkl->mgl", Z, A)  # (M, G, 6): Z_jᵀ A_j
    meat = sharing.noise * np.einsum("mkg,mkh->gh", Z, Z)
    M = len(T)
    for start in range(0, M, DISTANCE_BLOCK):
        rows = slice(start, min(start + DISTANCE_BLOCK, M))
        same = np.arange(M)[rows, None] == np.arange(M)[None, :]
        KQ = sharing.weights(T[rows], T, same) @ Q.reshape(M, -1)
        meat += np.einsum("igl,ihl->gh", Q[rows], KQ.reshape(Q[rows].shape))
    return np.asarray(meat)


def _covariance(views: ViewsLinearised, sharing: Sharing) -> FloatArray:
    """The sandwich covariance (G, G) of the per-view estimate under ``sharing``."""
    # The refinement's model V₀ = I + diag_j(A_j A_jᵀ): Z_j = V₀_j⁻¹ X_j.
    A = views.J_pose
    Z = np.linalg.solve(np.eye(A.shape[1]) + A @ A.transpose(0, 2, 1), views.J_global)
    information = views.J_prior.T @ views.J_prior
    H = np.einsum("mkg,mkh->gh", views.J_global, Z) + information
    H_inv = np.linalg.inv(H)
    covariance = H_inv @ (_meat(Z, A, views.T_base_flange, sharing) + information) @ H_inv
    return np.asarray(0.5 * (covariance + covariance.T))


def shared_pose_error(
    views: ViewsLinearised, learned: SharedPoseError | None = None
) -> SharedPoseError | None:
    """The robot's error shared by neighbouring views and the 1σ of the per-view estimate
    under it (see the module docstring); None with fewer than :data:`MIN_FIT_VIEWS` views
    or poses that do not differ. Where two models were learned, their covariances weighed by
    their likelihoods (:attr:`SharedPoseError.models`), each axis at least the
    :data:`ROUGH` model's. ``learned``: the sharing learned on a
    superset of the views (the self-check's subsets of a recording), taken as it is, without
    a search, where it was learned with the same robot prior.
    """
    if learned is not None and np.array_equal(learned.robot_sigma, views.robot_sigma):
        models = list(learned.models)
    else:
        models = _learn(views)
    if not models:
        return None
    fits = [
        (model, _covariance(views, model))
        for model in models
        if model.weight > MIN_WEIGHT or model.kind == ROUGH
    ]
    covariance = np.asarray(sum(model.weight * C for model, C in fits))
    for model, C in fits:
        if model.kind == ROUGH:  # the floor: each axis at least the prior-bounded model's
            widen = np.sqrt(np.maximum(1.0, np.diag(C) / np.diag(covariance)))
            covariance = covariance * np.outer(widen, widen)
    likeliest = max(models, key=lambda model: model.weight)
    return SharedPoseError(
        noise_factor=likeliest.noise,
        amplitude=likeliest.amplitude,
        length=likeliest.length,
        covariance=np.asarray(covariance),
        robot_sigma=np.asarray(views.robot_sigma, dtype=np.float64),
        kind=likeliest.kind,
        evidence=likeliest.evidence,
        models=tuple(models),
    )


def _left_out(likelihood: _Likelihood, sharing: Sharing) -> FloatArray:
    """Each view's residual given all the others' (the globals fitted) under ``sharing``, as
    χ² with K (its rows) degrees of freedom, (M,); NaN where V or H is not positive
    definite. With P = V⁻¹ − V⁻¹X H⁻¹ XᵀV⁻¹, view i's is (P r)_iᵀ P_ii⁻¹ (P r)_i."""
    M, K = len(likelihood.T), len(likelihood.y) // len(likelihood.T)
    fitted = likelihood.fitted(sharing)
    if fitted is None:
        return np.full(M, math.nan)
    factor, Vi_X, residual = fitted
    H = likelihood.X.T @ Vi_X + likelihood.prior_information
    P = cho_solve(factor, np.eye(len(likelihood.y))) - Vi_X @ np.linalg.solve(H, Vi_X.T)
    u = cho_solve(factor, residual).reshape(M, K)
    blocks = P.reshape(M, K, M, K)[np.arange(M), :, np.arange(M), :]
    return np.asarray(np.einsum("mk,mk->m", u, np.linalg.solve(blocks, u[..., None])[..., 0]))


def neighbour_chi2(views: ViewsLinearised, positions: list[int]) -> FloatArray:
    """How far each view at ``positions`` lies from what the other views predict for it, as
    χ² with K (its rows) degrees of freedom: its residual given the others' under the sharing
    learned from the others (the likelier model), the globals fitted, on the scale of the
    others' own (each given the rest: their median over χ²'s, at least 1, as
    :func:`~.solver.recording_chi2_scale` judges a view among the recording's). A regional
    robot error moves neighbouring views together, so their residuals predict it; a wrong
    corner is alone. Infinite (no view is cleared) where the others are too few or their
    poses do not differ."""
    out = np.full(len(positions), math.inf)
    doubted = np.zeros(len(views.residuals), dtype=bool)
    doubted[positions] = True
    others = np.flatnonzero(~doubted)
    fits = _learn(_subset(views, others)) if len(others) >= MIN_FIT_VIEWS else []
    if not fits:
        return out
    sharing = max(fits, key=lambda fit: fit.weight)
    neighbours = others[_picked(_subset(views, others))]
    scale = recording_chi2_scale(
        _left_out(_Likelihood(_subset(views, neighbours)), sharing), views.residuals.shape[1]
    )
    for n, position in enumerate(positions):
        chi2 = _left_out(_Likelihood(_subset(views, np.append(neighbours, position))), sharing)
        out[n] = math.inf if math.isnan(chi2[-1]) else float(chi2[-1]) / scale
    return out


def alone_among_neighbours(
    views: ViewsLinearised, positions: list[int], limit: float
) -> dict[int, float]:
    """The views at ``positions`` (doubted by a test that takes each view alone) that their
    neighbours do not explain either: :func:`neighbour_chi2` above ``limit`` (infinite where
    it cannot be judged), by position."""
    if not positions:
        return {}
    chi2 = neighbour_chi2(views, positions)
    return {p: float(c) for p, c in zip(positions, chi2, strict=True) if c > limit}
