"""Track the red target through a sampled video or image folder (chapter 7.3.3, Sections B and C).

The text records 30 frames/s video and samples it at 5 Hz; each sampled frame gives the target's
centre on the plane, and the trace gives the turning radius (circle fit, eqs. 7.8-7.10) and the mean
forward speed. Frames without an acceptable target are skipped and counted, never fatal.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from skidsteer_power.analysis.trace import CircleFit, fit_circle, mean_speed
from skidsteer_power.errors import InputError
from skidsteer_power.mocap.calibration import CameraCalibration
from skidsteer_power.mocap.config import TargetConfig
from skidsteer_power.mocap.plane import GroundPlane, check_image_size, pixels_to_plane
from skidsteer_power.mocap.target import TargetDetection, detect_target

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

DEFAULT_SAMPLE_HZ = 5.0  # the text samples its 30 fps video at 5 Hz (Figure 7.28)
IMAGE_SUFFIXES = frozenset({'.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff'})


@dataclass(frozen=True)
class Frame:
    index: int  # position in the video or folder [-]
    time_s: float  # index / fps [s]
    image: np.ndarray | None  # BGR, uint8; None if the video frame could not be decoded


@dataclass(frozen=True)
class TrackResult:
    """A trace on the plane and what follows from it.

    time_s, frame_index : per detected sample; xy_m : (N, 2) target centre on the plane [m];
    skipped : (frame index, reason) of sampled frames without a target; diameter_m : the disc's
    diameter measured in each detected sample [m]; fit : circle fit of the trace
    (eqs. 7.8-7.10) [m]; speed_m_s : mean forward speed [m/s]; fps, sample_hz : input and sampling
    rates [1/s].
    """

    time_s: np.ndarray
    frame_index: np.ndarray
    xy_m: np.ndarray
    skipped: list[tuple[int, str]]
    diameter_m: np.ndarray
    fit: CircleFit
    speed_m_s: float
    fps: float
    sample_hz: float

    def summary(self) -> JsonObject:
        """The CLI's JSON payload (SI units)."""
        return {
            'radius_m': self.fit.radius_m,
            'speed_m_s': self.speed_m_s,
            'center_m': [self.fit.center_x_m, self.fit.center_y_m],
            'samples': len(self.time_s),
            'skipped': len(self.skipped),
            'rms_residual_m': self.fit.rms_residual_m,
            'duration_s': float(self.time_s[-1] - self.time_s[0]),
            'target_diameter_m': float(np.median(self.diameter_m)),
            'fps': self.fps,
            'sample_hz': self.sample_hz,
            'skipped_frames': [{'frame': index, 'reason': reason} for index, reason in self.skipped],
        }


def _natural_key(path: Path) -> list[int | str]:
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', path.name)]


def _folder_images(folder: Path) -> list[Path]:
    images = sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
    if not images:
        raise InputError(f'no images ({", ".join(sorted(IMAGE_SUFFIXES))}) in {folder}')
    return images


def _is_sampled(index: int, fps: float, sample_hz: float, next_sample: list[float]) -> bool:
    """True for the frame nearest each sampling instant k / sample_hz (handles non-integer ratios)."""
    if index / fps + 0.5 / fps < next_sample[0]:
        return False
    next_sample[0] += 1.0 / sample_hz
    return True


def _video_frames(
    path: Path, fps: float | None, sample_hz: float | None
) -> tuple[Iterator[Frame], float, float]:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise InputError(f'cannot open video: {path}')
    if fps is None:
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        if not (math.isfinite(fps) and fps > 0):
            capture.release()
            raise InputError(f'{path}: the video does not state its frame rate; pass --fps')
    rate = DEFAULT_SAMPLE_HZ if sample_hz is None else sample_hz
    try:
        _check_rates(fps, rate)
    except InputError:
        capture.release()
        raise

    def frames() -> Iterator[Frame]:
        next_sample, index = [0.0], 0
        try:
            while capture.grab():  # grab every frame, decode only the sampled ones
                if _is_sampled(index, fps, rate, next_sample):
                    ok, image = capture.retrieve()
                    yield Frame(index, index / fps, image if ok else None)
                index += 1
        finally:
            capture.release()

    return frames(), fps, rate


def _folder_frames(
    folder: Path, fps: float | None, sample_hz: float | None
) -> tuple[Iterator[Frame], float, float]:
    if fps is None:
        raise InputError(f'{folder} is an image folder: pass --fps (the rate its images were taken at)')
    rate = fps if sample_hz is None else sample_hz
    _check_rates(fps, rate)
    paths = _folder_images(folder)

    def frames() -> Iterator[Frame]:
        next_sample = [0.0]
        for index, path in enumerate(paths):
            if _is_sampled(index, fps, rate, next_sample):
                image = cv2.imread(str(path), cv2.IMREAD_COLOR)
                if image is None:
                    raise InputError(f'not a readable image: {path}')
                yield Frame(index, index / fps, image)

    return frames(), fps, rate


def _check_rates(fps: float, sample_hz: float) -> None:
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f'frame rate must be > 0 frames/s, got {fps}')
    if not (math.isfinite(sample_hz) and 0 < sample_hz <= fps):
        raise InputError(f'sample rate must be > 0 and at most the frame rate {fps:g} Hz, got {sample_hz}')


def open_frames(
    source: str | os.PathLike[str], fps: float | None = None, sample_hz: float | None = None
) -> tuple[Iterator[Frame], float, float]:
    """Sampled frames of a video file or an image folder, with the frame rate and sample rate [Hz].

    Video: ``fps`` defaults to the file's own rate and ``sample_hz`` to 5 Hz (the text's rate).
    Folder: images in natural name order; ``fps`` is required, ``sample_hz`` defaults to every image.
    """
    path = Path(source)
    if path.is_dir():
        return _folder_frames(path, fps, sample_hz)
    if path.is_file():
        return _video_frames(path, fps, sample_hz)
    raise InputError(f'video or image folder not found: {path}')


def target_on_plane(
    detection: TargetDetection, calibration: CameraCalibration, plane: GroundPlane
) -> tuple[np.ndarray, float]:
    """Centre (x, y) [m] and diameter [m] of the detected disc on the plane.

    Centre: the outline is mapped to the plane first and the centroid taken there (area moments of
    the polygon), which is the disc's centre whatever the camera's tilt; the image centroid of a
    tilted disc is not. Diameter: the blob's pixel count times the plane area of one pixel at the
    blob's centroid (Jacobian of the pixel-to-plane map), as a disc of that area; a check against the
    real disc (the text: 144.30 mm measured for 144.00 mm) that the plane is right.
    """
    outline = pixels_to_plane(detection.outline_px, calibration, plane)
    origin = outline.mean(axis=0)
    moments = cv2.moments(((outline - origin) * 1e3).astype(np.float32).reshape(-1, 1, 2))  # mm
    centre = origin
    if moments['m00'] != 0:
        centre = origin + np.array([moments['m10'], moments['m01']]) / moments['m00'] * 1e-3
    cx, cy = detection.centroid_px
    steps = np.array([[cx - 0.5, cy], [cx + 0.5, cy], [cx, cy - 0.5], [cx, cy + 0.5]])
    p = pixels_to_plane(steps, calibration, plane)
    (ux, uy), (vx, vy) = p[1] - p[0], p[3] - p[2]
    pixel_area_m2 = abs(ux * vy - uy * vx)
    diameter = 2.0 * math.sqrt(detection.area_px * pixel_area_m2 / math.pi)
    return centre, diameter


def track(
    source: str | os.PathLike[str],
    calibration: CameraCalibration,
    plane: GroundPlane,
    *,
    fps: float | None = None,
    sample_hz: float | None = None,
    target: TargetConfig | None = None,
) -> TrackResult:
    """Trace the red target through ``source`` (video file or image folder) on the calibrated plane.

    Returns the trace, the skipped frames, its circle fit (eqs. 7.8-7.10) and mean forward speed.
    InputError if fewer than 3 sampled frames show the target (no circle can be fitted).
    """
    config = target or TargetConfig()
    frames, fps, rate = open_frames(source, fps, sample_hz)
    times, indices, points, diameters, skipped = [], [], [], [], []
    for frame in frames:
        if frame.image is None:
            skipped.append((frame.index, 'frame could not be decoded'))
            continue
        check_image_size(frame.image, calibration, f'frame {frame.index}')
        found = detect_target(frame.image, config)
        if not isinstance(found, TargetDetection):
            skipped.append((frame.index, found.reason))
            continue
        centre, diameter = target_on_plane(found, calibration, plane)
        diameters.append(diameter)
        times.append(frame.time_s)
        indices.append(frame.index)
        points.append(centre)
    if len(points) < 3:
        raise InputError(
            f'target found in {len(points)} of {len(points) + len(skipped)} sampled frames; '
            'need at least 3 for the circle fit (check the thresholds and the plane)'
        )
    xy, time_s = np.asarray(points), np.asarray(times)
    return TrackResult(
        time_s=time_s,
        frame_index=np.asarray(indices),
        xy_m=xy,
        skipped=skipped,
        diameter_m=np.asarray(diameters),
        fit=fit_circle(xy[:, 0], xy[:, 1]),
        speed_m_s=mean_speed(time_s, xy[:, 0], xy[:, 1]),
        fps=fps,
        sample_hz=rate,
    )


def write_trace_csv(path: str | os.PathLike[str], result: TrackResult) -> None:
    """Write the trace as CSV: frame, t_s, x_m, y_m (one row per detected sample)."""
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['frame', 't_s', 'x_m', 'y_m'])
        for index, t, (x, y) in zip(result.frame_index, result.time_s, result.xy_m, strict=True):
            writer.writerow([int(index), f'{t:.6f}', f'{x:.6f}', f'{y:.6f}'])
