"""The noise of a profile along its line, learned from a recording's residuals.

A real profiler's points err by a few µm of local (point-to-point) noise and by a smooth
depth error along the line of several µm over a few mm, drawn anew with every profile
(speckle, surface, the triangulation's peak finder). White noise averages out over a
profile's points; the smooth error does not: it moves a profile's fitted position by about
itself. A fit that weighs the points as independent takes every profile's smooth error for
signal, and says it knows the result far better than it does.

:class:`LineNoise` models the residual of point i of a profile (m, along the fitted
surface's normal) as

    C_ik = σ_w² δ_ik + c_i c_k σ_s² exp(−(x_i − x_k)² / (2 ℓ²)),

σ_w the white noise, σ_s and ℓ the smooth depth error's 1σ and correlation length along
the line (x, sensor frame), and c_i the cosine between the surface normal and the depth
axis (a depth error moves a point off a tilted surface by c times itself).

:func:`learn_line_noise` estimates (σ_w, σ_s, ℓ) from the residuals of a first fit pooled
over all the recording's profiles, by restricted maximum likelihood (REML): each profile's
residuals are scored only in the directions its own fitted parameters (its pose
correction) leave free, so that the smooth error those parameters absorbed is not missed.
:func:`line_whitening` turns the model into one linear map per profile that makes its
residuals independent and of unit variance (generalised least squares).

The smooth part is kept only where the residuals call for it: a likelihood-ratio test of
the fit against white noise alone (REML, 2 more parameters, χ² at
:data:`SMOOTH_FALSE_ALARM`). White-noise residuals learn ``smooth_sigma_m`` 0, and a
refinement then weighs the points as independent, as before.
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
#: False-alarm probability of the test that finds a smooth part in white-noise residuals
#: (the 3σ two-sided normal tail, as the self-check's tests).
SMOOTH_FALSE_ALARM = 0.0027


@dataclass(frozen=True)
class LineNoise:
    """White and smooth noise of a profile's points along its line (module docstring).

    Attributes
    ----------
    white_sigma_m : float
        1σ of the independent point noise, m.
    smooth_sigma_m : float
        1σ of the smooth depth error, m.
    length_m : float
        Correlation length of the smooth error along the line, m.
    """

    white_sigma_m: float
    smooth_sigma_m: float
    length_m: float

    def __post_init__(self) -> None:
        values = (self.white_sigma_m, self.smooth_sigma_m, self.length_m)
        if not all(math.isfinite(v) for v in values) or self.white_sigma_m <= 0.0:
            raise InputError(f"line noise: white σ must be > 0 and all finite, got {values}")
        if self.smooth_sigma_m < 0.0 or self.length_m <= 0.0:
            raise InputError(f"line noise: smooth σ >= 0 and length > 0 needed, got {values}")

    def covariance(self, x_m: FloatArray, cosine: FloatArray) -> FloatArray:
        """Covariance (..., N, N) of the residuals of points at ``x_m`` (..., N), m².

        ``cosine`` (..., N) is each point's normal-to-depth cosine (1: a surface facing
        the sensor).
        """
        d = x_m[..., :, None] - x_m[..., None, :]
        smooth = np.exp(-0.5 * (d / self.length_m) ** 2) * self.smooth_sigma_m**2
        C = cosine[..., :, None] * smooth * cosine[..., None, :]
        n = x_m.shape[-1]
        return np.asarray(C + self.white_sigma_m**2 * np.eye(n))


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

    C = w² I + U Λ Uᵀ (U orthonormal columns, K × R per profile), so
    W = (I − U diag(g) Uᵀ) / w with g = 1 − (1 + Λ/w²)^−½. :func:`line_whitening` builds it
    from a low-rank (Hilbert-space) basis of the smooth error; applying it costs O(K R).

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
    """

    white: float
    U: NDArray[np.float32]
    shrink: FloatArray

    def apply(self, a: FloatArray) -> FloatArray:
        """W a for residuals (M, K) or Jacobians (M, K, P)."""
        vector = a.ndim == 2
        b = a[..., None] if vector else a
        U = self.U.astype(np.float64)  # a chunk's: the problem applies it chunk by chunk
        projected = U.transpose(0, 2, 1) @ b  # (M, R, P)
        out = (b - U @ (self.shrink[..., None] * projected)) / self.white
        return np.asarray(out[..., 0] if vector else out)

    def take(self, rows: ArrayLike) -> Whitening:
        """The whitening of the profiles ``rows`` (indices)."""
        index = np.asarray(rows, dtype=np.intp)
        return Whitening(self.white, self.U[index], self.shrink[index])


def line_whitening(
    noise: LineNoise, x_m: FloatArray, cosine: FloatArray, mask: FloatArray, unit_m: float
) -> Whitening:
    """:class:`Whitening` of the points' residuals (in units of ``unit_m``) under ``noise``.

    The smooth part's Gaussian kernel is expanded per profile in the Laplacian eigenbasis of
    an interval around the profile's points, sin(π j (x − a) / (2 L)), weighted by the
    kernel's spectral density σ_s² √(2π) ℓ exp(−ω_j² ℓ² / 2) at ω_j = π j / (2 L) (Solin and
    Särkkä 2020), up to ω = :data:`SPECTRUM_CUT` / ℓ: a few tens of functions, however many
    points the profile has.

    Parameters
    ----------
    noise : LineNoise
    x_m : ndarray, shape (M, K)
        Each point's place along the line (sensor x), m.
    cosine : ndarray, shape (M, K)
        Each point's normal-to-depth cosine.
    mask : ndarray, shape (M, K)
        1 for a real point, 0 for padding (the map scales padding by 1 / w only).
    unit_m : float
        The unit the residuals are in (e.g. the configured sensor σ), m.
    """
    m = mask > 0.0
    length = noise.length_m
    lo = np.min(np.where(m, x_m, np.inf), axis=1)
    hi = np.max(np.where(m, x_m, -np.inf), axis=1)
    lo, hi = np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)
    half = 0.5 * np.maximum(hi - lo, 0.0) + DOMAIN_MARGIN * length  # L per profile
    n_basis = max(1, math.ceil(SPECTRUM_CUT * 2.0 * float(np.max(half)) / (math.pi * length)))
    j = np.arange(1, n_basis + 1)
    white = noise.white_sigma_m / unit_m
    M, K = x_m.shape
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
        B = np.where(
            m[rows, :, None], cosine[rows, :, None] * basis * np.sqrt(density)[:, None, :], 0.0
        )
        Q, R = np.linalg.qr(B)  # batched thin QR: B = Q R
        lam, V = np.linalg.eigh(R @ R.transpose(0, 2, 1))
        U[rows] = Q @ V
        shrink[rows] = 1.0 - 1.0 / np.sqrt(1.0 + np.maximum(lam, 0.0) / white**2)
    return Whitening(white, U, shrink)


class _Reml:
    """Minus twice the restricted log-likelihood of (σ_w, σ_s, ℓ) and its gradient, for
    one set of padded profiles (constants dropped; everything in units of ``unit_m``).

    With C the covariance, X the fitted directions and P = C⁻¹ − C⁻¹X (XᵀC⁻¹X)⁻¹ XᵀC⁻¹,
    the cost is log|C| + log|XᵀC⁻¹X| + rᵀPr and its derivative by a parameter θ is
    tr(P ∂C/∂θ) − (Pr)ᵀ ∂C/∂θ (Pr) (Harville 1977). The point distances are computed
    once, so a likelihood evaluation costs a Cholesky factor and a few products per profile.
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
        d = x_m[:, :, None] - x_m[:, None, :]
        self.d2 = np.where(both, d**2, 0.0)
        self.cc = np.where(both, cosine[:, :, None] * cosine[:, None, :], 0.0)
        self.eye_real = np.eye(x_m.shape[1]) * m[:, :, None]
        self.eye_pad = np.eye(x_m.shape[1]) * ~m[:, :, None]
        self.r = np.where(m, residuals, 0.0)[..., None] / unit_m
        self.X = bases

    def __call__(self, log_params: FloatArray) -> tuple[float, FloatArray]:
        white2, smooth2, length2 = np.exp(2.0 * np.asarray(log_params))
        shape = self.cc * np.exp(-0.5 * self.d2 / length2)
        smooth = smooth2 * shape
        C = white2 * self.eye_real + smooth + self.eye_pad
        L = np.linalg.cholesky(C)
        Ci = np.linalg.inv(C)  # symmetric positive definite, well conditioned (white part)
        X, r = self.X, self.r
        A = Ci @ X  # C⁻¹ X
        XtCiX = X.transpose(0, 2, 1) @ A
        # A profile of lower rank has zero columns: 1 on their diagonal keeps M invertible.
        XtCiX = XtCiX + np.eye(X.shape[2]) * (np.einsum("mii->mi", XtCiX) == 0.0)[:, None, :]
        P = Ci - A @ np.linalg.solve(XtCiX, A.transpose(0, 2, 1))
        Pr = P @ r
        logdet_C = 2.0 * np.sum(np.log(np.einsum("mii->mi", L)))
        _, logdet_X = np.linalg.slogdet(XtCiX)
        cost = float(logdet_C + np.sum(logdet_X) + np.sum(r * Pr))
        # tr(P ∂C) − (Pr)ᵀ ∂C (Pr) for ∂C/∂log σ_w = 2σ_w² I (real points), ∂C/∂log σ_s =
        # 2 × smooth, ∂C/∂log ℓ = smooth × d²/ℓ².
        Q = P - Pr * Pr.transpose(0, 2, 1)
        Qs = Q * smooth
        gradient = np.array(
            [
                2.0
                * white2
                * np.sum(np.einsum("mii->mi", Q) * np.einsum("mii->mi", self.eye_real)),
                2.0 * np.sum(Qs),
                np.sum(Qs * self.d2) / length2,
            ]
        )
        return cost, gradient


def learning_profiles(mask: FloatArray) -> NDArray[np.intp]:
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
    mask: FloatArray,
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
        1 for a real point, 0 for padding.
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
    from scipy.optimize import minimize  # loaded only where used
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
    d2 = np.diff(r, n=2, axis=1)[m[:, 2:] & m[:, 1:-1] & m[:, :-2]]
    white0 = float(np.sqrt(np.mean(d2**2) / 6.0)) if len(d2) else unit
    start = np.log([max(white0, 1e-3 * unit) / unit, 1.0, 0.2 * span])
    spacing = span / max(float(np.median(np.sum(m, axis=1))) - 1.0, 1.0)
    bounds = [(math.log(1e-4), math.log(10.0))] * 2 + [
        (math.log(spacing), math.log(max(2.0 * span, 2.0 * spacing)))
    ]
    reml = _Reml(r, x, c, m.astype(np.float64), X, unit)
    best = minimize(
        reml,
        np.clip(start, [b[0] for b in bounds], [b[1] for b in bounds]),
        method="L-BFGS-B",
        jac=True,
        bounds=bounds,
        # Relative to a cost of thousands: 1e-3 or less, against a test threshold of 11.8.
        options={"ftol": 1e-7},
    )
    white, smooth, length = np.exp(best.x)
    # White noise alone: the REML variance is closed form, the residual's part outside the
    # fitted directions over its degrees of freedom (the bases are orthonormal).
    free = np.count_nonzero(m) - np.count_nonzero(np.any(X != 0.0, axis=1))
    outside = np.sum(r**2) - np.sum((X.transpose(0, 2, 1) @ r[..., None]) ** 2)
    white_only = 0.5 * math.log(max(outside / max(free, 1), 1e-300)) - math.log(unit)
    white_only = float(np.clip(white_only, *bounds[0]))
    white_only_cost, _ = reml(np.array([white_only, bounds[1][0], best.x[2]]))
    if white_only_cost - best.fun < chdtri(2.0, SMOOTH_FALSE_ALARM):
        return LineNoise(float(math.exp(white_only) * unit), 0.0, float(length))
    return LineNoise(float(white * unit), float(smooth * unit), float(length))


def _orthonormal_bases(bases: FloatArray) -> FloatArray:
    """Each profile's fitted directions as orthonormal columns (M, K, P'), P' the largest
    rank; a profile of lower rank gets zero columns (which the cost leaves out)."""
    U, s, _ = np.linalg.svd(bases, full_matrices=False)
    rank = s > RANK_TOLERANCE * s[:, :1]
    p = int(np.max(np.sum(rank, axis=1)))
    U, rank = U[:, :, :p], rank[:, :p]
    return np.asarray(U * rank[:, None, :])
