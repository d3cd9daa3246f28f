"""Sphere scenes: a tooling ball on a table, scanned step-and-shoot from many poses.

The target is a sphere (centre ``centre_m``, radius ``radius_m``) standing on a table: the
plane ``table_gap_m`` below the sphere's lowest point, normal +z of the base (the stem
that holds the ball is not modelled; the table is in view beside the ball). Every profile
cuts the sphere in a circle of radius r = √(R² − h²), h the distance of the sphere centre
from the laser plane; the centre lies on the sensor's ``centre_side`` (+1: +y, −1: −y), as
an operator places the line beside the ball's top on one side.

:class:`SphereScenario` holds the sphere and the view pattern and, in its ``rig`` field, an
ordinary :class:`~linelaser_calib.sim.scenario.Scenario` for everything else: profiler
(fan, range, noise, spikes, dropouts, incidence gate, camera shadowing, intensity,
organised output), the true hand-eye, the robot's error model and motion timing, topics and
frames. The rig's cylinder, background and pose-sampler fields are not used; its
``n_poses`` is the number of views and its motion must be ``step``.

Views: the sensor's viewing axis (sensor z) is tilted from straight down by up to
``tilt_rad`` in a random direction, the laser line turned about it by a uniform angle in
±90 deg (every direction of the line across the ball), the plane's distance from the centre drawn as
h = u·R with u uniform in ``offset_range``, the ball's centre placed at a depth drawn from
``depth_range_m`` and sideways along the line by up to ± ``lateral_fraction`` of the half
fan width. A view is drawn again when the arc shows fewer than ``min_arc_points`` returns
(noise-free) or the sensor or flange comes within the rig's ``clearance_m`` of the ball or
the table.

Presets (:data:`SPHERE_PRESETS`): ``sphere``: a Ø50.8 mm (2 in) tooling ball, a
scanCONTROL-class profiler (70-150 mm, ±25 deg, 640 points, σ 8/6 µm, spikes, dropouts,
camera shadowing), a UR-class arm (0.03 mm, 0.003 deg), 30 views tilted up to 35 deg, the
centre on the sensor's −y side. ``sphere_sszn``: a FANUC-like cell, a 40 mm-radius ball
scanned by an SSZN-class profiler with its measured local noise and smooth shape error,
short gaps and an x scale 0.3 % off (``sszn_fanuc`` in
:mod:`~linelaser_calib.sim.sensor_models`; 0.05 mm pitch, dense profiles), robot σ
0.03 mm and 0.005 deg, 20 views tilted up to 20 deg, the centre 20-30 mm beyond the middle
of the range, the laser plane up to 0.5 R from the centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    invert_transform,
    matrix_from_rotvec,
    quaternion_xyzw_from_matrix,
    transform_from_rotation_translation,
)
from linelaser_calib.core.types import BoolArray, FloatArray
from linelaser_calib.sim.presets import PRESETS, rig_scene_from_preset
from linelaser_calib.sim.profiler import Trace, ray_directions, returns_seen
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import T_MIN_M, Int8Array, Int64Array, Surface
from linelaser_calib.sim.sensor_models import PROFILERS, profiler_fields
from linelaser_calib.sim.simulate import RigSimulatedData, step_and_shoot

Vec3 = tuple[float, float, float]

#: Draws per view before giving up.
MAX_DRAWS_PER_VIEW = 200


@dataclass(frozen=True)
class SphereScenario:
    """Every parameter of one simulated sphere run (see the module docstring).

    Attributes
    ----------
    name : str
    rig : Scenario
        Profiler, true hand-eye, robot errors, motion timing, topics and frames.
    centre_m : (3,) floats
        Sphere centre, base frame, m.
    radius_m : float
        Sphere radius, m.
    table_gap_m : float
        Distance from the sphere's lowest point down to the table plane, m (0: no table).
    centre_side : int
        +1 or −1: the sensor y side of the laser plane the centre lies on.
    tilt_rad : float
        Largest tilt of the viewing axis from straight down, rad.
    offset_range : (2,) floats
        Range of h / R (the plane's distance from the centre over the radius), in [0, 1).
    depth_range_m : (2,) floats
        Range of the sphere centre's depth (sensor z), m.
    lateral_fraction : float
        Largest |x| of the centre as a share of the half fan width at its depth.
    min_arc_points : int
        Fewest noise-free sphere returns within the range for a view to be used.
    """

    name: str = "custom"
    rig: Scenario = field(default_factory=Scenario)
    centre_m: Vec3 = (0.5, 0.1, 0.1)
    radius_m: float = 0.0254
    table_gap_m: float = 0.03
    centre_side: int = -1
    tilt_rad: float = math.radians(35.0)
    offset_range: tuple[float, float] = (0.05, 0.8)
    depth_range_m: tuple[float, float] = (0.11, 0.13)
    lateral_fraction: float = 0.3
    min_arc_points: int = 60

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, list):
                object.__setattr__(self, f.name, tuple(float(v) for v in value))
        self._validate()

    def _validate(self) -> None:
        def require(ok: bool, what: str) -> None:
            if not ok:
                raise InputError(f"sphere scenario {self.name!r}: {what}")

        c = np.asarray(self.centre_m, dtype=np.float64)
        require(c.shape == (3,) and bool(np.all(np.isfinite(c))), "centre_m must be 3 numbers")
        require(self.radius_m > 0.0, f"radius_m must be > 0, got {self.radius_m}")
        require(self.table_gap_m >= 0.0, f"table_gap_m must be >= 0, got {self.table_gap_m}")
        require(self.centre_side in (1, -1), f"centre_side must be 1 or -1, got {self.centre_side}")
        require(0.0 <= self.tilt_rad < math.pi / 2, "tilt_rad must be in [0, pi/2) rad")
        lo, hi = self.offset_range
        require(0.0 <= lo <= hi < 1.0, "offset_range must satisfy 0 <= low <= high < 1")
        dlo, dhi = self.depth_range_m
        require(0.0 < dlo <= dhi, "depth_range_m must satisfy 0 < low <= high")
        require(0.0 <= self.lateral_fraction < 1.0, "lateral_fraction must be in [0, 1)")
        require(self.min_arc_points >= 3, "min_arc_points must be >= 3")
        require(self.rig.motion == "step", "the rig's motion must be 'step' (step-and-shoot)")

    @property
    def centre(self) -> FloatArray:
        """The true sphere centre, shape (3,), m."""
        return np.asarray(self.centre_m, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Ball:
    """A sphere and an optional table plane (normal +z), ready for ray casting.

    Attributes
    ----------
    centre : ndarray, shape (3,)
        m.
    radius_m : float
    table_z_m : float or None
        Height of the table plane, m (None: no table).
    """

    centre: FloatArray
    radius_m: float
    table_z_m: float | None

    @classmethod
    def from_scenario(cls, scenario: SphereScenario) -> Ball:
        """The ball of a sphere scenario."""
        table = None
        if scenario.table_gap_m > 0.0:
            table = float(scenario.centre[2] - scenario.radius_m - scenario.table_gap_m)
        return cls(scenario.centre.copy(), scenario.radius_m, table)

    def cast(
        self, origin: FloatArray, rays: FloatArray, t_min: float = T_MIN_M
    ) -> tuple[FloatArray, Int8Array]:
        """Nearest hit of each ray ``origin + t · rays`` with ``t > t_min``.

        Returns the ray parameter (inf: none) and the :class:`Surface` hit: ``SIDE`` for the
        sphere (the target), ``BACKGROUND`` for the table.
        """
        w = origin - self.centre
        a = np.sum(rays * rays, axis=-1)
        b = np.sum(w * rays, axis=-1)
        c = np.sum(w * w, axis=-1) - self.radius_m**2
        disc = b * b - a * c
        ok = disc >= 0.0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        near, far = (-b - sq) / a, (-b + sq) / a
        t_ball = np.where(ok & (near > t_min), near, np.where(ok & (far > t_min), far, np.inf))
        t_table = np.full(t_ball.shape, np.inf)
        if self.table_z_m is not None:
            rz = rays[..., 2]
            safe = np.where(np.abs(rz) > 1e-18, rz, 1.0)
            t = np.where(np.abs(rz) > 1e-18, (self.table_z_m - origin[..., 2]) / safe, np.inf)
            t_table = np.where(t > t_min, t, np.inf)
        t = np.minimum(t_ball, t_table)
        surface = np.where(
            np.isinf(t), Surface.NONE, np.where(t_ball <= t_table, Surface.SIDE, Surface.BACKGROUND)
        ).astype(np.int8)
        return t, surface

    def normals(self, points: FloatArray, surface: Int8Array) -> FloatArray:
        """Outward unit normals (..., 3) at hits (NaN where nothing was hit)."""
        radial = (points - self.centre) / self.radius_m
        up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), points.shape)
        s = surface[..., None]
        out = np.where(s == Surface.SIDE, radial, np.nan)
        return np.asarray(np.where(s == Surface.BACKGROUND, up, out))

    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance (...,) of points from the ball and the table (negative inside), m."""
        to_ball = np.linalg.norm(points - self.centre, axis=-1) - self.radius_m
        if self.table_z_m is None:
            return np.asarray(to_ball)
        return np.asarray(np.minimum(to_ball, points[..., 2] - self.table_z_m))


def trace_ball(ball: Ball, rig: Scenario, T_base_sensor: FloatArray) -> Trace:
    """Cast the fan of every sensor pose (K, 4, 4) at the ball and table, without noise.

    A return needs a front-facing surface, an incidence within the rig's
    ``max_incidence_rad`` and, with a camera baseline, a clear line of sight to the camera
    at sensor (0, baseline, 0).
    """
    dirs = ray_directions(rig)
    origin = T_base_sensor[:, None, :3, 3]
    rays = np.einsum("kij,nj->kni", T_base_sensor[:, :3, :3], dirs)
    t, surface = ball.cast(origin, rays)
    hit = np.isfinite(t)
    t_hit = np.where(hit, t, 0.0)
    points = origin + t_hit[..., None] * rays
    normals = ball.normals(points, surface)
    cos_inc, seen = returns_seen(
        rig, T_base_sensor, rays, points, normals, hit, lambda o, r: ball.cast(o, r, 1e-6)[0]
    )
    return Trace(
        surface=surface,
        points_sensor=np.where(hit[..., None], t_hit[..., None] * dirs, np.nan),
        normals_base=normals,
        cos_incidence=cos_inc,
        seen=seen,
        side_occluded=np.zeros(hit.shape, dtype=np.bool_),
    )


def _arc_points(ball: Ball, rig: Scenario, T_base_sensor: FloatArray) -> Int64Array:
    """Seen sphere returns within the range per pose (K,), noise-free."""
    traced = trace_ball(ball, rig, T_base_sensor)
    z = traced.points_sensor[..., 2]
    with np.errstate(invalid="ignore"):
        usable = (
            traced.seen & (traced.surface == Surface.SIDE) & (z >= rig.z_min_m) & (z <= rig.z_max_m)
        )
    return np.asarray(np.sum(usable, axis=1))


def sphere_views(scenario: SphereScenario, ball: Ball, rng: np.random.Generator) -> FloatArray:
    """Sensor poses (M, 4, 4) of the view pattern (see the module docstring)."""
    rig = scenario.rig
    views: list[FloatArray] = []
    draws = 0
    # Straight down: sensor z = -base z; the line's direction is drawn per view.
    down = np.diag([1.0, -1.0, -1.0])
    while len(views) < rig.n_poses:
        draws += 1
        if draws > MAX_DRAWS_PER_VIEW * rig.n_poses:
            raise InputError(
                f"sphere scenario {scenario.name!r}: only {len(views)} of {rig.n_poses} views "
                "show the ball; reduce tilt_rad or offset_range, or widen the profiler's range "
                "or fan"
            )
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        tilt = rng.uniform(0.0, scenario.tilt_rad)
        spin = rng.uniform(-0.5 * math.pi, 0.5 * math.pi)
        R = (
            matrix_from_rotvec(tilt * np.array([math.cos(azimuth), math.sin(azimuth), 0.0]))
            @ down
            @ matrix_from_rotvec([0.0, 0.0, spin])
        )
        depth = rng.uniform(*scenario.depth_range_m)
        h = rng.uniform(*scenario.offset_range) * scenario.radius_m
        x = (
            rng.uniform(-1.0, 1.0)
            * scenario.lateral_fraction
            * depth
            * math.tan(rig.fan_half_angle_rad)
        )
        seen_at = np.array([x, scenario.centre_side * h, depth])
        T = transform_from_rotation_translation(R, ball.centre - R @ seen_at)
        T_flange = T @ invert_transform(rig.T_flange_sensor)
        clear = (
            min(float(ball.clearance(T[:3, 3])), float(ball.clearance(T_flange[:3, 3])))
            >= rig.clearance_m
        )
        if clear and int(_arc_points(ball, rig, T[None])[0]) >= scenario.min_arc_points:
            views.append(T)
    return np.stack(views)


@dataclass(frozen=True, eq=False)
class SphereTruth:
    """Ground truth of a simulated sphere run (K profiles of N rays each).

    Attributes
    ----------
    scenario : SphereScenario
    seed : int
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    centre_m : ndarray, shape (3,)
        The true sphere centre, base frame, m.
    radius_m : float
    centre_side : int
        +1 or −1.
    T_base_flange_true, T_base_flange_recorded : ndarray, shape (K, 4, 4)
        True and reported (without jitter) flange poses at the acquisition times.
    stamps_ns, acquisition_stamps_ns : ndarray of int64, shape (K,)
    T_base_sensor_waypoints : ndarray, shape (K, 4, 4)
    centre_sensor : ndarray, shape (K, 3)
        The sphere centre seen from each true sensor pose, m (its y is ± h).
    surface : ndarray of int8, shape (K, N)
    points_true_sensor : ndarray, shape (K, N, 3)
    valid, spike, dropout : ndarray of bool, shape (K, N)
    """

    scenario: SphereScenario
    seed: int
    T_flange_sensor: FloatArray
    centre_m: FloatArray
    radius_m: float
    centre_side: int
    T_base_flange_true: FloatArray
    T_base_flange_recorded: FloatArray
    stamps_ns: Int64Array
    acquisition_stamps_ns: Int64Array
    T_base_sensor_waypoints: FloatArray
    centre_sensor: FloatArray
    surface: Int8Array
    points_true_sensor: FloatArray
    valid: BoolArray
    spike: BoolArray
    dropout: BoolArray


#: Everything a sphere run produces.
SphereSimulatedData = RigSimulatedData[SphereTruth]


def simulate_sphere(scenario: SphereScenario, seed: int) -> SphereSimulatedData:
    """Simulate a sphere run; deterministic for a given scenario and seed.

    Raises
    ------
    InputError
        If too few views show the ball.
    """
    rng = np.random.default_rng(seed)
    rig = scenario.rig
    ball = Ball.from_scenario(scenario)
    views = sphere_views(scenario, ball, rng)
    run = step_and_shoot(rng, rig, views, lambda T: trace_ball(ball, rig, T))
    T = run.T_base_sensor
    truth = SphereTruth(
        scenario=scenario,
        seed=seed,
        T_flange_sensor=rig.T_flange_sensor,
        centre_m=ball.centre.copy(),
        radius_m=scenario.radius_m,
        centre_side=scenario.centre_side,
        T_base_flange_true=run.T_base_flange_true,
        T_base_flange_recorded=run.T_base_flange_recorded,
        stamps_ns=run.stamps_ns,
        acquisition_stamps_ns=rig.epoch_ns + run.acquisition_ns,
        T_base_sensor_waypoints=views,
        centre_sensor=np.einsum("kji,kj->ki", T[:, :3, :3], ball.centre - T[:, :3, 3]),
        surface=run.traced.surface,
        points_true_sensor=run.traced.points_sensor,
        valid=run.measured.valid,
        spike=run.measured.spike,
        dropout=run.measured.dropout,
    )
    return SphereSimulatedData(run.profiles, run.intensities, run.poses, truth)


def _sphere_rig() -> Scenario:
    """The ``ur_scancontrol`` profiler and arm with the sensor on another bracket."""
    R = Rotation.from_euler("xyz", [math.radians(10.0), math.radians(-6.0), math.radians(-80.0)])
    q = quaternion_xyzw_from_matrix(R.as_matrix())
    return replace(
        PRESETS["ur_scancontrol"],
        name="sphere",
        hand_eye_translation_m=(-0.02, 0.07, 0.10),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        spike_fraction=0.003,
        dropout_fraction=0.01,
        clearance_m=0.02,
    )


def _sphere_sszn() -> SphereScenario:
    """A FANUC-like cell with an SSZN-class profiler (``sszn_fanuc``) and a 40 mm-radius ball."""
    R = Rotation.from_euler("xyz", [math.radians(-8.0), math.radians(5.0), math.radians(90.0)])
    q = quaternion_xyzw_from_matrix(R.as_matrix())
    spec = PROFILERS["sszn_fanuc"]
    rig = replace(
        _sphere_rig(),
        name="sphere_sszn",
        **profiler_fields(spec),
        hand_eye_translation_m=(0.05, -0.03, 0.09),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        spike_fraction=0.0,
        dropout_fraction=0.0,
        camera_baseline_m=0.0,
        intensity=False,
        organised=False,
        n_poses=20,
        robot_sigma_translation_m=3e-5,
        robot_sigma_rotation_rad=math.radians(0.005),
    )
    middle = 0.5 * (rig.z_min_m + rig.z_max_m)
    return SphereScenario(
        name="sphere_sszn",
        rig=rig,
        radius_m=0.040,
        centre_side=-1,
        tilt_rad=math.radians(20.0),
        offset_range=(0.05, 0.5),
        depth_range_m=(middle + 0.02, middle + 0.03),
        lateral_fraction=0.1,
        min_arc_points=500,
    )


#: Named sphere scenarios; see the module docstring and :func:`sphere_scenario_from_preset`.
SPHERE_PRESETS: dict[str, SphereScenario] = {
    "sphere": SphereScenario(name="sphere", rig=_sphere_rig()),
    "sphere_sszn": _sphere_sszn(),
}


def sphere_scenario_from_preset(name: str, **overrides: Any) -> SphereScenario:
    """A sphere preset with fields replaced; rig (:class:`Scenario`) fields are accepted too.

    Raises
    ------
    InputError
        For an unknown preset or field, or an invalid value.
    """
    return rig_scene_from_preset(SPHERE_PRESETS, name, "sphere", overrides)
