"""Is a profile a V? The corner's two lines against rival shapes, and what a rival points to.

Built on :mod:`linelaser_calib.core.model_check`, for the targets that see a V (the known
point, the straight seam). A real profiler leaves tens of µm of smooth shape error on each
flank over a few µm of local noise, so the V is not judged by its residual against the
noise but against rivals fitted to the same points, by the information criterion over the
profile's effective point count (:func:`compare_corner`):

- a single **line**: a plane was scanned, no seam or edge in the laser line;
- an **arc**: a circle (3 numbers), or a general conic that is an ellipse (5), through
  points whose circle has a radius of at most :data:`MAX_ARC_RADIUS_M`: a cylinder or a
  sphere was scanned. The two flanks' points are often short pieces of the arc, on which a
  circle and an ellipse are not told apart (and a general conic comes out a hyperbola), so
  both targets are named. A hyperbola or parabola is no rival: it is a V with a rounded
  root (it fits a sharp V within the noise too). A flatter "arc" is a plane's smooth shape
  error (30 µm over 40 mm of line bends it by a radius of some metres), not a curved target.

A profile in which no corner was found (:func:`compare_without_corner`) meets the same
rivals with a line pair in the V's place. When the corner fit found it flat (no second line,
or the two lines nearly parallel) and a line pair fits it no clearly better than one line,
it is a plane: the simpler model, unless the other is clearly better. A profile's rejection
thus says what it shows; no profile decides the target: where too few profiles show a corner,
the whole recording's full models do (:mod:`linelaser_calib.core.targets.rivals`).
"""

from __future__ import annotations

from dataclasses import replace

from linelaser_calib.core.model_check import (
    CLEAR_BIC,
    Comparison,
    RivalRejection,
    ShapeFit,
    circle_fit,
    compare_models,
    conic_fit,
    line_fit,
    line_pair_fit,
    rival_rejection,
)
from linelaser_calib.core.types import FloatArray

#: Largest radius of curvature of a curved target's profile, m: five times the largest
#: cylinder of the design (100 mm diameter).
MAX_ARC_RADIUS_M = 0.25
#: What a profile that a rival fits clearly better is not.
NOT_A_V = "not a V (two straight flanks meeting at a corner)"
#: What a profile without a corner that one line fits as well as two is not.
NOT_TWO_LINES = "not a V: one straight line fits it as well as two (a plane)"


def _rivals(points_xz: FloatArray) -> list[ShapeFit]:
    """The line and, when the points' circle is a curved target's, the arcs (the circle, and
    the general conic when it is an ellipse)."""
    rivals: list[ShapeFit] = [line_fit(points_xz)]
    circle = circle_fit(points_xz)
    if circle.radius_m <= MAX_ARC_RADIUS_M:
        rivals.append(replace(circle, name="arc"))
        conic = conic_fit(points_xz)
        if conic.axis_ratio > 0.0:
            rivals.append(replace(conic, name="arc"))
    return rivals


def compare_corner(points_xz: FloatArray, residuals_m: FloatArray) -> Comparison:
    """The corner fit's two lines (5 numbers: two lines and where they part) against the
    rivals, on the points (N, 2), m, in scan order, that the lines hold; ``residuals_m``
    (N,) are those points' distances from their lines, m."""
    return compare_models(ShapeFit("line pair", residuals_m, 5), _rivals(points_xz))


def compare_without_corner(points_xz: FloatArray, flat: bool) -> tuple[str, Comparison] | None:
    """What a cleaned profile (N >= 8, 2), m, in scan order, in which no corner was found
    shows instead of a V: what it is not and the comparison, or None (the corner fit's own
    reason then stands).

    A rival that fits clearly better than a line pair is named; so is the line when the
    corner fit found the profile ``flat`` and a line pair fits no clearly better than one
    line (the simpler model).
    """
    pair = line_pair_fit(points_xz)
    comparison = compare_models(pair, _rivals(points_xz))
    if comparison.rival_wins:
        return NOT_A_V, comparison
    plane = compare_models(pair, [line_fit(points_xz)])
    if flat and plane.delta_bic > -CLEAR_BIC:
        return NOT_TWO_LINES, plane
    return None


def corner_rival_rejection(
    index: int, stamp_ns: int, not_the_shape: str, comparison: Comparison
) -> RivalRejection:
    """The rejection of a profile that a rival describes better than a V (``not_the_shape``:
    :data:`NOT_A_V` when the rival fits clearly better, :data:`NOT_TWO_LINES` when one line
    fits as well as the two)."""
    return rival_rejection(index, stamp_ns, "corner", not_the_shape, comparison)
