"""Stripe pixels to points (weld-seam paper eq. 5, 7) against a synthetic pinhole camera.

Known 3-D points on the light plane are projected to pixels with the pinhole model here,
independently of the module, then triangulated back.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import apply_transform, check_transform, orthonormal_basis
from linelaser_calib.core.targets.known_point.structured_light import (
    PAPER_INTRINSICS,
    PAPER_LIGHT_PLANE,
    CameraIntrinsics,
    T_camera_sensor_from_light_plane,
    camera_points_from_pixels,
    normalised_from_pixels,
    sensor_points_from_pixels,
)


def project(points: np.ndarray, k: CameraIntrinsics) -> np.ndarray:
    """Pinhole projection of camera-frame points (N, 3) to pixels (N, 2)."""
    return np.column_stack(
        [
            k.u0 + k.alpha * points[:, 0] / points[:, 2],
            k.v0 + k.beta * points[:, 1] / points[:, 2],
        ]
    )


def points_on_plane(
    plane: np.ndarray, rng: np.random.Generator, count: int, depth: tuple[float, float]
) -> np.ndarray:
    """Random camera-frame points on the plane with Z in ``depth`` (m)."""
    a, b, c, d = plane
    Y = rng.uniform(-0.02, 0.02, count)
    Z = rng.uniform(*depth, count)
    X = -(b * Y + c * Z + d) / a
    return np.column_stack([X, Y, Z])


def random_plane(rng: np.random.Generator) -> np.ndarray:
    """A light plane at 10-60 mm from the camera centre, crossing the optical axis at
    0.1-0.3 m and making 10-40 deg with it (a triangulation sensor)."""
    angle = np.radians(rng.uniform(10.0, 40.0))
    u, _ = orthonormal_basis([0.0, 0.0, 1.0])
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    side = np.cos(azimuth) * u + np.sin(azimuth) * np.cross([0.0, 0.0, 1.0], u)
    normal = np.cos(angle) * side - np.sin(angle) * np.array([0.0, 0.0, 1.0])
    crossing = np.array([0.0, 0.0, rng.uniform(0.1, 0.3)])
    scale = rng.uniform(0.5, 50.0)  # any scale of (a, b, c, d) describes the same plane
    return np.append(normal, -normal @ crossing) * scale


def test_paper_camera_round_trip_is_exact() -> None:
    rng = np.random.default_rng(0)
    plane = np.array(PAPER_LIGHT_PLANE)
    truth = points_on_plane(plane, rng, 200, (0.24, 0.30))
    pixels = project(truth, PAPER_INTRINSICS)
    # The paper's camera is 2592 x 1944 pixels; the stripe must be in view.
    assert np.all((pixels >= 0.0) & (pixels < [2592.0, 1944.0]))
    back = camera_points_from_pixels(pixels, PAPER_INTRINSICS, plane)
    np.testing.assert_allclose(back, truth, rtol=0.0, atol=1e-12)


def test_random_cameras_and_planes_round_trip() -> None:
    rng = np.random.default_rng(1)
    for _ in range(50):
        k = CameraIntrinsics(
            u0=rng.uniform(300.0, 1500.0),
            v0=rng.uniform(200.0, 1000.0),
            alpha=rng.uniform(500.0, 8000.0),
            beta=rng.uniform(500.0, 8000.0),
        )
        plane = random_plane(rng)
        truth = points_on_plane(plane, rng, 50, (0.08, 0.4))
        truth = truth[truth[:, 2] > 0.0]
        back = camera_points_from_pixels(project(truth, k), k, plane)
        np.testing.assert_allclose(back, truth, rtol=0.0, atol=1e-11)


def test_sensor_frame_has_the_light_plane_as_x_z() -> None:
    rng = np.random.default_rng(2)
    for _ in range(30):
        plane = random_plane(rng)
        T = T_camera_sensor_from_light_plane(plane)
        check_transform(T)
        y, z = T[:3, 1], T[:3, 2]
        normal = plane[:3] / np.linalg.norm(plane[:3])
        assert abs(abs(y @ normal) - 1.0) < 1e-12
        # z is the optical axis projected into the plane: depth grows with the camera's Z.
        assert z[2] > 0.0 and abs(z @ normal) < 1e-12
        assert abs(np.cross(z, [0.0, 0.0, 1.0]) @ y) < 1e-12
        # The origin lies on the plane, the camera centre on the sensor's +y side.
        assert abs(plane[:3] @ T[:3, 3] + plane[3]) < 1e-12 * np.linalg.norm(plane)
        camera_in_sensor = -T[:3, :3].T @ T[:3, 3]
        assert camera_in_sensor[1] > 0.0
        np.testing.assert_allclose(camera_in_sensor[[0, 2]], 0.0, atol=1e-12)

        truth = points_on_plane(plane, rng, 40, (0.08, 0.4))
        truth = truth[truth[:, 2] > 0.0]
        sensor = sensor_points_from_pixels(
            project(truth, PAPER_INTRINSICS), PAPER_INTRINSICS, plane
        )
        np.testing.assert_allclose(sensor[:, 1], 0.0, atol=1e-12)
        np.testing.assert_allclose(apply_transform(T, sensor), truth, atol=1e-11)


def test_rays_parallel_to_or_behind_the_plane_give_nan() -> None:
    plane = np.array([1.0, 0.0, 0.0, -0.05])  # X = 0.05 m
    k = CameraIntrinsics(500.0, 400.0, 1000.0, 1000.0)
    pixels = np.array([[500.0, 400.0], [400.0, 400.0], [600.0, 300.0]])  # axis, X<0, X>0
    points = camera_points_from_pixels(pixels, k, plane)
    assert np.all(np.isnan(points[0])) and np.all(np.isnan(points[1]))
    np.testing.assert_allclose(points[2], [0.05, -0.05, 0.5])


@pytest.mark.parametrize(
    "plane",
    [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [1.0, np.nan, 0.0, 1.0]],
)
def test_invalid_planes_are_refused(plane: list[float]) -> None:
    with pytest.raises(InputError):
        camera_points_from_pixels(np.zeros((1, 2)), PAPER_INTRINSICS, plane)


def test_plane_facing_the_camera_has_no_sensor_frame() -> None:
    with pytest.raises(InputError, match="perpendicular to the optical axis"):
        T_camera_sensor_from_light_plane([0.0, 0.0, 1.0, -0.2])


def test_invalid_intrinsics_are_refused() -> None:
    with pytest.raises(InputError, match="focal lengths"):
        CameraIntrinsics(100.0, 100.0, 0.0, 1000.0)
    with pytest.raises(InputError, match=r"shape \(N, 2\)"):
        camera_points_from_pixels(np.zeros((3, 3)), PAPER_INTRINSICS, PAPER_LIGHT_PLANE)


def distort(points: np.ndarray, k: CameraIntrinsics) -> np.ndarray:
    """Projection with OpenCV's lens distortion (k1, k2, p1, p2, k3), written out here."""
    k1, k2, p1, p2, k3 = k.distortion
    x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
    r2 = x**2 + y**2
    radial = 1.0 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x**2)
    yd = y * radial + p1 * (r2 + 2.0 * y**2) + 2.0 * p2 * x * y
    return np.column_stack([k.u0 + k.alpha * xd, k.v0 + k.beta * yd])


def test_opencv_undistortion_without_distortion_equals_the_pinhole_formula() -> None:
    rng = np.random.default_rng(5)
    pixels = rng.uniform([0.0, 0.0], [2592.0, 1944.0], (500, 2))
    pinhole = normalised_from_pixels(pixels, PAPER_INTRINSICS)
    opencv = normalised_from_pixels(pixels, replace(PAPER_INTRINSICS, distortion=(0.0,) * 4))
    np.testing.assert_allclose(opencv, pinhole, rtol=0.0, atol=1e-12)


def test_distorted_pixels_triangulate_back_to_the_plane() -> None:
    """A wide-angle lens (barrel distortion, decentring): points come back within 1 nm."""
    rng = np.random.default_rng(6)
    k = CameraIntrinsics(640.0, 480.0, 900.0, 905.0, (-0.25, 0.08, 1e-3, -5e-4, -0.01))
    for _ in range(10):
        plane = random_plane(rng)
        truth = points_on_plane(plane, rng, 200, (0.1, 0.3))
        truth = truth[np.hypot(*(truth[:, :2] / truth[:, 2:]).T) < 0.6]  # within the lens's view
        pixels = distort(truth, k)
        back = camera_points_from_pixels(pixels, k, plane)
        np.testing.assert_allclose(back, truth, rtol=0.0, atol=1e-9)
        ignored = camera_points_from_pixels(pixels, replace(k, distortion=()), plane)
        assert np.nanmax(np.linalg.norm(ignored - truth, axis=1)) > 1e-4


def test_distortion_needs_opencv_s_coefficient_count() -> None:
    with pytest.raises(InputError, match="4, 5, 8, 12 or 14"):
        CameraIntrinsics(100.0, 100.0, 1000.0, 1000.0, (0.1, 0.2, 0.3))
