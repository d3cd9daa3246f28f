"""Synthetic ellipse centres from a known hand-eye and cylinder axis (benches and tests).

Geometry only, no profiles: for each sample a point Q on the true axis and a true sensor pose
are chosen so that the laser plane (sensor x-z plane) passes through Q and cuts the axis at
an angle in a given range; then Q expressed in the sensor frame is the true ellipse centre
(x_c, z_c) (the centre of the plane's ellipse on a cylinder is where the plane meets the axis),
and the flange pose is T_base_sensor · T_flange_sensor⁻¹.

The noise model of the paper's §4.1.1 (robot ±0.1 mm, sensor ±5 µm) is read as 1σ Gaussian
errors: the reported flange translation is perturbed by ``robot_sigma_m`` per axis and the
centre by ``sensor_sigma_m`` per coordinate.

The tests import this module through ``test/_synthetic_centres.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linelaser_calib.core.geometry import (
    invert_transform,
    matrix_from_rotvec,
    project_to_so3,
    transform_from_rotation_translation,
)
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FloatArray

MM = 1e-3

#: The paper's eq. 17 (rotation as printed, not quite orthonormal) and translation, mm.
PAPER_T_EL_MM = np.array(
    [
        [0.5771, 0.4940, 0.6503, 150.0],
        [-0.8153, 0.3021, 0.4940, 200.0],
        [0.0475, -0.8153, 0.5771, 250.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


@dataclass(frozen=True)
class CentreData:
    """Centres and flange poses as a calibration would receive them, with their truth.

    Attributes
    ----------
    centres_xz : ndarray, shape (M, 2)
        Measured centres in the sensor frame, m.
    T_base_flange : ndarray, shape (M, 4, 4)
        Reported flange poses (m).
    T_flange_sensor : ndarray, shape (4, 4)
        True hand-eye.
    cylinder : Cylinder
        True axis (radius unused, NaN).
    """

    centres_xz: FloatArray
    T_base_flange: FloatArray
    T_flange_sensor: FloatArray
    cylinder: Cylinder


def paper_setup(
    direction: tuple[float, float, float] = (3.0, 1.0, 1.0),
) -> tuple[FloatArray, Cylinder]:
    """The §4.1.1 truth: T_EL of eq. 17 projected onto SO(3), axis through (1, 1, 1) mm.

    Parameters
    ----------
    direction : 3 floats
        Axis direction (normalised here); eq. 16 is (3, 1, 1). Table 4 varies it.
    """
    T = transform_from_rotation_translation(
        project_to_so3(PAPER_T_EL_MM[:3, :3]), PAPER_T_EL_MM[:3, 3] * MM
    )
    d = np.asarray(direction, dtype=np.float64)
    return T, Cylinder(point=np.full(3, MM), direction=d / np.linalg.norm(d), radius=float("nan"))


def random_setup(rng: np.random.Generator) -> tuple[FloatArray, Cylinder]:
    """A random hand-eye (any rotation, |t| ≤ 0.25 m) and a random axis in the workspace.

    The axis passes through a point in [−0.8, 0.8] × [−0.8, 0.8] × [−0.2, 0.8] m with a
    uniformly random direction.
    """
    R = matrix_from_rotvec(_random_unit(rng) * rng.uniform(0.0, np.pi))
    t = _random_unit(rng) * rng.uniform(0.0, 0.25)
    point = rng.uniform([-0.8, -0.8, -0.2], [0.8, 0.8, 0.8])
    return transform_from_rotation_translation(R, t), Cylinder(
        point=point, direction=_random_unit(rng), radius=float("nan")
    )


def synthetic_centres(
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
    n_poses: int,
    rng: np.random.Generator,
    *,
    robot_sigma_m: float = 0.0,
    sensor_sigma_m: float = 0.0,
    cut_angle_deg: tuple[float, float] = (40.0, 75.0),
    standoff_m: tuple[float, float] = (0.08, 0.16),
    line_offset_m: float = 0.02,
    axis_span_m: float = 0.15,
    azimuth_spread_deg: float = 180.0,
) -> CentreData:
    """Centres seen from ``n_poses`` random sensor poses around the axis.

    Parameters
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        True hand-eye, m.
    cylinder : Cylinder
        True axis, m.
    n_poses : int
    rng : numpy.random.Generator
    robot_sigma_m, sensor_sigma_m : float
        1σ flange translation error and centre error, m.
    cut_angle_deg : (float, float)
        Range of the angle between the laser plane and the axis, deg.
    standoff_m : (float, float)
        Range of the centre depth z_c, m.
    line_offset_m : float
        |x_c| bound, m.
    axis_span_m : float
        Length of the axis segment the centres are spread over, m.
    azimuth_spread_deg : float
        The viewing directions lie within ± this angle (deg) of one random direction around
        the axis; 180 views from all around, small values from one side as a robot would.
    """
    n = cylinder.direction / np.linalg.norm(cylinder.direction)
    e1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    azimuth0 = rng.uniform(0.0, 2.0 * np.pi)
    T_sensor_flange = invert_transform(T_flange_sensor)
    centres = np.empty((n_poses, 2))
    T_base_flange = np.empty((n_poses, 4, 4))
    for j in range(n_poses):
        q = cylinder.point + rng.uniform(-0.5, 0.5) * axis_span_m * n
        azimuth = azimuth0 + np.deg2rad(rng.uniform(-azimuth_spread_deg, azimuth_spread_deg))
        view = np.cos(azimuth) * e1 + np.sin(azimuth) * e2  # sensor z, perpendicular to the axis
        side = np.cross(n, view)
        tilt = np.deg2rad(90.0 - rng.uniform(*cut_angle_deg))  # angle between sensor y and axis
        y_axis = np.cos(tilt) * n + np.sin(tilt) * rng.choice([-1.0, 1.0]) * side
        x_axis = np.cross(y_axis, view)
        R_sensor = np.column_stack([x_axis, y_axis, view])
        R_sensor = R_sensor @ matrix_from_rotvec([0.0, rng.uniform(-0.3, 0.3), 0.0])
        c = np.array([rng.uniform(-line_offset_m, line_offset_m), 0.0, rng.uniform(*standoff_m)])
        T_base_sensor = transform_from_rotation_translation(R_sensor, q - R_sensor @ c)
        T_base_flange[j] = T_base_sensor @ T_sensor_flange
        T_base_flange[j, :3, 3] += rng.normal(0.0, robot_sigma_m, 3)
        centres[j] = c[[0, 2]] + rng.normal(0.0, sensor_sigma_m, 2)
    return CentreData(
        centres_xz=centres,
        T_base_flange=T_base_flange,
        T_flange_sensor=np.asarray(T_flange_sensor, dtype=np.float64),
        cylinder=cylinder,
    )


def axis_errors(estimate: Cylinder, truth: Cylinder) -> tuple[float, float]:
    """Angle between two axes (rad, sign-free) and distance of the estimated point (m).

    The distance is from ``estimate.point`` to the true axis line.
    """
    d_est = estimate.direction / np.linalg.norm(estimate.direction)
    d_true = truth.direction / np.linalg.norm(truth.direction)
    angle = float(np.arccos(np.clip(abs(float(d_est @ d_true)), 0.0, 1.0)))
    w = estimate.point - truth.point
    return angle, float(np.linalg.norm(w - float(w @ d_true) * d_true))


def _random_unit(rng: np.random.Generator) -> FloatArray:
    v = rng.normal(size=3)
    return np.asarray(v / np.linalg.norm(v))
