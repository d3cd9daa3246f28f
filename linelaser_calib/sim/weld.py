"""Weld-seam scenes: a V-groove or fillet joint scanned through one taught point.

The target (``v_groove``) is two half-planes (the flanks) meeting along a straight seam; the
laser plane crosses the seam, so every profile is a V whose corner is the seam point in the
plane. The user has taught the weld point (a point on the seam) with the tool tip and scans
it from several flange poses, each aimed so that the laser line passes through it (weld-seam
paper §2.3).

:class:`WeldScenario` holds the weld geometry and the view pattern and, in its ``rig`` field,
an ordinary :class:`~linelaser_calib.sim.scenario.Scenario` for everything else: profiler
(fan, range, noise, spikes, dropouts, incidence gate, camera shadowing, intensity,
organised output), the true hand-eye, the robot's error model and motion timing, topics and
frames. The rig's cylinder, background and pose-sampler fields are not used; its
``n_poses`` is the number of views and its motion must be ``step``.

Geometry (base frame): seam through the weld point p along the unit s; the unit bisector b
(perpendicular to s) points out of the groove into the free space; with m = s × b, flank
k = 1, 2 runs from the seam along f = cos(φ/2) b ± sin(φ/2) m for ``flank_width_m`` (φ the
opening angle: 90 deg for a fillet joint, 60-120 deg for V-grooves) and along the seam for
± ``seam_half_length_m``. Its normal faces the free side, inside the V.

Views (``pose_pattern``):

``paper``
    The paper's eq. 6: one orientation for every view, stepping by ``step_m`` along
    ``step_direction`` (base z), with the position corrected along the laser plane's normal
    so that the plane keeps passing through p (the paper's x_i, y_i), and optionally moved
    sideways along the laser line by up to ± ``lateral_spread_m`` (0 in the paper: then the
    point moves through the sensor along one line). The orientation is the nominal view
    (sensor z against b, laser plane perpendicular to the seam) turned by
    ``view_rotvec_rad`` about the sensor axes.
``general``
    Each view tilts the nominal view's axis by up to ``general_tilt_rad`` in a random
    direction and turns the laser plane about the viewing axis by up to
    ± ``general_yaw_rad``; the weld point's depth is drawn from ``general_depth_range_m`` and
    its offset along the line from ± ``general_lateral_fraction`` of the half fan width.
    Views whose profile does not show both flanks with ``min_flank_points`` returns each, or
    whose sensor or flange is within the rig's ``clearance_m`` of a flank plane, are drawn
    again.

Errors: the robot's (reported = true · E_sys · E per view, exactly the rig's model of
:mod:`linelaser_calib.sim.robot`); the aim (the true laser plane misses p by a Gaussian
``aim_sigma_m`` along its normal, so the corner is a nearby seam point); the teaching (the
taught point is p plus Gaussian ``teach_sigma_m`` per axis); and the profiler noise.

Presets (:data:`WELD_PRESETS`): ``weld_seam`` (the paper's pattern) and ``weld_seam_general``.
Both use a scanCONTROL-class profiler (70-150 mm, ±25 deg, 640 points), a 20-view program and
a PR1400-class robot: 0.05 mm per axis (the paper's ±0.05 mm repeatability taken as 1σ, on
the safe side) and 0.002 deg per axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    invert_transform,
    matrix_from_rotvec,
    quaternion_xyzw_from_matrix,
    transform_from_rotation_translation,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.types import BoolArray, FloatArray
from linelaser_calib.sim.presets import rig_scene_from_preset
from linelaser_calib.sim.profiler import Trace, ray_directions
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import T_MIN_M, Int8Array, Int64Array, Surface
from linelaser_calib.sim.simulate import RigSimulatedData, step_and_shoot

Vec3 = tuple[float, float, float]

#: Accepted values of :attr:`WeldScenario.pose_pattern`.
POSE_PATTERNS = ("paper", "general")
#: Draws per view in the ``general`` pattern before giving up.
MAX_DRAWS_PER_VIEW = 200
#: Share of the half fan width and of the measuring range kept free around the weld point in
#: the ``paper`` pattern's range check.
_FAN_MARGIN = 0.8
_RANGE_MARGIN_M = 0.003


def _unit(v: Any) -> FloatArray:
    a = np.asarray(v, dtype=np.float64)
    return np.asarray(a / np.linalg.norm(a))


class GrooveScene:
    """Checks shared by the groove scenes (:class:`WeldScenario`, the line scenes).

    A scene dataclass derives from this class, names its 3-vector fields in ``vectors`` and
    the ones that must not be zero in ``directions``, and extends :meth:`__post_init__` with
    its own checks through :meth:`require`. Lists given for tuple fields (as YAML readers
    produce them) become tuples of floats.
    """

    kind: ClassVar[str]
    vectors: ClassVar[tuple[str, ...]]
    directions: ClassVar[tuple[str, ...]]
    name: str
    seam_direction: Vec3
    groove_bisector: Vec3
    opening_angle_rad: float
    flank_width_m: float
    seam_half_length_m: float
    min_flank_points: int

    def require(self, ok: bool, what: str) -> None:
        """Raise InputError naming the scene when ``ok`` is false."""
        if not ok:
            raise InputError(f"{self.kind} scenario {self.name!r}: {what}")

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if isinstance(value, list):
                object.__setattr__(self, f.name, tuple(float(v) for v in value))
        for name in self.vectors:
            v = np.asarray(getattr(self, name), dtype=np.float64)
            self.require(
                v.shape == (3,) and bool(np.all(np.isfinite(v))), f"{name} must be 3 numbers"
            )
        for name in self.directions:
            self.require(
                float(np.linalg.norm(getattr(self, name))) > 1e-12, f"{name} must not be zero"
            )
        s, b = _unit(self.seam_direction), _unit(self.groove_bisector)
        self.require(
            abs(float(s @ b)) < math.cos(math.radians(10.0)),
            "groove_bisector must not be (nearly) parallel to seam_direction",
        )
        self.require(
            0.0 < self.opening_angle_rad < math.pi, "opening_angle_rad must be in (0, pi) rad"
        )
        for name in ("flank_width_m", "seam_half_length_m"):
            self.require(
                getattr(self, name) > 0.0, f"{name} must be > 0, got {getattr(self, name)}"
            )
        self.require(self.min_flank_points >= 2, "min_flank_points must be >= 2")


@dataclass(frozen=True)
class GrooveShape:
    """How a groove departs from a symmetric V of two equal flanks (SI units).

    Attributes
    ----------
    ridge : bool
        The flanks run from the seam away from the sensor's side (a ridge on a block, seen
        from outside) instead of towards it.
    turn_rad : float
        Both flanks turned about the seam by this angle, rad (an asymmetric V: one flank
        gentle, the other steep).
    second_flank_width_m : float
        Width of the second flank, m; 0: the first's.
    floor_width_m : float
        Width of a floor (perpendicular to the bisector, away from the first flank) from the
        second flank's far edge, m; 0: none.
    """

    ridge: bool = False
    turn_rad: float = 0.0
    second_flank_width_m: float = 0.0
    floor_width_m: float = 0.0


@dataclass(frozen=True)
class WeldScenario(GrooveScene):
    """Every parameter of one simulated weld-seam run (see the module docstring).

    Attributes
    ----------
    name : str
    rig : Scenario
        Profiler, true hand-eye, robot errors, motion timing, topics and frames.
    weld_point_m : (3,) floats
        The weld point p on the seam, base frame, m.
    seam_direction : (3,) floats
        Seam direction (normalised on use).
    groove_bisector : (3,) floats
        Out of the groove into the free space (made perpendicular to the seam, normalised).
    opening_angle_rad : float
        Angle between the flanks, rad, in (0, π).
    flank_width_m : float
        Extent of each flank from the seam, m.
    seam_half_length_m : float
        The flanks end this far from p along the seam, m.
    pose_pattern : str
        ``paper`` or ``general``.
    view_rotvec_rad : (3,) floats
        Rotation of the nominal view about the sensor axes, rad (paper: every view; general:
        the centre of the tilts).
    first_depth_m : float
        Paper pattern: depth (sensor z) of the weld point in the first view, m.
    step_m : float
        Paper pattern: the step Δz between views, m.
    step_direction : (3,) floats
        Paper pattern: the stepping direction in the base frame (normalised on use).
    lateral_spread_m : float
        Paper pattern: sideways moves along the laser line, uniform in ± this, m.
    general_tilt_rad, general_yaw_rad : float
        General pattern: largest tilt of the viewing axis and turn of the laser plane, rad.
    general_depth_range_m : (2,) floats
        General pattern: depth of the weld point, m.
    general_lateral_fraction : float
        General pattern: largest |x| of the weld point as a share of the half fan width.
    aim_sigma_m : float
        1σ distance of the true laser plane from p along its normal, m.
    teach_sigma_m : float
        1σ per axis of the taught point's error, m.
    min_flank_points : int
        Fewest noise-free returns on each flank for a view to be used.
    floor_width_m : float
        A floor this wide beyond the second flank's far edge, m (a third straight segment in
        the profiles that reach it); 0: none.
    """

    name: str = "custom"
    rig: Scenario = field(default_factory=Scenario)
    weld_point_m: Vec3 = (0.55, 0.10, 0.02)
    seam_direction: Vec3 = (0.3, 1.0, 0.0)
    groove_bisector: Vec3 = (0.0, 0.0, 1.0)
    opening_angle_rad: float = math.radians(90.0)
    flank_width_m: float = 0.03
    seam_half_length_m: float = 0.1
    pose_pattern: str = "paper"
    view_rotvec_rad: Vec3 = (0.06, -0.10, 0.15)
    first_depth_m: float = 0.085
    step_m: float = 0.0025
    step_direction: Vec3 = (0.0, 0.0, 1.0)
    lateral_spread_m: float = 0.0
    general_tilt_rad: float = math.radians(25.0)
    general_yaw_rad: float = math.radians(30.0)
    general_depth_range_m: tuple[float, float] = (0.08, 0.14)
    general_lateral_fraction: float = 0.4
    aim_sigma_m: float = 0.0
    teach_sigma_m: float = 0.0
    min_flank_points: int = 40
    floor_width_m: float = 0.0

    kind: ClassVar[str] = "weld"
    vectors: ClassVar[tuple[str, ...]] = (
        "weld_point_m",
        "seam_direction",
        "groove_bisector",
        "view_rotvec_rad",
    )
    directions: ClassVar[tuple[str, ...]] = ("seam_direction", "groove_bisector", "step_direction")

    def __post_init__(self) -> None:
        super().__post_init__()
        require = self.require
        require(self.first_depth_m > 0.0, f"first_depth_m must be > 0, got {self.first_depth_m}")
        for name in ("step_m", "lateral_spread_m", "aim_sigma_m", "teach_sigma_m", "floor_width_m"):
            require(getattr(self, name) >= 0.0, f"{name} must be >= 0, got {getattr(self, name)}")
        require(self.pose_pattern in POSE_PATTERNS, f"pose_pattern must be one of {POSE_PATTERNS}")
        require(
            0.0 <= self.general_tilt_rad < math.pi / 2
            and 0.0 <= self.general_yaw_rad < math.pi / 2,
            "general_tilt_rad and general_yaw_rad must be in [0, pi/2) rad",
        )
        lo, hi = self.general_depth_range_m
        require(0.0 < lo <= hi, "general_depth_range_m must satisfy 0 < low <= high")
        require(
            0.0 <= self.general_lateral_fraction < 1.0,
            "general_lateral_fraction must be in [0, 1)",
        )
        require(self.rig.motion == "step", "the rig's motion must be 'step' (step-and-shoot)")

    @property
    def weld_point(self) -> FloatArray:
        """The true weld point p, shape (3,), m."""
        return np.asarray(self.weld_point_m, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Groove:
    """The V-groove (or ridge) geometry in the base frame, ready for ray casting.

    Its faces are strips: the two flanks from the seam, and optionally a floor from the far
    edge of the second flank.

    Attributes
    ----------
    point : ndarray, shape (3,)
        Weld point p, m.
    seam : ndarray, shape (3,)
        Unit seam direction s.
    bisector : ndarray, shape (3,)
        Unit b, perpendicular to s, towards the free side (the sensor's side).
    origins : ndarray, shape (P, 3)
        Where each face starts (p for the flanks), m.
    flanks : ndarray, shape (P, 3)
        Unit direction of each face from its origin, across the seam.
    normals : ndarray, shape (P, 3)
        Unit normal of each face, facing the free side.
    widths : ndarray, shape (P,)
        Extent of each face across the seam, m.
    half_length_m : float
    ridge : bool
        The flanks run away from the free side (a ridge, convex) rather than towards it.
    """

    point: FloatArray
    seam: FloatArray
    bisector: FloatArray
    origins: FloatArray
    flanks: FloatArray
    normals: FloatArray
    widths: FloatArray
    half_length_m: float
    ridge: bool = False

    @classmethod
    def build(
        cls,
        point: Any,
        seam_direction: Any,
        groove_bisector: Any,
        opening_angle_rad: float,
        flank_width_m: float,
        seam_half_length_m: float,
        shape: GrooveShape | None = None,
    ) -> Groove:
        """A groove through ``point`` (m) along ``seam_direction``, opening towards
        ``groove_bisector`` (made perpendicular to the seam) by ``opening_angle_rad``; a
        ``shape`` makes it a ridge, turns it, sets the second flank's width or adds a floor.
        """
        shape = shape or GrooveShape()
        s = _unit(seam_direction)
        b = _unit(np.asarray(groove_bisector) - (s @ np.asarray(groove_bisector)) * s)
        m = np.cross(s, b)
        centre = (math.pi if shape.ridge else 0.0) + shape.turn_rad
        angles = [centre + sign * 0.5 * opening_angle_rad for sign in (1.0, -1.0)]
        flanks = np.array([math.cos(a) * b + math.sin(a) * m for a in angles])
        widths = [flank_width_m, shape.second_flank_width_m or flank_width_m]
        origins = np.tile(np.asarray(point, dtype=np.float64), (2, 1))
        if shape.floor_width_m > 0.0:
            away = math.copysign(1.0, float(flanks[1] @ m)) * m
            origins = np.vstack([origins, origins[1] + widths[1] * flanks[1]])
            flanks = np.vstack([flanks, away])
            widths.append(shape.floor_width_m)
        # Face the free side: the bisector's part perpendicular to each face.
        normals = np.cross(s, flanks)
        inward = b - np.einsum("ki,i->k", flanks, b)[:, None] * flanks
        normals *= np.sign(np.einsum("ki,ki->k", normals, inward))[:, None]
        return cls(
            np.asarray(point, dtype=np.float64).copy(),
            s,
            b,
            origins,
            flanks,
            normals / np.linalg.norm(normals, axis=1, keepdims=True),
            np.asarray(widths, dtype=np.float64),
            seam_half_length_m,
            shape.ridge,
        )

    @classmethod
    def from_scenario(cls, scenario: WeldScenario) -> Groove:
        """The groove of a weld scenario."""
        return cls.build(
            scenario.weld_point,
            scenario.seam_direction,
            scenario.groove_bisector,
            scenario.opening_angle_rad,
            scenario.flank_width_m,
            scenario.seam_half_length_m,
            GrooveShape(floor_width_m=scenario.floor_width_m),
        )

    def cast(
        self, origin: FloatArray, rays: FloatArray, t_min: float = T_MIN_M
    ) -> tuple[FloatArray, Int8Array]:
        """Nearest face hit of each ray ``origin + t · rays`` with ``t > t_min``.

        Parameters
        ----------
        origin, rays : ndarray, shape (..., 3)
            Broadcasting against each other.

        Returns
        -------
        t : ndarray, shape (...)
            Ray parameter of the nearest hit (inf: none).
        flank : ndarray of int8, shape (...)
            1 or 2 for the flank hit, 3 for the floor, 0 for none.
        """
        best = np.full(np.broadcast_shapes(origin.shape, rays.shape)[:-1], np.inf)
        flank = np.zeros(best.shape, dtype=np.int8)
        for k in range(len(self.flanks)):
            n = self.normals[k]
            denom = rays @ n
            ok = np.abs(denom) > 1e-18
            t = np.where(ok, ((self.origins[k] - origin) @ n) / np.where(ok, denom, 1.0), np.inf)
            hit = origin + np.where(np.isfinite(t), t, 0.0)[..., None] * rays - self.origins[k]
            across = hit @ self.flanks[k]
            along = (hit + self.origins[k] - self.point) @ self.seam
            inside = (
                (across >= 0.0) & (across <= self.widths[k]) & (np.abs(along) <= self.half_length_m)
            )
            take = ok & (t > t_min) & inside & (t < best)
            best = np.where(take, t, best)
            flank = np.where(take, np.int8(k + 1), flank)
        return best, flank

    def free_clearance(self, points: FloatArray) -> FloatArray:
        """Signed distance (...,) of points from the solid, positive in the air (the nearer
        flank plane of a groove, the farther of a ridge; above a floor too)."""
        flanks = (points - self.point) @ self.normals[:2].T
        clear = np.max(flanks, axis=-1) if self.ridge else np.min(flanks, axis=-1)
        if len(self.normals) > 2:
            clear = np.minimum(clear, (points - self.origins[2]) @ self.normals[2])
        return np.asarray(clear)

    def seam_point_in_plane(self, T_base_sensor: FloatArray) -> FloatArray:
        """Where each sensor's laser plane (y = 0) meets the seam line, base frame (K, 3), m."""
        y = T_base_sensor[:, :3, 1]
        lam = np.einsum("ki,ki->k", y, T_base_sensor[:, :3, 3] - self.point) / (y @ self.seam)
        return np.asarray(self.point + lam[:, None] * self.seam)


def trace_groove(
    groove: Groove, rig: Scenario, T_base_sensor: FloatArray
) -> tuple[Trace, Int8Array]:
    """Cast the fan of every sensor pose (K, 4, 4) at the groove, without noise.

    Returns the simulator's :class:`~linelaser_calib.sim.profiler.Trace` and the flank hit by
    each ray (K, N) (1, 2; 0 for none). In the trace, flank hits are labelled
    :attr:`Surface.SIDE` (the target, so that :func:`measure` gives them the rig's
    ``cylinder_reflectance``), misses :attr:`Surface.NONE`. A return needs a front-facing
    flank, an incidence within the rig's ``max_incidence_rad`` and, with a camera baseline,
    a clear line of sight to the camera at sensor (0, baseline, 0).
    """
    dirs = ray_directions(rig)
    R = T_base_sensor[:, :3, :3]
    origin = T_base_sensor[:, None, :3, 3]
    rays = np.einsum("kij,nj->kni", R, dirs)
    t, flank = groove.cast(origin, rays)
    hit = np.isfinite(t)
    t_hit = np.where(hit, t, 0.0)
    points = origin + t_hit[..., None] * rays
    normals = np.where(hit[..., None], groove.normals[np.maximum(flank - 1, 0)], np.nan)
    cos_inc = np.where(hit, -np.sum(rays * np.nan_to_num(normals), axis=-1), np.nan)
    with np.errstate(invalid="ignore"):
        seen = hit & (cos_inc > 0.0) & (cos_inc >= math.cos(rig.max_incidence_rad) - 1e-12)
    if rig.camera_baseline_m > 0.0:
        camera = origin + rig.camera_baseline_m * R[:, None, :, 1]
        to_camera = camera - points
        faces = np.sum(np.nan_to_num(normals) * to_camera, axis=-1) > 0.0
        t_block, _ = groove.cast(points, to_camera, 1e-6)
        seen &= faces & (t_block >= 1.0 - 1e-6)
    surface = np.where(hit, Surface.SIDE, Surface.NONE).astype(np.int8)
    traced = Trace(
        surface=surface,
        points_sensor=np.where(hit[..., None], t_hit[..., None] * dirs, np.nan),
        normals_base=normals,
        cos_incidence=cos_inc,
        seen=seen,
        side_occluded=np.zeros(hit.shape, dtype=np.bool_),
    )
    return traced, flank


def flank_counts(groove: Groove, rig: Scenario, T_base_sensor: FloatArray) -> Int64Array:
    """Seen returns within the range on each flank per pose, shape (K, 2), noise-free."""
    traced, flank = trace_groove(groove, rig, T_base_sensor)
    z = traced.points_sensor[..., 2]
    with np.errstate(invalid="ignore"):
        usable = traced.seen & (z >= rig.z_min_m) & (z <= rig.z_max_m)
    return np.stack([np.sum(usable & (flank == k), axis=1) for k in (1, 2)], axis=1)


def nominal_view(groove: Groove) -> FloatArray:
    """Sensor orientation (3, 3) looking into the groove across the seam.

    Sensor z = −b (looking into the groove), y = s (laser plane across the seam).
    """
    z, y = -groove.bisector, groove.seam
    return np.column_stack([np.cross(y, z), y, z])


def nominal_orientation(scenario: WeldScenario, groove: Groove) -> FloatArray:
    """Sensor orientation (3, 3) of the :func:`nominal_view` turned by ``view_rotvec_rad``."""
    return np.asarray(nominal_view(groove) @ matrix_from_rotvec(scenario.view_rotvec_rad))


def _pose(R: FloatArray, point_in_sensor: FloatArray, point: FloatArray) -> FloatArray:
    """Sensor pose with orientation R that sees ``point`` at ``point_in_sensor``."""
    return transform_from_rotation_translation(R, point - R @ point_in_sensor)


def _views_ok(
    scenario: WeldScenario, groove: Groove, T_base_sensor: FloatArray
) -> tuple[BoolArray, list[str]]:
    """Which views show both flanks and keep sensor and flange clear of the plates."""
    rig = scenario.rig
    counts = flank_counts(groove, rig, T_base_sensor)
    T_base_flange = T_base_sensor @ invert_transform(rig.T_flange_sensor)
    clear_sensor = groove.free_clearance(T_base_sensor[:, :3, 3]) >= rig.clearance_m
    clear_flange = groove.free_clearance(T_base_flange[:, :3, 3]) >= rig.clearance_m
    ok = (counts.min(axis=1) >= scenario.min_flank_points) & clear_sensor & clear_flange
    reasons = [
        f"view {k}: {counts[k, 0]} and {counts[k, 1]} returns on the flanks "
        f"(need {scenario.min_flank_points}), sensor clear {bool(clear_sensor[k])}, "
        f"flange clear {bool(clear_flange[k])}"
        for k in np.flatnonzero(~ok)
    ]
    return ok, reasons


def paper_views(scenario: WeldScenario, groove: Groove, rng: np.random.Generator) -> FloatArray:
    """Sensor poses (M, 4, 4) of the paper's pattern (eq. 6), true laser planes through p."""
    rig = scenario.rig
    R = nominal_orientation(scenario, groove)
    x_axis, y_axis = R[:, 0], R[:, 1]
    e = _unit(scenario.step_direction)
    correction = y_axis - float(y_axis @ e) * e
    if float(np.linalg.norm(correction)) < 1e-6:
        raise InputError(
            f"weld scenario {scenario.name!r}: the laser plane is perpendicular to the step "
            "direction, so no sideways correction keeps it on the weld point"
        )
    correction /= np.linalg.norm(correction)
    start = _pose(R, np.array([0.0, 0.0, scenario.first_depth_m]), groove.point)
    M = rig.n_poses
    i = np.arange(M, dtype=np.float64)
    step = i[:, None] * scenario.step_m * e
    # Move along the correction so that the plane (normal y) passes through p again.
    lam = -(step @ y_axis) / float(correction @ y_axis)
    lateral = rng.uniform(-1.0, 1.0, M) * scenario.lateral_spread_m
    positions = start[:3, 3] + step + lam[:, None] * correction + lateral[:, None] * x_axis
    T = np.tile(start, (M, 1, 1))
    T[:, :3, 3] = positions
    seen = np.einsum("ji,kj->ki", R, groove.point - positions)
    half_width = seen[:, 2] * math.tan(rig.fan_half_angle_rad) * _FAN_MARGIN
    in_range = (
        (seen[:, 2] >= rig.z_min_m + _RANGE_MARGIN_M)
        & (seen[:, 2] <= rig.z_max_m - _RANGE_MARGIN_M)
        & (np.abs(seen[:, 0]) <= half_width)
    )
    ok, reasons = _views_ok(scenario, groove, T)
    if not np.all(in_range & ok):
        bad = int(np.flatnonzero(~(in_range & ok))[0])
        raise InputError(
            f"weld scenario {scenario.name!r}: the paper pattern fails at view {bad}: weld point "
            f"at depth {seen[bad, 2] * 1e3:.1f} mm and x {seen[bad, 0] * 1e3:.1f} mm in the "
            f"sensor (range {rig.z_min_m * 1e3:.0f}-{rig.z_max_m * 1e3:.0f} mm); "
            + "; ".join(reasons[:2])
            + ". Reduce step_m, n_poses or lateral_spread_m, or change first_depth_m"
        )
    return T


def general_views(scenario: WeldScenario, groove: Groove, rng: np.random.Generator) -> FloatArray:
    """Sensor poses (M, 4, 4) of the general pattern, true laser planes through p."""
    rig = scenario.rig
    R0 = nominal_orientation(scenario, groove)
    views: list[FloatArray] = []
    draws = 0
    while len(views) < rig.n_poses:
        draws += 1
        if draws > MAX_DRAWS_PER_VIEW * rig.n_poses:
            raise InputError(
                f"weld scenario {scenario.name!r}: only {len(views)} of {rig.n_poses} general "
                "views show both flanks; reduce general_tilt_rad or general_yaw_rad, or widen "
                "the profiler's range or fan"
            )
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        tilt = rng.uniform(0.0, scenario.general_tilt_rad)
        yaw = rng.uniform(-scenario.general_yaw_rad, scenario.general_yaw_rad)
        R = (
            R0
            @ matrix_from_rotvec(tilt * np.array([math.cos(azimuth), math.sin(azimuth), 0.0]))
            @ matrix_from_rotvec([0.0, 0.0, yaw])
        )
        depth = rng.uniform(*scenario.general_depth_range_m)
        x = (
            rng.uniform(-1.0, 1.0)
            * scenario.general_lateral_fraction
            * depth
            * math.tan(rig.fan_half_angle_rad)
        )
        T = _pose(R, np.array([x, 0.0, depth]), groove.point)
        ok, _ = _views_ok(scenario, groove, T[None])
        if ok[0]:
            views.append(T)
    return np.stack(views)


@dataclass(frozen=True, eq=False)
class WeldTruth:
    """Ground truth of a simulated weld-seam run (K profiles of N rays each).

    Attributes
    ----------
    scenario : WeldScenario
    seed : int
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    weld_point_m : ndarray, shape (3,)
        The true weld point p, base frame, m.
    taught_point_m : ndarray, shape (3,)
        The point as taught (p plus the teaching error), m.
    seam_direction : ndarray, shape (3,)
        Unit seam direction.
    T_base_flange_true, T_base_flange_recorded : ndarray, shape (K, 4, 4)
        True and reported (without jitter) flange poses at the acquisition times.
    stamps_ns, acquisition_stamps_ns : ndarray of int64, shape (K,)
    T_base_sensor_waypoints : ndarray, shape (K, 4, 4)
        The true sensor poses of the views.
    corner_true_sensor : ndarray, shape (K, 3)
        The seam point in each true laser plane, sensor frame (y = 0), m: what a perfect
        corner extraction returns (p itself when the aim is exact).
    corner_true_base : ndarray, shape (K, 3)
        The same points in the base frame, m.
    flank : ndarray of int8, shape (K, N)
        Flank hit by each ray: 1, 2, or 0 for none.
    points_true_sensor : ndarray, shape (K, N, 3)
        Noise-free hits in the sensor frame, m (NaN: no hit).
    valid, spike, dropout : ndarray of bool, shape (K, N)
    """

    scenario: WeldScenario
    seed: int
    T_flange_sensor: FloatArray
    weld_point_m: FloatArray
    taught_point_m: FloatArray
    seam_direction: FloatArray
    T_base_flange_true: FloatArray
    T_base_flange_recorded: FloatArray
    stamps_ns: Int64Array
    acquisition_stamps_ns: Int64Array
    T_base_sensor_waypoints: FloatArray
    corner_true_sensor: FloatArray
    corner_true_base: FloatArray
    flank: Int8Array
    points_true_sensor: FloatArray
    valid: BoolArray
    spike: BoolArray
    dropout: BoolArray


#: Everything a weld-seam run produces.
WeldSimulatedData = RigSimulatedData[WeldTruth]


def simulate_weld(scenario: WeldScenario, seed: int) -> WeldSimulatedData:
    """Simulate a weld-seam run; deterministic for a given scenario and seed.

    Raises
    ------
    InputError
        If the view pattern leaves the profiler's range or fan, or too few views show both
        flanks.
    """
    rng = np.random.default_rng(seed)
    rig = scenario.rig
    groove = Groove.from_scenario(scenario)
    views = (paper_views if scenario.pose_pattern == "paper" else general_views)(
        scenario, groove, rng
    )
    views[:, :3, 3] += rng.normal(size=(len(views), 1)) * scenario.aim_sigma_m * views[:, :3, 1]
    taught = groove.point + rng.normal(size=3) * scenario.teach_sigma_m
    run = step_and_shoot(rng, rig, views, lambda T: trace_groove(groove, rig, T)[0])
    T_sensor_shot = run.T_base_sensor
    _, flank = trace_groove(groove, rig, T_sensor_shot)
    corner_base = groove.seam_point_in_plane(T_sensor_shot)
    corner_sensor = np.einsum(
        "kji,kj->ki", T_sensor_shot[:, :3, :3], corner_base - T_sensor_shot[:, :3, 3]
    )
    truth = WeldTruth(
        scenario=scenario,
        seed=seed,
        T_flange_sensor=rig.T_flange_sensor,
        weld_point_m=groove.point.copy(),
        taught_point_m=taught,
        seam_direction=groove.seam.copy(),
        T_base_flange_true=run.T_base_flange_true,
        T_base_flange_recorded=run.T_base_flange_recorded,
        stamps_ns=run.stamps_ns,
        acquisition_stamps_ns=rig.epoch_ns + run.acquisition_ns,
        T_base_sensor_waypoints=views,
        corner_true_sensor=corner_sensor,
        corner_true_base=corner_base,
        flank=flank,
        points_true_sensor=run.traced.points_sensor,
        valid=run.measured.valid,
        spike=run.measured.spike,
        dropout=run.measured.dropout,
    )
    return WeldSimulatedData(run.profiles, run.intensities, run.poses, truth)


def _weld_rig() -> Scenario:
    R = Rotation.from_euler("xyz", [math.radians(-15.0), math.radians(8.0), math.radians(92.0)])
    q = quaternion_xyzw_from_matrix(R.as_matrix())
    return Scenario(
        name="weld_seam",
        hand_eye_translation_m=(0.035, -0.060, 0.110),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        z_min_m=0.07,
        z_max_m=0.15,
        fan_half_angle_rad=math.radians(25.0),
        resolution=640,
        sigma_depth_m=8e-6,
        sigma_lateral_m=6e-6,
        spike_fraction=0.002,
        dropout_fraction=0.01,
        max_incidence_rad=math.radians(80.0),
        camera_baseline_m=0.03,
        intensity=True,
        organised=True,
        n_poses=20,
        clearance_m=0.02,
        robot_sigma_translation_m=5e-5,
        robot_sigma_rotation_rad=math.radians(0.002),
        robot_rate_hz=125.0,
        dwell_s=0.3,
    )


#: Named weld-seam scenarios; see the module docstring and :func:`weld_scenario_from_preset`.
WELD_PRESETS: dict[str, WeldScenario] = {
    "weld_seam": WeldScenario(name="weld_seam", rig=_weld_rig(), pose_pattern="paper"),
    "weld_seam_general": WeldScenario(
        name="weld_seam_general", rig=_weld_rig(), pose_pattern="general"
    ),
}


def weld_scenario_from_preset(name: str, **overrides: Any) -> WeldScenario:
    """A weld preset with fields replaced; rig (:class:`Scenario`) fields are accepted too.

    Parameters
    ----------
    name : str
        A key of :data:`WELD_PRESETS`.
    **overrides
        :class:`WeldScenario` fields, or :class:`Scenario` fields (applied to the rig), SI.

    Raises
    ------
    InputError
        For an unknown preset or field, or an invalid value.
    """
    return rig_scene_from_preset(WELD_PRESETS, name, "weld", overrides)


def bumped_hand_eye(
    T_flange_sensor: FloatArray,
    rng: np.random.Generator,
    angle_range_rad: tuple[float, float] = (np.radians(1.0), np.radians(2.0)),
    shift_range_m: tuple[float, float] = (0.001, 0.003),
) -> FloatArray:
    """An old hand-eye for a re-assembled sensor: the truth turned and shifted at random.

    Parameters
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    rng : numpy.random.Generator
    angle_range_rad, shift_range_m : (2,) floats
        Ranges of the rotation angle (rad, about a uniformly random axis) and of the
        translation shift (m, in a uniformly random direction).

    Returns
    -------
    ndarray, shape (4, 4)
    """
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    angle = rng.uniform(*angle_range_rad)
    length = rng.uniform(*shift_range_m)
    bump = transform_from_rotvec_translation(
        angle * axis / np.linalg.norm(axis), length * shift / np.linalg.norm(shift)
    )
    return np.asarray(T_flange_sensor @ bump)
