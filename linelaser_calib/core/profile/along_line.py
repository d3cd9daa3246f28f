"""The sensor's along-line scale, shared by the targets that estimate it with the hand-eye.

A profiler reports a point's position along its laser line (sensor x) as (1 + s) times the
true one, s its scale error (a few tenths of a percent typically, about a percent for a
poorly calibrated camera-based one). A target that estimates s removes it from the points
(:func:`measured_to_true`) and names it in words (:func:`scale_text`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..geometry import FloatArray

#: How a target's default method treats the scale: ``free`` estimates it with the hand-eye,
#: ``fixed`` holds it at 1, ``auto`` leaves the choice to the target.
SCALE_MODES = ("auto", "fixed", "free")
#: Largest along-line scale error taken as a plausible explanation of a misfit: a
#: profiler's x scale is typically good to a few tenths of a percent, a poorly calibrated
#: camera-based one to about a percent.
PLAUSIBLE_SCALE_ERROR = 0.02
#: With ``auto``, an estimated scale is kept only when it lies this many of its 1σ from 1:
#: a scale the recording cannot tell from 1 adds a parameter and no information (on
#: ``cluttered_camera`` a +0.19 ± 0.10 % estimate took the hand-eye from 2.9 to 3.5 of its
#: 1σ off the truth), so the simpler model, with the scale held, is solved again and used.
SIGNIFICANT_SCALE_SIGMAS = 3.0


def measured_to_true(points: ArrayLike, scale: float, depth_scale: float = 0.0) -> FloatArray:
    """Sensor points with the along-line scale error s removed, x → x / (1 + s), and the
    depth scale error s_z (about the sensor origin) too, z → z / (1 + s_z), m.

    ``points`` is (..., 3) x, y, z, or (..., 2) x, z (a profile's corner in its plane).
    """
    if scale == 0.0 and depth_scale == 0.0:
        return np.asarray(points, dtype=np.float64)
    p = np.array(points, dtype=np.float64)
    p[..., 0] /= 1.0 + scale
    p[..., -1] /= 1.0 + depth_scale
    return p


def scale_text(scale: float, sigma: float | None, axis: str = "along-line (x)") -> str:
    """The along-line scale in words: the ratio and the difference in %, with its 1σ, which
    is the noise model's: whatever else stretches the profiles along the line (a
    grazing-angle smear at the ends of an arc, a robot error that grows along the line) goes
    into the scale too, and the self-check judges the hand-eye, not the scale (``axis`` names
    the scale, e.g. ``"depth (z)"`` for a depth scale). On
    ``cluttered_camera`` (0.5 % true, with a grazing-angle bias) the cylinder reads about
    0.82 ± 0.02 %."""
    spread = "" if sigma is None else f" ± {sigma:.5f}"
    percent = "" if sigma is None else f" ± {100.0 * sigma:.3f}"
    return (
        f"sensor {axis} scale {1.0 + scale:.5f}{spread} "
        f"({100.0 * scale:+.3f}{percent} % from nominal, estimated; noise-model 1 sigma: "
        "anything else that stretches the profiles, such as grazing-angle smear, goes into it "
        "too)"
    )


def scale_significant(scale: float, sigma: float | None) -> bool:
    """Whether an estimated along-line scale lies clearly off 1 (:data:`SIGNIFICANT_SCALE_SIGMAS`
    of its 1σ); an estimate without a 1σ counts as significant."""
    return sigma is None or abs(scale) >= SIGNIFICANT_SCALE_SIGMAS * sigma


def implausible_scale_held(scale: float, axis: str = "along-line") -> str:
    """The warning of a target that estimated the ``axis`` scale by default (``auto``),
    found it implausible (beyond :data:`PLAUSIBLE_SCALE_ERROR`) and solved again with it
    held at 1."""
    return (
        f"the {axis} scale, estimated by default, read {1.0 + scale:.4f} "
        f"({100.0 * scale:+.2f} % from nominal): a scale error beyond "
        f"{100.0 * PLAUSIBLE_SCALE_ERROR:.0f} % is implausible, so it was held at 1 and the "
        "hand-eye solved again. Something else stretches the profiles along the line, such as "
        "a target that is not the given size or the profiler's own shape error; "
        "{setting:scale} free keeps the estimate"
    )


def scale_entries(key: str, scale: float | None, sigma: float | None) -> dict[str, Any]:
    """A result file's entries of an estimated scale error: ``key`` (the ratio 1 + s) and
    ``key``_sigma (its 1σ); none when it was not estimated (``scale`` None)."""
    if scale is None:
        return {}
    return {key: 1.0 + float(scale), f"{key}_sigma": None if sigma is None else float(sigma)}


def scales_from_mapping(mapping: Mapping[str, Any], key: str) -> tuple[float | None, float | None]:
    """The scale error s and its 1σ from a result file's entries written by
    :func:`scale_entries` ((None, None) without them; ValueError naming a bad value)."""
    ratio = mapping.get(key)
    if ratio is None:
        return None, None
    if not (isinstance(ratio, (int, float)) and ratio > 0.0):
        raise ValueError(f"key {key} must be a ratio > 0, got {ratio!r}")
    sigma = mapping.get(f"{key}_sigma")
    return float(ratio) - 1.0, None if sigma is None else float(sigma)


#: Result-file keys of the x and z scale errors a corner target (line, known point)
#: estimates, each with ``_sigma``; and those axes in words.
XZ_SCALE_KEYS = ("along_line_scale", "depth_scale")
XZ_SCALE_AXES = ("along-line (x)", "depth (z)")

#: The x and z scale errors (or their 1σ), None where held at 1.
ScalePair = tuple[float | None, float | None]


def xz_scale_entries(scales: ScalePair, sigmas: ScalePair) -> dict[str, Any]:
    """A result file's entries of the estimated x and z scale errors (:func:`scale_entries`)."""
    entries: dict[str, Any] = {}
    for key, s, sigma in zip(XZ_SCALE_KEYS, scales, sigmas, strict=True):
        entries.update(scale_entries(key, s, sigma))
    return entries


def xz_scales_from_mapping(mapping: Mapping[str, Any]) -> tuple[ScalePair, ScalePair]:
    """The x and z scale errors and their 1σ written by :func:`xz_scale_entries`."""
    (x, sigma_x), (z, sigma_z) = (scales_from_mapping(mapping, key) for key in XZ_SCALE_KEYS)
    return (x, z), (sigma_x, sigma_z)


def xz_scale_text(scales: ScalePair, sigmas: ScalePair) -> str:
    """``; `` and each estimated scale in words (:func:`scale_text`), or nothing."""
    return "".join(
        f"; {scale_text(s, sigma, axis)}"
        for s, sigma, axis in zip(scales, sigmas, XZ_SCALE_AXES, strict=True)
        if s is not None
    )
