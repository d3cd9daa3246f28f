"""Line-laser profiler model: a fan of rays in the sensor x-z plane, cast into the scene.

The model, in the sensor frame (laser plane x-z, z = depth):

1. ``resolution`` rays leave the origin with directions (τ, 0, 1)/|.|, τ evenly spaced in
   [-tan θ, +tan θ], θ = ``fan_half_angle_rad`` (the laser fan of a triangulation sensor;
   even spacing in x at any depth, like camera columns).
2. Each ray returns the nearest hit in the scene (cylinder side, end caps, background
   plane); the far side of the cylinder is occluded by construction. A hit on a surface
   facing away from the ray (the origin inside the solid) returns nothing.
3. A return is lost at grazing incidence (``max_incidence_rad``) and, with a camera baseline,
   where the triangulation camera at (0, ``camera_baseline_m``, 0) cannot see the point
   (back-facing to the camera, or another surface in between).
4. Noise: Gaussian on x (``sigma_lateral_m``), z (``sigma_depth_m``) and y (``sigma_y_m``);
   a ``spike_fraction`` of returns displaced along their ray by ±(``spike_min_m`` ..
   ``spike_max_m``).
5. Gates on the measured point: depth in [``z_min_m``, ``z_max_m``]; then a
   ``dropout_fraction`` of the remaining rays lost at random.
6. With an active ``sensor`` model (:mod:`~linelaser_calib.sim.sensor_models`), before the
   gates: the profiler's shape errors (linearity bow, smooth per-profile error, correlated
   speckle), x/z output steps, and weak returns lost on steep or dark surfaces.

:func:`trace` does steps 1-3 without randomness (it also serves the pose sampler);
:func:`measure` adds steps 4-6 from a generator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.types import BoolArray, FloatArray
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Int8Array, Scene, Surface
from linelaser_calib.sim.sensor_models import apply_sensor_model

#: Smallest ray parameter of the camera visibility rays (in units of the point-camera
#: distance), so a point does not occlude itself.
_CAMERA_T_MIN = 1e-6


def ray_directions(scenario: Scenario) -> FloatArray:
    """Unit ray directions of the fan in the sensor frame, shape (resolution, 3), y = 0."""
    tau = np.linspace(-1.0, 1.0, scenario.resolution) * math.tan(scenario.fan_half_angle_rad)
    d = np.stack([tau, np.zeros_like(tau), np.ones_like(tau)], axis=1)
    return np.asarray(d / np.linalg.norm(d, axis=1, keepdims=True))


@dataclass(frozen=True, eq=False)
class Trace:
    """Noise-free returns of K sensor poses, N rays each.

    Attributes
    ----------
    surface : ndarray of int8, shape (K, N)
        :class:`~linelaser_calib.sim.scene.Surface` of the nearest hit (before any gate).
    points_sensor : ndarray, shape (K, N, 3)
        Hit points in the sensor frame, m (y = 0 exactly); NaN where nothing was hit.
    normals_base : ndarray, shape (K, N, 3)
        Outward surface normals at the hits in the base frame (NaN where nothing was hit).
    cos_incidence : ndarray, shape (K, N)
        Cosine of the angle between the reversed ray and the normal (NaN: no hit).
    seen : ndarray of bool, shape (K, N)
        The hit returns light: front-facing, not grazing, visible to the camera.
    side_occluded : ndarray of bool, shape (K, N)
        The ray meets the cylinder side but something else is nearer (e.g. the plane).
    """

    surface: Int8Array
    points_sensor: FloatArray
    normals_base: FloatArray
    cos_incidence: FloatArray
    seen: BoolArray
    side_occluded: BoolArray


def trace(scene: Scene, scenario: Scenario, T_base_sensor: FloatArray) -> Trace:
    """Cast the fan of every sensor pose into the scene, without noise.

    Parameters
    ----------
    scene : Scene
    scenario : Scenario
        Sensor parameters (fan, resolution, incidence gate, camera baseline).
    T_base_sensor : ndarray, shape (K, 4, 4)
        Sensor poses in the base frame.
    """
    dirs = ray_directions(scenario)
    R = T_base_sensor[:, :3, :3]
    origin = T_base_sensor[:, None, :3, 3]
    rays = np.einsum("kij,nj->kni", R, dirs)
    t, surface, t_side = scene.cast(origin, rays)
    hit = np.isfinite(t)
    t_hit = np.where(hit, t, 0.0)
    points_base = origin + t_hit[..., None] * rays
    normals = scene.normals(points_base, surface)
    cos_inc, seen = returns_seen(
        scenario,
        T_base_sensor,
        rays,
        points_base,
        normals,
        hit,
        lambda o, r: scene.cast(o, r, _CAMERA_T_MIN)[0],
    )
    points_sensor = np.where(hit[..., None], t_hit[..., None] * dirs, np.nan)
    side_occluded = np.isfinite(t_side) & (surface != Surface.SIDE)
    return Trace(surface, points_sensor, normals, cos_inc, seen, side_occluded)


def returns_seen(
    scenario: Scenario,
    T_base_sensor: FloatArray,
    rays: FloatArray,
    points_base: FloatArray,
    normals: FloatArray,
    hit: BoolArray,
    cast: Callable[[FloatArray, FloatArray], FloatArray],
) -> tuple[FloatArray, BoolArray]:
    """Incidence and whether each hit returns light (steps 2-3 of the module docstring).

    Parameters
    ----------
    scenario : Scenario
        Incidence gate and camera baseline.
    T_base_sensor : ndarray, shape (K, 4, 4)
    rays : ndarray, shape (K, N, 3)
        Ray directions in the base frame.
    points_base, normals : ndarray, shape (K, N, 3)
        Hit points and outward unit normals (NaN where nothing was hit).
    hit : ndarray of bool, shape (K, N)
    cast : callable
        ``cast(origins, directions)``: the scene's nearest-hit ray parameter (inf: none) for
        rays from the points towards the camera, ignoring hits closer than a tiny fraction.

    Returns
    -------
    cos_incidence : ndarray, shape (K, N)
        Cosine of the angle between the reversed ray and the normal (NaN: no hit).
    seen : ndarray of bool, shape (K, N)
        Front-facing, within the incidence gate and (with a baseline) visible to the camera
        at sensor (0, ``camera_baseline_m``, 0).
    """
    cos_inc = np.where(hit, -np.sum(rays * np.nan_to_num(normals), axis=-1), np.nan)
    with np.errstate(invalid="ignore"):
        seen = hit & (cos_inc > 0.0) & (cos_inc >= math.cos(scenario.max_incidence_rad) - 1e-12)
    if scenario.camera_baseline_m > 0.0:
        origin = T_base_sensor[:, None, :3, 3]
        camera = origin + scenario.camera_baseline_m * T_base_sensor[:, None, :3, 1]
        to_camera = camera - points_base
        faces = np.sum(np.nan_to_num(normals) * to_camera, axis=-1) > 0.0
        seen &= faces & (cast(points_base, to_camera) >= 1.0 - _CAMERA_T_MIN)
    return np.asarray(cos_inc), np.asarray(seen)


@dataclass(frozen=True, eq=False)
class Measurement:
    """Noisy profiles of K sensor poses in organised form (N rays each).

    Attributes
    ----------
    points : ndarray, shape (K, N, 3)
        Measured points in the sensor frame, m; NaN rows for invalid rays.
    intensity : ndarray, shape (K, N), or None
        Intensities 0..1 (0 for invalid rays); None if the scenario has no intensity.
    valid : ndarray of bool, shape (K, N)
        The ray returned a point.
    spike : ndarray of bool, shape (K, N)
        Valid points displaced by a reflection spike.
    dropout : ndarray of bool, shape (K, N)
        Rays that would have been valid but were dropped (at random, or as weak returns of
        the scenario's sensor model).
    """

    points: FloatArray
    intensity: FloatArray | None
    valid: BoolArray
    spike: BoolArray
    dropout: BoolArray


def measure(rng: np.random.Generator, scenario: Scenario, traced: Trace) -> Measurement:
    """Add sensor noise, spikes, gates and dropouts to a noise-free :class:`Trace`.

    The random draws do not depend on the geometry or on the output format, so the same
    seed gives the same noise for organised and dense output. A scenario's
    :class:`~linelaser_calib.sim.sensor_models.SensorModel` (step 6 of the module docstring)
    draws from generators spawned from ``rng``, which leaves ``rng``'s own draws unchanged.
    """
    shape = traced.seen.shape
    noise = rng.normal(size=(3, *shape))
    spike_draw = rng.random(shape) < scenario.spike_fraction
    spike_size = rng.uniform(scenario.spike_min_m, scenario.spike_max_m, shape)
    spike_sign = np.where(rng.random(shape) < 0.5, -1.0, 1.0)
    drop_draw = rng.random(shape) < scenario.dropout_fraction
    intensity_noise = rng.normal(size=shape)
    glint = rng.uniform(0.8, 1.0, shape)

    seen = traced.seen
    p = np.where(seen[..., None], traced.points_sensor, 0.0)
    sigma = np.array([scenario.sigma_lateral_m, scenario.sigma_y_m, scenario.sigma_depth_m])
    p = p + np.moveaxis(noise, 0, -1) * sigma
    dirs = ray_directions(scenario)
    spiked = seen & spike_draw
    p = p + np.where(spiked, spike_sign * spike_size, 0.0)[..., None] * dirs
    reflectance = np.where(
        traced.surface == Surface.BACKGROUND,
        scenario.background_reflectance,
        scenario.cylinder_reflectance,
    )
    lost = np.zeros(shape, dtype=np.bool_)
    if scenario.sensor.active:
        p, lost = apply_sensor_model(
            rng,
            scenario.sensor,
            p,
            traced.points_sensor,
            (scenario.z_min_m, scenario.z_max_m),
            traced.cos_incidence,
            reflectance,
        )
    in_range = (p[..., 2] >= scenario.z_min_m) & (p[..., 2] <= scenario.z_max_m)
    returned = seen & in_range
    dropped = drop_draw | lost
    valid = returned & ~dropped
    points = np.where(valid[..., None], p, np.nan)

    intensity: FloatArray | None = None
    if scenario.intensity:
        diffuse = reflectance * np.nan_to_num(traced.cos_incidence)
        diffuse = diffuse * (1.0 + scenario.intensity_noise * intensity_noise)
        value = np.clip(np.where(spiked, glint, diffuse), 0.0, 1.0)
        intensity = np.asarray(np.where(valid, value, 0.0))
    return Measurement(points, intensity, valid, valid & spiked, returned & dropped)
