"""The noise of a profile along its line, learned from a recording's residuals.

A real profiler's points err by a few µm of local (point-to-point) noise and by a smooth
depth error along the line of several µm over a few mm, drawn anew with every profile
(speckle, surface, the triangulation's peak finder). White noise averages out over a
profile's points; the smooth error does not: it moves a profile's fitted position by about
itself. A fit that weighs the points as independent takes every profile's smooth error for
signal, and says it knows the result far better than it does.

:class:`LineNoise` models the residual of point i of a profile (m, along the fitted
surface's normal) as

    C_ik = (σ_w² + c_i² σ_d²) δ_ik + c_i c_k σ_s² exp(−(x_i − x_k)² / (2 ℓ²)),

σ_w the white noise, σ_d a depth noise drawn anew at every point (the smooth part's limit
ℓ → 0), σ_s and ℓ the smooth depth error's 1σ and correlation length along the line (x,
sensor frame), and c_i the cosine between the surface normal and the depth axis (a depth
error moves a point off a tilted surface by c times itself).

:func:`learn_line_noise` estimates (σ_w, σ_d, σ_s, ℓ) from the residuals of a first fit pooled
over all the recording's profiles, by restricted maximum likelihood (REML): each profile's
residuals are scored only in the directions its own fitted parameters (its pose
correction) leave free, so that the smooth error those parameters absorbed is not missed.
The likelihood is multimodal in ℓ, so ℓ is searched globally (its profile likelihood on a
log-spaced grid, then refined), the same wherever a caller starts.
:func:`line_whitening` turns the model into one linear map per profile that makes its
residuals independent and of unit variance (generalised least squares).

The smooth part is kept only where the residuals call for it, by two likelihood-ratio
tests (REML, χ² at :data:`SMOOTH_FALSE_ALARM`): against white noise alone (2 more
parameters, σ_s and ℓ), and against the model's own uncorrelated limit ℓ → 0 (1 more, ℓ),
where the depth part is drawn anew at every point. A smooth part that the second test
does not find is no error correlated along the line but a point variance σ_w² + c_i² σ_d²
that grows with the cosine (a profiler whose depth noise exceeds its lateral one, or a
surface normal out of the laser plane): the residuals of ``paper`` (5 µm in x and z) and
``ur_scancontrol`` (8 µm depth, 6 µm lateral) favour that limit by 8 and 80 over any
ℓ ≥ one learning point spacing. That limit is kept as σ_d where it beats white noise by
the same test (1 more parameter): the points are then weighed by 1 / (σ_w² + c_i² σ_d²),
a diagonal whitening (``paper``: 3.4 µm white and 3.0 µm depth, ``ur_scancontrol`` 3.7 and
7.3 µm: its 8 µm at c = 1). A σ_d without bound (σ_w → 0, the τ grid's top:
``cluttered_camera``, whose grazing points would weigh without limit) is not kept.
Where σ_d is kept, a smooth part beside it (σ_w, σ_d, σ_s, ℓ together) is kept where it
beats σ_d alone by the same test (2 more parameters): a profiler with a larger depth noise
and a smooth shape error (``ur_scancontrol`` with issue 29's ``shape`` face, 4 µm over 2 mm:
without it 8 of 8 recordings took the smooth part for per-point depth noise, and the
rotation about the line was 1.3 times its 1σ RMS over 16 seeds).
White-noise residuals learn σ_d = σ_s = 0, and a refinement then weighs the points as
independent and alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..types import FloatArray

#: Fewest points a profile needs to take part in :func:`learn_line_noise`.
MIN_POINTS = 8
#: Points per profile that :func:`learn_line_noise` uses at most (evenly spaced along the
#: profile): enough to see a correlation length of a few point spacings, at a quarter of
#: the cost of 200 (60 points under-estimated a 6 µm smooth part by a third).
LEARN_POINTS = 100
#: Profiles that :func:`learn_line_noise` uses at most (evenly spaced through the recording):
#: the noise is the sensor's, and 16 profiles of 100 points pin its three numbers to 10-25 %
#: (test_line_noise); every profile more costs a Cholesky factor per likelihood evaluation.
LEARN_PROFILES = 16
#: Relative singular-value floor below which a profile's fitted directions are dependent.
RANK_TOLERANCE = 1e-6
#: False-alarm probability of the tests that find a smooth part in white-noise residuals
#: (the 3σ two-sided normal tail, as the self-check's tests).
SMOOTH_FALSE_ALARM = 0.0027
#: Ratio of neighbouring correlation lengths on :func:`learn_line_noise`'s grid (from one
#: point spacing to twice the span; 13-15 lengths on the committed bags), each costing an
#: eigendecomposition per learning profile; the best is refined between its neighbours.
LENGTH_STEP = 1.5
#: Grid of the smooth-to-white variance ratio τ = σ_s² / σ_w² at one correlation length
#: (σ_s from 1/1000 to 1000 times σ_w, steps of 1.33 in σ_s), refined by a parabola through
#: the best and its neighbours. A cost that still falls at its top marks a smooth part of
#: unbounded size: a pattern in the residuals (a misfit) that no noise level explains.
TAU_GRID = tuple(float(t) for t in np.geomspace(1e-6, 1e6, 49))
#: Fractions of the depth-only model's τ_d = σ_d² / σ_w² at which a smooth part beside the
#: depth noise is searched (a smooth part takes some of the variance the depth noise held
#: alone: the ``shape`` face on ``ur_scancontrol`` learns 0.5-0.8 of it).
DEPTH_FRACTIONS = tuple(float(f) for f in np.geomspace(0.05, 1.0, 8))


@dataclass(frozen=True)
class LineNoise:
    """White, per-point depth and smooth noise of a profile's points along its line (module
    docstring).

    Attributes
    ----------
    white_sigma_m : float
        1σ of the independent point noise, m.
    smooth_sigma_m : float
        1σ of the smooth depth error, m.
    length_m : float
        Correlation length of the smooth error along the line, m.
    depth_sigma_m : float
        1σ of the independent depth noise beyond the white noise, m: a point whose surface
        normal makes the cosine c with the depth axis errs by √(σ_w² + c² σ_d²).
    """

    white_sigma_m: float
    smooth_sigma_m: float
    length_m: float
    depth_sigma_m: float = 0.0

    def __post_init__(self) -> None:
        values = (self.white_sigma_m, self.smooth_sigma_m, self.length_m, self.depth_sigma_m)
        if not all(math.isfinite(v) for v in values) or self.white_sigma_m <= 0.0:
            raise InputError(f"line noise: white σ must be > 0 and all finite, got {values}")
        if self.smooth_sigma_m < 0.0 or self.length_m <= 0.0 or self.depth_sigma_m < 0.0:
            raise InputError(
                f"line noise: smooth σ >= 0, depth σ >= 0 and length > 0 needed, got {values}"
            )

    @property
    def point_sigma_m(self) -> float:
        """1σ of a point on a surface that faces the sensor (c = 1), every part together, m."""
        return math.sqrt(self.white_sigma_m**2 + self.depth_sigma_m**2 + self.smooth_sigma_m**2)

    def point_variance(self, cosine: FloatArray) -> FloatArray:
        """Independent variance σ_w² + c² σ_d² of points with normal-to-depth ``cosine``, m²."""
        return np.asarray(self.white_sigma_m**2 + (cosine * self.depth_sigma_m) ** 2)

    def covariance(self, x_m: FloatArray, cosine: FloatArray) -> FloatArray:
        """Covariance (..., N, N) of the residuals of points at ``x_m`` (..., N), m².

        ``cosine`` (..., N) is each point's normal-to-depth cosine (1: a surface facing
        the sensor).
        """
        d = x_m[..., :, None] - x_m[..., None, :]
        smooth = np.exp(-0.5 * (d / self.length_m) ** 2) * self.smooth_sigma_m**2
        C = cosine[..., :, None] * smooth * cosine[..., None, :]
        n = x_m.shape[-1]
        return np.asarray(C + self.point_variance(cosine)[..., None] * np.eye(n))


#: Highest angular frequency of the smooth error's spectrum the low-rank whitening keeps, in
#: units of 1 / length: the Gaussian kernel's spectral density there is e^-10 of its peak.
SPECTRUM_CUT = 4.5
#: Margin of the low-rank basis' domain beyond each profile's ends, in correlation lengths
#: (the Hilbert-space basis bends the covariance near its domain's boundary).
DOMAIN_MARGIN = 2.0
#: Values per array of one chunk of :func:`line_whitening` (profiles × points × basis
#: functions): 8 MB in float64, however long the recording.
WHITENING_CHUNK_VALUES = 1 << 20


@dataclass(frozen=True)
class Whitening:
    """Per-profile W with W C Wᵀ = I, applied without forming the K × K matrices.

    C = D + B Bᵀ, D = diag(σ_i²) the points' independent variances (σ_i² = w² + c_i² σ_d²)
    and B the smooth part's basis. With s_i = w / σ_i and U Λ Uᵀ = diag(s) B Bᵀ diag(s)
    (U orthonormal columns, K × R per profile), W = (I − U diag(g) Uᵀ) diag(s) / w with
    g = 1 − (1 + Λ/w²)^−½. :func:`line_whitening` builds it from a low-rank (Hilbert-space)
    basis of the smooth error; applying it costs O(K R), and O(K) without a smooth part
    (R = 0: a diagonal whitening).

    Attributes
    ----------
    white : float
        w, the white σ in the residuals' unit.
    U : ndarray, shape (M, K, R)
        Orthonormal directions of the smooth part (zero rows on padding), float32: a few
        tens of them per point, the largest array of a long recording's problem, and a
        weighting that float32's 1e-7 moves by far less than any 1σ.
    shrink : ndarray, shape (M, R)
        g per direction.
    diagonal : ndarray, shape (M, K), or None
        s_i = w / σ_i per point (1 on padding), float32; None where every σ_i is w
        (no depth noise).
    """

    white: float
    U: NDArray[np.float32]
    shrink: FloatArray
    diagonal: NDArray[np.float32] | None = None

    def apply(self, a: FloatArray) -> FloatArray:
        """W a for residuals (M, K) or Jacobians (M, K, P)."""
        vector = a.ndim == 2
        b = a[..., None] if vector else a
        if self.diagonal is not None:
            b = b * self.diagonal[..., None]
        if self.U.shape[2]:
            U = self.U.astype(np.float64)  # a chunk's: the problem applies it chunk by chunk
            projected = U.transpose(0, 2, 1) @ b  # (M, R, P)
            b = b - U @ (self.shrink[..., None] * projected)
        out = b / self.white
        return np.asarray(out[..., 0] if vector else out)

    def white_share(self) -> FloatArray:
        """w² (C⁻¹)_ii per point (M, K): the share of a point's weight in the whitened fit
        that its white noise holds. C⁻¹ = WᵀW = diag(s) (I − U diag(2g − g²) Uᵀ) diag(s) / w²."""
        U = self.U.astype(np.float64)
        g = self.shrink
        share = 1.0 - np.einsum("mkr,mr->mk", U**2, 2.0 * g - g**2)
        return np.asarray(share if self.diagonal is None else share * self.diagonal**2)

    def take(self, rows: ArrayLike) -> Whitening:
        """The whitening of the profiles ``rows`` (indices)."""
        index = np.asarray(rows, dtype=np.intp)
        diagonal = None if self.diagonal is None else self.diagonal[index]
        return Whitening(self.white, self.U[index], self.shrink[index], diagonal)


def line_whitening(
    noise: LineNoise, x_m: FloatArray, cosine: FloatArray, mask: ArrayLike, unit_m: float
) -> Whitening:
    """:class:`Whitening` of the points' residuals (in units of ``unit_m``) under ``noise``.

    The smooth part's Gaussian kernel is expanded per profile in the Laplacian eigenbasis of
    an interval around the profile's points, sin(π j (x − a) / (2 L)), weighted by the
    kernel's spectral density σ_s² √(2π) ℓ exp(−ω_j² ℓ² / 2) at ω_j = π j / (2 L) (Solin and
    Särkkä 2020), up to ω = :data:`SPECTRUM_CUT` / ℓ: a few tens of functions, however many
    points the profile has. Without a smooth part the whitening is diagonal (no basis).

    Parameters
    ----------
    noise : LineNoise
    x_m : ndarray, shape (M, K)
        Each point's place along the line (sensor x), m.
    cosine : ndarray, shape (M, K)
        Each point's normal-to-depth cosine.
    mask : ndarray, shape (M, K)
        1 (or True) for a real point, 0 for padding (the map scales padding by 1 / w only).
    unit_m : float
        The unit the residuals are in (e.g. the configured sensor σ), m.
    """
    m = np.asarray(mask) > 0.0
    M, K = x_m.shape
    white = noise.white_sigma_m / unit_m
    diagonal = None
    if noise.depth_sigma_m > 0.0:
        ratio = noise.white_sigma_m / np.sqrt(noise.point_variance(cosine))
        diagonal = np.where(m, ratio, 1.0).astype(np.float32)
    if noise.smooth_sigma_m == 0.0:
        return Whitening(white, np.zeros((M, K, 0), dtype=np.float32), np.zeros((M, 0)), diagonal)
    length = noise.length_m
    lo = np.min(np.where(m, x_m, np.inf), axis=1)
    hi = np.max(np.where(m, x_m, -np.inf), axis=1)
    lo, hi = np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)
    half = 0.5 * np.maximum(hi - lo, 0.0) + DOMAIN_MARGIN * length  # L per profile
    n_basis = max(1, math.ceil(SPECTRUM_CUT * 2.0 * float(np.max(half)) / (math.pi * length)))
    j = np.arange(1, n_basis + 1)
    rank = min(K, n_basis)
    U, shrink = np.empty((M, K, rank), dtype=np.float32), np.empty((M, rank))
    step = max(1, WHITENING_CHUNK_VALUES // max(K * n_basis, 1))
    for start in range(0, M, step):  # a chunk of profiles at a time: (K, J) arrays each
        rows = slice(start, start + step)
        omega = math.pi * j[None, :] / (2.0 * half[rows, None])  # (m, J)
        density = (
            (noise.smooth_sigma_m / unit_m) ** 2
            * math.sqrt(2.0 * math.pi)
            * length
            * np.exp(-0.5 * (omega * length) ** 2)
        )
        centre = 0.5 * (lo[rows] + hi[rows])
        phase = (x_m[rows] - centre[:, None] + half[rows, None])[..., None] * omega[:, None, :]
        basis = np.sin(phase) / np.sqrt(half[rows])[:, None, None]  # (m, K, J)
        weight = cosine[rows] if diagonal is None else cosine[rows] * diagonal[rows]
        B = np.where(
            m[rows, :, None], weight[..., None] * basis * np.sqrt(density)[:, None, :], 0.0
        )
        Q, R = np.linalg.qr(B)  # batched thin QR: B = Q R
        lam, V = np.linalg.eigh(R @ R.transpose(0, 2, 1))
        U[rows] = Q @ V
        shrink[rows] = 1.0 - 1.0 / np.sqrt(1.0 + np.maximum(lam, 0.0) / white**2)
    return Whitening(white, U, shrink, diagonal)


class _Profile:
    """Minus twice the restricted log-likelihood of one set of padded profiles at a fixed
    correlation length ℓ, minimised over the two variances (constants dropped; everything
    in units of ``unit_m``).

    With C = σ_w² (I + τ S), S the smooth part's shape (c_i c_k exp(−d²/(2ℓ²))), X the fitted
    directions and P = C⁻¹ − C⁻¹X (XᵀC⁻¹X)⁻¹ XᵀC⁻¹, the cost is log|C| + log|XᵀC⁻¹X| + rᵀPr
    (Harville 1977). One eigendecomposition S = Q Λ Qᵀ per profile and ℓ makes it cheap for
    any (σ_w, τ): C = σ_w² Q (1 + τΛ) Qᵀ, and σ_w² has the closed form rᵀP₁r / (N − p) (P₁
    at σ_w = 1; N points, p fitted directions), so the cost is a function of τ alone,
    minimised on a grid of τ (:data:`TAU_GRID`) and refined by a parabola through the best
    and its neighbours. ℓ = 0 is the family's limit where the smooth part is uncorrelated from point
    to point (S diagonal, c_i²): a variance that grows with the cosine, no correlation.
    """

    def __init__(
        self,
        residuals: FloatArray,
        x_m: FloatArray,
        cosine: FloatArray,
        mask: FloatArray,
        bases: FloatArray,
        unit_m: float,
    ) -> None:
        m = mask > 0.0
        both = m[:, :, None] & m[:, None, :]
        self.d2 = np.where(both, (x_m[:, :, None] - x_m[:, None, :]) ** 2, 0.0)
        self.cc = np.where(both, cosine[:, :, None] * cosine[:, None, :], 0.0)
        self.c2 = np.where(m, cosine**2, 0.0)
        self.r = np.where(m, residuals, 0.0) / unit_m
        self.X = bases
        # A profile of lower rank has zero columns: 1 on their diagonal keeps XᵀC⁻¹X
        # invertible and leaves its determinant alone.
        self.zero_columns = np.all(bases == 0.0, axis=1)  # (M, P)
        self.free = max(float(np.count_nonzero(m) - np.count_nonzero(~self.zero_columns)), 1.0)

    def __call__(self, length_m: float) -> tuple[float, float, float]:
        """(cost, σ_w, τ) at the best τ for correlation length ``length_m`` (0: the
        uncorrelated limit); σ_w in units of ``unit_m``. τ is the grid's largest where the
        cost still falls there (a smooth part of unbounded size)."""
        if length_m > 0.0:
            lam, Q = np.linalg.eigh(self.cc * np.exp(-0.5 * self.d2 / length_m**2))
            rq = np.einsum("mki,mk->mi", Q, self.r)
            Xq = Q.transpose(0, 2, 1) @ self.X
        else:
            lam, rq, Xq = self.c2, self.r, self.X
        lam = np.maximum(lam, 0.0)
        log_tau = np.log(TAU_GRID)
        costs, white2 = self._cost(lam, rq, Xq, np.exp(log_tau))
        i = int(np.argmin(costs))
        if 0 < i < len(log_tau) - 1:  # the vertex of the parabola through i and its neighbours
            y0, y1, y2 = costs[i - 1 : i + 2]
            h = log_tau[1] - log_tau[0]
            vertex = log_tau[i] + 0.5 * h * (y0 - y2) / max(y0 - 2.0 * y1 + y2, 1e-300)
            cost, white2_at = self._cost(lam, rq, Xq, np.exp([vertex]))
            if cost[0] < costs[i]:
                return float(cost[0]), math.sqrt(float(white2_at[0])), math.exp(vertex)
        return float(costs[i]), math.sqrt(float(white2[i])), TAU_GRID[i]

    def white_only(self) -> tuple[float, float]:
        """(cost, σ_w) of white noise alone (τ = 0), in units of ``unit_m``."""
        cost, white2 = self._cost(self.c2, self.r, self.X, np.zeros(1))
        return float(cost[0]), math.sqrt(float(white2[0]))

    def _cost(
        self, lam: FloatArray, rq: FloatArray, Xq: FloatArray, tau: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Cost and σ_w² at each τ of ``tau`` (T,), in the eigenbasis of S (eigenvalues
        ``lam`` (M, K), residuals ``rq`` (M, K) and directions ``Xq`` (M, K, P) in it)."""
        d = 1.0 + tau[:, None, None] * lam  # (T, M, K): C's eigenvalues over σ_w²
        Xd = Xq / d[..., None]
        A = Xq.transpose(0, 2, 1) @ Xd + np.eye(Xq.shape[2]) * self.zero_columns[:, None, :]
        b = np.einsum("tmkp,mk->tmp", Xd, rq)
        quad = np.sum(rq**2 / d, axis=(1, 2)) - np.sum(
            b * np.linalg.solve(A, b[..., None])[..., 0], axis=(1, 2)
        )
        white2 = np.maximum(quad, 1e-300) / self.free
        logdet = np.sum(np.log(d), axis=(1, 2)) + np.sum(np.linalg.slogdet(A)[1], axis=1)
        return self.free * np.log(white2) + logdet, white2


def learning_profiles(mask: ArrayLike) -> NDArray[np.intp]:
    """The rows (profiles) of a padded (M, K) point ``mask`` that :func:`learn_line_noise`
    learns from: at most :data:`LEARN_PROFILES` of those with :data:`MIN_POINTS` points,
    evenly spaced. A caller may hand :func:`learn_line_noise` these rows alone (the same
    outcome) and so compute the bases of a few profiles, not of the whole recording.

    Raises
    ------
    InputError
        Fewer than two profiles with :data:`MIN_POINTS` points.
    """
    keep = np.sum(np.asarray(mask) > 0.0, axis=1) >= MIN_POINTS
    if np.count_nonzero(keep) < 2:
        raise InputError(f"learn_line_noise needs two profiles of {MIN_POINTS}+ points")
    rows = np.flatnonzero(keep)
    spread = np.linspace(0, len(rows) - 1, min(len(rows), LEARN_PROFILES)).astype(int)
    return np.asarray(rows[np.unique(spread)])


def learn_line_noise(
    residuals_m: FloatArray,
    x_m: FloatArray,
    cosine: FloatArray,
    mask: ArrayLike,
    bases: FloatArray,
) -> LineNoise:
    """The recording's :class:`LineNoise` from a first fit's residuals (REML).

    Parameters
    ----------
    residuals_m : ndarray, shape (M, K)
        Signed point residuals of M profiles after a fit, m (any value on padding).
    x_m : ndarray, shape (M, K)
        Each point's place along the line (sensor x), m.
    cosine : ndarray, shape (M, K)
        Each point's normal-to-depth cosine.
    mask : ndarray, shape (M, K)
        1 (or True) for a real point, 0 for padding.
    bases : ndarray, shape (M, K, P)
        Per profile, the residuals' derivatives by the profile's own fitted parameters (its
        pose correction): directions in which its residuals were fitted away. Dependent
        columns are allowed.

    Returns
    -------
    LineNoise

    Raises
    ------
    InputError
        Fewer than two profiles with :data:`MIN_POINTS` points, or shapes that differ.
    """
    from scipy.optimize import minimize_scalar  # loaded only where used
    from scipy.special import chdtri

    shapes = {np.shape(a) for a in (residuals_m, x_m, cosine, mask)}
    if len(shapes) != 1 or np.shape(bases)[:2] != np.shape(mask):
        raise InputError(f"learn_line_noise: array shapes differ: {shapes}, {np.shape(bases)}")
    rows = learning_profiles(mask)
    every = max(1, math.ceil(np.shape(mask)[1] / LEARN_POINTS))
    m = (np.asarray(mask) > 0.0)[rows, ::every]
    r = np.where(m, residuals_m[rows, ::every], 0.0)
    x = np.where(m, x_m[rows, ::every], 0.0)
    c = np.where(m, cosine[rows, ::every], 0.0)
    X = _orthonormal_bases(np.where(m[..., None], bases[rows, ::every], 0.0))
    unit = float(np.sqrt(np.sum(r**2) / np.count_nonzero(m)))
    if not unit > 0.0:
        raise InputError("learn_line_noise: the residuals are all zero")
    span = float(
        np.median(np.max(np.where(m, x, -np.inf), axis=1) - np.min(np.where(m, x, np.inf), axis=1))
    )
    spacing = span / max(float(np.median(np.sum(m, axis=1))) - 1.0, 1.0)
    profile = _Profile(r, x, c, m.astype(np.float64), X, unit)
    # The likelihood is multimodal in ℓ (and flat where the smooth part is small): its
    # profile over a log-spaced grid from one point spacing to twice the span, then a
    # bounded search between the best grid point's neighbours.
    lengths = np.geomspace(
        spacing,
        max(2.0 * span, 2.0 * spacing),
        max(2, math.ceil(math.log(max(2.0 * span / spacing, 2.0)) / math.log(LENGTH_STEP)) + 1),
    )
    top = TAU_GRID[-1]

    def proper(length: float) -> float:
        """The profile's cost at ``length``, +inf where the smooth part is unbounded."""
        cost, _, tau = profile(length)
        return cost if tau < top else math.inf

    costs = [proper(float(length)) for length in lengths]
    i = int(np.argmin(costs))
    length = float(lengths[i])
    if math.isfinite(costs[i]):
        refined = minimize_scalar(
            lambda log_length: min(proper(math.exp(log_length)), costs[i] + 1.0),
            bounds=(
                math.log(lengths[max(i - 1, 0)]),
                math.log(lengths[min(i + 1, len(lengths) - 1)]),
            ),
            method="bounded",
            options={"xatol": 0.03},
        )
        length = math.exp(refined.x) if refined.fun < costs[i] else length
    best, white, tau = profile(length)
    white_cost, white_only = profile.white_only()
    uncorrelated, white_at_zero, tau_at_zero = profile(0.0)
    # A smooth part is kept where it explains the residuals better than white noise alone
    # (σ_s and ℓ: 2 degrees of freedom) and better than its own uncorrelated limit (ℓ: 1).
    # Where ℓ → 0 fits as well, the residuals show a variance that varies with the cosine
    # (e.g. a profiler's depth noise larger than its lateral one), not an error correlated
    # along the line: that limit is kept as σ_d where it beats white noise (σ_d: 1).
    if (
        math.isfinite(costs[i])
        and white_cost - best >= chdtri(2.0, SMOOTH_FALSE_ALARM)
        and uncorrelated - best >= chdtri(1.0, SMOOTH_FALSE_ALARM)
    ):
        return LineNoise(float(white * unit), float(math.sqrt(tau) * white * unit), float(length))
    if tau_at_zero < top and white_cost - uncorrelated >= chdtri(1.0, SMOOTH_FALSE_ALARM):
        depth = math.sqrt(tau_at_zero) * white_at_zero * unit
        # A smooth part beside the depth noise (σ_s and ℓ: 2 more degrees of freedom).
        cost, w, tau_s, tau_d, ell = _smooth_beside_depth(
            (r, x, c, m.astype(np.float64), X, unit), lengths, tau_at_zero
        )
        if uncorrelated - cost >= chdtri(2.0, SMOOTH_FALSE_ALARM):
            smooth, beside = math.sqrt(tau_s) * w * unit, math.sqrt(tau_d) * w * unit
            return LineNoise(float(w * unit), float(smooth), float(ell), float(beside))
        return LineNoise(float(white_at_zero * unit), 0.0, float(length), float(depth))
    return LineNoise(float(white_only * unit), 0.0, float(length))


def _smooth_beside_depth(
    arrays: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, float],
    lengths: FloatArray,
    tau_depth: float,
) -> tuple[float, float, float, float, float]:
    """The best (cost, σ_w, τ_s, τ_d, ℓ) of the full model C = σ_w² (I + τ_d D + τ_s S),
    D = diag(c²); σ_w in the residuals' unit. ℓ is searched over ``lengths`` at half the
    depth-only model's τ_d (``tau_depth``), then τ_d over the fractions
    :data:`DEPTH_FRACTIONS` of it at that ℓ (a sixth of the cost of the whole grid, the
    same noise on the ``shape`` face).

    At fixed τ_d, with A = I + τ_d D, C = σ_w² A^½ (I + τ_s S′) A^½ where S′ is the smooth
    shape with the cosines c / √(1 + τ_d c²): :class:`_Profile` of the residuals and
    directions scaled by A^−½ gives the cost, plus log|A|. ``arrays``: the residuals,
    places, cosines, mask, orthonormal directions and unit that :class:`_Profile` takes.
    """
    r, x, c, m, X, unit = arrays

    def scaled(fraction: float) -> tuple[_Profile, float]:
        a = np.where(m > 0.0, 1.0 + fraction * tau_depth * c**2, 1.0)
        root = np.sqrt(a)
        profile = _Profile(r / root, x, c / root, m, X / root[..., None], unit)
        return profile, float(np.sum(np.log(a)))

    def proper(profile: _Profile, log_det: float, length: float) -> tuple[float, float, float]:
        cost, white, tau = profile(length)
        return (cost + log_det if tau < TAU_GRID[-1] else math.inf), white, tau

    half, log_det = scaled(0.5)
    length = float(min(lengths, key=lambda ell: proper(half, log_det, float(ell))[0]))
    best = (math.inf, 1.0, 0.0, tau_depth, length)
    for fraction in DEPTH_FRACTIONS:
        cost, white, tau = proper(*scaled(fraction), length)
        if cost < best[0]:
            best = (cost, white, tau, fraction * tau_depth, length)
    return best


def _orthonormal_bases(bases: FloatArray) -> FloatArray:
    """Each profile's fitted directions as orthonormal columns (M, K, P'), P' the largest
    rank; a profile of lower rank gets zero columns (which the cost leaves out)."""
    U, s, _ = np.linalg.svd(bases, full_matrices=False)
    rank = s > RANK_TOLERANCE * s[:, :1]
    p = int(np.max(np.sum(rank, axis=1)))
    U, rank = U[:, :, :p], rank[:, :p]
    return np.asarray(U * rank[:, None, :])
