"""Shape errors of real line profilers, beyond white point noise, and datasheet presets.

A real profiler shows a few µm of local (point-to-point) noise but tens of µm of smooth
shape error along its line. :class:`SensorModel` holds those terms (SI units; all zero, the
default, means none); :func:`apply_sensor_model` adds them to noisy points in the sensor
frame (x along the line, z depth), for K profiles of N rays each:

1. **Linearity bow**, fixed per sensor (drawn once per run): a depth error
   ``linearity_m · b(u, v)`` with ``b = (a0 T2(u) + a1 T2(v) + a2 u v) / (|a0| + |a1| + |a2|)``,
   ``a ~ N(0, 1)``, T2(s) = 2 s² − 1, u ∈ [−1, 1] the ray's place in the fan and
   v ∈ [−1, 1] the depth within the measuring range; |b| ≤ 1, so ``linearity_m`` is the
   datasheet's ± linearity (a fraction of full scale times the range).
2. **Smooth shape error**, drawn per profile (it follows the speckle and surface of each
   shot): a stationary Gaussian-kernel process in the true x, 1σ ``shape_sigma_m``,
   correlation exp(−d² / (2 ``shape_length_m``²)), as a sum of
   :data:`SHAPE_FEATURES` random cosines per profile (random Fourier features).
3. **Speckle**: white depth noise smoothed along the line by a Gaussian kernel of
   ``speckle_points`` rays (``scipy.ndimage.gaussian_filter1d``) and scaled to 1σ
   ``speckle_sigma_m``, so neighbouring points share it.
4. **Quantisation**: x and z rounded to multiples of ``x_step_m`` and ``z_step_m`` (the
   output unit; 0 leaves a coordinate as it is).
5. **Weak returns**: the returned light ``reflectance · cos(incidence) · exp(signal_spread · n)``,
   n ~ N(0, 1) per point, must reach ``min_signal``; otherwise the return is lost. Steep
   (grazing) and dark surfaces therefore drop out more.
6. **Thinning at incidence**: a return is kept with probability
   ``cos(incidence) ** incidence_falloff``, so a steep flank met at grazing incidence holds
   few points (the spot smears over many pixels and the peak detector gives up on many).
7. **Gaps**: per profile a Poisson number (mean ``gap_rate``) of runs of missing returns,
   each centred on a random return and ``gap_length_m`` long along the line on average
   (exponential): a shadow, a dirty spot, a saturated patch.
8. **Scales**: x measured as (1 + ``x_scale_error``) x and z as (1 + ``z_scale_error``) z,
   both about the sensor's own origin (the fan apex, where the simulator's sensor frame
   is): a profiler whose two axes' calibrations are off by a little, and by different
   amounts. The origin is the one convention under which the truth is well defined: a z
   scale about any other depth z_0 equals this one plus a shift of the sensor frame by
   −``z_scale_error`` · z_0 along z, and such a shift is part of the hand-eye itself, which
   no calibration can tell from it (about the middle of a 0.11 m range, a −0.2 % z scale
   moves the true sensor origin 0.22 mm).

Each term draws from its own generator (spawned from the one passed in), so turning one
on leaves the others' draws unchanged.

:class:`ProfilerSpec` holds a datasheet's figures (measuring range, widths, points,
repeatability, linearity) with a :class:`SensorModel`; :func:`profiler_fields` turns it into
:class:`~linelaser_calib.sim.scenario.Scenario` fields (the fan apex is placed where the
near and far widths extrapolate to zero, the simulator's sensor origin). :data:`PROFILERS`
names the presets, each with its sources in a comment.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter1d

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.targets.sphere.circle import (
    circle_residuals,
    fit_circle_algebraic,
    fit_circle_geometric,
)
from linelaser_calib.core.types import BoolArray, FloatArray

#: Random cosines per profile of the smooth shape error.
SHAPE_FEATURES = 64
#: Half-width of the speckle kernel, in units of ``speckle_points``.
SPECKLE_TRUNCATE = 4.0
#: Fields of :class:`SensorModel` that may be negative, and their largest magnitude.
SIGNED_FIELDS, MAX_SCALE_ERROR = ("x_scale_error", "z_scale_error"), 0.5


@dataclass(frozen=True)
class SensorModel:
    """Shape-error terms of a profiler (see the module docstring); zeros disable each.

    Attributes
    ----------
    linearity_m : float
        Largest depth error of the fixed bow (± linearity over the range), m.
    shape_sigma_m : float
        1σ of the smooth per-profile depth error, m.
    shape_length_m : float
        Correlation length of that error along the line, m.
    speckle_sigma_m : float
        1σ of the neighbour-correlated depth noise, m.
    speckle_points : float
        Width (1σ of the Gaussian kernel) of the speckle correlation, in rays.
    x_step_m, z_step_m : float
        Output steps of x and z, m; 0 disables the rounding.
    min_signal : float
        Least returned light (reflectance · cos(incidence) · speckle factor, 0..1) that
        gives a point; 0 disables weak-return dropouts.
    signal_spread : float
        1σ of the natural log of the per-point speckle factor of the returned light.
    incidence_falloff : float
        Exponent p of the share ``cos(incidence) ** p`` of returns kept; 0 keeps all.
    gap_rate : float
        Mean number of gaps (runs of missing returns) per profile.
    gap_length_m : float
        Mean length of a gap along the line (sensor x), m.
    x_scale_error, z_scale_error : float
        Relative errors of the x and z scales (both about the sensor origin), signed.
    """

    linearity_m: float = 0.0
    shape_sigma_m: float = 0.0
    shape_length_m: float = 0.005
    speckle_sigma_m: float = 0.0
    speckle_points: float = 1.5
    x_step_m: float = 0.0
    z_step_m: float = 0.0
    min_signal: float = 0.0
    signal_spread: float = 0.0
    incidence_falloff: float = 0.0
    gap_rate: float = 0.0
    gap_length_m: float = 1e-3
    x_scale_error: float = 0.0
    z_scale_error: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            signed = f.name in SIGNED_FIELDS
            if not (
                isinstance(value, int | float)
                and math.isfinite(value)
                and (abs(value) < MAX_SCALE_ERROR if signed else value >= 0.0)
            ):
                bound = f"within +-{MAX_SCALE_ERROR}" if signed else ">= 0"
                raise InputError(f"sensor model: {f.name} must be a number {bound}, got {value!r}")
        for name in ("shape_length_m", "speckle_points", "gap_length_m"):
            if getattr(self, name) <= 0.0:
                raise InputError(f"sensor model: {name} must be > 0, got {getattr(self, name)}")
        if self.min_signal >= 1.0:
            raise InputError(f"sensor model: min_signal must be < 1, got {self.min_signal}")

    @property
    def active(self) -> bool:
        """Whether any term changes a measurement."""
        return any(
            getattr(self, name) > 0.0
            for name in (
                "linearity_m",
                "shape_sigma_m",
                "speckle_sigma_m",
                "x_step_m",
                "z_step_m",
                "min_signal",
                "incidence_falloff",
                "gap_rate",
            )
        ) or (self.x_scale_error != 0.0 or self.z_scale_error != 0.0)


def sensor_model_from_mapping(values: Mapping[str, Any]) -> SensorModel:
    """A :class:`SensorModel` from plain values (as a YAML reader gives them).

    Raises
    ------
    InputError
        For an unknown field or an invalid value.
    """
    known = {f.name for f in fields(SensorModel)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise InputError(f"sensor model: unknown field(s) {unknown}; known: {sorted(known)}")
    return SensorModel(**values)


def _smoothed_noise(rng: np.random.Generator, shape: tuple[int, int], width: float) -> FloatArray:
    """Unit-variance white noise (K, N) smoothed along axis 1 by a Gaussian of ``width`` rays.

    The noise is drawn with a margin on both sides and cropped, so every point has the same
    variance (no edge effect).
    """
    pad = math.ceil(SPECKLE_TRUNCATE * width)
    white = rng.normal(size=(shape[0], shape[1] + 2 * pad))
    smooth = gaussian_filter1d(white, width, axis=1, mode="constant", truncate=SPECKLE_TRUNCATE)
    impulse = np.zeros(2 * pad + 1)
    impulse[pad] = 1.0
    kernel = gaussian_filter1d(impulse, width, mode="constant", truncate=SPECKLE_TRUNCATE)
    return np.asarray(smooth[:, pad : pad + shape[1]] / np.linalg.norm(kernel))


def shape_error(rng: np.random.Generator, model: SensorModel, x_m: FloatArray) -> FloatArray:
    """The smooth per-profile depth error at positions ``x_m`` (K, N) along the line, m.

    A random Fourier feature sample of a zero-mean process with covariance
    ``shape_sigma_m² · exp(−d² / (2 shape_length_m²))``; each profile draws its own.
    """
    k = x_m.shape[0]
    omega = rng.normal(size=(k, SHAPE_FEATURES)) / model.shape_length_m
    phase = rng.uniform(0.0, 2.0 * math.pi, (k, SHAPE_FEATURES))
    waves = np.cos(x_m[:, :, None] * omega[:, None, :] + phase[:, None, :])
    return np.asarray(model.shape_sigma_m * math.sqrt(2.0 / SHAPE_FEATURES) * waves.sum(axis=2))


def linearity_bow(
    rng: np.random.Generator, model: SensorModel, u: FloatArray, v: FloatArray
) -> FloatArray:
    """The sensor's fixed depth bow at fan positions ``u`` and range positions ``v``, m.

    ``u`` and ``v`` broadcast together, each in [−1, 1]; see the module docstring.
    """
    a = rng.normal(size=3)
    shape = a[0] * (2.0 * u**2 - 1.0) + a[1] * (2.0 * v**2 - 1.0) + a[2] * u * v
    return np.asarray(model.linearity_m * shape / np.sum(np.abs(a)))


def apply_sensor_model(
    rng: np.random.Generator,
    model: SensorModel,
    points: FloatArray,
    truth: FloatArray,
    z_range_m: tuple[float, float],
    cos_incidence: FloatArray,
    reflectance: FloatArray,
) -> tuple[FloatArray, BoolArray]:
    """Add a profiler's shape errors to measured points and find its weak returns.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of four child generators (bow, shape, speckle, signal).
    model : SensorModel
    points : ndarray, shape (K, N, 3)
        Noisy points in the sensor frame, m (any value where nothing returned).
    truth : ndarray, shape (K, N, 3)
        Noise-free points, m (NaN where nothing was hit); x sets the shape error's place
        along the line.
    z_range_m : (float, float)
        The measuring range (near, far) in depth, m.
    cos_incidence : ndarray, shape (K, N)
        Cosine of the incidence angle (NaN: no hit).
    reflectance : ndarray, shape (K, N)
        Reflectance (0..1) of the surface each ray hit.

    Returns
    -------
    points : ndarray, shape (K, N, 3)
        The points with the depth errors added and x, z quantised, m.
    weak : ndarray of bool, shape (K, N)
        Returns too weak to give a point.
    """
    bow_rng, shape_rng, speckle_rng, signal_rng = rng.spawn(4)
    k, n = points.shape[:2]
    p = points.copy()
    if model.linearity_m > 0.0:
        u = np.linspace(-1.0, 1.0, n)[None, :]
        half = 0.5 * (z_range_m[1] - z_range_m[0])
        v = np.clip((p[..., 2] - 0.5 * (z_range_m[0] + z_range_m[1])) / half, -1.0, 1.0)
        p[..., 2] += linearity_bow(bow_rng, model, u, v)
    if model.shape_sigma_m > 0.0:
        p[..., 2] += shape_error(shape_rng, model, np.nan_to_num(truth[..., 0]))
    if model.speckle_sigma_m > 0.0:
        p[..., 2] += model.speckle_sigma_m * _smoothed_noise(
            speckle_rng, (k, n), model.speckle_points
        )
    if model.x_scale_error != 0.0:
        p[..., 0] *= 1.0 + model.x_scale_error
    if model.z_scale_error != 0.0:
        p[..., 2] *= 1.0 + model.z_scale_error
    for axis, step in ((0, model.x_step_m), (2, model.z_step_m)):
        if step > 0.0:
            p[..., axis] = np.round(p[..., axis] / step) * step
    weak = np.zeros((k, n), dtype=np.bool_)
    if model.min_signal > 0.0:
        speckle_factor = np.exp(model.signal_spread * signal_rng.normal(size=(k, n)))
        signal = reflectance * np.nan_to_num(cos_incidence) * speckle_factor
        weak = np.asarray(signal < model.min_signal)
    thin_rng, gap_rng = rng.spawn(2)
    if model.incidence_falloff > 0.0:
        kept = np.clip(np.nan_to_num(cos_incidence), 0.0, 1.0) ** model.incidence_falloff
        weak |= thin_rng.random((k, n)) >= kept
    if model.gap_rate > 0.0:
        weak |= _gaps(gap_rng, model, truth[..., 0])
    return p, weak


def _gaps(rng: np.random.Generator, model: SensorModel, x_m: FloatArray) -> BoolArray:
    """Rays (K, N) inside the gaps of each profile (term 7 of the module docstring); ``x_m``
    (K, N) is where each ray meets a surface along the line (NaN: nowhere), m."""
    k, n = x_m.shape
    gap = np.zeros((k, n), dtype=np.bool_)
    counts: list[int] = np.asarray(rng.poisson(model.gap_rate, size=k)).tolist()
    for row, count in enumerate(counts):
        rays = np.flatnonzero(np.isfinite(x_m[row]))
        if not len(rays):
            continue
        centres = x_m[row, rng.choice(rays, count)]
        halves = 0.5 * rng.exponential(model.gap_length_m, count)
        with np.errstate(invalid="ignore"):
            for centre, half in zip(centres, halves, strict=True):
                gap[row] |= np.abs(x_m[row] - centre) <= half
    return gap


def second_difference_noise_m(points: FloatArray) -> float:
    """Local point noise of one profile, 1σ, m: RMS of the depth's second differences / √6.

    ``points`` (N, 3) in scan order, NaN rows for invalid rays (organised) or valid rows
    only (dense); a second difference counts only where its three rows are valid. For white
    depth noise σ this is σ; a smooth shape error adds nearly nothing. Returns NaN with no
    valid triple.
    """
    d2 = np.diff(np.asarray(points, dtype=np.float64)[:, 2], n=2)
    d2 = d2[np.isfinite(d2)]
    return float(np.sqrt(np.mean(d2 * d2) / 6.0)) if len(d2) else math.nan


def circle_rms_m(points: FloatArray) -> float:
    """RMS distance of a profile's valid points (N, 3) from their best circle in x-z, m.

    The circle (centre and radius free) is the geometric least-squares fit started from
    the algebraic one, as a sphere section is fitted.
    """
    p = np.asarray(points, dtype=np.float64)
    xz = p[np.all(np.isfinite(p), axis=1)][:, [0, 2]]
    centre, radius = fit_circle_algebraic(xz)
    centre, radius = fit_circle_geometric(xz, centre, radius)
    r = circle_residuals(xz, centre, radius)
    return float(np.sqrt(np.mean(r * r)))


@dataclass(frozen=True)
class ProfilerSpec:
    """A profiler's datasheet figures and its shape-error model.

    Attributes
    ----------
    name : str
    z_near_m, z_far_m : float
        Near and far ends of the measuring range, from the sensor's reference face, m.
    width_near_m, width_far_m : float
        Width of the line (x range) at the near and far ends, m.
    points : int
        Points per profile.
    sigma_depth_m, sigma_lateral_m : float
        White point noise (1σ) on z and x, m.
    model : SensorModel
    """

    name: str
    z_near_m: float
    z_far_m: float
    width_near_m: float
    width_far_m: float
    points: int
    sigma_depth_m: float
    sigma_lateral_m: float
    model: SensorModel = field(default_factory=SensorModel)

    @property
    def tan_half_fan(self) -> float:
        """tan of the fan's half angle, from the widths at both ends of the range."""
        return 0.5 * (self.width_far_m - self.width_near_m) / (self.z_far_m - self.z_near_m)

    @property
    def apex_offset_m(self) -> float:
        """Distance from the fan apex (the simulator's sensor origin) to ``z_near_m``, m."""
        return 0.5 * self.width_near_m / self.tan_half_fan


def profiler_fields(spec: ProfilerSpec) -> dict[str, Any]:
    """:class:`~linelaser_calib.sim.scenario.Scenario` fields of a profiler, SI.

    The simulator's rays leave one apex, so the range is measured from the apex where the
    near and far widths extrapolate to zero; the datasheet's reference face lies elsewhere,
    an offset the hand-eye absorbs.
    """
    near = spec.apex_offset_m
    return {
        "z_min_m": near,
        "z_max_m": near + spec.z_far_m - spec.z_near_m,
        "fan_half_angle_rad": math.atan(spec.tan_half_fan),
        "resolution": spec.points,
        "sigma_depth_m": spec.sigma_depth_m,
        "sigma_lateral_m": spec.sigma_lateral_m,
        "sensor": spec.model,
    }


#: Faces of reality (issue 29) at the sizes the real scans in ../shared/external/ show, added
#: to every profiler preset below (``bench/realism.py --only real`` measures them): gaps, 3 runs
#: of 2-3 missing columns (about 0.1 mm) in the 15 profiles of the SSZN SR7140 set (rate 0.2
#: per profile); no thinning at incidence beyond the ray fan's own, since every column returns
#: up to the end of each arc in both sphere sets (in the 60-70 deg slope band 194 of 194
#: columns on a 39 mm circle), so ``incidence_falloff`` stays 0; the scales and the shape error
#: are each preset's own (the SR7140 set's free along-line scale reads 0.99911 +- 0.00012,
#: its smooth circle residual 5-15 um).
MEASURED_GAPS = {"gap_rate": 0.2, "gap_length_m": 1e-4}


def _keyence_lj_x8080() -> ProfilerSpec:
    # Keyence LJ-X8080 (LJ-X8000 series head). Source: Keyence "LJ-X8000 Series User's
    # Manual", specifications table (printed page 10-5), as transcribed in the public
    # repository CZPavel/keyence-ljx-s-skill (skill_data/hardware/head_specifications.yaml);
    # the manual itself was not found in the searchable corpus. Reference distance 73 mm,
    # Z range ±20.5 mm (52.5-93.5 mm, F.S. 41 mm), X width 30 mm (near) / 35 mm (reference) /
    # 39 mm (far), 3200 points, X profile data interval 12.5 µm, repeatability Z 0.5 µm and
    # X 1 µm (averaged, so the single-shot noise below is assumed larger: 1.5 µm / 1 µm).
    # Linearity: not found (the transcription marks it unverified); assumed ±0.03 % of F.S.
    # = ±12 µm. Output: x on the uniform 12.5 µm column grid with z taken there, so no x
    # rounding; z output unit assumed 0.01 µm (as in the LJ-V7000 communication manual).
    # Shape error and speckle: not in any datasheet; assumed 6 µm over 3 mm and 1 µm. Scales:
    # not in the datasheet; assumed x 0.1 % long (the size the real SR7140 set shows).
    full_scale = 0.041
    return ProfilerSpec(
        name="keyence_lj_x8080",
        z_near_m=0.0525,
        z_far_m=0.0935,
        width_near_m=0.030,
        width_far_m=0.039,
        points=3200,
        sigma_depth_m=1.5e-6,
        sigma_lateral_m=1e-6,
        model=SensorModel(
            linearity_m=3e-4 * full_scale,
            shape_sigma_m=6e-6,
            shape_length_m=0.003,
            speckle_sigma_m=1e-6,
            speckle_points=1.5,
            z_step_m=1e-8,
            min_signal=0.05,
            signal_spread=0.5,
            x_scale_error=0.001,
            **MEASURED_GAPS,
        ),
    )


def _scancontrol_3010_50() -> ProfilerSpec:
    # Micro-Epsilon scanCONTROL 3010-50 (30xx-50 head). The datasheet was not found in the
    # searchable corpus; the vendor page https://www.micro-epsilon.com/2d-3d-measurement/
    # laser-profile-scanners/scancontrol-30x0/ is quoted second-hand (public repository
    # text) for the family: 2048 points per profile, point spacing down to 12 µm. The
    # -50 geometry is from memory of the 30xx datasheet and is an assumption: range
    # 95-160 mm (65 mm), x width 42 mm at the start and 58.5 mm at the end. Linearity:
    # not found; assumed ±0.03 % of 65 mm = ±20 µm. Output: x and z as 16-bit values,
    # assumed 1 µm steps for this range. Noise assumed 3 µm depth, 4 µm lateral; shape
    # error 10 µm over 4 mm and speckle 2 µm (not datasheet figures); x scale 0.1 % short
    # (assumed, the size the real SR7140 set shows).
    full_scale = 0.065
    return ProfilerSpec(
        name="scancontrol_3010_50",
        z_near_m=0.095,
        z_far_m=0.160,
        width_near_m=0.042,
        width_far_m=0.0585,
        points=2048,
        sigma_depth_m=3e-6,
        sigma_lateral_m=4e-6,
        model=SensorModel(
            linearity_m=3e-4 * full_scale,
            shape_sigma_m=1e-5,
            shape_length_m=0.004,
            speckle_sigma_m=2e-6,
            speckle_points=1.5,
            x_step_m=1e-6,
            z_step_m=1e-6,
            min_signal=0.05,
            signal_spread=0.5,
            x_scale_error=-0.001,
            **MEASURED_GAPS,
        ),
    )


def _gocator_2330() -> ProfilerSpec:
    # LMI Gocator 2330. Source: LMI "Gocator 2300 Series" datasheet,
    # https://lmi3d.com/wp-content/uploads/2025/05/DATASHEET_Gocator_2300_US_WEB.pdf, page 2,
    # as transcribed in a public repository (the PDF was not in the searchable corpus):
    # clearance distance 90 mm, measurement range 80 mm (90-170 mm), field of view 47 mm
    # (near) to 85 mm (far). From memory of the same datasheet, not verified here: 1280
    # points per profile, Z resolution 6-14 µm, linearity Z ±0.01 % of the range (±8 µm).
    # Output: profile ranges are 16-bit values (Gocator protocol, "ranges 16s"), so the z
    # step is about 80 mm / 65536 ≈ 1.2 µm (assumed zScale); x is resampled onto a uniform
    # grid, so no x rounding. Noise assumed 6 µm depth, 10 µm lateral; shape error 12 µm
    # over 5 mm and speckle 3 µm (not datasheet figures); z scale 0.1 % long (assumed, the
    # size the real SR7140 set shows between its axes).
    measuring_range = 0.080
    return ProfilerSpec(
        name="gocator_2330",
        z_near_m=0.090,
        z_far_m=0.170,
        width_near_m=0.047,
        width_far_m=0.085,
        points=1280,
        sigma_depth_m=6e-6,
        sigma_lateral_m=1e-5,
        model=SensorModel(
            linearity_m=1e-4 * measuring_range,
            shape_sigma_m=1.2e-5,
            shape_length_m=0.005,
            speckle_sigma_m=3e-6,
            speckle_points=1.5,
            z_step_m=measuring_range / 65536,
            min_signal=0.05,
            signal_spread=0.5,
            z_scale_error=0.001,
            **MEASURED_GAPS,
        ),
    )


def _sszn_sr7140() -> ProfilerSpec:
    # SSZN (Shenzhen Shenshi) SR7140, the sensor of the real scans in
    # ../shared/external/robcalibrator. Its datasheet was not found in the searchable
    # corpus. The vendor's SR7IF SDK samples (public repositories) give its height range as
    # "half of F.S." 12 mm in some and 15 mm in others; the real recordings span z -28.7 to
    # +19.1 mm about the measuring centre, so a 48 mm range is assumed. The recordings
    # show 3200 columns on a 0.03 mm x grid (x 0.24-95.88 mm) and z steps of about 10 nm.
    # Reference distance: not found; assumed 140 mm (the model number), with the fan apex
    # at the sensor face, so the 96 mm line width at 140 mm gives 79.5 mm near and 112.5 mm
    # far. Linearity: not found; assumed ±0.03 % of F.S. = ±14 µm. Noise and shape error
    # are set so that simulated sphere profiles look like the real ones (local noise
    # 4-6 µm, circle residual about 10-15 µm RMS away from the steep ends). Its x scale is
    # 0.09 % short of z, as a free along-line scale reads on the real 40 mm ball set.
    full_scale = 0.048
    return ProfilerSpec(
        name="sszn_sr7140",
        z_near_m=0.116,
        z_far_m=0.164,
        width_near_m=0.0795,
        width_far_m=0.1125,
        points=3200,
        sigma_depth_m=4.5e-6,
        sigma_lateral_m=2e-6,
        model=SensorModel(
            linearity_m=3e-4 * full_scale,
            shape_sigma_m=1.5e-5,
            shape_length_m=0.004,
            speckle_sigma_m=3e-6,
            speckle_points=1.5,
            z_step_m=1e-8,
            min_signal=0.05,
            signal_spread=0.5,
            x_scale_error=-0.0009,
            **MEASURED_GAPS,
        ),
    )


def _sszn_fanuc() -> ProfilerSpec:
    # An SSZN-class profiler as measured in a real FANUC cell: 3.5-4.5 µm local noise (RMS
    # of second differences / √6) and 20-40 µm RMS circle residual on a 40 mm-radius sphere
    # at 0.05 mm point pitch. The SR7140 geometry above with 1920 points (0.05 mm pitch at
    # 140 mm, as if the driver bins columns; an assumption) and the noise and shape error
    # set to reproduce those two figures (test/test_sensor_models.py checks them). Its x
    # scale 0.3 % long of z: the low end of the 0.3-1 % the field's profilers showed.
    return replace(
        _sszn_sr7140(),
        name="sszn_fanuc",
        points=1920,
        sigma_depth_m=3.9e-6,
        model=replace(
            _sszn_sr7140().model,
            shape_sigma_m=4.2e-5,
            speckle_sigma_m=2.5e-6,
            x_scale_error=0.003,
        ),
    )


#: Faces of a real profiler that the field showed (issue 29), as :class:`SensorModel` fields:
#: ``grazing``: points thin out as the incidence grows (a steep flank met at grazing
#: incidence holds a few dozen points); ``gaps``: about one run of missing returns 1.5 mm
#: long per profile; ``scales``: x and z scales off by +0.6 % and -0.2 % (0.8 % apart; both
#: about the sensor origin, see term 8 of the module docstring); ``shape``: the profile shape
#: error with which a conic fits a single profile of a ball clearly better than a circle, as
#: measured on the two real sphere sets in ../shared/external/robcalibrator
#: (``bench/realism.py --only conic``). There the conic's gain comes from a fixed linear
#: distortion of the sensor's plane common to every profile, not from a smooth error drawn
#: per profile: one anisotropy per set (40 mm set: axes 0.27 % apart, the short one 22 deg
#: off x; 12.7 mm set: x 9.5 % short of z, along the axes) takes the conic's win away on 13
#: of 14 and 4 of 10 profiles; the smooth per-profile part is small beside the local noise
#: (2.7 um over 2.5 mm beside 4.9 um; 32 um over 1.2 mm beside 88 um) and alone (42 um over
#: 4 mm, the FANUC cell's SSZN profiler) lets a conic win on 4 of 14 profiles of the
#: ``sphere`` preset. So the face is a smooth error of 4 um over 2 mm (half the ``sphere``
#: preset's 8 um local noise) and x 1.0 % short of z (the 12.7 mm set's direction; the top
#: of the 0.3-1 % the field's profilers showed), sized so that on the stress matrix's
#: ``sphere`` scene a conic wins on as large a share of the profiles, by as much per point,
#: as on the real 12.7 mm set (13 of 14 against 10 of 10; BIC 0.35-0.42 lower
#: per point against a median of 0.40; circle/conic robust scale 1.22 against 1.29).
REAL_FACES: dict[str, dict[str, float]] = {
    "grazing": {"incidence_falloff": 0.5},
    "gaps": {"gap_rate": 1.0, "gap_length_m": 1.5e-3},
    "scales": {"x_scale_error": 0.006, "z_scale_error": -0.002},
    "shape": {"shape_sigma_m": 4e-6, "shape_length_m": 0.002, "x_scale_error": -0.01},
}


def with_faces(model: SensorModel, *faces: str) -> SensorModel:
    """``model`` with the named :data:`REAL_FACES` added (InputError for an unknown one, or
    for two that set one field, such as ``scales`` and ``shape`` the x scale)."""
    unknown = sorted(set(faces) - set(REAL_FACES))
    if unknown:
        raise InputError(f"unknown profiler face(s) {unknown}; known: {sorted(REAL_FACES)}")
    named = [k for face in set(faces) for k in REAL_FACES[face]]
    twice = sorted({k for k in named if named.count(k) > 1})
    if twice:
        raise InputError(f"profiler faces {sorted(set(faces))} each set {twice}; give one of them")
    return replace(model, **{k: v for face in faces for k, v in REAL_FACES[face].items()})


#: Named profilers (datasheet figures, sources and assumptions in each one's comment).
PROFILERS: dict[str, ProfilerSpec] = {
    spec.name: spec
    for spec in (
        _keyence_lj_x8080(),
        _scancontrol_3010_50(),
        _gocator_2330(),
        _sszn_sr7140(),
        _sszn_fanuc(),
    )
}
