"""Which samples the sphere's whole fit flags as outliers (the rejection loop's test).

Two readings of each sample after a refinement, each judged against the recording's other
samples (median and robust spread, 1.4826 · MAD), never against one profile alone:

- its points' RMS distance from the sphere: a profile whose points the common sphere does
  not explain (a reflection, a second object on the arc);
- its pose correction: how far the fit had to move the sample's flange pose. A mis-paired
  pose shows here, not in the points: its profile is a good circle, and the per-sample
  correction absorbs the whole displacement, widening the robot σ learned from the
  corrections until every direction looks undetermined (the industrial cell twin's sensor
  A, seed 0, with profile 5 given profile 9's pose: refused as undetermined before). The
  corrections' six components, each about its median, have a robust scale per axis over
  the recording (never below the robot's stated σ); a sample's squared correction over
  those scales is a χ² of 6 degrees of freedom, flagged beyond the value as rare as
  ``sigmas`` Gaussian σ (51.9 at 6). A robot's regional error makes good samples'
  corrections differ, and unequally per axis: on the cell twin (seeds 0-4, both sensors,
  every solve of a run) good samples reach χ² 29 per axis, 64 with one scale for the three
  axes, 3 times the median length (a limit on the lengths' spread set one aside); the
  mis-paired profile reaches 160-1800.

The points' limit is ``sigmas`` robust spreads above the median, and never below three
learned sensor σ.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.special import chdtri, ndtr
from scipy.stats import median_abs_deviation

from linelaser_calib.core.model_check import robust_scale_m
from linelaser_calib.core.solver import Flag
from linelaser_calib.core.targets.sphere.refine import SphereRefinement
from linelaser_calib.core.types import FloatArray


def _beyond(values: FloatArray, limit: float, reason: Callable[[int, float], str]) -> list[Flag]:
    """Flags of the values (K,) above ``limit``, each with its ``reason(k, value)``."""
    return [
        Flag(float(value / limit), k, reason(k, float(value)))
        for k, value in enumerate(values)
        if value > limit
    ]


def _above(values_m: FloatArray, sigmas: float, floor_m: float, what: str) -> list[Flag]:
    """Flags of the values (K,), m, above the recording's limit, ``what`` naming them."""
    median = float(np.median(values_m))
    limit = max(median + sigmas * robust_scale_m(values_m), floor_m)
    return _beyond(
        values_m,
        limit,
        lambda k, value: (
            f"{what} {value * 1e6:.1f} um, above the {limit * 1e6:.1f} um the "
            f"other profiles allow (median {median * 1e6:.1f} um)"
        ),
    )


def _pose_flags(
    corrections: FloatArray, sigmas: float, stated_t_m: float, stated_r_rad: float
) -> list[Flag]:
    """Flags of the samples whose pose corrections (K, 6) [ω rad, τ m] lie beyond the
    recording's (see the module docstring)."""
    centred = corrections - np.median(corrections, axis=0)
    stated = np.repeat([stated_r_rad, stated_t_m], 3)
    scales = np.maximum(median_abs_deviation(corrections, axis=0, scale="normal"), stated)
    limit = float(chdtri(6, 2.0 * ndtr(-sigmas)))
    return _beyond(
        np.sum((centred / scales) ** 2, axis=1),
        limit,
        lambda k, value: (
            f"pose correction {np.linalg.norm(centred[k, 3:]) * 1e3:.3f} mm and "
            f"{math.degrees(float(np.linalg.norm(centred[k, :3]))):.4f} deg off the other "
            f"profiles' median, chi2 {value:.0f} on 6 degrees of freedom over their robust "
            f"scales per axis (up to {np.max(scales[3:]) * 1e3:.3f} mm and "
            f"{math.degrees(float(np.max(scales[:3]))):.4f} deg), above {limit:.0f} "
            f"({sigmas:g} sigma)"
        ),
    )


def sample_flags(
    outcome: SphereRefinement, sigmas: float, stated_t_m: float, stated_r_rad: float
) -> list[Flag]:
    """The samples a refinement flags (see the module docstring), the worse of the two
    readings where both flag one.

    Parameters
    ----------
    outcome : SphereRefinement
    sigmas : float
        Robust spreads above the median that flag a sample.
    stated_t_m, stated_r_rad : float
        The robot's stated σ (translation m, rotation rad per axis).
    """
    rms = outcome.sample_rms_m()
    flags = _above(rms, sigmas, 3.0 * outcome.sensor_sigma_m, "RMS distance from the sphere")
    flags += _pose_flags(outcome.state.corrections, sigmas, stated_t_m, stated_r_rad)
    worst: dict[int, Flag] = {}
    for flag in flags:
        if flag.position not in worst or flag.severity > worst[flag.position].severity:
            worst[flag.position] = flag
    return list(worst.values())
