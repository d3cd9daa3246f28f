"""The simulated scene: a finite cylinder (side and two end caps) and an optional plane.

Ray casting is vectorised: origins and directions are arrays of shape (..., 3) that
broadcast against each other, and every function returns arrays of the broadcast shape.
A ray is ``o + t r`` with ``t > t_min``; directions need not be unit (then ``t`` is in units
of ``|r|``). Misses are ``t = inf``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim.scenario import Scenario

Int8Array = NDArray[np.int8]
Int64Array = NDArray[np.int64]

#: Smallest accepted ray parameter for rays from the sensor, m.
T_MIN_M = 1e-9


class Surface(IntEnum):
    """What a ray hit (stored as int8 in the per-ray truth arrays)."""

    NONE = 0
    SIDE = 1
    CAP = 2
    BACKGROUND = 3
    FIXTURE = 4


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.asarray(np.sum(a * b, axis=-1))


@dataclass(frozen=True, eq=False)
class Scene:
    """A finite cylinder and an optional background plane.

    Attributes
    ----------
    base_m : ndarray, shape (3,)
        Centre of the bottom face, m.
    axis : ndarray, shape (3,)
        Unit axis direction.
    radius_m, length_m : float
    plane_point_m : ndarray, shape (3,), or None
        A point of the background plane, m (None: no background).
    plane_normal : ndarray, shape (3,), or None
        Unit normal of the plane, pointing to the free side (where the sensor is).
    """

    base_m: FloatArray
    axis: FloatArray
    radius_m: float
    length_m: float
    plane_point_m: FloatArray | None
    plane_normal: FloatArray | None

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> Scene:
        """Build the scene of a scenario (``table`` is the plane through the cylinder base)."""
        axis = scenario.axis_unit
        base = np.asarray(scenario.cylinder_base_m, dtype=np.float64)
        point: FloatArray | None = None
        normal: FloatArray | None = None
        if scenario.background == "table":
            point, normal = base.copy(), axis.copy()
        elif scenario.background == "plane":
            point = np.asarray(scenario.background_point_m, dtype=np.float64)
            n = np.asarray(scenario.background_normal, dtype=np.float64)
            normal = n / np.linalg.norm(n)
        return cls(
            base, axis, scenario.cylinder_radius_m, scenario.cylinder_length_m, point, normal
        )

    def side_distance(self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M) -> FloatArray:
        """Smallest ray parameter ``t > t_min`` at which the ray meets the finite side, else inf."""
        w = o - self.base_m
        wa, ra = _dot(w, self.axis), _dot(r, self.axis)
        w_perp = w - wa[..., None] * self.axis
        r_perp = r - ra[..., None] * self.axis
        a2 = _dot(r_perp, r_perp)
        b = _dot(w_perp, r_perp)
        c = _dot(w_perp, w_perp) - self.radius_m**2
        disc = b * b - a2 * c
        ok = (disc >= 0.0) & (a2 > 1e-24)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        # Numerically stable roots: q = -(b + sign(b) sq), roots q / a2 and c / q.
        q = -(b + np.where(b >= 0.0, sq, -sq))
        with np.errstate(divide="ignore", invalid="ignore"):
            r1 = np.where(ok, q / np.where(ok, a2, 1.0), np.inf)
            r2 = np.where(ok & (q != 0.0), c / np.where(q != 0.0, q, 1.0), np.inf)
        best = np.full(np.shape(disc), np.inf)
        for root in (np.minimum(r1, r2), np.maximum(r1, r2)):
            axial = wa + root * ra
            hit = ok & (root > t_min) & (axial >= 0.0) & (axial <= self.length_m)
            best = np.where(np.isinf(best) & hit, root, best)
        return best

    def cap_distance(self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M) -> FloatArray:
        """Smallest ``t > t_min`` at which the ray meets one of the two end discs, else inf."""
        w = o - self.base_m
        wa, ra = _dot(w, self.axis), _dot(r, self.axis)
        best = np.full(np.shape(wa), np.inf)
        safe_ra = np.where(np.abs(ra) > 1e-18, ra, 1.0)
        for height in (0.0, self.length_m):
            t = np.where(np.abs(ra) > 1e-18, (height - wa) / safe_ra, np.inf)
            finite_t = np.where(np.isfinite(t), t, 0.0)
            p = w + finite_t[..., None] * r
            radial = p - _dot(p, self.axis)[..., None] * self.axis
            inside = _dot(radial, radial) <= self.radius_m**2
            best = np.where((t > t_min) & np.isfinite(t) & inside, np.minimum(best, t), best)
        return best

    def plane_distance(self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M) -> FloatArray:
        """``t > t_min`` at which the ray meets the background plane, else inf."""
        if self.plane_point_m is None or self.plane_normal is None:
            return np.full(np.broadcast_shapes(o.shape, r.shape)[:-1], np.inf)
        denom = _dot(r, self.plane_normal)
        num = _dot(self.plane_point_m - o, self.plane_normal)
        ok = np.abs(denom) > 1e-18
        t = np.where(ok, num / np.where(ok, denom, 1.0), np.inf)
        return np.asarray(np.where(t > t_min, t, np.inf))

    def cast(
        self, o: FloatArray, r: FloatArray, t_min: float = T_MIN_M
    ) -> tuple[FloatArray, Int8Array, FloatArray]:
        """Nearest hit of each ray.

        Returns
        -------
        t : ndarray, shape (...)
            Ray parameter of the nearest hit (inf: none).
        surface : ndarray of int8, shape (...)
            :class:`Surface` code of the nearest hit.
        t_side : ndarray, shape (...)
            Ray parameter of the side hit alone (ignoring caps and plane), inf if none.
        """
        t_side = self.side_distance(o, r, t_min)
        candidates = np.stack(
            [t_side, self.cap_distance(o, r, t_min), self.plane_distance(o, r, t_min)], axis=0
        )
        index = np.argmin(candidates, axis=0)
        t = np.take_along_axis(candidates, index[None], axis=0)[0]
        surface = np.where(np.isfinite(t), index + 1, Surface.NONE).astype(np.int8)
        return t, surface, t_side

    def normals(self, points: FloatArray, surface: Int8Array) -> FloatArray:
        """Outward unit normals (..., 3) at hit points of the given surfaces (NaN for NONE)."""
        w = points - self.base_m
        wa = _dot(w, self.axis)
        radial = w - wa[..., None] * self.axis
        with np.errstate(invalid="ignore", divide="ignore"):
            side = radial / np.linalg.norm(radial, axis=-1, keepdims=True)
        cap = np.where((wa < 0.5 * self.length_m)[..., None], -self.axis, self.axis)
        plane = (
            np.broadcast_to(self.plane_normal, points.shape)
            if self.plane_normal is not None
            else np.full(points.shape, np.nan)
        )
        s = surface[..., None]
        out = np.where(s == Surface.SIDE, side, np.nan)
        out = np.where(s == Surface.CAP, cap, out)
        return np.asarray(np.where(s == Surface.BACKGROUND, plane, out))

    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance (...,) of points from the solid cylinder and the plane (negative inside)."""
        w = points - self.base_m
        wa = _dot(w, self.axis)
        radial = np.linalg.norm(w - wa[..., None] * self.axis, axis=-1) - self.radius_m
        axial = np.maximum(-wa, wa - self.length_m)
        outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
        to_cylinder = np.where((radial <= 0.0) & (axial <= 0.0), np.maximum(radial, axial), outside)
        if self.plane_point_m is None or self.plane_normal is None:
            return np.asarray(to_cylinder)
        to_plane = _dot(points - self.plane_point_m, self.plane_normal)
        return np.asarray(np.minimum(to_cylinder, to_plane))
