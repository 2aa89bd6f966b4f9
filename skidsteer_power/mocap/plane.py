"""Ground plane of the target from a reference checkerboard (chapter 7.3.3, Sections A and C).

With one camera there is no depth, so the reference board lies in the plane of the target (the text
levels it with a level meter and a ruler). solvePnP gives the board's pose (R, T of eq. 7.6); a pixel
then maps to metres on that plane by undistorting it (eq. 7.7, inverted by OpenCV) and intersecting
its viewing ray with the plane.

World frame: the board's frame, origin at the first detected inner corner, x along the pattern's
columns, y along its rows, z out of the plane; coordinates in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.mocap.calibration import CameraCalibration, board_points, find_corners


@dataclass(frozen=True)
class GroundPlane:
    """Pose of the plane in the camera frame: rotation vector [rad] and translation [m].

    ``plane_to_normalized`` is the homography [R1 R2 T] from plane (X, Y, 1) [m] to normalized
    (undistorted, focal length 1) image coordinates; ``reprojection_px`` the RMS board reprojection
    error [px].
    """

    rvec: np.ndarray
    tvec: np.ndarray
    reprojection_px: float

    @property
    def plane_to_normalized(self) -> np.ndarray:
        rotation, _ = cv2.Rodrigues(self.rvec)
        return np.column_stack([rotation[:, 0], rotation[:, 1], self.tvec.ravel()])

    @property
    def camera_height_m(self) -> float:
        """Distance from the camera centre to the plane [m]."""
        rotation, _ = cv2.Rodrigues(self.rvec)
        return float(abs(rotation[:, 2] @ self.tvec.ravel()))


def estimate_ground_plane(
    image: np.ndarray,
    calibration: CameraCalibration,
    pattern: tuple[int, int],
    square_size_m: float,
) -> GroundPlane:
    """Extrinsics of a checkerboard (inner corners ``pattern``, squares ``square_size_m`` [m]) in
    ``image``, taken by the calibrated camera; InputError if the board is not found."""
    if not (np.isfinite(square_size_m) and square_size_m > 0):
        raise InputError(f'plane board square size must be a positive length in m, got {square_size_m}')
    check_image_size(image, calibration, 'plane image')
    corners = find_corners(image, pattern)
    if corners is None:
        cols, rows = pattern
        raise InputError(f'no {cols}x{rows} checkerboard found in the plane image')
    objects = board_points(pattern, square_size_m)
    matrix, dist = calibration.camera_matrix, calibration.dist_coeffs
    ok, rvec, tvec = cv2.solvePnP(objects, corners, matrix, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise InputError('could not solve the pose of the plane board')
    projected, _ = cv2.projectPoints(objects, rvec, tvec, matrix, dist)
    error = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - corners) ** 2, axis=1))))
    return GroundPlane(rvec=rvec.ravel(), tvec=tvec.ravel(), reprojection_px=error)


def check_image_size(image: np.ndarray, calibration: CameraCalibration, what: str) -> None:
    """InputError unless ``image`` has the calibrated size (intrinsics are per resolution)."""
    size = (image.shape[1], image.shape[0])
    if size != tuple(calibration.image_size):
        raise InputError(
            f'{what} is {size[0]}x{size[1]} px but the camera was calibrated at '
            f'{calibration.image_size[0]}x{calibration.image_size[1]} px'
        )


def pixels_to_plane(points_px: np.ndarray, calibration: CameraCalibration, plane: GroundPlane) -> np.ndarray:
    """Map distorted pixel positions (N, 2) [px] to plane coordinates (N, 2) [m] (eqs. 7.5-7.7 inverted)."""
    points = np.asarray(points_px, dtype=np.float64).reshape(-1, 1, 2)
    normalized = cv2.undistortPoints(
        points,
        calibration.camera_matrix,
        calibration.dist_coeffs,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12),
    ).reshape(-1, 2)
    homogeneous = np.column_stack([normalized, np.ones(len(normalized))])
    plane_xyw = np.linalg.solve(plane.plane_to_normalized, homogeneous.T).T
    return plane_xyw[:, :2] / plane_xyw[:, 2:3]
