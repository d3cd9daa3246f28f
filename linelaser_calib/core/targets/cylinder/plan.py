"""Planning for the cylinder: predicted profiles, the paper's viewing rules, per-pose information.

Placement
---------
:class:`CylinderPlacement`: the axis (point nearest the base origin, unit direction pointing
up), the radius and the axial span ``[lo, hi]`` (m along the direction from that point)
where the shaft can be scanned.

Predicted profile
-----------------
A ray o + t·r meets the (infinite) cylinder where |P(o + t·r − c)|² = R², P = I − d dᵀ: the
quadratic A t² + B t + C = 0 with A = |P r|², B = 2 (P r)·(P w), C = |P w|² − R², w = o − c.
The nearer root is the hit when the origin is outside (C > 0) and the discriminant is
non-negative; hits outside the axial span are misses.

Viewing rules (the cylinder paper's appendix)
---------------------------------------------
The laser plane's normal n makes the cut angle φ with the axis: n = cos φ d + sin φ w, w ⟂ d
(azimuth ψ). The plane cuts the side in an ellipse with semi-axes R / cos φ along
u = (d − cos φ n) / sin φ and R along m = d × w. Long-axis profiles (α ∈ [50°, 75°]) look
along the minor axis m and see the flat arc across the major axis; short-axis profiles
(β ∈ [40°, 60°]) look along the major axis u, obliquely along the shaft, and see the curved
arc around a vertex. The ellipse centre is placed at a random height with the whole ellipse
inside the axial span, the standoff is drawn over the measuring range, and
:func:`~linelaser_calib.core.planning.feasible` keeps the poses whose whole arc is in view.

Rough placement from exploratory scans
--------------------------------------
With an initial hand-eye, each ellipse's centre maps to a point on the axis, and its axis
ratio and major-axis direction give the axis direction in the sensor frame up to a two-fold
sign: d = cos φ y ± sin φ u_s, cos φ = b / a (the cut angle), u_s the major axis. The signs
of all scans are chosen together so that the directions agree best.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import DegenerateError, InputError
from ...geometry import FloatArray, orthonormal_basis
from ...planning import UP, PlanConstraints, per_sample_information, required_radius
from ...settings_text import setting
from .config import CylinderConfig
from .features import FittedSample
from .model import Cylinder
from .problem import build_problem, initial_state

#: Cut-angle ranges of long-axis (α) and short-axis (β) profiles, rad (paper appendix).
LONG_AXIS_CUT_RAD = (math.radians(50.0), math.radians(75.0))
SHORT_AXIS_CUT_RAD = (math.radians(40.0), math.radians(60.0))
#: Spread of the viewing direction within the laser plane around the rule's, rad.
VIEW_SPREAD_RAD = math.radians(15.0)
#: Spread of the aim (yaw about the laser-plane normal), rad.
AIM_SPREAD_RAD = math.radians(8.0)
#: Gap kept between the ellipse and the ends of the axial span, m.
AXIAL_GAP_M = 0.002
#: Most exploratory scans whose sign combinations are tried exhaustively.
MAX_SIGN_SEARCH = 12


@dataclass(frozen=True)
class CylinderPlacement:
    """The cylinder's rough pose and extent (base frame).

    Attributes
    ----------
    cylinder : Cylinder
        Axis point nearest the base origin, unit direction (pointing up), radius, m.
    axial_range_m : (float, float)
        Scannable span along the direction from ``cylinder.point``, m.
    """

    cylinder: Cylinder
    axial_range_m: tuple[float, float]

    def __post_init__(self) -> None:
        lo, hi = self.axial_range_m
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise InputError(
                f"the cylinder's axial span must be two finite heights lo < hi in m, got "
                f"{self.axial_range_m}"
            )
        if not self.cylinder.radius > 0.0:
            raise InputError(f"the cylinder radius must be positive, got {self.cylinder.radius}")


def placement(
    cylinder: Cylinder,
    axial_range_m: tuple[float, float] | None,
    points_base: FloatArray | None = None,
) -> CylinderPlacement:
    """A placement with the axis point moved to the one nearest the base origin and the
    direction turned up (``axial_range_m`` is measured from that point); without a span,
    the span the points (N, 3; base frame, m) cover.

    Raises
    ------
    InputError
        A bad cylinder, or neither a span nor points.
    """
    d = np.asarray(cylinder.direction, dtype=np.float64)
    c = np.asarray(cylinder.point, dtype=np.float64)
    if d.shape != (3,) or c.shape != (3,) or not np.all(np.isfinite(np.concatenate([c, d]))):
        raise InputError(
            f"the cylinder needs a finite point and direction of 3 numbers each, got "
            f"{cylinder.point} and {cylinder.direction}"
        )
    if not np.linalg.norm(d) > 0.0:
        raise InputError("the cylinder direction must not be zero")
    d = d / np.linalg.norm(d)
    if d @ UP < 0.0:
        d = -d
    c = c - (c @ d) * d
    if axial_range_m is None:
        if points_base is None:
            raise InputError(
                "the planner needs the span of the shaft that can be scanned: give "
                "{setting:axial_range_m} LO,HI (m along the axis, upwards, from its point "
                "nearest the "
                "base origin) or scans of the shaft"
            )
        along = (points_base - c) @ d
        axial_range_m = (float(np.min(along)), float(np.max(along)))
    return CylinderPlacement(Cylinder(c, d, float(cylinder.radius)), axial_range_m)


class CylinderPlanner:
    """:class:`~linelaser_calib.core.planning.Plannable` for the cylinder (module docstring)."""

    numbers_setting = "cylinder_placement"
    numbers_help = "px,py,pz,dx,dy,dz: a point on the axis and its direction (base frame, m)"

    def placement_from_section(
        self, section: Any, config: Any, extent: Any, points_base: FloatArray | None
    ) -> CylinderPlacement:
        """From a result's ``cylinder`` section."""
        return placement(section.cylinder, extent, points_base)

    def placement_from_numbers(
        self, numbers: list[float], config: Any, extent: Any, points_base: FloatArray | None
    ) -> CylinderPlacement:
        """From ``px,py,pz,dx,dy,dz`` (m) and the configured radius."""
        if len(numbers) != 6:
            raise InputError(
                f"{setting(self.numbers_setting)} takes 6 numbers, {self.numbers_help}; "
                f"got {len(numbers)}"
            )
        values = np.asarray(numbers, dtype=np.float64)
        return placement(
            Cylinder(values[:3], values[3:], required_radius(config.radius_m, "cylinder")),
            extent,
            points_base,
        )

    def placement_from_features(
        self, features: list[Any], T_flange_sensor: FloatArray, config: Any, extent: Any
    ) -> CylinderPlacement:
        """From exploratory scans (:func:`rough_placement`)."""
        return rough_placement(
            features, T_flange_sensor, required_radius(config.radius_m, "cylinder"), extent
        )

    def sample_points(self, features: list[Any]) -> list[FloatArray]:
        """Each ellipse's inlier points."""
        return [f.inlier_points for f in features]

    def ray_depths(
        self, placement: Any, T_base_sensor: FloatArray, directions: FloatArray
    ) -> FloatArray:
        """Distance (K, N) to the shaft along each ray, m; NaN where it misses."""
        cyl = placement.cylinder
        d = cyl.direction
        origin = T_base_sensor[:, :3, 3]
        rays = directions @ T_base_sensor[:, :3, :3].transpose(0, 2, 1)
        w = origin - cyl.point
        w_perp = w - np.outer(w @ d, d)
        r_perp = rays - (rays @ d)[..., None] * d
        a = np.sum(r_perp**2, axis=2)
        b = 2.0 * np.einsum("kni,ki->kn", r_perp, w_perp)
        c = np.sum(w_perp**2, axis=1)[:, None] - cyl.radius**2
        disc = b**2 - 4.0 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-b - np.sqrt(disc)) / (2.0 * a)
        along = (w @ d)[:, None] + t * (rays @ d)
        lo, hi = placement.axial_range_m
        hit = (disc >= 0.0) & (c > 0.0) & (a > 1e-12) & (t > 0.0) & (along >= lo) & (along <= hi)
        return np.asarray(np.where(hit, t, np.nan))

    def candidate_views(
        self, placement: Any, constraints: PlanConstraints, rng: np.random.Generator, n: int
    ) -> FloatArray:
        """``n`` sensor poses by the paper's rules: half long-axis, half short-axis."""
        cyl = placement.cylinder
        d, radius = cyl.direction, cyl.radius
        draws = rng.random((8, n))
        is_long = draws[0] < 0.5
        (llo, lhi), (slo, shi) = LONG_AXIS_CUT_RAD, SHORT_AXIS_CUT_RAD
        cut = np.where(is_long, llo + (lhi - llo) * draws[1], slo + (shi - slo) * draws[1])
        side = np.where(draws[2] < 0.5, 0.0, math.pi)
        gamma = np.where(is_long, side, side + 0.5 * math.pi)
        gamma = gamma + VIEW_SPREAD_RAD * (2.0 * draws[3] - 1.0)
        yaw = AIM_SPREAD_RAD * (2.0 * draws[4] - 1.0)
        psi = 2.0 * math.pi * draws[5]
        e0, e1 = orthonormal_basis(d)
        w = np.cos(psi)[:, None] * e0 + np.sin(psi)[:, None] * e1
        normal = np.cos(cut)[:, None] * d + np.sin(cut)[:, None] * w
        u = d - np.cos(cut)[:, None] * normal
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        m = np.cross(d, w)
        q = np.cos(gamma)[:, None] * m + np.sin(gamma)[:, None] * u
        z = -np.cos(yaw)[:, None] * q - np.sin(yaw)[:, None] * np.cross(normal, q)
        y = np.where(draws[6, :, None] < 0.5, normal, -normal)
        R = np.stack([np.cross(y, z), y, z], axis=2)

        lo, hi = placement.axial_range_m
        reach = radius * np.tan(cut) + AXIAL_GAP_M
        height = lo + reach + (hi - lo - 2.0 * reach) * draws[7]
        major = radius / np.cos(cut)
        s_lo = constraints.z_min_m + 0.5 * radius
        s_hi = constraints.z_max_m + 0.5 * major
        standoff = s_lo + (s_hi - s_lo) * rng.random(n)
        T = np.tile(np.eye(4), (n, 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = cyl.point + height[:, None] * d + standoff[:, None] * q
        return np.asarray(T[hi - lo - 2.0 * reach > 0.0])

    def clearance(self, placement: Any, points: FloatArray) -> FloatArray:
        """Distance (K,) of points (K, 3) from the cylinder's side, m (negative inside)."""
        cyl = placement.cylinder
        w = points - cyl.point
        radial = w - np.outer(w @ cyl.direction, cyl.direction)
        return np.asarray(np.linalg.norm(radial, axis=1) - cyl.radius)

    def centre(self, placement: Any) -> FloatArray:
        """The middle of the axial span on the axis (3,), m."""
        lo, hi = placement.axial_range_m
        cyl = placement.cylinder
        return np.asarray(cyl.point + 0.5 * (lo + hi) * cyl.direction)

    def information(
        self,
        placement: Any,
        T_flange_sensor: FloatArray,
        points_sensor: list[FloatArray],
        T_base_flange: FloatArray,
        config: Any,
    ) -> FloatArray:
        """Per-sample information (M, G, G) of the default problem (:mod:`.refine`) at the
        estimate, each sample's pose correction marginalised; G = 10, or 11 with the radius
        estimated. Built by the refinement's own problem and the shared solver."""
        cfg: CylinderConfig = config
        refine = replace(cfg.refine, min_samples=3)
        estimate_radius = cfg.radius_m is None or refine.estimate_radius
        problem = build_problem(points_sensor, T_base_flange, refine, estimate_radius)
        state = initial_state(
            problem, T_flange_sensor, placement.cylinder, placement.cylinder.radius
        )
        return per_sample_information(problem.linearise(state))


def rough_placement(
    features: list[FittedSample],
    T_flange_sensor: FloatArray,
    radius_m: float,
    axial_range_m: tuple[float, float] | None,
) -> CylinderPlacement:
    """The cylinder from exploratory scans and an initial hand-eye (module docstring).

    Parameters
    ----------
    features : list of FittedSample
        At least 1 ellipse; 3 or more make the direction robust.
    T_flange_sensor : ndarray, shape (4, 4)
        Initial hand-eye.
    radius_m : float
    axial_range_m : (float, float), optional
        Scannable span (m from the axis point nearest the base origin, upwards); None: the
        span the scans' points cover.

    Raises
    ------
    DegenerateError
        No scan.
    """
    if not features:
        raise DegenerateError(
            "no exploratory scan shows the cylinder's arc: scan it from 3 or more poses first"
        )
    centres, directions = [], []
    for f in features[:MAX_SIGN_SEARCH]:
        T_base_sensor = f.T_base_flange @ T_flange_sensor
        R = T_base_sensor[:3, :3]
        xc, zc = f.ellipse.centre_xz
        centres.append(R @ np.array([xc, 0.0, zc]) + T_base_sensor[:3, 3])
        A, B, C = f.ellipse.conic[:3]
        values, vectors = np.linalg.eigh(np.array([[A, B / 2.0], [B / 2.0, C]]))
        major = vectors[:, int(np.argmin(np.abs(values)))]
        semi_major, semi_minor = f.ellipse.semi_axes
        cos_cut = min(1.0, float(semi_minor / semi_major))
        sin_cut = math.sqrt(1.0 - cos_cut**2)
        u_s = np.array([major[0], 0.0, major[1]])
        y_s = np.array([0.0, 1.0, 0.0])
        directions.append([R @ (cos_cut * y_s + sign * sin_cut * u_s) for sign in (1.0, -1.0)])
    best, best_length = directions[0][0], -1.0
    for choice in itertools.product((0, 1), repeat=len(directions)):
        picked = np.array([directions[k][c] for k, c in enumerate(choice)])
        aligned = picked * np.where(picked @ picked[0] < 0.0, -1.0, 1.0)[:, None]
        total = aligned.sum(axis=0)
        if np.linalg.norm(total) > best_length:
            best, best_length = total, float(np.linalg.norm(total))
    hits = []
    for f in features:
        T_base_sensor = f.T_base_flange @ T_flange_sensor
        hits.append(f.inlier_points @ T_base_sensor[:3, :3].T + T_base_sensor[:3, 3])
    axis = Cylinder(np.mean(centres, axis=0), best, radius_m)
    return placement(axis, axial_range_m, np.concatenate(hits))
