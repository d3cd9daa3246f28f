"""Sensor pose sampler: poses whose laser plane cuts the cylinder side at chosen angles.

Geometry of one candidate (a = unit axis, R = radius):

- The laser-plane normal n (sensor ±y) makes the cut angle φ with the axis, tilted towards
  the azimuth ψ: n = cos φ a + sin φ w(ψ). The plane cuts the side in an ellipse with
  semi-axes A = R / cos φ along u = (a - cos φ n) / sin φ (the axis projected into the plane)
  and R along m = a × w.
- The sensor sits in the laser plane at c + s q, c the ellipse centre, s the standoff and
  q = cos γ m + sin γ u the direction from the centre. Long-axis profiles (paper
  appendix, α) look along the minor axis (γ = 0 or π) and see the flat arc spanning the
  major axis; short-axis profiles (β) look along the major axis (γ = ±π/2), obliquely along
  the cylinder, and see the curved arc around a vertex. γ is spread by ``view_spread_rad``.
- The sensor looks at -q yawed about n by up to ``aim_spread_rad``; half of the sensors are
  rolled 180° about their viewing axis (``flip_roll``).
- The centre c is placed along the axis so the whole ellipse lies on the finite side, and s
  is drawn from the interval where the whole visible arc (between the tangent rays from the
  origin) lies within the measuring range and the fan. That interval is found on a grid of
  standoffs with the arc computed in closed form.
- Candidates that pass are checked once more by casting the real fan into the scene
  (:func:`~linelaser_calib.sim.profiler.trace`): the outermost rays must miss the cylinder,
  every cylinder hit must be within range and unoccluded, no end cap may be hit, and at
  least ``min_arc_fraction`` of the rays must return cylinder points. Sensor and flange
  origins must keep ``clearance_m`` from the cylinder and the background, and the sensor's
  azimuth must be within ``azimuth_range_rad``.

Accepted poses are ordered into a short tour (greedy nearest neighbour in position plus
turn), as a robot program would visit them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import invert_transform, orthonormal_basis
from linelaser_calib.core.types import BoolArray, FloatArray
from linelaser_calib.sim.profiler import trace
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Int64Array, Scene, Surface

#: Kind labels of the sampled poses.
LONG_AXIS, SHORT_AXIS, GENERAL = "long", "short", "general"
_KINDS = (LONG_AXIS, SHORT_AXIS, GENERAL)

_STANDOFF_STEPS = 48
_ARC_SAMPLES = 32
#: Safety margins of the closed-form check: fraction of the measuring range and of tan(fan).
_RANGE_MARGIN = 0.02
_FAN_MARGIN = 0.03
#: Axial gap kept between the ellipse and the cylinder's end faces, m.
_AXIAL_GAP_M = 0.002
_MAX_ROUNDS = 40


@dataclass(frozen=True, eq=False)
class SensorPoses:
    """Sampled sensor poses, in visiting order.

    Attributes
    ----------
    T_base_sensor : ndarray, shape (M, 4, 4)
    kinds : tuple of str
        ``long``, ``short`` or ``general`` per pose.
    cut_angles_rad : ndarray, shape (M,)
        Angle between the laser plane and the cylinder cross-section, rad.
    """

    T_base_sensor: FloatArray
    kinds: tuple[str, ...]
    cut_angles_rad: FloatArray


def azimuth_reference(scene: Scene) -> tuple[FloatArray, FloatArray]:
    """Unit vectors (e0, e1) perpendicular to the axis; azimuth 0 points to the base origin.

    If the axis passes within 1 cm of the base origin, e0 is an arbitrary perpendicular.
    """
    a = scene.axis
    to_origin = -(scene.base_m - (scene.base_m @ a) * a)
    norm = float(np.linalg.norm(to_origin))
    e0 = to_origin / norm if norm > 0.01 else orthonormal_basis(a)[0]
    return e0, np.cross(a, e0)


@dataclass(frozen=True, eq=False)
class _Candidates:
    """K candidate orientations with their ellipse geometry (arrays over K)."""

    kind: Int64Array  # index into _KINDS
    cut: FloatArray
    centre: FloatArray  # (K, 3)
    major: FloatArray  # (K,) semi-major axis A, m
    u: FloatArray  # (K, 3) major-axis direction
    m: FloatArray  # (K, 3) minor-axis direction
    q: FloatArray  # (K, 3) from the centre towards the sensor
    R: FloatArray  # (K, 3, 3) sensor rotation, columns x, y, z
    standoff_draw: FloatArray  # (K,) uniform 0..1


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


def _draw(rng: np.random.Generator, scenario: Scenario, scene: Scene, k: int) -> _Candidates:
    """Draw k candidate orientations and ellipse placements (standoff not yet chosen)."""
    draws = rng.random((9, k))
    a = scene.axis
    if scenario.pose_mode == "general":
        kind = np.full(k, _KINDS.index(GENERAL))
        lo, hi = scenario.general_cut_range_rad
        cut = lo + (hi - lo) * draws[0]
        gamma0 = 2.0 * math.pi * draws[1]
    else:
        is_long = draws[2] < scenario.long_axis_fraction
        kind = np.where(is_long, _KINDS.index(LONG_AXIS), _KINDS.index(SHORT_AXIS))
        (llo, lhi), (slo, shi) = scenario.long_axis_cut_range_rad, scenario.short_axis_cut_range_rad
        cut = np.where(is_long, llo + (lhi - llo) * draws[0], slo + (shi - slo) * draws[0])
        half = np.where(draws[1] < 0.5, 0.0, math.pi)
        gamma0 = np.where(is_long, half, half + 0.5 * math.pi)
    gamma = gamma0 + scenario.view_spread_rad * (2.0 * draws[3] - 1.0)
    yaw = scenario.aim_spread_rad * (2.0 * draws[4] - 1.0)
    psi = 2.0 * math.pi * draws[5]
    flip = np.where((draws[6] < 0.5) & scenario.flip_roll, -1.0, 1.0)

    e0, e1 = azimuth_reference(scene)
    w = np.cos(psi)[:, None] * e0 + np.sin(psi)[:, None] * e1
    n = np.cos(cut)[:, None] * a + np.sin(cut)[:, None] * w
    u = _unit(a - np.cos(cut)[:, None] * n)
    m = np.cross(a, w)
    q = np.cos(gamma)[:, None] * m + np.sin(gamma)[:, None] * u
    z = -np.cos(yaw)[:, None] * q - np.sin(yaw)[:, None] * np.cross(n, q)
    y = flip[:, None] * n
    x = np.cross(y, z)
    R = np.stack([x, y, z], axis=2)

    radius, length = scene.radius_m, scene.length_m
    reach = radius * np.tan(cut) + _AXIAL_GAP_M
    lo_ax, hi_ax = reach, length - reach
    mid = 0.5 * (lo_ax + hi_ax)
    axial = mid + scenario.axial_spread * (draws[7] - 0.5) * (hi_ax - lo_ax)
    axial = np.where(hi_ax >= lo_ax, axial, np.nan)
    centre = scene.base_m + axial[:, None] * a
    return _Candidates(kind, cut, centre, radius / np.cos(cut), u, m, q, R, draws[8])


def _arc_fits(scenario: Scenario, radius: float, c: _Candidates, s: FloatArray) -> BoolArray:
    """Closed-form check that the visible arc lies in range and fan, for standoffs s (K, S)."""
    A = c.major[:, None]
    # Origin in the ellipse's normalised coordinates (cos θ ↔ u / A, sin θ ↔ m / R).
    qu = np.sum(c.q * c.u, axis=1)[:, None]
    qm = np.sum(c.q * c.m, axis=1)[:, None]
    px, py = s * qu / A, s * qm / radius
    rho = np.hypot(px, py)
    half = np.arccos(np.clip(1.0 / np.maximum(rho, 1.0), -1.0, 1.0))
    theta = np.arctan2(py, px)[..., None] + half[..., None] * np.linspace(-1, 1, _ARC_SAMPLES)

    def sensor_coord(axis: int) -> FloatArray:
        e = c.R[:, :, axis]
        eu = np.sum(c.u * e, axis=1)[:, None, None]
        em = np.sum(c.m * e, axis=1)[:, None, None]
        eq = np.sum(c.q * e, axis=1)[:, None, None]
        return np.asarray(
            A[..., None] * np.cos(theta) * eu + radius * np.sin(theta) * em - s[..., None] * eq
        )

    x, z = sensor_coord(0), sensor_coord(2)
    span = scenario.z_max_m - scenario.z_min_m
    z_lo = scenario.z_min_m + _RANGE_MARGIN * span
    z_hi = scenario.z_max_m - _RANGE_MARGIN * span
    tan_fan = math.tan(scenario.fan_half_angle_rad) * (1.0 - _FAN_MARGIN)
    with np.errstate(invalid="ignore"):
        ok = (z.min(axis=-1) >= z_lo) & (z.max(axis=-1) <= z_hi)
        ok &= np.all(np.abs(x) <= tan_fan * z, axis=-1)
    return np.asarray(ok & (rho > 1.0 + 1e-9))


def _choose_standoff(scenario: Scenario, scene: Scene, c: _Candidates) -> FloatArray:
    """Standoff per candidate from its feasible interval (NaN if none)."""
    s_min = np.full_like(c.major, scenario.z_min_m)
    s_max = scenario.z_max_m + c.major
    grid = s_min[:, None] + (s_max - s_min)[:, None] * np.linspace(0.0, 1.0, _STANDOFF_STEPS)
    ok = _arc_fits(scenario, scene.radius_m, c, grid)
    any_ok = ok.any(axis=1)
    first = np.argmax(ok, axis=1)
    last = _STANDOFF_STEPS - 1 - np.argmax(ok[:, ::-1], axis=1)
    rows = np.arange(len(grid))
    lo, hi = grid[rows, first], grid[rows, last]
    s = 0.5 * (lo + hi) + scenario.standoff_spread * (c.standoff_draw - 0.5) * (hi - lo)
    s = np.where(any_ok & np.isfinite(c.centre[:, 0]), s, np.nan)
    fits = _arc_fits(scenario, scene.radius_m, c, np.nan_to_num(s)[:, None])[:, 0]
    return np.asarray(np.where(fits, s, np.nan))


def _azimuth_ok(scenario: Scenario, scene: Scene, q: FloatArray) -> BoolArray:
    e0, e1 = azimuth_reference(scene)
    azimuth = np.arctan2(q @ e1, q @ e0)
    lo, hi = scenario.azimuth_range_rad
    return np.asarray(np.mod(azimuth - lo, 2.0 * math.pi) <= hi - lo)


def _traced_ok(scenario: Scenario, scene: Scene, T_base_sensor: FloatArray) -> BoolArray:
    """Check candidates by casting the real fan (see the module docstring)."""
    t = trace(scene, scenario, T_base_sensor)
    on_cylinder = (t.surface == Surface.SIDE) | (t.surface == Surface.CAP)
    z = t.points_sensor[..., 2]
    with np.errstate(invalid="ignore"):
        in_range = (z >= scenario.z_min_m) & (z <= scenario.z_max_m)
    ok = ~on_cylinder[:, 0] & ~on_cylinder[:, -1]
    ok &= np.all(~on_cylinder | in_range, axis=1)
    ok &= ~np.any(t.surface == Surface.CAP, axis=1) & ~np.any(t.side_occluded, axis=1)
    arc_points = np.sum(on_cylinder & t.seen, axis=1)
    return np.asarray(ok & (arc_points >= scenario.min_arc_fraction * scenario.resolution))


def _tour(T_base_sensor: FloatArray, metres_per_rad: float, start: int) -> list[int]:
    """Greedy nearest-neighbour visiting order (distance: |Δp| + metres_per_rad · angle)."""
    p = T_base_sensor[:, :3, 3]
    R = T_base_sensor[:, :3, :3]
    cos_angle = (np.einsum("aij,bij->ab", R, R) - 1.0) / 2.0
    cost = np.linalg.norm(p[:, None] - p[None], axis=2)
    cost = cost + metres_per_rad * np.arccos(np.clip(cos_angle, -1.0, 1.0))
    order = [start]
    left = set(range(len(p))) - {start}
    while left:
        here = order[-1]
        nxt = min(left, key=lambda j: (cost[here, j], j))
        order.append(nxt)
        left.remove(nxt)
    return order


def sample_sensor_poses(rng: np.random.Generator, scenario: Scenario, scene: Scene) -> SensorPoses:
    """Draw ``scenario.n_poses`` feasible sensor poses (see the module docstring).

    Raises
    ------
    InputError
        If too few feasible poses are found: the sensor cannot hold the whole arc at the
        requested cut angles (widen the range or fan, narrow the cut-angle ranges, use a
        smaller cylinder or fewer constraints).
    """
    T_flange_sensor = scenario.T_flange_sensor
    sensor_flange = invert_transform(T_flange_sensor)[:3, 3]
    wanted = scenario.n_poses
    batch = 4 * wanted + 32
    accepted: list[tuple[FloatArray, int, float]] = []
    tried = 0
    for _ in range(_MAX_ROUNDS):
        c = _draw(rng, scenario, scene, batch)
        tried += batch
        s = _choose_standoff(scenario, scene, c)
        keep = np.isfinite(s) & _azimuth_ok(scenario, scene, c.q)
        origin = c.centre + np.nan_to_num(s)[:, None] * c.q
        flange = origin + np.einsum("kij,j->ki", c.R, sensor_flange)
        keep &= scene.clearance(origin) >= scenario.clearance_m
        keep &= scene.clearance(flange) >= scenario.clearance_m
        idx = np.flatnonzero(keep)
        T = np.tile(np.eye(4), (len(idx), 1, 1))
        T[:, :3, :3] = c.R[idx]
        T[:, :3, 3] = origin[idx]
        if len(idx):
            passed = _traced_ok(scenario, scene, T)
            idx, T = idx[passed], T[passed]
        accepted.extend((T[j], int(c.kind[i]), float(c.cut[i])) for j, i in enumerate(idx))
        if len(accepted) >= wanted:
            break
    if len(accepted) < wanted:
        raise InputError(
            f"scenario {scenario.name!r}: found only {len(accepted)} of {wanted} feasible sensor "
            f"poses in {tried} candidates; the sensor cannot hold the whole arc at the requested "
            "cut angles. Widen the measuring range (z_min_m, z_max_m) or fan_half_angle_rad, "
            "narrow the cut-angle ranges, use a smaller cylinder or relax clearance_m and "
            "azimuth_range_rad"
        )
    chosen = accepted[:wanted]
    T_all = np.stack([a[0] for a in chosen])
    flange_dist = np.linalg.norm((T_all @ invert_transform(T_flange_sensor))[:, :3, 3], axis=1)
    order = _tour(
        T_all,
        scenario.move_speed_m_s / scenario.move_angular_speed_rad_s,
        int(np.argmin(flange_dist)),
    )
    return SensorPoses(
        T_base_sensor=T_all[order],
        kinds=tuple(_KINDS[chosen[i][1]] for i in order),
        cut_angles_rad=np.array([chosen[i][2] for i in order]),
    )
