"""Camera-based line structured light: laser-stripe pixels to points (weld-seam paper eq. 5, 7).

A camera with pinhole intrinsics (u0, v0, α, β) and, optionally, lens distortion in
OpenCV's model (k1, k2, p1, p2[, k3[, k4, k5, k6]]), both from Zhang's calibration, sees a
laser stripe that lies in the light plane ``a X + b Y + c Z + d = 0`` (camera frame, X right,
Y down, Z along the optical axis, metres). A stripe pixel (u, v), undistorted to the normalised
image point ``(x_n, y_n)`` (``cv2.undistortPoints``; without distortion
``((u − u0)/α, (v − v0)/β)``), is the ray ``(X, Y, Z) = Z · (x_n, y_n, 1)``; meeting the plane
(eq. 7)::

    Z = −d / (a x_n + b y_n + c),  X = Z x_n,  Y = Z y_n.

Units: with X, Y, Z in metres, ``d`` is in metres when (a, b, c) is dimensionless. The paper
gives its plane in millimetres (eq. 18: 41.29 X + 0.30 Y + 3.18 Z + 1000 = 0); divide ``d``
(only) by 1000 to get metres: 41.29 X + 0.30 Y + 3.18 Z + 1 = 0.

The sensor frame of this package has the laser plane as its x-z plane (y = 0, z the depth).
:func:`T_camera_sensor_from_light_plane` gives the fixed transform from the plane:

- origin: the foot of the perpendicular from the camera centre onto the plane;
- y: the plane's unit normal, signed so that the camera centre lies at positive y (where the
  simulator puts a profiler's triangulation camera, ``camera_baseline_m`` along +y);
- z: the optical axis projected into the plane (depth grows along it, as the camera's Z);
- x = y × z.

Sensor-frame points are then ``inv(T_camera_sensor) · p_camera`` (exactly y = 0 up to
rounding), and a hand-eye found for this sensor frame converts to the camera's as
``T_flange_camera = T_flange_sensor · inv(T_camera_sensor)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ...errors import InputError
from ...geometry import apply_transform, invert_transform, transform_from_rotation_translation
from ...types import FloatArray

#: A ray meeting the light plane at a smaller |cos| of the angle to its normal than this
#: (relative) is taken as parallel to the plane and gives NaN.
PARALLEL_TOLERANCE = 1e-12
#: OpenCV's iterative undistortion stops after this many steps or a step below
#: UNDISTORT_EPS (normalised units); its default of 5 steps leaves ~1e-6 (a micrometre at
#: 0.3 m) on wide-angle lenses.
UNDISTORT_STEPS = 50
UNDISTORT_EPS = 1e-14


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in pixels (paper §2.1: u0, v0, α, β).

    Attributes
    ----------
    u0, v0 : float
        Principal point, pixels.
    alpha, beta : float
        Focal lengths in pixels along u and v (focal length over pixel size).
    distortion : tuple of float
        Lens distortion in OpenCV's order (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3,
        s4[, τx, τy]]]]), dimensionless; empty for pixels that are already undistorted.
    """

    u0: float
    v0: float
    alpha: float
    beta: float
    distortion: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        values = (self.u0, self.v0, self.alpha, self.beta)
        if not all(np.isfinite(values)) or self.alpha <= 0.0 or self.beta <= 0.0:
            raise InputError(
                "camera intrinsics need finite u0, v0 and positive focal lengths alpha, beta "
                f"(pixels), got u0={self.u0}, v0={self.v0}, alpha={self.alpha}, beta={self.beta}"
            )
        if len(self.distortion) not in (0, 4, 5, 8, 12, 14) or not all(
            np.isfinite(self.distortion)
        ):
            raise InputError(
                "camera distortion needs 4, 5, 8, 12 or 14 finite coefficients in OpenCV's "
                f"order (k1, k2, p1, p2[, k3[, k4, k5, k6[, ...]]]) or none, got {self.distortion}"
            )

    @property
    def K(self) -> FloatArray:
        """The camera matrix (3, 3), pixels."""
        return np.array([[self.alpha, 0.0, self.u0], [0.0, self.beta, self.v0], [0.0, 0.0, 1.0]])


def normalised_from_pixels(pixels_uv: ArrayLike, intrinsics: CameraIntrinsics) -> FloatArray:
    """Normalised image points (x_n, y_n) (N, 2) of pixels (N, 2), lens distortion removed.

    With distortion coefficients, OpenCV's iterative inversion of its distortion model
    (``cv2.undistortPoints``); without, ``((u − u0)/α, (v − v0)/β)``.
    """
    uv = np.asarray(pixels_uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise InputError(f"pixels must have shape (N, 2) (u, v), got {uv.shape}")
    if not intrinsics.distortion:
        return np.column_stack(
            [
                (uv[:, 0] - intrinsics.u0) / intrinsics.alpha,
                (uv[:, 1] - intrinsics.v0) / intrinsics.beta,
            ]
        )
    import cv2  # only cameras with distortion need OpenCV (~0.5 s to import)

    undistorted = cv2.undistortPoints(
        uv.reshape(-1, 1, 2),
        intrinsics.K,
        np.array(intrinsics.distortion, dtype=np.float64),
        criteria=(
            cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
            UNDISTORT_STEPS,
            UNDISTORT_EPS,
        ),
    )
    return np.asarray(undistorted, dtype=np.float64).reshape(-1, 2)


#: The weld-seam paper's intrinsics (§3: a MER-500-14GC camera, 2592 x 1944 pixels).
PAPER_INTRINSICS = CameraIntrinsics(u0=1446.36, v0=978.11, alpha=7505.75, beta=7499.5)
#: The paper's light plane (eq. 18) with d converted from mm to m: (a, b, c, d).
PAPER_LIGHT_PLANE = (41.29, 0.30, 3.18, 1.0)


def check_light_plane(plane: ArrayLike) -> FloatArray:
    """Validate a light plane (a, b, c, d) in the camera frame; returns it as float64 (4,).

    Raises
    ------
    InputError
        If it is not 4 finite numbers, (a, b, c) is zero, or the plane passes through the
        camera centre (d = 0: every stripe pixel would be ambiguous).
    """
    p = np.asarray(plane, dtype=np.float64)
    if p.shape != (4,) or not np.all(np.isfinite(p)):
        raise InputError(f"the light plane must be 4 finite numbers (a, b, c, d), got {p!r}")
    norm = float(np.linalg.norm(p[:3]))
    if norm == 0.0:
        raise InputError("the light plane's normal (a, b, c) is zero")
    if abs(p[3]) <= 1e-12 * norm:
        raise InputError(
            "the light plane passes through the camera centre (d = 0), so depth cannot be "
            "triangulated; check the plane calibration"
        )
    return p


def camera_points_from_pixels(
    pixels_uv: ArrayLike, intrinsics: CameraIntrinsics, plane: ArrayLike
) -> FloatArray:
    """Triangulate stripe pixels on the light plane (paper eq. 7).

    Parameters
    ----------
    pixels_uv : array-like, shape (N, 2)
        Stripe pixel coordinates (u, v), as the camera gives them (``intrinsics.distortion``
        removes the lens distortion, if any).
    intrinsics : CameraIntrinsics
    plane : array-like, shape (4,)
        Light plane (a, b, c, d) in the camera frame, d in m.

    Returns
    -------
    ndarray, shape (N, 3)
        Points (X, Y, Z) in the camera frame, m. NaN rows for rays parallel to the plane or
        meeting it behind the camera (Z <= 0).
    """
    a, b, c, d = check_light_plane(plane)
    x_n, y_n = normalised_from_pixels(pixels_uv, intrinsics).T
    denominator = a * x_n + b * y_n + c
    ray_norm = np.sqrt(x_n**2 + y_n**2 + 1.0) * float(np.linalg.norm([a, b, c]))
    ok = np.abs(denominator) > PARALLEL_TOLERANCE * ray_norm
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = np.where(ok, -d / np.where(ok, denominator, 1.0), np.nan)
    Z = np.where(Z > 0.0, Z, np.nan)
    return np.column_stack([Z * x_n, Z * y_n, Z])


def T_camera_sensor_from_light_plane(plane: ArrayLike) -> FloatArray:
    """The sensor frame (laser plane = x-z) in the camera frame, see the module docstring.

    Parameters
    ----------
    plane : array-like, shape (4,)
        Light plane (a, b, c, d) in the camera frame, d in m.

    Returns
    -------
    ndarray, shape (4, 4)
        ``T_camera_sensor``: maps sensor-frame points into the camera frame.

    Raises
    ------
    InputError
        For an invalid plane, or one containing the optical axis direction (the camera
        would look along the plane, not at the stripe on it).
    """
    p = check_light_plane(plane)
    norm = float(np.linalg.norm(p[:3]))
    n, distance = p[:3] / norm, p[3] / norm  # n · X + distance = 0
    # The camera centre (the camera origin) lies at y = |distance| in the sensor frame.
    y = n if distance > 0.0 else -n
    optical = np.array([0.0, 0.0, 1.0])
    z = optical - float(optical @ y) * y
    if float(np.linalg.norm(z)) < 1e-6:
        raise InputError(
            "the light plane is perpendicular to the optical axis: the camera looks straight "
            "along the plane's normal and sees no triangulation baseline"
        )
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    origin = -distance * n
    return transform_from_rotation_translation(np.column_stack([x, y, z]), origin)


def sensor_points_from_pixels(
    pixels_uv: ArrayLike, intrinsics: CameraIntrinsics, plane: ArrayLike
) -> FloatArray:
    """Stripe pixels to points in the sensor frame (laser plane x-z, y = 0), m.

    :func:`camera_points_from_pixels` followed by ``inv(T_camera_sensor)``; shape (N, 3),
    NaN rows where the ray misses the plane.
    """
    camera = camera_points_from_pixels(pixels_uv, intrinsics, plane)
    return apply_transform(invert_transform(T_camera_sensor_from_light_plane(plane)), camera)
