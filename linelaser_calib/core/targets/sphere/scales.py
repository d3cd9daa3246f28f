"""The sphere's along-line scale under ``--scale auto``: which of the held (scale 1) and the
estimated solutions is kept, and the 1σ that counts the other reading of the profiles' x/z
stretch (the same ratio read as a depth scale)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from linelaser_calib.core.errors import CalibrationError, DegenerateError
from linelaser_calib.core.model_spread import with_model_spread
from linelaser_calib.core.profile.along_line import (
    PLAUSIBLE_SCALE_ERROR,
    implausible_scale_held,
    measured_to_true,
    scale_significant,
)
from linelaser_calib.core.targets.base import TargetSolution
from linelaser_calib.core.targets.sphere.features import SphereFeature


def read_as_depth(features: list[SphereFeature], scale: float) -> list[SphereFeature]:
    """The features with the along-line scale error ``scale`` read as a depth scale of the
    same x/z ratio instead: x true and z reading 1 / (1 + ``scale``) times the true depth
    (about the sensor origin), so the points' and circle centres' z stretched by
    1 + ``scale``."""
    depth = -scale / (1.0 + scale)
    return [
        replace(
            f,
            points=measured_to_true(f.points, 0.0, depth),
            circle=replace(f.circle, centre_xz=measured_to_true(f.circle.centre_xz, 0.0, depth)),
        )
        for f in features
    ]


def with_scale_model_spread(
    held: TargetSolution | DegenerateError,
    estimated: TargetSolution,
    depth_reading: Callable[[float], TargetSolution],
) -> TargetSolution:
    """The solution ``--scale auto`` keeps of the two with the along-line scale held at 1
    (``held``) and estimated (``estimated``), its 1σ widened by the move to the other
    reading of the profiles where that move exceeds its 1σ on some axis; ``depth_reading``
    solves the same profiles with a scale error read as a depth scale (:func:`read_as_depth`).
    ``held`` is the held solve's refusal where the poses could not determine the hand-eye
    with the scale held: the noise levels learned there take up the stretch the held model
    leaves, and its 1σ grows past the undetermined limit. Where the scale then reads
    clearly off 1 and plausible, the estimated solution is kept as below; otherwise the
    refusal stands. The industrial cell twin's sensor B (x +0.6 %, z −0.2 %, 18 views;
    seeds 2-4): held, refused; estimated, 1.0-2.4 mm off truth with the largest per-axis
    |error| / 1σ 0.3-1.3 (held and let through: 2.2-5.1 mm, up to 2.8).

    The whole recording decides. Where estimating the scale moves the hand-eye within the
    held solution's 1σ, the simpler model is kept (the real 40 mm ball set: a free scale
    reads 0.99911 ± 0.00012, clearly off 1, yet scatters the ball centres more, 0.262 mm
    against 0.244 mm held, and moves the free radius from the independent circle fits'
    39.977 mm to 40.034 mm: it takes up the profiler's own shape error); where the move
    exceeds the held 1σ on some axis it is added to that 1σ in quadrature
    (:func:`~linelaser_calib.core.model_spread.with_model_spread`). Where it moves it
    beyond, and the scale lies clearly off 1 by its own 1σ (:func:`scale_significant`, the
    1σ widened by how the profiles scatter it), the held model leaves a bias its 1σ does not
    see and the estimated solution is kept: on the stress matrix's ``shape`` face (x 1.0 %
    short of z) it reads 0.9899 ± 0.0002 and the hand-eye is 0.04-0.12 mm off against
    0.38-0.56 mm held (seeds 0-2; clean twin 0.07-0.10 mm).

    The profiles fix the ratio of the x and z scales, not which of them is off, so the kept
    estimated solution's 1σ counts the other reading of that ratio, the same stretch read
    as a depth scale, not the held solution (a model the recording has just refused, whose
    bias the move was): with the radius estimated a depth scale s_z moves the hand-eye by
    about s_z times the points' depth along it, which the x scale cannot take up. On the
    ``shape`` face read as a z scale instead (z +1.0 %, x true) the estimated hand-eye is
    1.1-1.5 mm off along the flange's z, and the two readings are 1.1-1.4 mm apart there,
    where the held solution was 0.3-0.7 mm off; along the rotation about the sensor's x
    the held move was 0.18-0.34 deg and the readings differ by 0.01-0.15 deg (seeds 0-5).
    The truth lies anywhere between the two readings (x +0.6 % and z -0.2 % on the
    ``scales`` face), so the 1σ counts their move over √3, the RMS distance from the kept
    end. Where the depth reading cannot be solved, the move to the held solution counts.
    An estimated scale beyond :data:`PLAUSIBLE_SCALE_ERROR` is no model of the profiles (the
    12.7 mm ball set: 0.958 with the radius given): the held solution is kept with a warning.
    """
    section = estimated.section
    scale = getattr(section, "scale", None)
    scale_sigma = getattr(section, "scale_sigma", None)
    if isinstance(held, DegenerateError):
        if (
            scale is None
            or abs(scale) > PLAUSIBLE_SCALE_ERROR
            or not scale_significant(scale, scale_sigma)
        ):
            raise held
    elif scale is None:
        return held
    elif abs(scale) > PLAUSIBLE_SCALE_ERROR:
        return replace(held, warnings=[*held.warnings, implausible_scale_held(scale)])
    spread = "" if scale_sigma is None else f" ± {scale_sigma:.5f}"
    reading = (
        f"the along-line scale, held at 1 by default, reads {1.0 + scale:.5f}{spread} "
        f"({100.0 * scale:+.3f} % from nominal) when estimated"
    )
    if isinstance(held, DegenerateError):
        estimated_reading = (
            f"{reading}, clearly off 1; held at 1 it leaves the poses unable to determine "
            "the hand-eye (the held model's misfit counted as noise)"
        )
    else:
        kept = with_model_spread(
            held,
            estimated,
            f"{reading}, and estimating it",
            "A profiler's own shape error can read as a scale; if its x scale is known to be "
            "off, {setting:scale} free estimates it",
        )
        if kept is held or not scale_significant(scale, scale_sigma):
            return kept
        estimated_reading = f"{reading}, clearly off 1 and moving the hand-eye beyond its 1 sigma"
    advice = (
        "The profiles fix the ratio of the x and z scales, not which one is off: check the "
        "profiler's x scale on a known length; {setting:scale} fixed holds it at 1"
    )
    try:
        depth = depth_reading(scale)
    except CalibrationError:
        if isinstance(held, DegenerateError):
            return replace(
                estimated,
                warnings=[*estimated.warnings, f"{estimated_reading}, so it is estimated"],
            )
        return with_model_spread(
            estimated, held, f"{estimated_reading}, so it is estimated; holding it at 1", advice
        )
    return with_model_spread(
        estimated,
        depth,
        f"{estimated_reading}, so it is estimated; read as a depth scale of "
        f"{1.0 / (1.0 + scale):.5f} instead, the same stretch",
        advice,
        between=True,
    )
