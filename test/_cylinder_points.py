"""Tiny self-contained generator of cylinder profiles for the refinement tests and study.

A stand-in for ``linelaser_calib.sim`` (written separately): exact point-on-cylinder
geometry, Gaussian sensor noise on the profile x and z, Gaussian robot noise on the reported
flange poses.

Geometry: in the cylinder frame (axis = z through the origin) a sensor pose is built from the
viewing azimuth ψ (the sensor looks at the axis from the direction (cos ψ, sin ψ, 0)), the cut
angle α between the laser plane and the cylinder's cross-section (α = 0 cuts a circle), a roll
γ of the viewing direction inside the laser plane, a height h along the axis, a stand-off and
a shift along the laser line. The laser plane (sensor x-z plane) always contains the axis point at
height h, which is at depth ``radius + standoff`` on the sensor z axis before the shift.
The profile is the near-side arc of the plane's ellipse: cylinder points at angles φ within
``half_arc_deg`` of the sensor's azimuth, at the height where they meet the plane.

Motions (``motion``):

- ``diverse``: every pose draws ψ, α, γ, h and the shift (the good case);
- ``narrow``: orientations within about ±2 deg, the origin translated in 3-D (weak);
- ``same_orientation``: one orientation, the origin translated in 3-D;
- ``along_axis``: one orientation, translated only along the cylinder axis;
- ``about_axis``: one pose rotated about the cylinder axis (orbiting it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.geometry import (
    FloatArray,
    invert_transform,
    matrix_from_rotvec,
    project_to_so3,
    transform_from_rotation_translation,
)
from linelaser_calib.core.targets.cylinder.model import Cylinder

#: The cylinder paper's simulated hand-eye (eq. 17, mm), projected onto SO(3) below.
_PAPER_T_EL_MM = np.array(
    [
        [0.5771, 0.4940, 0.6503, 150.0],
        [-0.8153, 0.3021, 0.4940, 200.0],
        [0.0475, -0.8153, 0.5771, 250.0],
    ]
)


@dataclass(frozen=True)
class Scene:
    """Simulated data and its truth.

    Attributes
    ----------
    points : list of ndarray, shape (N, 3)
        Noisy sensor-frame profile points, m (y = 0).
    T_base_flange : ndarray, shape (M, 4, 4)
        Reported (noisy) flange poses.
    T_base_flange_true : ndarray, shape (M, 4, 4)
    T_flange_sensor : ndarray, shape (4, 4)
        True hand-eye.
    cylinder : Cylinder
        True cylinder in the base frame.
    """

    points: list[FloatArray]
    T_base_flange: FloatArray
    T_base_flange_true: FloatArray
    T_flange_sensor: FloatArray
    cylinder: Cylinder


def paper_truth(radius: float = 0.02) -> tuple[FloatArray, Cylinder]:
    """Hand-eye of the paper's eq. 17 and its axis (eq. 16) through (1, 1, 1) mm, in m."""
    T = transform_from_rotation_translation(
        project_to_so3(_PAPER_T_EL_MM[:, :3]), _PAPER_T_EL_MM[:, 3] * 1e-3
    )
    d = np.array([3.0, 1.0, 1.0]) / np.sqrt(11.0)
    return T, Cylinder(point=np.full(3, 1e-3), direction=d, radius=radius)


def _cylinder_frame(cylinder: Cylinder) -> FloatArray:
    """T_base_cyl (4, 4): z along the axis, origin on the axis."""
    d = cylinder.direction / np.linalg.norm(cylinder.direction)
    u = np.cross(d, np.eye(3)[int(np.argmin(np.abs(d)))])
    u /= np.linalg.norm(u)
    return transform_from_rotation_translation(
        np.column_stack([u, np.cross(d, u), d]), cylinder.point
    )


def _sensor_pose(
    psi: float,
    alpha: float,
    gamma: float,
    height: float,
    shift: float,
    radius: float,
    standoff: float,
) -> FloatArray:
    """T_cyl_sensor (4, 4) from the viewing parameters (see the module docstring)."""
    e = np.array([np.cos(psi), np.sin(psi), 0.0])
    tangent = np.array([-np.sin(psi), np.cos(psi), 0.0])
    s = np.cos(alpha) * tangent + np.sin(alpha) * np.array([0.0, 0.0, 1.0])
    y_axis = np.cross(e, s)
    z_axis = -(np.cos(gamma) * e + np.sin(gamma) * s)
    x_axis = np.cross(y_axis, z_axis)
    R = np.column_stack([x_axis, y_axis, z_axis])
    origin = np.array([0.0, 0.0, height]) - (radius + standoff) * z_axis + shift * x_axis
    return transform_from_rotation_translation(R, origin)


def _profile(T_cyl_sensor: FloatArray, radius: float, n_points: int, half_arc: float) -> FloatArray:
    """Noise-free sensor-frame points (n_points, 3) of the near arc of the plane's ellipse."""
    n = T_cyl_sensor[:3, 1]
    o = T_cyl_sensor[:3, 3]
    phi0 = np.arctan2(o[1], o[0])
    phi = phi0 + np.linspace(-half_arc, half_arc, n_points)
    ring = radius * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    height = (n @ o - ring @ n) / n[2]
    points_cyl = ring + np.outer(height, [0.0, 0.0, 1.0])
    T_sensor_cyl = invert_transform(T_cyl_sensor)
    p = points_cyl @ T_sensor_cyl[:3, :3].T + T_sensor_cyl[:3, 3]
    p[:, 1] = 0.0
    return p


def make_scene(
    rng: np.random.Generator,
    *,
    n_poses: int = 50,
    n_points: int = 800,
    radius: float = 0.02,
    sensor_sigma: float = 5e-6,
    robot_sigma_t: float = 1e-4,
    robot_sigma_r: float = float(np.deg2rad(0.01)),
    standoff: float = 0.1,
    motion: str = "diverse",
    half_arc_deg: float = 55.0,
    truth: tuple[FloatArray, Cylinder] | None = None,
) -> Scene:
    """Simulate one calibration run (see the module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
    n_poses, n_points : int
    radius, standoff : float
        m. The ``diverse`` motion varies the stand-off by ±30 %.
    sensor_sigma : float
        1σ noise on each point's x and z, m.
    robot_sigma_t, robot_sigma_r : float
        1σ per axis of the reported flange translation (m) and rotation (rad).
    motion : str
        ``diverse``, ``narrow``, ``same_orientation``, ``along_axis`` or ``about_axis``.
    truth : (T_flange_sensor, Cylinder), optional
        Default: the paper's eq. 16-17.
    """
    T_flange_sensor, cylinder = truth if truth is not None else paper_truth(radius)
    cylinder = Cylinder(cylinder.point, cylinder.direction, radius)
    T_base_cyl = _cylinder_frame(cylinder)
    T_sensor_flange = invert_transform(T_flange_sensor)
    sign = rng.choice([-1.0, 1.0])
    base = (
        rng.uniform(-0.5, 0.5),
        sign * np.deg2rad(rng.uniform(50.0, 65.0)),
        0.1,
        0.0,
        0.0,
        standoff,
    )
    T_true = np.empty((n_poses, 4, 4))
    T_meas = np.empty((n_poses, 4, 4))
    points = []
    for j in range(n_poses):
        psi, alpha, gamma, height, shift, depth = base
        if motion == "diverse":
            psi = base[0] + rng.uniform(-0.9, 0.9)
            alpha = rng.choice([-1.0, 1.0]) * np.deg2rad(rng.uniform(40.0, 75.0))
            gamma = rng.uniform(-0.3, 0.3)
            height = rng.uniform(-0.03, 0.03)
            shift = rng.uniform(-0.01, 0.01)
            depth = standoff * rng.uniform(0.7, 1.3)
        elif motion == "narrow":
            psi = base[0] + rng.uniform(-0.03, 0.03)
            alpha = base[1] + rng.uniform(-0.03, 0.03)
            height = rng.uniform(-0.03, 0.03)
            shift = rng.uniform(-0.01, 0.01)
            depth = standoff * rng.uniform(0.8, 1.2)
        elif motion == "same_orientation":
            height = rng.uniform(-0.03, 0.03)
            shift = rng.uniform(-0.005, 0.005)
        elif motion == "along_axis":
            height = rng.uniform(-0.03, 0.03)
        elif motion == "about_axis":
            psi = base[0] + rng.uniform(-0.9, 0.9)
        else:
            raise ValueError(f"unknown motion {motion!r}")
        T_cyl_sensor = _sensor_pose(psi, alpha, gamma, height, shift, radius, depth)
        if motion == "same_orientation":
            T_cyl_sensor[:3, 3] += T_cyl_sensor[:3, :3] @ [0.0, 0.0, rng.uniform(-0.01, 0.01)]
        T_true[j] = T_base_cyl @ T_cyl_sensor @ T_sensor_flange
        T_meas[j] = T_true[j]
        T_meas[j, :3, :3] = (
            matrix_from_rotvec(rng.normal(0.0, robot_sigma_r, 3)) @ T_true[j, :3, :3]
        )
        T_meas[j, :3, 3] += rng.normal(0.0, robot_sigma_t, 3)
        p = _profile(T_cyl_sensor, radius, n_points, np.deg2rad(half_arc_deg))
        p[:, [0, 2]] += rng.normal(0.0, sensor_sigma, (n_points, 2))
        points.append(p)
    return Scene(points, T_meas, T_true, T_flange_sensor, cylinder)


def perturbed_start(
    rng: np.random.Generator,
    scene: Scene,
    angle: float = float(np.deg2rad(1.0)),
    offset: float = 2e-3,
    radius_offset: float = 0.0,
) -> tuple[FloatArray, Cylinder]:
    """Initial hand-eye and cylinder: the truth rotated by ``angle`` (rad) about random axes
    and shifted by ``offset`` (m) in random directions; radius off by ``radius_offset``."""

    def unit() -> FloatArray:
        v = rng.normal(size=3)
        return np.asarray(v / np.linalg.norm(v))

    T0 = scene.T_flange_sensor @ transform_from_rotation_translation(
        matrix_from_rotvec(angle * unit()), offset * unit()
    )
    d = matrix_from_rotvec(angle * unit()) @ scene.cylinder.direction
    cylinder0 = Cylinder(
        scene.cylinder.point + offset * unit(), d, scene.cylinder.radius + radius_offset
    )
    return T0, cylinder0
