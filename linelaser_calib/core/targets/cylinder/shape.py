"""Is a profile a cylinder's elliptical arc? Rival shapes, and what a rival points to.

Built on :mod:`linelaser_calib.core.model_check`. Per profile (:func:`compare_ellipse`) the
fitted ellipse (5 numbers) meets a line (a plane) and a line pair (a V seam, an edge) on the
same points, by the information criterion over the profile's effective point count; a
profile whose arc was not found meets them with a general conic in its place
(:func:`compare_without_arc`), so that its rejection says what it shows. No profile
decides the target: a recording most of whose profiles a rival fits better puts the
cylinder in doubt (:meth:`~.target.CylinderTarget.model_doubt`), and the whole recording's
full models decide (:mod:`..rivals`).

A cylinder's cut is an ellipse in every view, so a circle is no rival here: a sphere shows as
circles of varying radius, which no single cylinder explains; the joint fit of all profiles
judges that (:meth:`~.target.CylinderTarget.check_fit`).
"""

from __future__ import annotations

from linelaser_calib.core.model_check import (
    Comparison,
    RivalRejection,
    ShapeFit,
    compare_models,
    conic_fit,
    line_fit,
    line_pair_fit,
    rival_rejection,
)
from linelaser_calib.core.targets.cylinder.conic import sampson_distance
from linelaser_calib.core.types import FloatArray

#: What a profile that a rival fits clearly better is not.
NOT_AN_ARC = "no elliptical arc"


def compare_ellipse(points_xz: FloatArray, conic: FloatArray) -> Comparison:
    """The fitted ellipse (conic (6,), m) against the rival shapes on the points (N, 2), m,
    in scan order, that it was fitted among."""
    ellipse = ShapeFit("ellipse", sampson_distance(conic, points_xz), 5)
    return compare_models(ellipse, [line_fit(points_xz), line_pair_fit(points_xz)])


def compare_with_line(points_xz: FloatArray, conic: FloatArray) -> Comparison:
    """A short arc's ellipse (conic (6,), m) against a line alone, on its inliers (N, 2), m:
    is the arc clearly curved (:attr:`~linelaser_calib.core.model_check.Comparison.model_wins`)?"""
    ellipse = ShapeFit("ellipse", sampson_distance(conic, points_xz), 5)
    return compare_models(ellipse, [line_fit(points_xz)])


def compare_without_arc(points_xz: FloatArray) -> Comparison:
    """A general conic in the ellipse's place against the rival shapes, on a cleaned profile
    (N, 2), m, in scan order, in which no arc was found."""
    return compare_models(conic_fit(points_xz), [line_fit(points_xz), line_pair_fit(points_xz)])


def arc_rival_rejection(index: int, stamp_ns: int, comparison: Comparison) -> RivalRejection:
    """The rejection of a profile whose rival fits clearly better than an ellipse."""
    return rival_rejection(index, stamp_ns, "ellipse", NOT_AN_ARC, comparison)
