"""RANSAC's hypotheses for the ellipse fit of :mod:`.ellipse`: conics through five points of
a profile spread over windows of its scan line, their MSAC costs and the number of hypotheses
a confidence asks for. The points are normalised ones (see :mod:`.ellipse`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ...types import FloatArray
from .conic import value_and_gradient_sq

IntArray = NDArray[np.intp]


#: Points in a minimal sample: five points fix a conic.
SAMPLE_SIZE = 5


#: Smallest window of the scan line that a RANSAC sample is spread over, as a fraction of
#: the points.
MIN_WINDOW_FRACTION = 0.05


def minimal_conics(u: FloatArray, samples: IntArray) -> FloatArray:
    """Conics through 5 points each: null vectors of the (K, 5, 6) design matrices (the last
    column of the complete QR factor of each transposed design, a third of the time of an
    SVD).

    Parameters
    ----------
    u : ndarray, shape (N, 2)
        Normalised points.
    samples : ndarray of int, shape (K, 5)

    Returns
    -------
    conics : ndarray, shape (K, 6), unit norm, in normalised coordinates.
    """
    x, z = u[samples, 0], u[samples, 1]
    design = np.stack([x * x, x * z, z * z, x, z, np.ones_like(x)], axis=-1)
    q, _ = np.linalg.qr(np.swapaxes(design, 1, 2), mode="complete")
    return np.asarray(q[:, :, -1], dtype=np.float64)


def required_iterations(p_good: float, confidence: float) -> float:
    """Hypotheses needed to draw one all-inlier sample with the given confidence.

    ``p_good`` is the probability that one sample is all inliers.
    """
    if p_good >= 1.0:
        return 1.0
    if p_good <= 0.0:
        return math.inf
    return math.log(1.0 - confidence) / math.log(1.0 - p_good)


def window_samples(order: IntArray, count: int, rng: np.random.Generator) -> IntArray:
    """5-point samples spread evenly over random windows of the profile.

    The points are taken in ``order`` (along the scan line). A window covers a random
    fraction of them, log-uniform from :data:`MIN_WINDOW_FRACTION` to all; each of its five
    equal sub-windows gives one point. The cylinder's arc is one contiguous run of the scan
    line, so a window inside it gives an all-inlier, well-spread sample far more often than
    uniform sampling does when table or background points surround the arc.

    Returns
    -------
    samples : ndarray of int, shape (count, 5)
        Indices into the points.
    """
    n = len(order)
    lengths = np.exp(rng.uniform(math.log(MIN_WINDOW_FRACTION), 0.0, count)) * n
    starts = rng.uniform(0.0, 1.0, count) * (n - lengths)
    fractions = (np.arange(SAMPLE_SIZE) + rng.uniform(0.0, 1.0, (count, SAMPLE_SIZE))) / SAMPLE_SIZE
    positions = np.floor(starts[:, None] + fractions * lengths[:, None]).astype(np.intp)
    return np.asarray(order[np.minimum(positions, n - 1)], dtype=np.intp)


def msac_costs(conics: FloatArray, u: FloatArray, threshold_sq: float) -> FloatArray:
    """Truncated squared Sampson distances min(d^2, t^2), shape (K, N)."""
    q, gradient_sq = value_and_gradient_sq(conics, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.fmin(q * q / gradient_sq, threshold_sq), dtype=np.float64)
