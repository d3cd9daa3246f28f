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
  recording's profiles gives its scale (median, robust spread); a profile far above it is
  set aside, with the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.model_check import (
    Comparison,
    ShapeFit,
    compare_models,
    conic_fit,
    line_fit,
    line_pair_fit,
    recording_scale,
)
from linelaser_calib.core.targets.sphere.circle import NOT_A_CIRCLE, circle_residuals
from linelaser_calib.core.types import FloatArray, Rejection

#: An ellipse whose axes differ by less than this share is a circle seen through the
#: profiler's scale error, not a rival.
MAX_AXIS_DIFFERENCE = 0.02
#: What each rival shape says the scans show instead, with the target to choose.
RIVAL_TARGETS = {
    "line pair": "a seam's V or an edge ({setting:target} known_point or line)",
    "conic": "a cylinder's elliptical arcs ({setting:target} cylinder)",
    "line": "a plane: no curved target in the line ({setting:target} line for a straight edge)",
}


@dataclass(frozen=True)
class RivalRejection(Rejection):
    """A profile a rival shape fits clearly better than a circle.

    Attributes
    ----------
    rival : str
        The rival's name (a key of :data:`RIVAL_TARGETS`).
    """

    rival: str = ""


def compare_circle(points_xz: FloatArray, centre_xz: FloatArray, radius_m: float) -> Comparison:
    """A circle (3 numbers) against the rival shapes on a cleaned profile (N, 2), m, in
    scan order."""
    circle = ShapeFit("circle", circle_residuals(points_xz, centre_xz, radius_m), 3)
    rivals: list[ShapeFit] = [line_fit(points_xz), line_pair_fit(points_xz)]
    ellipse = conic_fit(points_xz)
    if 0.0 < ellipse.axis_ratio < 1.0 - MAX_AXIS_DIFFERENCE:
        rivals.append(ellipse)
    return compare_models(circle, rivals)


def rival_rejection(index: int, stamp_ns: int, comparison: Comparison) -> RivalRejection:
    """The rejection of a profile whose rival fits clearly better."""
    assert comparison.rival is not None
    return RivalRejection(
        index,
        stamp_ns,
        "circle",
        f"{NOT_A_CIRCLE}: {comparison.describe()}",
        rival=comparison.rival.name,
    )


def rival_verdict(rejections: list[Rejection], n_features: int) -> str | None:
    """The refusal of a recording most of whose profiles a rival fits clearly better, naming
    the rival seen most often and what it shows; None otherwise."""
    rivals = [r for r in rejections if isinstance(r, RivalRejection)]
    if not rivals or len(rivals) < n_features:
        return None
    names = [r.rival for r in rivals]
    rival = max(set(names), key=names.count)
    example = next(r for r in rivals if r.rival == rival)
    return (
        f"the sphere model does not fit these data: {len(rivals)} of "
        f"{len(rivals) + n_features} profiles are no circular arc, and {names.count(rival)} "
        f"of them are fitted clearly better by a {rival} (profile {example.index}: "
        f"{example.reason.removeprefix(NOT_A_CIRCLE + ': ')}). The scans show "
        f"{RIVAL_TARGETS[rival]}; or the profiles are not in metres. No result was written."
    )


def set_aside_outliers(rms_m: FloatArray, sigmas: float) -> list[tuple[int, str]]:
    """Profiles whose circle RMS (K,), m, lies ``sigmas`` robust spreads above the median of
    the recording's profiles: their positions and the reasons, with the numbers (none for
    fewer than 3 profiles)."""
    if len(rms_m) < 3:
        return []
    scale = recording_scale(rms_m)
    limit = scale.limit_m(sigmas)
    return [
        (
            int(k),
            f"the circle leaves {rms_m[k] * 1e6:.1f} um RMS, "
            f"{scale.sigmas_above(float(rms_m[k])):.0f} robust spreads above the median "
            f"{scale.median_m * 1e6:.1f} um of this recording's {len(rms_m)} profiles (spread "
            f"{scale.spread_m * 1e6:.1f} um; limit {limit * 1e6:.1f} um at {sigmas:.0f} "
            "spreads)",
        )
        for k in np.flatnonzero(np.asarray(rms_m) > limit)
    ]
