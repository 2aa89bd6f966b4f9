"""Camera calibration from checkerboard images (chapter 7.3.3, Section A; eqs. 7.5-7.7).

Pinhole model with radial distortion k1, k2 (k3 optional, for wide-angle lenses, eq. 7.7); the text's
webcam has no tangential distortion, so p1 = p2 = 0 is fixed. OpenCV does the work: corner detection
(findChessboardCorners + cornerSubPix), calibrateCamera, undistort. Stored as YAML.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
import yaml

from skidsteer_power.errors import ConfigError, InputError

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
MIN_CALIBRATION_IMAGES = 3
YAML_KIND = 'skidsteer_power camera calibration'


@dataclass(frozen=True)
class CameraCalibration:
    """Intrinsics of one camera.

    camera_matrix : 3x3 intrinsic matrix K [px] (fx, fy focal lengths; cx, cy principal point)
    dist_coeffs : OpenCV order (k1, k2, p1, p2, k3) [-]; p1 = p2 = 0 here (eq. 7.7 is radial only)
    image_size : (width, height) [px] of the calibrated images
    rms_reprojection_px : RMS reprojection error of the calibration [px]
    pattern : inner corners (columns, rows) of the board used
    square_size_m : board square side [m]
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_reprojection_px: float = float('nan')
    pattern: tuple[int, int] = (0, 0)
    square_size_m: float = float('nan')
    images_used: tuple[str, ...] = field(default=())
    images_rejected: tuple[str, ...] = field(default=())

    @property
    def focal_px(self) -> tuple[float, float]:
        """(fx, fy) [px]."""
        return float(self.camera_matrix[0, 0]), float(self.camera_matrix[1, 1])

    def summary(self) -> JsonObject:
        """Plain numbers for the CLI (px, dimensionless coefficients)."""
        k1, k2, _, _, k3 = (float(v) for v in self.dist_coeffs)
        return {
            'fx_px': self.focal_px[0],
            'fy_px': self.focal_px[1],
            'cx_px': float(self.camera_matrix[0, 2]),
            'cy_px': float(self.camera_matrix[1, 2]),
            'k1': k1,
            'k2': k2,
            'k3': k3,
            'image_size_px': list(self.image_size),
            'rms_reprojection_px': self.rms_reprojection_px,
            'images_used': len(self.images_used),
            'images_rejected': list(self.images_rejected),
        }


def board_points(pattern: tuple[int, int], square_size_m: float) -> np.ndarray:
    """Inner-corner positions on the board plane, (cols*rows, 3) [m], row by row, Z = 0.

    The order matches findChessboardCorners: x along a row of the pattern, y from row to row.
    """
    cols, rows = pattern
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float64) * square_size_m
    return np.column_stack([grid, np.zeros(len(grid))])


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a colour image (BGR, uint8); InputError if missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f'image not found: {path}')
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise InputError(f'not a readable image: {path}')
    return image


def find_corners(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of a checkerboard, (cols*rows, 2) [px], or None if not found."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, pattern, flags=flags)
    if not found:
        return None
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), _SUBPIX_CRITERIA)
    return corners.reshape(-1, 2).astype(np.float64)


def _check_square_size(square_size_m: float) -> None:
    if not (np.isfinite(square_size_m) and square_size_m > 0):
        raise InputError(f'square size must be a positive length in m, got {square_size_m}')


def calibrate_camera(
    images: Sequence[str | os.PathLike[str]],
    square_size_m: float,
    pattern: tuple[int, int],
    *,
    use_k3: bool = False,
) -> CameraCalibration:
    """Calibrate from checkerboard image files (eq. 7.5-7.7), radial k1, k2 (+ k3 if ``use_k3``).

    Images without a detectable board are left out and listed in ``images_rejected``; fewer than
    3 usable images, or images of different sizes, raise InputError.
    """
    _check_square_size(square_size_m)
    if not images:
        raise InputError('no calibration images given')
    object_points, image_points, used, rejected = [], [], [], []
    size: tuple[int, int] | None = None
    board = board_points(pattern, square_size_m).astype(np.float32)
    for name in images:
        image = read_image(name)
        this_size = (image.shape[1], image.shape[0])
        if size is not None and this_size != size:
            raise InputError(f'{name}: image size {this_size} differs from the first image {size}')
        size = this_size
        corners = find_corners(image, pattern)
        if corners is None:
            rejected.append(str(name))
            continue
        object_points.append(board)
        image_points.append(corners.astype(np.float32).reshape(-1, 1, 2))
        used.append(str(name))
    if len(used) < MIN_CALIBRATION_IMAGES:
        cols, rows = pattern
        raise InputError(
            f'checkerboard with {cols}x{rows} inner corners found in {len(used)} of {len(images)} images; '
            f'calibration needs at least {MIN_CALIBRATION_IMAGES} (check --pattern)'
        )
    assert size is not None  # set by the first of the (non-empty) images
    flags = cv2.CALIB_ZERO_TANGENT_DIST | (0 if use_k3 else cv2.CALIB_FIX_K3)
    rms, matrix, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None, flags=flags)
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=float).ravel()
    return CameraCalibration(
        camera_matrix=np.asarray(matrix, dtype=float),
        dist_coeffs=np.pad(dist, (0, max(0, 5 - dist.size)))[:5],
        image_size=size,
        rms_reprojection_px=float(rms),
        pattern=pattern,
        square_size_m=float(square_size_m),
        images_used=tuple(used),
        images_rejected=tuple(rejected),
    )


def undistort_image(image: np.ndarray, calibration: CameraCalibration) -> np.ndarray:
    """The image with the lens distortion removed (same K), as in the text's Figure 7.29."""
    return cv2.undistort(image, calibration.camera_matrix, calibration.dist_coeffs)


def save_calibration(path: str | os.PathLike[str], calibration: CameraCalibration) -> None:
    """Write the calibration as YAML (plain lists; units in the keys)."""
    document = {
        'kind': YAML_KIND,
        'image_size_px': [int(v) for v in calibration.image_size],
        'camera_matrix_px': np.asarray(calibration.camera_matrix, dtype=float).tolist(),
        'dist_coeffs_k1_k2_p1_p2_k3': [float(v) for v in calibration.dist_coeffs],
        'rms_reprojection_px': float(calibration.rms_reprojection_px),
        'pattern_cols_rows': [int(v) for v in calibration.pattern],
        'square_size_m': float(calibration.square_size_m),
        'images_used': list(calibration.images_used),
        'images_rejected': list(calibration.images_rejected),
    }
    Path(path).write_text(yaml.safe_dump(document, sort_keys=False))


def load_calibration(path: str | os.PathLike[str]) -> CameraCalibration:
    """Read a calibration written by :func:`save_calibration`; ConfigError if malformed."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f'calibration file not found: {path}')
    try:
        document = yaml.safe_load(path.read_text())
        matrix = np.asarray(document['camera_matrix_px'], dtype=float)
        dist = np.asarray(document['dist_coeffs_k1_k2_p1_p2_k3'], dtype=float)
        width, height = (int(v) for v in document['image_size_px'])
        cols, rows = (int(v) for v in document.get('pattern_cols_rows', (0, 0)))
        square = float(document.get('square_size_m', float('nan')))
        rms = float(document.get('rms_reprojection_px', float('nan')))
    except (yaml.YAMLError, AttributeError, KeyError, TypeError, ValueError) as err:
        raise ConfigError(f'{path}: not a camera calibration file ({err})') from err
    if matrix.shape != (3, 3) or dist.shape != (5,) or not np.all(np.isfinite(matrix)):
        raise ConfigError(f'{path}: camera matrix must be 3x3 and dist coefficients 5 numbers')
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0 or width <= 0 or height <= 0:
        raise ConfigError(f'{path}: focal lengths and image size must be positive')
    return CameraCalibration(
        camera_matrix=matrix,
        dist_coeffs=dist,
        image_size=(width, height),
        rms_reprojection_px=rms,
        pattern=(cols, rows),
        square_size_m=square,
        images_used=tuple(document.get('images_used') or ()),
        images_rejected=tuple(document.get('images_rejected') or ()),
    )
