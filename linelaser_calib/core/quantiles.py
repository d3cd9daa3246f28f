"""Quantiles of the normal, χ² and Student-t distributions, on the standard library.

The calibration needs a handful of them per run (outlier limits, the self-check's limits),
always at moderate probabilities and small degrees of freedom. ``scipy.special`` has them,
but importing it costs a calibration about 0.25 s, as long as the whole solve; these agree
with it to 1e-12 relative over the range used (test_quantiles).

- the normal quantile is :meth:`statistics.NormalDist.inv_cdf`;
- the χ² and t quantiles invert their distribution functions (the regularised incomplete
  gamma and beta functions: a power series or a continued fraction, whichever converges
  fast at the point) by bisection to the last bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from statistics import NormalDist

#: Iterations and floor of the series and continued fractions below.
_MAX_TERMS = 1000
_TINY = 1e-300
_EPSILON = 1e-16


def normal_quantile(p: float) -> float:
    """x with Φ(x) = p, for 0 < p < 1."""
    return NormalDist().inv_cdf(p)


def _gamma_lower_series(a: float, x: float) -> float:
    """P(a, x), the regularised lower incomplete gamma function, by its series (x < a + 1)."""
    term = total = 1.0 / a
    n = a
    for _ in range(_MAX_TERMS):
        n += 1.0
        term *= x / n
        total += term
        if abs(term) < abs(total) * _EPSILON:
            break
    return total * math.exp(-x + a * math.log(x) - math.lgamma(a))


def _gamma_upper_fraction(a: float, x: float) -> float:
    """Q(a, x) = 1 − P(a, x) by its continued fraction (modified Lentz; x >= a + 1)."""
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, _MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = _TINY if abs(d) < _TINY else d
        c = b + an / c
        c = _TINY if abs(c) < _TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPSILON:
            break
    return math.exp(-x + a * math.log(x) - math.lgamma(a)) * h


def chi2_survival(dof: float, x: float) -> float:
    """P(χ²_dof > x)."""
    if x <= 0.0:
        return 1.0
    a, half = 0.5 * dof, 0.5 * x
    if half < a + 1.0:
        return 1.0 - _gamma_lower_series(a, half)
    return _gamma_upper_fraction(a, half)


def _beta_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c = 1.0
    d = 1.0 - qab * x / qap
    d = 1.0 / (_TINY if abs(d) < _TINY else d)
    h = d
    for m in range(1, _MAX_TERMS):
        m2 = 2 * m
        for an in (m * (b - m) * x / ((qam + m2) * (a + m2)), None):
            if an is None:
                an = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
            d = 1.0 + an * d
            d = 1.0 / (_TINY if abs(d) < _TINY else d)
            c = 1.0 + an / c
            c = _TINY if abs(c) < _TINY else c
            delta = d * c
            h *= delta
        if abs(delta - 1.0) < _EPSILON:
            break
    return h


def _beta_regularised(a: float, b: float, x: float) -> float:
    """I_x(a, b), the regularised incomplete beta function, 0 <= x <= 1."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _beta_fraction(a, b, x) / a
    return 1.0 - front * _beta_fraction(b, a, 1.0 - x) / b


def student_t_survival(dof: float, t: float) -> float:
    """P(T_dof > t), for t >= 0."""
    return 0.5 * _beta_regularised(0.5 * dof, 0.5, dof / (dof + t * t))


def _bisect(decreasing: Callable[[float], float], target: float, low: float, high: float) -> float:
    """x in [low, high] where a decreasing function crosses ``target``, to the last bit."""
    while decreasing(high) > target:
        low, high = high, 2.0 * high
    for _ in range(200):
        middle = 0.5 * (low + high)
        if middle in (low, high):
            break
        if decreasing(middle) > target:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def chi2_upper_quantile(dof: float, p: float) -> float:
    """x with P(χ²_dof > x) = p, for 0 < p < 1 (``scipy.special.chdtri``)."""
    if not (0.0 < p < 1.0 and dof > 0.0):
        raise ValueError(f"need 0 < p < 1 and dof > 0, got p={p}, dof={dof}")
    return _bisect(lambda x: chi2_survival(dof, x), p, 0.0, max(2.0 * dof, 1.0))


def student_t_quantile(dof: float, q: float) -> float:
    """t with P(T_dof <= t) = q, for 0 < q < 1 (``scipy.special.stdtrit``)."""
    if not (0.0 < q < 1.0 and dof > 0.0):
        raise ValueError(f"need 0 < q < 1 and dof > 0, got q={q}, dof={dof}")
    if q == 0.5:
        return 0.0
    tail, sign = (1.0 - q, 1.0) if q > 0.5 else (q, -1.0)
    return sign * _bisect(lambda t: student_t_survival(dof, t), tail, 0.0, 1.0)
