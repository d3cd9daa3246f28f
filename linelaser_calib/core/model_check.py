"""Is this profile the target's shape? Rival shape models, and a scale learned per recording.

A real profiler shows a few µm of local noise over tens of µm of smooth shape error (lens
distortion, laser-line curvature, surface form). A model residual measured against the
local noise therefore flags good profiles; this module judges a profile by two other
questions, and knows no target:

1. **Does a rival shape fit clearly better?** The target's own model of one profile (a
   circle, an ellipse, a V ...) and its rivals are fitted to the same points; each leaves a
   robust scale s (1.4826 · MAD of its residuals). The Bayesian information criterion

       BIC = n_eff · ln s² + k · ln n_eff

   (k the model's numbers) trades fit against complexity. Smooth shape error makes the
   residuals of neighbouring points alike, so the information a profile holds is that of
   n_eff = N (1 − ρ) / (1 + ρ) independent points (ρ the lag-1 autocorrelation of the best
   fit's residuals, in scan order), not of its N points: a more flexible rival that only
   follows some of the shape error gains little. A rival whose BIC lies
   :data:`CLEAR_BIC` below the model's fits clearly better (Kass & Raftery's "very strong"
   evidence). It names what a profile without the target's feature shows
   (:func:`rival_rejection`), and where it fits most of a recording's profiles better it
   puts the target's model in doubt (:func:`shape_doubt`); it never decides the target,
   which only the whole recording's full models do (:mod:`linelaser_calib.core.targets.rivals`).
2. **Is the profile an outlier among its recording's profiles?** The residual of the
   target's model on every profile of one recording (one sensor) gives the recording's
   scale: its median and robust spread across the profiles (:class:`RecordingScale`). A
   profile far above it is set aside; one within it is used, whatever its local noise.
   A profile's RMS is itself an estimate from its n_eff independent points, with a relative
   spread of 1/√(2 n_eff) (a χ² of n_eff degrees of freedom): where the caller gives n_eff,
   that spread is added to the recording's in quadrature (:func:`recording_outliers`). A
   smooth shape error a few millimetres long leaves a profile few independent points, so a
   larger RMS there is weak evidence (the ``sphere_sszn`` cell twin: 50 µm over 4 effective
   points against a median of 31 µm, one such stretch more); point-wise corruption (a dirty
   window, clutter on the arc) raises the RMS over hundreds of independent points, and is
   set aside.

Shapes fitted here (points (N, 2) in scan order, m): :func:`line_fit` (2 numbers),
:func:`circle_fit` (3), :func:`line_pair_fit` (a V or a step's two lines, 5 with the break),
:func:`conic_fit` (a general conic, 5). A target adds its own model (its circle, ellipse ...) as a
:class:`ShapeFit`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import ArrayLike
from scipy.special import ndtri

from linelaser_calib.core.types import FloatArray, Rejection

#: A rival whose BIC lies this much below the model's fits clearly better.
CLEAR_BIC = 10.0
#: The recording's spread across profiles is taken as at least this share of its median
#: (profiles that agree to a few per cent would otherwise make every small difference an
#: outlier).
MIN_SPREAD_SHARE = 0.1
#: σ per median absolute deviation for Gaussian values (scipy.stats.median_abs_deviation's
#: "normal" scale; its per-call cost, some ms, would dominate the fits here). The normal
#: quantile comes from scipy.special: scipy.stats costs most of a second to import.
MAD_TO_SIGMA = 1.0 / float(ndtri(0.75))


@dataclass(frozen=True)
class ShapeFit:
    """One shape model fitted to one profile.

    Attributes
    ----------
    name : str
        What the shape is, in words (``circle``, ``line pair``, ...).
    residuals_m : ndarray, shape (N,)
        Signed distances of the profile's points from the shape, in scan order, m.
    n_params : int
        The numbers the shape is fitted with.
    """

    name: str
    residuals_m: FloatArray
    n_params: int

    @cached_property
    def scale_m(self) -> float:
        """Robust scale of the residuals (1.4826 · MAD), m (computed once: a comparison
        asks for it several times)."""
        return robust_scale_m(self.residuals_m)


def median(values: ArrayLike) -> float:
    """The median of values (N,) as a float (NaN when one is NaN or N is 0)."""
    v = np.asarray(values, dtype=np.float64)
    return math.nan if v.size == 0 else float(np.median(v))


def robust_scale_m(residuals_m: ArrayLike) -> float:
    """1.4826 · median absolute deviation of residuals (N,), m: σ for Gaussian residuals,
    unmoved by a minority of outliers."""
    r = np.asarray(residuals_m, dtype=np.float64)
    return MAD_TO_SIGMA * median(np.abs(r - median(r)))


def effective_count(residuals_m: ArrayLike, scale_m: float | None = None) -> float:
    """Independent points the residuals (N,) of a fit, in scan order, are worth.

    N (1 − ρ) / (1 + ρ) with ρ the lag-1 autocorrelation (the variance of the mean of an
    AR(1) series, Pearson's correlation of neighbours), over the points within 3 robust σ
    (spikes left out; ``scale_m``, m, when the caller has it, else
    :func:`robust_scale_m`); at least 2 and at most N.
    """
    r = np.asarray(residuals_m, dtype=np.float64)
    scale = robust_scale_m(r) if scale_m is None else scale_m
    inside = r[np.abs(r) <= 3.0 * max(scale, 1e-300)]
    if len(inside) < 3 or float(np.std(inside)) == 0.0:
        return float(len(r))
    before = inside[:-1] - inside[:-1].mean()
    after = inside[1:] - inside[1:].mean()
    rho = float(before @ after) / math.sqrt(float(before @ before) * float(after @ after))
    rho = min(max(rho, 0.0), 1.0)
    return float(np.clip(len(inside) * (1.0 - rho) / (1.0 + rho), 2.0, len(r)))


@dataclass(frozen=True)
class Comparison:
    """A model against its rivals on one profile (:func:`compare_models`).

    Attributes
    ----------
    model : ShapeFit
        The target's model.
    rival : ShapeFit or None
        The rival with the lowest BIC (None without rivals).
    delta_bic : float
        The model's BIC minus that rival's: positive when the rival fits better.
    n_effective : float
        Independent points the profile is worth (:func:`effective_count`).
    """

    model: ShapeFit
    rival: ShapeFit | None
    delta_bic: float
    n_effective: float

    @property
    def rival_wins(self) -> bool:
        """Whether the rival fits clearly better (its BIC :data:`CLEAR_BIC` lower)."""
        return self.rival is not None and self.delta_bic > CLEAR_BIC

    @property
    def model_wins(self) -> bool:
        """Whether the model fits clearly better than every rival (its BIC :data:`CLEAR_BIC`
        lower)."""
        return self.rival is not None and self.delta_bic < -CLEAR_BIC

    def describe(self) -> str:
        """Both scales in µm and the BIC margin, for messages."""
        if self.rival is None:
            return f"{_a(self.model.name)} leaves {self.model.scale_m * 1e6:.1f} um"
        return (
            f"{_a(self.rival.name)} leaves {self.rival.scale_m * 1e6:.1f} um where "
            f"{_a(self.model.name)} leaves {self.model.scale_m * 1e6:.1f} um (robust scale; BIC "
            f"{abs(self.delta_bic):.0f} {'lower' if self.delta_bic > 0 else 'higher'}, over "
            f"{self.n_effective:.0f} effective of {len(self.model.residuals_m)} points)"
        )


def _a(name: str) -> str:
    """The name with its indefinite article ("an ellipse", "a line")."""
    return f"{'an' if name[:1] in 'aeiou' else 'a'} {name}"


def bic(fit: ShapeFit, n_effective: float) -> float:
    """n_eff · ln s² + k · ln n_eff of a fit (s its robust scale, floored at 1e-12 m)."""
    scale = max(fit.scale_m, 1e-12)
    return n_effective * math.log(scale * scale) + fit.n_params * math.log(n_effective)


def compare_models(model: ShapeFit, rivals: Sequence[ShapeFit]) -> Comparison:
    """The model against the rivals fitted to the same points (see the module docstring)."""
    if not rivals:
        return Comparison(model, None, 0.0, effective_count(model.residuals_m))
    fits = [model, *rivals]
    best = min(fits, key=lambda f: f.scale_m)
    n_effective = effective_count(best.residuals_m, best.scale_m)
    rival = min(rivals, key=lambda f: bic(f, n_effective))
    return Comparison(model, rival, bic(model, n_effective) - bic(rival, n_effective), n_effective)


def _check_points(points_xz: ArrayLike, least: int) -> FloatArray:
    p = np.asarray(points_xz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < least:
        raise ValueError(f"a shape fit needs points of shape (N >= {least}, 2), got {p.shape}")
    return p


def _line_distances(points_xz: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The least-squares line through points (cv2.fitLine): its unit normal and the signed
    distances (N,) of the points, m."""
    vx, vz, x0, z0 = cv2.fitLine(points_xz.astype(np.float32), cv2.DIST_L2, 0, 0.01, 0.01).ravel()
    normal = np.array([-vz, vx], dtype=np.float64)
    return normal, (points_xz - np.array([x0, z0], dtype=np.float64)) @ normal


def line_fit(points_xz: ArrayLike) -> ShapeFit:
    """A straight line (a plane's profile) fitted by least squares; 2 numbers."""
    p = _check_points(points_xz, 3)
    return ShapeFit("line", _line_distances(p)[1], 2)


def _line_cost(sums: FloatArray, count: FloatArray) -> FloatArray:
    """Sum of squared distances from its total least squares line of each group of points,
    from the groups' sums (K, 5) of x, z, x², xz, z² and their counts (K,)."""
    mx, mz = sums[:, 0] / count, sums[:, 1] / count
    a = sums[:, 2] - count * mx * mx
    b = sums[:, 3] - count * mx * mz
    c = sums[:, 4] - count * mz * mz
    smallest = 0.5 * (a + c) - np.sqrt(0.25 * (a - c) ** 2 + b * b)
    return np.asarray(np.maximum(smallest, 0.0))


def line_pair_fit(points_xz: ArrayLike) -> ShapeFit:
    """Two straight lines meeting at a break in scan order (a V seam, an edge); 5 numbers.

    Every break that leaves at least 3 points on each side is tried at once (the total least
    squares cost of each side from cumulative moments); each line is fitted to the points on
    its side of the best one. The points stay on their side: giving each point to the nearer
    line would let two nearly equal lines split a plane's noise between them and fit a plane
    better than one line does.
    """
    p = _check_points(points_xz, 8)
    n = len(p)
    q = p - p.mean(axis=0)
    moments = np.column_stack([q[:, 0], q[:, 1], q[:, 0] ** 2, q[:, 0] * q[:, 1], q[:, 1] ** 2])
    before = np.cumsum(moments, axis=0)[2 : n - 3]  # sums over points 0..k, k = 2 .. n - 4
    after = moments.sum(axis=0) - before
    count = np.arange(3, n - 2, dtype=np.float64)
    cost = _line_cost(before, count) + _line_cost(after, n - count)
    split = 3 + int(np.argmin(cost))
    residuals = np.concatenate([_line_distances(p[:split])[1], _line_distances(p[split:])[1]])
    return ShapeFit("line pair", residuals, 5)


@dataclass(frozen=True)
class ConicFit(ShapeFit):
    """A conic fitted to one profile (:func:`conic_fit`).

    Attributes
    ----------
    axis_ratio : float
        Minor over major axis of the conic when it is an ellipse (1 for a circle), 0 for a
        hyperbola or parabola (a V, a corner).
    """

    axis_ratio: float = 0.0


def conic_fit(points_xz: ArrayLike) -> ConicFit:
    """A general conic (ellipse, hyperbola, parabola) by algebraic least squares; 5 numbers.

    The points are centred and scaled to unit spread; the conic is the design matrix's
    singular vector of least singular value, and a point's residual its Sampson distance
    (the algebraic value over the gradient's length, to first order the geometric one).
    """
    p = _check_points(points_xz, 6)
    centre = p.mean(axis=0)
    length = float(np.sqrt(np.mean(np.sum((p - centre) ** 2, axis=1))))
    u = (p - centre) / length
    x, z = u[:, 0], u[:, 1]
    design = np.column_stack([x * x, x * z, z * z, x, z, np.ones(len(u))])
    a, b, c, d, e, f = np.linalg.svd(design, full_matrices=False)[2][-1]
    value = a * x * x + b * x * z + c * z * z + d * x + e * z + f
    gradient = np.hypot(2.0 * a * x + b * z + d, b * x + 2.0 * c * z + e)
    # The quadratic part's eigenvalues: one sign for an ellipse, whose semi-axes go as
    # 1 / sqrt(|eigenvalue|).
    eigen = np.linalg.eigvalsh(np.array([[a, 0.5 * b], [0.5 * b, c]]))
    magnitude = np.sort(np.abs(eigen))
    ratio = math.sqrt(magnitude[0] / magnitude[1]) if eigen[0] * eigen[1] > 0.0 else 0.0
    residuals = length * value / np.maximum(gradient, 1e-300)
    return ConicFit("conic", residuals, 5, axis_ratio=float(ratio))


@dataclass(frozen=True)
class CircleShapeFit(ShapeFit):
    """A circle fitted to one profile (:func:`circle_fit`).

    Attributes
    ----------
    radius_m : float
        The circle's radius, m (inf for collinear points).
    """

    radius_m: float = math.inf


def circle_fit(points_xz: ArrayLike) -> CircleShapeFit:
    """A circle (a sphere's section, a short piece of any arc) by algebraic least squares;
    3 numbers.

    The Kåsa fit: 2 c·q + k = |q|² solved for the centre c and k on the centred points, the
    radius sqrt(k + |c|²); a point's residual is its distance from the circle. Exact on
    noise-free points, and biased by less than the noise where the noise is small against
    the arc's sagitta.
    """
    p = _check_points(points_xz, 3)
    q = p - p.mean(axis=0)
    design = np.column_stack([2.0 * q, np.ones(len(q))])
    (cx, cz, k), *_ = np.linalg.lstsq(design, np.sum(q * q, axis=1), rcond=None)
    radius_sq = float(k + cx * cx + cz * cz)
    radius = math.sqrt(radius_sq) if math.isfinite(radius_sq) and radius_sq > 0.0 else math.inf
    if not math.isfinite(radius):
        return CircleShapeFit("circle", _line_distances(p)[1], 3, radius_m=math.inf)
    residuals = np.hypot(q[:, 0] - cx, q[:, 1] - cz) - radius
    return CircleShapeFit("circle", residuals, 3, radius_m=radius)


@dataclass(frozen=True)
class RecordingScale:
    """How far a model's residual lies from the profile across one recording's profiles.

    Attributes
    ----------
    median_m : float
        Median over the profiles of the per-profile residual (e.g. RMS), m.
    spread_m : float
        Its robust spread across the profiles (1.4826 · MAD), at least
        :data:`MIN_SPREAD_SHARE` of the median, m.
    """

    median_m: float
    spread_m: float

    def limit_m(self, sigmas: float) -> float:
        """The residual ``sigmas`` spreads above the median, m."""
        return self.median_m + sigmas * self.spread_m

    def sigmas_above(self, value_m: float) -> float:
        """How many spreads a residual lies above the median."""
        return (value_m - self.median_m) / self.spread_m


def recording_scale(values_m: ArrayLike) -> RecordingScale:
    """The recording's scale from one residual per profile (K ≥ 1,), m."""
    v = np.asarray(values_m, dtype=np.float64)
    if v.ndim != 1 or len(v) == 0 or not np.all(np.isfinite(v)):
        raise ValueError(f"the recording scale needs finite per-profile values, got {v!r}")
    median = float(np.median(v))
    spread = robust_scale_m(v)
    return RecordingScale(median, max(spread, MIN_SPREAD_SHARE * median, 1e-300))


def recording_outliers(
    values_m: ArrayLike, sigmas: float, model: str, n_effective: ArrayLike | None = None
) -> list[tuple[int, str]]:
    """Profiles whose model residual (K,), m, lies ``sigmas`` robust spreads above the median
    of the recording's profiles (:func:`recording_scale`): their positions and the reasons,
    with the numbers (none for fewer than 3 profiles). ``model`` names the model in the
    reasons ("circle", "line pair").

    ``n_effective`` (K,): the independent points each residual is an RMS over
    (:func:`effective_count`); each profile's spread is then the recording's and its own
    RMS's sampling spread, median / √(2 n_eff), in quadrature (see the module docstring).
    """
    v = np.asarray(values_m, dtype=np.float64)
    if len(v) < 3:
        return []
    scale = recording_scale(v)
    spread = np.full(len(v), scale.spread_m)
    if n_effective is not None:
        sampling = scale.median_m / np.sqrt(2.0 * np.asarray(n_effective, dtype=np.float64))
        spread = np.hypot(spread, sampling)
    limit = scale.median_m + sigmas * spread

    def own(k: int) -> str:
        if n_effective is None:
            return ""
        count = float(np.asarray(n_effective, dtype=np.float64)[k])
        return f", the profiles' and that of an RMS over its {count:.0f} effective points"

    return [
        (
            int(k),
            f"the {model} leaves {v[k] * 1e6:.1f} um RMS, "
            f"{(v[k] - scale.median_m) / spread[k]:.0f} robust spreads above the median "
            f"{scale.median_m * 1e6:.1f} um of this recording's {len(v)} profiles (spread "
            f"{spread[k] * 1e6:.1f} um{own(int(k))}; limit {limit[k] * 1e6:.1f} um at "
            f"{sigmas:.0f} spreads)",
        )
        for k in np.flatnonzero(v > limit)
    ]


@dataclass(frozen=True)
class RivalRejection(Rejection):
    """A profile a rival shape fits clearly better than the target's model (its reason gives
    the comparison's numbers)."""


def rival_rejection(
    index: int, stamp_ns: int, stage: str, not_the_shape: str, comparison: Comparison
) -> RivalRejection:
    """The rejection of a profile whose rival fits clearly better: ``not_the_shape`` (what
    the profile is not, e.g. "no circular arc") and the comparison's numbers."""
    assert comparison.rival is not None
    return RivalRejection(index, stamp_ns, stage, f"{not_the_shape}: {comparison.describe()}")


def shape_doubt(comparisons: Sequence[tuple[int, Comparison | None]], shape: str) -> str | None:
    """Why single profiles put a model in doubt, in words: at least half of a recording's
    profiles fit a rival shape clearly better than the model's ``shape`` ("circle") one by
    one; None otherwise.

    ``comparisons`` holds each profile's index and its comparison where a rival fits it
    clearly better (None where not). A doubt never decides the target: it asks for the whole
    recording's comparison of the full models
    (:func:`~linelaser_calib.core.targets.rivals.check_model`).
    """
    shown = [(index, c) for index, c in comparisons if c is not None]
    if not shown or 2 * len(shown) < len(comparisons):
        return None
    index, example = shown[0]
    return (
        f"{len(shown)} of {len(comparisons)} profiles fit a rival shape better than "
        f"{_a(shape)} one by one (profile {index}: {example.describe()})"
    )
