"""The cylinder's sensor scales read from the recording: which the default method estimates,
the radius-free cylinder's two readings of one stretch (along the line or in depth) and
their move counted in the 1σ, and the scale's verdict on a radius gap, in words."""

from __future__ import annotations

import math

from ...model_spread import with_held_sigma, with_model_spread
from ...profile.along_line import (
    PLAUSIBLE_SCALE_ERROR,
    SIGNIFICANT_SCALE_SIGMAS,
    scale_significant,
    scale_text,
)
from ..base import TargetSolution
from .config import CylinderConfig
from .refine import RefineResult
from .section import CylinderSection


def estimates_scale(config: CylinderConfig) -> tuple[bool, bool]:
    """Whether the default method's first solve estimates the sensor's along-line (x) and
    depth (z) scales: with ``free`` and ``auto`` (default) the x scale always and the z scale
    when the radius is given, ``auto`` then holding each at 1 again when its estimate is
    implausible, poorly determined or not clearly off 1 (the x scale only with the radius
    free; :meth:`.target.CylinderTarget.solve_default`); ``fixed`` holds both.

    With the radius given the x scale is determined by the arcs' shape alone (within ±0.003 %
    of 1 on the ``paper`` and ``ur_scancontrol`` presets, 20 seeds) and costs no accuracy
    there, whereas a scale error left fixed makes the stretched profiles contradict the
    radius, and the hand-eye absorbs the misfit: RMS 19.6 mm (2.7-35 mm) over 20 seeds of
    ``cluttered_camera`` (0.5 % scale error) against 1.8 mm (0.08-3.1 mm) with the scale
    estimated (bench/accuracy.py ``scale``). The z scale (about the sensor origin) is then
    determined too: on the stress matrix's ``scales`` face (x +0.6 %, z -0.2 %, 12 poses of
    ``ur_scancontrol``, seeds 3 and 4) it reads -0.19 ± 0.05 % and -0.25 ± 0.04 %, and the
    hand-eye is 0.026 and 0.065 mm off (0.20 mm with the z scale held); on seed 5 it reads
    -0.13 ± 0.05 %, under 3σ, so ``auto`` holds it (0.195 mm off; ``free`` 0.067 mm).
    With the radius estimated the profiles determine only the ratio of the two scales: the
    x scale alone reads their difference (+0.81 ± 0.03 %), both together drift with the
    radius (+3.9 ± 0.6 % and +3.1 ± 0.6 %), so the z scale is held and its share, s_z times
    the depth of the points (0.26 mm there), stays in the hand-eye; the 1σ counts it where
    the profiles show it (:func:`with_depth_reading`). Give the radius.
    """
    free = config.scale != "fixed"
    return free, free and config.radius_m is not None


def with_depth_reading(
    kept: TargetSolution, other: TargetSolution, x_reading: tuple[float, float] | None = None
) -> TargetSolution:
    """The solution of the radius-free cylinder (``kept``: its along-line (x) scale kept, or
    held at 1 where the reading ``x_reading`` (value, 1σ) was not clearly off it), with the
    move to ``other``, the same stretch read as a depth (z) scale (x held at 1), as its
    model spread (:func:`~linelaser_calib.core.model_spread.with_model_spread`) where the
    two read one stretch and the move exceeds the 1σ.

    With the radius free the profiles fix the ratio of the two scales, not how it splits
    between them: a z scale about the sensor origin moves every point by s_z times its
    depth, which the x scale cannot take up, and the common part of the two scales moves
    the radius and, through the depth, the hand-eye. Both estimated, they drift together
    (+3.9 ± 0.6 % and +3.1 ± 0.6 % on the stress matrix's ``scales`` face, x +0.6 % and z
    -0.2 %; +12.5 % each on ``cylinder_scancontrol``), so no split is estimated. On that
    face the x scale alone reads +0.81 ± 0.03 % and the hand-eye is 0.26 mm off against a
    1σ of 0.02 mm; read as a z scale the stretch is -0.79 ± 0.03 %, the same ratio, and the
    hand-eye moves 1.0 mm: the truth lies between the readings, and their difference counts
    in the 1σ. Where the z reading is no reading of the same ratio (beyond
    :data:`SIGNIFICANT_SCALE_SIGMAS` of their combined 1σ), the two are not one stretch and
    the kept one stands alone.

    An x reading not clearly off 1 does not make the z scale 1: the held solution assumes
    it, and a depth scale below the detection limit still moves the hand-eye by s_z times
    the points' depth. ``cylinder_gocator`` (z 0.1 % long, x true; seeds 1, 2) reads x
    -0.097 ± 0.040 % and -0.110 ± 0.041 % (held), z +0.101 ± 0.038 % and +0.116 ± 0.037 %;
    held, the hand-eye is 0.127 and 0.120 mm off along z at a 1σ of 0.022 mm (5.8σ), read
    as a depth scale 0.012 and 0.016 mm. So with the x scale held the move counts too where
    the z reading is clearly off 1 (:func:`scale_significant`); where it is not, counting
    its move would widen clean recordings' 1σ by the reading's own noise (``make demo``'s
    ``cylinder_keyence`` 0.024 -> 0.078 mm along z, its error 0.022 mm, and the warning
    makes it USE WITH CARE), so there the 1σ counts the larger of that move and what the
    depth scale's own 1σ moves, without a warning (:func:`with_held_sigma`). The z reading is
    unbiased since the residuals are kept in the sensor's measured units
    (:mod:`.problem`, "Scales and the noise's units"); before, it read +0.20 to +0.35 %
    with the z scale true, and counting it widened clean recordings' 1σ several times.
    """
    section, alternative = kept.section, other.section
    assert isinstance(section, CylinderSection) and isinstance(alternative, CylinderSection)
    x, sigma_x = (section.scale, section.scale_sigma) if x_reading is None else x_reading
    z, sigma_z = alternative.depth_scale, alternative.depth_scale_sigma
    if x is None or sigma_x is None or z is None or sigma_z is None:
        return kept
    # The ratio (1 + s_x) / (1 + s_z) each reading gives, compared on a log scale.
    gap = math.log1p(x) + math.log1p(z)
    if abs(gap) > SIGNIFICANT_SCALE_SIGMAS * math.hypot(sigma_x / (1 + x), sigma_z / (1 + z)):
        return kept
    if section.scale is None and not scale_significant(z, sigma_z):
        return with_held_sigma(kept, other)
    return with_model_spread(
        kept,
        other,
        "with the radius estimated the profiles fix only the ratio of the along-line and "
        f"depth scales: the along-line scale reads {_reading(x, sigma_x)} with the depth "
        f"scale held at 1; read as a depth scale the same stretch is {_reading(z, sigma_z)}, "
        "and that reading",
        "Give the measured {setting:radius_m}: with it both scales are estimated",
    )


def _reading(scale: float, sigma: float) -> str:
    """A scale and its 1σ, in words."""
    return f"{1.0 + scale:.5f} ± {sigma:.5f} ({100.0 * scale:+.3f} % from nominal)"


def scale_verdict(refined: RefineResult) -> str:
    """Whether the estimated along-line scale explains a radius gap, in words."""
    if refined.sigma_scale is None:
        return (
            ". The scale was held fixed ({setting:scale} fixed); {setting:scale} free "
            "estimates it with the hand-eye"
        )
    text = scale_text(refined.scale, refined.sigma_scale)
    if abs(refined.scale) > PLAUSIBLE_SCALE_ERROR:
        return (
            f". Estimated with the hand-eye, the {text} would explain the gap, but a scale "
            f"error beyond {100.0 * PLAUSIBLE_SCALE_ERROR:.0f} % is implausible: the cylinder "
            "is likely not the given size (measure it, or omit {setting:radius_m})"
        )
    return f". Estimated with the hand-eye, the {text} explains the gap"
