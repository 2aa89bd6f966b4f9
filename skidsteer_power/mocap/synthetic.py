"""Synthetic camera images of a plane: checkerboard, sand-like texture, red disc.

For tests, benchmarks and trying the pipeline without a camera. The renderer is independent of the
tracker: each pixel's viewing ray is undistorted by a fixed-point inversion of eq. 7.7 written here
in numpy (the tracker uses OpenCV's), then intersected with the plane Z = 0 of the world frame, and the
texture is sampled there (``supersample`` x ``supersample`` rays per pixel for anti-aliased edges).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (X, Y) [m] -> (N, 3) BGR in 0..255

SAND_BGR = np.array([128.0, 178.0, 194.0])  # tan
RED_BGR = np.array([35.0, 30.0, 200.0])
BLACK, WHITE = 25.0, 230.0


@dataclass(frozen=True)
class SyntheticCamera:
    """Pinhole camera with radial distortion: K [px], (k1, k2, p1, p2, k3) [-], (width, height) [px]."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]


def look_at(
    camera_position: np.ndarray, target: np.ndarray, image_right: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (rvec [rad], tvec [m]) of a camera at ``camera_position`` [m] looking at
    ``target`` [m], its image x axis as close as possible to ``image_right``."""
    forward = np.asarray(target, float) - np.asarray(camera_position, float)
    forward /= np.linalg.norm(forward)
    right = np.asarray(image_right, float) - forward * (forward @ image_right)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.vstack([right, down, forward])
    rvec, _ = cv2.Rodrigues(rotation)
    return rvec.ravel(), -rotation @ np.asarray(camera_position, float)


def _undistort_normalized(xd: np.ndarray, yd: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert eq. 7.7 (radial k1, k2, k3) by fixed-point iteration: x = x_d / (1 + k1 r^2 + ...)."""
    k1, k2, _, _, k3 = dist
    x, y = xd.copy(), yd.copy()
    for _ in range(40):
        r2 = x * x + y * y
        factor = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x, y = xd / factor, yd / factor
    return x, y


def pixel_rays_to_plane(
    camera: SyntheticCamera, rvec: np.ndarray, tvec: np.ndarray, u: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Plane coordinates (X, Y) [m] seen at distorted pixel positions (u, v) [px]."""
    k = camera.camera_matrix
    x, y = _undistort_normalized((u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], camera.dist_coeffs)
    rotation, _ = cv2.Rodrigues(np.asarray(rvec, float))
    rays_world = np.column_stack([x, y, np.ones_like(x)]) @ rotation  # R^T d, row-wise
    centre_world = -rotation.T @ np.asarray(tvec, float)
    scale = -centre_world[2] / rays_world[:, 2]
    world = centre_world + scale[:, None] * rays_world
    return world[:, 0], world[:, 1]


def render(
    camera: SyntheticCamera,
    rvec: np.ndarray,
    tvec: np.ndarray,
    texture: Texture,
    *,
    supersample: int = 3,
    box: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """BGR uint8 image of the textured plane Z = 0 (or of the pixel ``box`` = (x0, y0, x1, y1))."""
    width, height = camera.image_size
    x0, y0, x1, y1 = box or (0, 0, width, height)
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    cols = (np.arange(x0, x1)[:, None] + offsets).ravel()
    rows = (np.arange(y0, y1)[:, None] + offsets).ravel()
    u, v = np.meshgrid(cols, rows)
    big_x, big_y = pixel_rays_to_plane(camera, rvec, tvec, u.ravel(), v.ravel())
    colours = texture(big_x, big_y).reshape(y1 - y0, supersample, x1 - x0, supersample, 3)
    image: np.ndarray = np.clip(colours.mean(axis=(1, 3)) + 0.5, 0, 255).astype(np.uint8)  # numpy: Any
    return image


def _hash_noise(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    h = (ix * 73856093) ^ (iy * 19349663) ^ (seed * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    noise: np.ndarray = ((h ^ (h >> 16)) & 0xFFFF) / 65535.0  # numpy types integer ^ as Any
    return noise


def sand(cell_m: float = 0.004, seed: int = 1) -> Texture:
    """Sand-like texture: tan with bilinear value noise of cell ``cell_m`` [m] (+-20 % brightness)."""

    def texture(big_x: np.ndarray, big_y: np.ndarray) -> np.ndarray:
        gx, gy = big_x / cell_m, big_y / cell_m
        ix, iy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
        fx, fy = gx - ix, gy - iy
        noise = (
            _hash_noise(ix, iy, seed) * (1 - fx) * (1 - fy)
            + _hash_noise(ix + 1, iy, seed) * fx * (1 - fy)
            + _hash_noise(ix, iy + 1, seed) * (1 - fx) * fy
            + _hash_noise(ix + 1, iy + 1, seed) * fx * fy
        )
        return SAND_BGR * (0.8 + 0.4 * noise)[:, None]

    return texture


def checkerboard(pattern: tuple[int, int], square_m: float, background: Texture | None = None) -> Texture:
    """Board with ``pattern`` = (cols, rows) inner corners at (i, j) * ``square_m`` [m] (first at the
    origin), a white margin of one square, and ``background`` (plain grey if None) around it."""
    cols, rows = pattern

    def texture(big_x: np.ndarray, big_y: np.ndarray) -> np.ndarray:
        i, j = np.floor(big_x / square_m), np.floor(big_y / square_m)
        squares = (i >= -1) & (i <= cols - 1) & (j >= -1) & (j <= rows - 1)
        margin = (i >= -2) & (i <= cols) & (j >= -2) & (j <= rows)
        value = np.where(squares & ((i + j) % 2 == 0), BLACK, WHITE)
        colours = np.repeat(value[:, None], 3, axis=1)
        outside = ~margin
        if np.any(outside):
            colours[outside] = background(big_x[outside], big_y[outside]) if background else 128.0
        return colours

    return texture


def with_disc(base: Texture, centre_m: tuple[float, float], radius_m: float) -> Texture:
    """``base`` with a red disc of ``radius_m`` [m] at ``centre_m`` [m] on top."""

    def texture(big_x: np.ndarray, big_y: np.ndarray) -> np.ndarray:
        colours = base(big_x, big_y)
        inside = (big_x - centre_m[0]) ** 2 + (big_y - centre_m[1]) ** 2 <= radius_m**2
        colours[inside] = RED_BGR
        return colours

    return texture


def disc_box(
    camera: SyntheticCamera,
    rvec: np.ndarray,
    tvec: np.ndarray,
    centre_m: tuple[float, float],
    radius_m: float,
) -> tuple[int, int, int, int]:
    """Pixel box (x0, y0, x1, y1) holding the disc's image, with a 3 px margin, clipped to the image."""
    angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rim = np.column_stack(
        [
            centre_m[0] + radius_m * np.cos(angles),
            centre_m[1] + radius_m * np.sin(angles),
            np.zeros_like(angles),
        ]
    )
    pixels, _ = cv2.projectPoints(rim, rvec, tvec, camera.camera_matrix, camera.dist_coeffs)
    pixels = pixels.reshape(-1, 2)
    width, height = camera.image_size
    x0, y0 = np.maximum(np.floor(pixels.min(axis=0)).astype(int) - 3, 0)
    x1, y1 = np.minimum(np.ceil(pixels.max(axis=0)).astype(int) + 4, (width, height))
    return int(x0), int(y0), int(x1), int(y1)


def render_disc_frame(
    background: np.ndarray,
    camera: SyntheticCamera,
    rvec: np.ndarray,
    tvec: np.ndarray,
    ground: Texture,
    centre_m: tuple[float, float],
    radius_m: float,
    *,
    supersample: int = 3,
) -> np.ndarray:
    """``background`` (the rendered ``ground``) with the disc at ``centre_m`` re-rendered in its box."""
    frame = background.copy()
    x0, y0, x1, y1 = disc_box(camera, rvec, tvec, centre_m, radius_m)
    if x1 > x0 and y1 > y0:
        patch = render(
            camera,
            rvec,
            tvec,
            with_disc(ground, centre_m, radius_m),
            supersample=supersample,
            box=(x0, y0, x1, y1),
        )
        frame[y0:y1, x0:x1] = patch
    return frame
