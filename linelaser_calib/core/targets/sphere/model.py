"""The sphere's geometry: profile circles to sphere centres, and the fixed-point solve.

A sphere of radius R with centre c (base frame) is scanned from flange poses T_j =
``T_base_flange[j]``. Profile j is a circle in the laser plane (sensor y = 0) with centre
(x_j, z_j) and radius r_j ≤ R; the sphere centre seen from the sensor is

    p_j = (x_j, s·h_j, z_j),   h_j = √(R² − r_j²),

with s = +1 or −1: the side of the laser plane (sensor ±y) the centre lies on. One circle
cannot tell the side; the whole set can, because only the right side gives centres that map
to one fixed base-frame point through a rotation.

The fixed point (as in the tools that calibrate a profiler on a sphere):

    R_j (R_X p_j + t_X) + t_j = c   for every j,

is linear in the nine entries of R_X, in t_X and in c: three equations per profile, fifteen
unknowns (:func:`solve_fixed_point_linear`). The 3×3 block is then projected onto SO(3)
(nearest rotation by SVD) and all three are polished by least squares on the same
equations with the rotation parametrised minimally (:func:`polish_fixed_point`). The side
is chosen by solving with both and keeping the smaller scatter of the centres
(:func:`resolve_side`); an unknown radius by the radius that minimises it
(:func:`estimate_radius`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares, minimize_scalar

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.geometry import (
    matrix_from_rotvec,
    project_to_so3,
    skews,
    transform_from_rotation_translation,
)
from linelaser_calib.core.types import FloatArray

#: Side labels in results, by sign of sensor y.
SIDE_LABELS = {1: "+y", -1: "-y"}
#: The side is called ambiguous when the worse side's centre scatter is less than this many
#: times the better side's.
SIDE_RATIO = 3.0
#: Largest sphere radius searched when the radius is unknown, as a multiple of the largest
#: circle radius.
RADIUS_SEARCH_FACTOR = 20.0


def side_from_label(label: str) -> int:
    """+1 or −1 from ``+y`` or ``-y`` (the result's ``centre_side``)."""
    for sign, text in SIDE_LABELS.items():
        if label == text:
            return sign
    raise InputError(f"the sphere centre side must be '+y' or '-y', got {label!r}")


def centres_in_sensor(
    centres_xz: ArrayLike, radii_m: ArrayLike, sphere_radius_m: float, side: int
) -> FloatArray:
    """Sphere centres seen from the sensor (K, 3), m, from the profile circles.

    Parameters
    ----------
    centres_xz : array-like, shape (K, 2)
        Circle centres in the laser plane, m.
    radii_m : array-like, shape (K,)
        Circle radii, m. A radius above ``sphere_radius_m`` (noise at the equator) counts as
        equal to it (the centre is then in the plane).
    sphere_radius_m : float
    side : int
        +1 or −1: the sign of the centres' sensor y.
    """
    xz = np.asarray(centres_xz, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(radii_m, dtype=np.float64).reshape(-1)
    h = np.sqrt(np.maximum(sphere_radius_m**2 - r**2, 0.0))
    return np.column_stack([xz[:, 0], side * h, xz[:, 1]])


def solve_fixed_point_linear(
    T_base_flange: ArrayLike, centres_sensor: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """The linear fixed-point solve: R_X (projected to SO(3)), t_X and c.

    Parameters
    ----------
    T_base_flange : array-like, shape (K, 4, 4)
    centres_sensor : array-like, shape (K, 3)
        The sphere centre p_j seen from each sensor pose, m.

    Returns
    -------
    T_flange_sensor : ndarray, shape (4, 4)
    centre_base : ndarray, shape (3,)
        m.

    Raises
    ------
    DegenerateError
        When the 15 unknowns are not determined (fewer than 5 poses, or poses that do not
        rotate the flange).
    """
    T = np.asarray(T_base_flange, dtype=np.float64)
    p = np.asarray(centres_sensor, dtype=np.float64)
    K = len(T)
    A = np.zeros((3 * K, 15))
    # Row-major vec(R_X): (R_j R_X p)_i = Σ_ab R_j[i, a] R_X[a, b] p[b].
    A[:, :9] = np.einsum("kia,kb->kiab", T[:, :3, :3], p).reshape(3 * K, 9)
    A[:, 9:12] = T[:, :3, :3].reshape(3 * K, 3)
    A[:, 12:] = -np.tile(np.eye(3), (K, 1))
    b = -T[:, :3, 3].reshape(3 * K)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    solution, _, rank, singular = np.linalg.lstsq(A / scale, b, rcond=None)
    if rank < 15 or singular[-1] < 1e-9 * singular[0]:
        raise DegenerateError(
            f"the {K} flange poses cannot determine the hand-eye from the sphere centres: the "
            "linear fixed-point equations are singular. Use at least 5 poses and rotate the "
            "flange by 20 deg or more about two different axes between them"
        )
    x = solution / scale
    R = project_to_so3(x[:9].reshape(3, 3))
    return transform_from_rotation_translation(R, x[9:12]), np.asarray(x[12:])


def fixed_point_residuals(
    T_base_flange: FloatArray, centres_sensor: FloatArray, T_flange_sensor: FloatArray
) -> FloatArray:
    """Each profile's sphere centre mapped into the base frame (K, 3), m."""
    sensor = np.einsum("ij,kj->ki", T_flange_sensor[:3, :3], centres_sensor)
    sensor += T_flange_sensor[:3, 3]
    return np.asarray(
        np.einsum("kij,kj->ki", T_base_flange[:, :3, :3], sensor) + T_base_flange[:, :3, 3]
    )


def centre_scatter_m(points_base: FloatArray) -> float:
    """RMS distance (m) of points (K, 3) from their mean: the centres' scatter."""
    d = points_base - points_base.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def polish_fixed_point(
    T_base_flange: ArrayLike,
    centres_sensor: ArrayLike,
    T_flange_sensor: ArrayLike,
    centre_base: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Least squares on R_j (R_X p_j + t_X) + t_j − c with R_X = R̂·Exp(θ); start from a solve.

    Returns the polished T_flange_sensor (4, 4) and c (3,), m.
    """
    T = np.asarray(T_base_flange, dtype=np.float64)
    p = np.asarray(centres_sensor, dtype=np.float64)
    X0 = np.asarray(T_flange_sensor, dtype=np.float64)
    R0 = X0[:3, :3]

    def transform(v: FloatArray) -> FloatArray:
        return transform_from_rotation_translation(R0 @ matrix_from_rotvec(v[:3]), v[3:6])

    def residual(v: FloatArray) -> FloatArray:
        return (fixed_point_residuals(T, p, transform(v)) - v[6:]).reshape(-1)

    start = np.concatenate([np.zeros(3), X0[:3, 3], np.asarray(centre_base, dtype=np.float64)])
    solved = least_squares(residual, start, method="lm", xtol=1e-15, ftol=1e-15)
    return transform(solved.x), np.asarray(solved.x[6:])


def fixed_point_information(
    T_base_flange: ArrayLike, centres_sensor: ArrayLike, T_flange_sensor: ArrayLike
) -> FloatArray:
    """Information (6, 6) of the hand-eye [θ (sensor axes), ρ (flange axes)] in the
    fixed-point equations, per unit variance of the mapped centres, with c marginalised.

    The residual R_j (R_X p_j + t_X) + t_j − c has the Jacobians −R_j R_X [p_j]ₓ (θ, with
    R_X ← R_X·Exp(θ)), R_j (ρ) and −I (c).
    """
    T = np.asarray(T_base_flange, dtype=np.float64)
    p = np.asarray(centres_sensor, dtype=np.float64)
    R = np.asarray(T_flange_sensor, dtype=np.float64)[:3, :3]
    K = len(T)
    J = np.zeros((K, 3, 9))
    J[:, :, :3] = -np.einsum("kij,jl,klm->kim", T[:, :3, :3], R, skews(p))
    J[:, :, 3:6] = T[:, :3, :3]
    J[:, :, 6:] = -np.eye(3)
    J2 = J.reshape(3 * K, 9)
    H = J2.T @ J2
    S = H[:6, :6] - H[:6, 6:] @ np.linalg.solve(H[6:, 6:], H[6:, :6])
    return np.asarray(0.5 * (S + S.T))


@dataclass(frozen=True)
class FixedPointSolution:
    """The fixed-point solve for one side and radius.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    centre_base : ndarray, shape (3,)
        Sphere centre in the base frame, m.
    side : int
        +1 or −1 (sensor ±y).
    radius_m : float
    centres_sensor : ndarray, shape (K, 3)
        The sphere centre seen from each pose, m.
    scatter_m : float
        RMS distance of the mapped centres from c, m.
    """

    T_flange_sensor: FloatArray
    centre_base: FloatArray
    side: int
    radius_m: float
    centres_sensor: FloatArray
    scatter_m: float


def solve_fixed_point(
    T_base_flange: ArrayLike,
    centres_xz: ArrayLike,
    radii_m: ArrayLike,
    sphere_radius_m: float,
    side: int,
    *,
    polish: bool = True,
) -> FixedPointSolution:
    """Linear solve, projection onto SO(3) and (unless ``polish`` is False) polish, for one
    side and radius; the scatter is about c (polished) or about the centres' mean."""
    T = np.asarray(T_base_flange, dtype=np.float64)
    p = centres_in_sensor(centres_xz, radii_m, sphere_radius_m, side)
    X, c = solve_fixed_point_linear(T, p)
    mapped = fixed_point_residuals(T, p, X)
    if polish:
        X, c = polish_fixed_point(T, p, X, c)
        mapped = fixed_point_residuals(T, p, X)
    else:
        c = mapped.mean(axis=0)
    scatter = float(np.sqrt(np.mean(np.sum((mapped - c) ** 2, axis=1))))
    return FixedPointSolution(X, c, side, float(sphere_radius_m), p, scatter)


def resolve_side(
    T_base_flange: ArrayLike,
    centres_xz: ArrayLike,
    radii_m: ArrayLike,
    sphere_radius_m: float,
    *,
    polish: bool = True,
) -> tuple[FixedPointSolution, FixedPointSolution]:
    """Solve with the centre on either side; returns (better, worse) by centre scatter."""
    a, b = (
        solve_fixed_point(T_base_flange, centres_xz, radii_m, sphere_radius_m, side, polish=polish)
        for side in (1, -1)
    )
    return (a, b) if a.scatter_m <= b.scatter_m else (b, a)


def side_is_clear(better: FixedPointSolution, worse: FixedPointSolution) -> bool:
    """Whether the data tell the side: the worse side scatters :data:`SIDE_RATIO` times more.

    When every circle has about the same radius and the flange barely turns, a mirrored
    hand-eye explains the other side as well, and the side must be given.
    """
    return worse.scatter_m > SIDE_RATIO * max(better.scatter_m, 1e-12)


def estimate_radius(
    T_base_flange: ArrayLike,
    centres_xz: ArrayLike,
    radii_m: ArrayLike,
    side: int | None,
) -> float:
    """The sphere radius (m) whose fixed-point solve scatters the centres least.

    Searched between the largest circle radius and :data:`RADIUS_SEARCH_FACTOR` times it
    (log-spaced grid, then a bounded 1-D minimisation around the best grid point), over both
    sides when ``side`` is None, with the linear solve alone (the polish moves the scatter
    far less than the radius does).
    """
    r = np.asarray(radii_m, dtype=np.float64)
    lo, hi = float(np.max(r)), float(np.max(r)) * RADIUS_SEARCH_FACTOR

    def scatter(radius: float) -> float:
        if side is None:
            return resolve_side(T_base_flange, centres_xz, r, radius, polish=False)[0].scatter_m
        return solve_fixed_point(T_base_flange, centres_xz, r, radius, side, polish=False).scatter_m

    grid = lo * np.exp(np.linspace(0.0, math.log(hi / lo), 40))
    values = [scatter(float(g)) for g in grid]
    k = int(np.argmin(values))
    bracket = (float(grid[max(k - 1, 0)]), float(grid[min(k + 1, len(grid) - 1)]))
    found = minimize_scalar(scatter, bounds=bracket, method="bounded", options={"xatol": 1e-7})
    return float(found.x) if float(found.fun) <= values[k] else float(grid[k])


def fit_sphere_centre(
    T_base_flange: ArrayLike,
    points: list[FloatArray],
    T_flange_sensor: ArrayLike,
    sphere_radius_m: float,
    start_m: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """The sphere centre (3,) that fits the points best under a hand-eye, and the distances.

    Every sample's points (N_j, 3, sensor frame) are mapped into the base frame through its
    recorded flange pose and ``T_flange_sensor`` (no pose corrections), and the centre of a
    sphere of the given radius is fitted by least squares from ``start_m``. This judges a
    hand-eye by the data alone: how well the scans, mapped with it, form one sphere.

    Returns
    -------
    centre : ndarray, shape (3,)
        m, base frame.
    distances : ndarray, shape (ΣN_j,)
        Signed point-to-sphere distances, m.
    """
    T = np.asarray(T_base_flange, dtype=np.float64) @ np.asarray(T_flange_sensor, dtype=np.float64)
    mapped = np.concatenate([p @ Tk[:3, :3].T + Tk[:3, 3] for p, Tk in zip(points, T, strict=True)])

    def residual(c: FloatArray) -> FloatArray:
        return np.asarray(np.linalg.norm(mapped - c, axis=1) - sphere_radius_m)

    solved = least_squares(residual, np.asarray(start_m, dtype=np.float64), method="lm")
    return np.asarray(solved.x), residual(solved.x)
