"""Motion-capture throughput on synthetic full-HD frames (the text's Logitech C920: 1920x1080, 30 fps).

Figures: per-frame target detection + plane mapping [frames/s], and end-to-end tracking of a 30 fps
MJPG video sampled at 5 Hz (the text's rate) in video frames per second of wall time; goal: faster
than real time (> 30 video frames/s), so a run is processed in less than its own duration.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from benchmarks.harness import Report, best_time
from skidsteer_power.mocap import synthetic as syn
from skidsteer_power.mocap.calibration import CameraCalibration
from skidsteer_power.mocap.config import TargetConfig
from skidsteer_power.mocap.plane import GroundPlane
from skidsteer_power.mocap.target import TargetDetection, detect_target
from skidsteer_power.mocap.tracking import target_on_plane, track

SIZE = (1920, 1080)
FPS = 30.0
SECONDS = 4.0


def _camera() -> syn.SyntheticCamera:
    matrix = np.array([[1400.0, 0.0, 960.0], [0.0, 1400.0, 540.0], [0.0, 0.0, 1.0]])
    return syn.SyntheticCamera(matrix, np.array([-0.1, 0.02, 0.0, 0.0, 0.0]), SIZE)


def _disc_at(t_s: float) -> tuple[float, float]:
    angle = 0.25 / 0.8 * t_s  # 0.25 m/s on a 0.8 m circle
    return 0.8 * np.cos(angle), 0.8 * np.sin(angle)


def run(report: Report) -> None:
    camera = _camera()
    rvec, tvec = syn.look_at(np.array([0.3, 0.0, -2.0]), np.zeros(3), np.array([1.0, 0.0, 0.0]))
    calibration = CameraCalibration(camera.camera_matrix, camera.dist_coeffs, SIZE)
    plane = GroundPlane(rvec=rvec, tvec=tvec, reprojection_px=0.0)
    sand = syn.sand()
    background = syn.render(camera, rvec, tvec, sand, supersample=1)
    frame = syn.render_disc_frame(background, camera, rvec, tvec, sand, _disc_at(0.0), 0.07)
    config = TargetConfig()

    def one_frame() -> None:
        detection = detect_target(frame, config)
        assert isinstance(detection, TargetDetection), detection  # the synthetic disc is in view
        target_on_plane(detection, calibration, plane)

    per_frame = best_time(one_frame, repeat=5, number=5)
    report.figure(
        'detect + map one 1920x1080 frame',
        1.0 / per_frame,
        'frames/s',
        goal='>= 30 (every frame of a 30 fps video in real time)',
        met=1.0 / per_frame >= FPS,
    )

    with tempfile.TemporaryDirectory() as folder:
        video = Path(folder) / 'run.avi'
        writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*'MJPG'), FPS, SIZE)
        n_frames = int(SECONDS * FPS)
        for index in range(n_frames):
            writer.write(syn.render_disc_frame(background, camera, rvec, tvec, sand, _disc_at(index / FPS),
                                               0.07, supersample=1))  # fmt: skip
        writer.release()
        start = time.perf_counter()
        result = track(video, calibration, plane, sample_hz=5.0)
        elapsed = time.perf_counter() - start
    rate = n_frames / elapsed
    note = f'{len(result.time_s)} samples, radius {result.fit.radius_m:.4f} m (true 0.8)'
    report.figure(
        'track 30 fps MJPG video sampled at 5 Hz',
        rate,
        'frames/s',
        goal='> 30 (real time)',
        met=rate > FPS,
        note=note,
    )
