"""A cluttered scene seen by a coarse camera-based profiler, from a less accurate robot.

The pieces a real recording adds to the plain cylinder scan, each off by default (the
:class:`~linelaser_calib.sim.scenario.Scenario` fields named below):

- **Fixture fin** (``fixture_length_m``, ``fixture_direction``, ``fixture_band_m``): a thin
  plate in a plane through the cylinder axis, sticking out radially along
  ``fixture_direction`` (projected perpendicular to the axis) for ``fixture_length_m`` beyond
  the surface, over the axial band ``fixture_band_m`` from the cylinder base. A profile that
  crosses the band sees the arc run into the fin's straight trace with no gap between them.
- **Clustered poses** (``pose_clusters``, ``cluster_spread_m``, ``cluster_spread_rad``): the
  pose sampler draws one pose per cluster; each cluster's members are that pose turned by a
  rotation vector and shifted by a translation, uniform within ± the spreads per axis (the
  rotation about the sensor origin, the shift in the base frame).
- **Robot error field** (``robot_field_m``, ``robot_field_length_m``): the recorded flange
  pose of each shot is off by a translation that depends smoothly on where the flange is,
  so that nearby poses share their error (a stand-in for a robot's kinematic errors). In the
  sensor frame the offset is ``delta_i(p) = A_i / 2 * g_i(p)``, A = ``robot_field_m``, where
  each ``g_i`` is a unit-variance random Fourier field of the flange position p (8
  cosines with wave vectors drawn with 1σ 1 / ``robot_field_length_m`` per axis); about 95 %
  of the offsets lie within ±A. Mapped with the recorded pose, a profile appears shifted by
  ``delta`` in its own frame.
- **Camera profiler effects** (applied to the measured points):
  the noise of each profile is scaled by a factor uniform in
  [1 - ``sigma_spread``, 1 + ``sigma_spread``] (exposure and range differ per shot);
  a grazing-angle bias moves each return out along the surface normal (its direction in
  the laser plane) by
  ``edge_bias_m * (1 / cos(incidence) - 1)``, capped at 10 ``edge_bias_m`` (the laser spot
  smears along a steep surface and the peak detector's centroid leaves the surface), so
  the arc's steep ends bulge outwards; the along-line coordinate is
  scaled by ``1 + lateral_scale_error`` (a calibration error of the sensor's x scale); and
  the depth is rounded to multiples of ``depth_quantum_m`` (the sub-pixel resolution of the
  camera).

All draws come from their own generator (:func:`clutter_rng`), so that turning these pieces
on leaves every other draw of a seed unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim.poses import SensorPoses
from linelaser_calib.sim.profiler import Measurement, Trace
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import T_MIN_M, Int8Array, Scene, Surface

#: Second seed word of the clutter generator (the first is the run's seed).
CLUTTER_STREAM = 15
#: Cosines per component of the robot error field.
FIELD_FEATURES = 8
#: Largest grazing-angle bias, in units of ``edge_bias_m``.
MAX_EDGE_BIAS_FACTOR = 10.0


def clutter_rng(seed: int) -> np.random.Generator:
    """The generator of every draw of this module for a run's ``seed``."""
    return np.random.default_rng([seed, CLUTTER_STREAM])


@dataclass(frozen=True, eq=False)
class ClutteredScene(Scene):
    """A :class:`Scene` with a fixture fin (see the module docstring).

    Attributes
    ----------
    fin_direction : ndarray, shape (3,)
        Unit radial direction of the fin, perpendicular to the axis.
    fin_length_m : float
        How far the fin reaches beyond the cylinder surface, m.
    fin_band_m : (float, float)
        Axial band of the fin from the cylinder base, m.
    """

    fin_direction: FloatArray = field(default_factory=lambda: np.zeros(3))
    fin_length_m: float = 0.0
    fin_band_m: tuple[float, float] = (0.0, 0.0)

    @property
    def fin_normal(self) -> FloatArray:
        """Unit normal of the fin's plane on the robot side, shape (3,).

        The fin is seen from the side of the base origin (the presets' sensors stay there),
        so its normal is the one with a non-negative component towards the origin.
        """
        n = np.cross(self.axis, self.fin_direction)
        return np.asarray(-n if n @ self.base_m > 0.0 else n)

    def fin_distance(self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M) -> FloatArray:
        """``t > t_min`` at which the ray meets the fin, else inf."""
        n = self.fin_normal
        denom = np.sum(r * n, axis=-1)
        ok = np.abs(denom) > 1e-18
        t = np.where(ok, np.sum((self.base_m - o) * n, axis=-1) / np.where(ok, denom, 1.0), np.inf)
        p = o + np.where(np.isfinite(t), t, 0.0)[..., None] * r - self.base_m
        axial = p @ self.axis
        radial = p @ self.fin_direction
        inside = (axial >= self.fin_band_m[0]) & (axial <= self.fin_band_m[1])
        inside &= (radial >= self.radius_m) & (radial <= self.radius_m + self.fin_length_m)
        return np.asarray(np.where((t > t_min) & inside, t, np.inf))

    def cast(
        self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M
    ) -> tuple[FloatArray, Int8Array, FloatArray]:
        """Nearest hit of each ray, the fin included (see :meth:`Scene.cast`)."""
        t, surface, t_side = super().cast(o, r, t_min)
        t_fin = self.fin_distance(o, r, t_min)
        nearer = t_fin < t
        return (
            np.asarray(np.where(nearer, t_fin, t)),
            np.where(nearer, np.int8(Surface.FIXTURE), surface).astype(np.int8),
            t_side,
        )

    def normals(self, points: FloatArray, surface: Int8Array) -> FloatArray:
        """Outward unit normals (see :meth:`Scene.normals`); the fin's is :attr:`fin_normal`."""
        base = super().normals(points, surface)
        n = np.broadcast_to(self.fin_normal, points.shape)
        return np.asarray(np.where((surface == Surface.FIXTURE)[..., None], n, base))


def scene_from_scenario(scenario: Scenario) -> Scene:
    """The scene of a scenario: a :class:`ClutteredScene` when it has a fixture fin."""
    scene = Scene.from_scenario(scenario)
    if scenario.fixture_length_m <= 0.0:
        return scene
    d = np.asarray(scenario.fixture_direction, dtype=np.float64)
    d = d - (d @ scene.axis) * scene.axis
    return ClutteredScene(
        scene.base_m,
        scene.axis,
        scene.radius_m,
        scene.length_m,
        scene.plane_point_m,
        scene.plane_normal,
        fin_direction=d / np.linalg.norm(d),
        fin_length_m=scenario.fixture_length_m,
        fin_band_m=scenario.fixture_band_m,
    )


def clustered_poses(
    rng: np.random.Generator, scenario: Scenario, centres: SensorPoses
) -> SensorPoses:
    """``scenario.n_poses`` sensor poses around the cluster centres ``centres``.

    The members are spread evenly over the clusters and kept together (a robot program
    visits one region after the other); each keeps its centre's kind and cut angle.
    """
    owner = np.arange(scenario.n_poses) * len(centres.T_base_sensor) // scenario.n_poses
    rotvec = rng.uniform(-1.0, 1.0, (scenario.n_poses, 3)) * scenario.cluster_spread_rad
    shift = rng.uniform(-1.0, 1.0, (scenario.n_poses, 3)) * scenario.cluster_spread_m
    T = centres.T_base_sensor[owner].copy()
    T[:, :3, :3] = T[:, :3, :3] @ Rotation.from_rotvec(rotvec).as_matrix()
    T[:, :3, 3] += shift
    return SensorPoses(
        T_base_sensor=np.asarray(T),
        kinds=tuple(centres.kinds[i] for i in owner),
        cut_angles_rad=np.asarray(centres.cut_angles_rad[owner]),
    )


def field_offsets(
    rng: np.random.Generator, scenario: Scenario, flange_positions_m: FloatArray
) -> FloatArray:
    """The robot error field at flange positions, in the sensor frame, shape (K, 3), m."""
    amplitude = np.asarray(scenario.robot_field_m, dtype=np.float64)
    omega = rng.normal(size=(3, FIELD_FEATURES, 3)) / scenario.robot_field_length_m
    phase = rng.uniform(0.0, 2.0 * math.pi, (3, FIELD_FEATURES))
    angles = np.einsum("ifj,kj->kif", omega, flange_positions_m) + phase
    unit = math.sqrt(2.0 / FIELD_FEATURES) * np.sum(np.cos(angles), axis=2)
    return np.asarray(0.5 * amplitude * unit)


def field_errors(
    rng: np.random.Generator, scenario: Scenario, T_base_sensor: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Flange-frame translation errors of the field at each waypoint, and the offsets.

    Returns
    -------
    translation_flange_m : ndarray, shape (K, 3)
        To add to the robot's per-waypoint translation errors, m.
    offset_sensor_m : ndarray, shape (K, 3)
        The same errors as profile offsets in the sensor frame, m.
    """
    T_fs = scenario.T_flange_sensor
    flange = T_base_sensor[:, :3, 3] - np.einsum(
        "kij,j->ki", T_base_sensor[:, :3, :3], T_fs[:3, :3].T @ T_fs[:3, 3]
    )
    offset = field_offsets(rng, scenario, flange)
    return np.asarray(offset @ T_fs[:3, :3].T), offset


def profile_sigma_factors(rng: np.random.Generator, scenario: Scenario, count: int) -> FloatArray:
    """Per-profile noise factors, shape (count,), uniform in 1 ± ``sigma_spread``."""
    return np.asarray(1.0 + scenario.sigma_spread * rng.uniform(-1.0, 1.0, count))


def camera_effects(
    scenario: Scenario,
    traced: Trace,
    measured: Measurement,
    sigma_factor: FloatArray,
    R_base_sensor: FloatArray,
) -> Measurement:
    """Per-profile noise scale, grazing-angle bias, along-line scale and depth quantisation.

    Parameters
    ----------
    scenario : Scenario
    traced : Trace
        The noise-free returns the measurement was made from.
    measured : Measurement
    sigma_factor : ndarray, shape (K,)
        Noise factor of each profile (:func:`profile_sigma_factors`).
    R_base_sensor : ndarray, shape (K, 3, 3)
        Orientation of each shot's sensor (turns the surface normals into its frame).
    """
    truth = np.nan_to_num(traced.points_sensor)
    noise = np.nan_to_num(measured.points) - truth
    p = truth + np.where(measured.spike[..., None], 1.0, sigma_factor[:, None, None]) * noise
    with np.errstate(divide="ignore", invalid="ignore"):
        grazing = 1.0 / np.abs(np.nan_to_num(traced.cos_incidence, nan=1.0)) - 1.0
    bias = scenario.edge_bias_m * np.minimum(grazing, MAX_EDGE_BIAS_FACTOR)
    normals = np.einsum("kji,knj->kni", R_base_sensor, np.nan_to_num(traced.normals_base))
    normals[..., 1] = 0.0  # the sensor measures in its laser plane only
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    in_plane = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0.0)
    p = p + bias[..., None] * in_plane
    p[..., 0] *= 1.0 + scenario.lateral_scale_error
    if scenario.depth_quantum_m > 0.0:
        p[..., 2] = np.round(p[..., 2] / scenario.depth_quantum_m) * scenario.depth_quantum_m
    points = np.where(measured.valid[..., None], p, np.nan)
    return replace(measured, points=np.asarray(points))


def has_camera_effects(scenario: Scenario) -> bool:
    """Whether :func:`camera_effects` changes anything for this scenario."""
    return bool(
        scenario.sigma_spread > 0.0
        or scenario.edge_bias_m > 0.0
        or scenario.lateral_scale_error != 0.0
        or scenario.depth_quantum_m > 0.0
    )
