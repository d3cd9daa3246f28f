"""Is a profile a sphere's circle? Rival shapes, and the recording's own scale.

Built on :mod:`linelaser_calib.core.model_check`:

- **Per profile** (:func:`compare_circle`): the circle against a line (a plane), a line
  pair (a V seam, an edge) and an ellipse (a cylinder's section), all fitted to the cleaned
  profile, by the information criterion with the profile's effective point count. A
  profiler's x and z scales agree only to its calibration, so a sphere's section shows as an
  ellipse of axis ratio close to 1 (the RobCalibrator SR7140: 0.997); an ellipse with axes
  within :data:`MAX_AXIS_DIFFERENCE` of each other is that distortion, not a rival (a
  cylinder cut 11 deg or more off its cross-section differs by more).
- **Per recording** (:func:`set_aside_outliers`): the circles' RMS residual across the
  recording's profiles gives its scale (median, robust spread); a profile far above it, by
  that spread and its own RMS's over its effective points, is set aside, with the numbers.
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
    recording_outliers,
    rival_rejection,
)
from linelaser_calib.core.targets.sphere.circle import NOT_A_CIRCLE, circle_residuals
from linelaser_calib.core.types import FloatArray

#: An ellipse whose axes differ by less than this share is a circle seen through the
#: profiler's scale error, not a rival.
MAX_AXIS_DIFFERENCE = 0.02


def compare_circle(points_xz: FloatArray, centre_xz: FloatArray, radius_m: float) -> Comparison:
    """A circle (3 numbers) against the rival shapes on a cleaned profile (N, 2), m, in
    scan order."""
    circle = ShapeFit("circle", circle_residuals(points_xz, centre_xz, radius_m), 3)
    rivals: list[ShapeFit] = [line_fit(points_xz), line_pair_fit(points_xz)]
    ellipse = conic_fit(points_xz)
    if 0.0 < ellipse.axis_ratio < 1.0 - MAX_AXIS_DIFFERENCE:
        rivals.append(ellipse)
    return compare_models(circle, rivals)


def circle_rival_rejection(index: int, stamp_ns: int, comparison: Comparison) -> RivalRejection:
    """The rejection of a profile whose rival fits clearly better than its circle."""
    return rival_rejection(index, stamp_ns, "circle", NOT_A_CIRCLE, comparison)


def set_aside_outliers(
    rms_m: FloatArray, n_effective: FloatArray, sigmas: float
) -> list[tuple[int, str]]:
    """Profiles whose circle RMS (K,), m, an estimate over ``n_effective`` (K,) independent
    points each, lies ``sigmas`` robust spreads above the median of the recording's profiles
    (:func:`~linelaser_calib.core.model_check.recording_outliers`)."""
    return recording_outliers(rms_m, sigmas, "circle", n_effective)
