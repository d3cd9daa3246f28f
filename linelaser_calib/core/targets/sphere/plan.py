"""Planning for the sphere: predicted profiles, the cap-in-view rules, per-pose information.

Placement
---------
:class:`SpherePlacement`: the centre (base frame), the radius and the side of the laser
plane (sensor ±y) the centre lies on in every view, which the sphere target's circles
assume.

Predicted profile
-----------------
A ray o + t·r meets the sphere where |o + t·r − c|² = R²: t² + 2 t r·w + |w|² − R² = 0 with
w = o − c (r a unit vector); the nearer root is the hit when the origin is outside.

Viewing rules
-------------
The laser plane cuts the ball in a circle of radius √(R² − h²), h the plane's distance from
the centre, drawn as h = u·R with u in :data:`OFFSET_RANGE` (a cap well away from the
equator, where the side of the centre is clear, and from the pole, where the arc is short).
The viewing axis (sensor z) is tilted from straight down by up to :data:`MAX_TILT_RAD`, the
line turned about it by any angle, the centre placed at a depth inside the measuring range
and sideways along the line by up to :data:`LATERAL_FRACTION` of the half fan width;
:func:`~linelaser_calib.core.planning.feasible` keeps the poses whose whole cap is in view.

Rough placement from exploratory scans
--------------------------------------
With an initial hand-eye, each circle (centre x_c, z_c in the laser plane, radius r) gives
the sphere centre at (x_c, ±√(R² − r²), z_c) in the sensor frame; the side is the given one,
else the one whose centres agree best in the base frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.geometry import FloatArray, matrix_from_rotvec
from linelaser_calib.core.planning import PlanConstraints, per_sample_information, required_radius
from linelaser_calib.core.settings_text import setting
from linelaser_calib.core.targets.sphere.config import SphereConfig
from linelaser_calib.core.targets.sphere.model import side_from_label
from linelaser_calib.core.targets.sphere.refine import SphereProblem, SphereState

#: Range of h / R of the planned views.
OFFSET_RANGE = (0.2, 0.8)
#: Largest tilt of the viewing axis from straight down, rad.
MAX_TILT_RAD = math.radians(40.0)
#: Largest sideways offset of the centre as a share of the half fan width at its depth.
LATERAL_FRACTION = 0.3


@dataclass(frozen=True)
class SpherePlacement:
    """The ball's rough pose (base frame).

    Attributes
    ----------
    centre : ndarray, shape (3,)
        m.
    radius : float
        m.
    centre_side : int
        +1 or −1: the sensor y side of the laser plane the centre lies on.
    """

    centre: FloatArray
    radius: float
    centre_side: int

    def __post_init__(self) -> None:
        c = np.asarray(self.centre, dtype=np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise InputError(f"the sphere centre must be 3 finite numbers, got {self.centre}")
        if not (np.isfinite(self.radius) and self.radius > 0.0):
            raise InputError(f"the sphere radius must be positive, got {self.radius}")


def _side(config: SphereConfig) -> int | None:
    return None if config.centre_side is None else side_from_label(config.centre_side)


def _no_extent(extent: Any) -> None:
    if extent is not None:
        raise InputError(
            "{setting:axial_range_m} does not apply to the sphere target and would be ignored; "
            "omit it"
        )


class SpherePlanner:
    """:class:`~linelaser_calib.core.planning.Plannable` for the sphere (module docstring)."""

    numbers_setting = "sphere_placement"
    numbers_help = "cx,cy,cz: the centre of the ball (base frame, m)"

    def placement_from_section(
        self, section: Any, config: Any, extent: Any, points_base: FloatArray | None
    ) -> SpherePlacement:
        """From a result's ``sphere`` section."""
        _no_extent(extent)
        return SpherePlacement(
            np.asarray(section.centre_m, dtype=np.float64),
            float(section.radius_m),
            int(section.centre_side),
        )

    def placement_from_numbers(
        self, numbers: list[float], config: Any, extent: Any, points_base: FloatArray | None
    ) -> SpherePlacement:
        """From ``cx,cy,cz`` (m), the configured radius and side (default −y)."""
        _no_extent(extent)
        if len(numbers) != 3:
            raise InputError(
                f"{setting(self.numbers_setting)} takes 3 numbers, {self.numbers_help}; "
                f"got {len(numbers)}"
            )
        side = _side(config)
        return SpherePlacement(
            np.asarray(numbers, dtype=np.float64),
            required_radius(config.radius_m, "sphere"),
            -1 if side is None else side,
        )

    def placement_from_features(
        self, features: list[Any], T_flange_sensor: FloatArray, config: Any, extent: Any
    ) -> SpherePlacement:
        """From exploratory scans (see the module docstring)."""
        _no_extent(extent)
        if not features:
            raise DegenerateError(
                "no exploratory scan shows the sphere's cap: scan it from 3 or more poses first"
            )
        radius = required_radius(config.radius_m, "sphere")
        given = _side(config)
        best: tuple[float, FloatArray, int] | None = None
        for side in (given,) if given is not None else (1, -1):
            centres = []
            for f in features:
                T = f.T_base_flange @ T_flange_sensor
                xc, zc = f.circle.centre_xz
                h = math.sqrt(max(radius**2 - f.circle.radius_m**2, 0.0))
                centres.append(T[:3, :3] @ np.array([xc, side * h, zc]) + T[:3, 3])
            spread = float(np.sum(np.var(centres, axis=0)))
            if best is None or spread < best[0]:
                best = (spread, np.mean(centres, axis=0), side)
        assert best is not None
        return SpherePlacement(best[1], radius, best[2])

    def sample_points(self, features: list[Any]) -> list[FloatArray]:
        """Each circle's inlier points."""
        return [f.points for f in features]

    def ray_depths(
        self, placement: Any, T_base_sensor: FloatArray, directions: FloatArray
    ) -> FloatArray:
        """Distance (K, N) to the ball along each ray, m; NaN where it misses."""
        rays = directions @ T_base_sensor[:, :3, :3].transpose(0, 2, 1)
        w = T_base_sensor[:, :3, 3] - placement.centre
        b = np.einsum("kni,ki->kn", rays, w)
        c = np.sum(w**2, axis=1)[:, None] - placement.radius**2
        disc = b**2 - c
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        return np.asarray(np.where((disc >= 0.0) & (c > 0.0) & (t > 0.0), t, np.nan))

    def candidate_views(
        self, placement: Any, constraints: PlanConstraints, rng: np.random.Generator, n: int
    ) -> FloatArray:
        """``n`` sensor poses looking down at the cap, tilted and turned at random."""
        draws = rng.random((6, n))
        down = np.diag([1.0, -1.0, -1.0])
        azimuth = 2.0 * math.pi * draws[0]
        tilt = MAX_TILT_RAD * draws[1]
        spin = math.pi * (draws[2] - 0.5)
        axes = np.stack([np.cos(azimuth), np.sin(azimuth), np.zeros(n)], axis=1)
        R = (
            matrix_from_rotvec(tilt[:, None] * axes)
            @ down
            @ matrix_from_rotvec(spin[:, None] * np.array([0.0, 0.0, 1.0]))
        )
        lo, hi = OFFSET_RANGE
        h = (lo + (hi - lo) * draws[3]) * placement.radius
        depth = constraints.z_min_m + (constraints.z_max_m - constraints.z_min_m) * draws[4]
        half_width = depth * math.tan(constraints.fan_half_angle_rad)
        x = LATERAL_FRACTION * half_width * (2.0 * draws[5] - 1.0)
        seen_at = np.stack([x, placement.centre_side * h, depth], axis=1)
        T = np.tile(np.eye(4), (n, 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = placement.centre - np.einsum("kij,kj->ki", R, seen_at)
        return T

    def clearance(self, placement: Any, points: FloatArray) -> FloatArray:
        """Distance (K,) of points (K, 3) from the ball's surface, m."""
        return np.asarray(np.linalg.norm(points - placement.centre, axis=1) - placement.radius)

    def centre(self, placement: Any) -> FloatArray:
        """The ball's centre, m."""
        return np.asarray(placement.centre, dtype=np.float64)

    def information(
        self,
        placement: Any,
        T_flange_sensor: FloatArray,
        points_sensor: list[FloatArray],
        T_base_flange: FloatArray,
        config: Any,
    ) -> FloatArray:
        """Per-sample information (M, G, G) of the default problem (:mod:`.refine`) at the
        estimate, each sample's pose correction marginalised; G = 9, or 10 with the radius
        estimated. Built by the refinement's own problem and the shared solver."""
        cfg: SphereConfig = config
        refine = replace(cfg.refine, estimate_radius=cfg.radius_m is None)
        lever = float(np.median(np.linalg.norm(np.concatenate(points_sensor), axis=1)))
        problem = SphereProblem(np.asarray(T_base_flange), points_sensor, refine, lever)
        state = SphereState(
            np.asarray(T_flange_sensor, dtype=np.float64),
            placement.centre,
            placement.radius,
            np.zeros((len(points_sensor), 6)),
        )
        return per_sample_information(problem.linearise(state))
