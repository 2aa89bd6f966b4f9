"""Motion capture (chapter 7.3.3) on synthetic frames from a known camera.

The scene: a 640x480 camera, fx = fy = 520 px, principal point (322, 238) px, radial distortion
k1 = -0.25, k2 = 0.08 (eq. 7.7; barrel, as a webcam); a 9x6-corner checkerboard of 50 mm squares;
a red disc of 50 mm radius driven round a circle of 0.55 m radius centred at (0.20, 0.125) m in the
board's frame at 0.25 m/s over a textured sand-like plane, filmed at 30 frames/s for 5 s from 1.4 m
away at a 21 degree tilt and sampled at 5 Hz, as in the text (Figure 7.28).
Required accuracy (issue 10): focal length 1 %, trace 5 mm, radius 1 %, speed 2 %.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TypedDict, overload

import cv2
import numpy as np
import pytest
import yaml

from skidsteer_power.cli.main import main
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.mocap import (
    CameraCalibration,
    GroundPlane,
    TargetConfig,
    TargetDetection,
    TargetMiss,
    TrackResult,
    calibrate_camera,
    detect_target,
    estimate_ground_plane,
    load_calibration,
    parse_pattern,
    pixels_to_plane,
    save_calibration,
    track,
    undistort_image,
)
from skidsteer_power.mocap import synthetic as syn
from skidsteer_power.mocap.target import target_mask
from skidsteer_power.mocap.tracking import open_frames


class Scene(TypedDict):
    """The files of the synthetic experiment (the ``scene`` fixture)."""

    root: Path
    calibration_images: list[Path]
    plane_image: Path
    video: Path
    folder: Path
    n_frames: int


CAMERA = syn.SyntheticCamera(
    camera_matrix=np.array([[520.0, 0.0, 322.0], [0.0, 520.0, 238.0], [0.0, 0.0, 1.0]]),
    dist_coeffs=np.array([-0.25, 0.08, 0.0, 0.0, 0.0]),
    image_size=(640, 480),
)
PATTERN = (9, 6)
SQUARE_M = 0.05
DISC_RADIUS_M = 0.05
CENTRE_M = (0.20, 0.125)
RADIUS_M = 0.55
SPEED_M_S = 0.25
PHASE0_RAD = -0.9
FPS = 30.0
DURATION_S = 5.0
SAMPLE_HZ = 5.0
NO_TARGET_FRAME = 60  # a sampled frame (every 6th at 30 fps -> 5 Hz) with the disc hidden


@overload
def disc_position(t_s: float) -> tuple[float, float]: ...


@overload
def disc_position(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


def disc_position(t_s: np.ndarray | float) -> tuple[np.ndarray | float, np.ndarray | float]:
    """True centre of the disc on the plane [m] at time t [s]."""
    angle = PHASE0_RAD + SPEED_M_S / RADIUS_M * np.asarray(t_s)
    return CENTRE_M[0] + RADIUS_M * np.cos(angle), CENTRE_M[1] + RADIUS_M * np.sin(angle)


def calibration_poses() -> list[tuple[np.ndarray, np.ndarray]]:
    """Eight board poses 0.9 m away, over the centre, edges and corners of the image, each tilted
    0.7 rad (40 degrees) about a different axis: Zhang's method needs non-parallel board orientations
    to separate the focal length from the distance."""
    tilt = 0.7
    centre_board = np.array([(PATTERN[0] - 1) * SQUARE_M / 2, (PATTERN[1] - 1) * SQUARE_M / 2, 0.0])
    placements = [
        ((-0.22, -0.15), (tilt, 0, 0.1)),
        ((0.22, -0.15), (0, tilt, -0.1)),
        ((-0.22, 0.15), (-tilt, 0, 0.2)),
        ((0.22, 0.15), (0, -tilt, 0)),
        ((0.0, 0.0), (0.7 * tilt, 0.7 * tilt, 0.3)),
        ((0.0, -0.15), (-0.7 * tilt, 0.7 * tilt, 0)),
        ((-0.22, 0.0), (tilt, -0.3 * tilt, 0.1)),
        ((0.22, 0.0), (0.3 * tilt, tilt, -0.2)),
    ]
    poses = []
    for (cx, cy), axis in placements:
        rvec = np.array(axis, dtype=float)
        rotation, _ = cv2.Rodrigues(rvec)
        poses.append((rvec, np.array([cx, cy, 0.9]) - rotation @ centre_board))
    return poses


VIEW = syn.look_at(np.array([0.7, 0.125, -1.3]), np.array([0.2, 0.125, 0.0]), np.array([1.0, 0.0, 0.0]))


@pytest.fixture(scope='module')
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    """Files of the synthetic experiment: calibration images, plane image, video, image folder."""
    root = tmp_path_factory.mktemp('mocap')
    board = syn.checkerboard(PATTERN, SQUARE_M)
    calibration_images = []
    for k, (rvec, tvec) in enumerate(calibration_poses()):
        path = root / f'board_{k}.png'
        cv2.imwrite(str(path), syn.render(CAMERA, rvec, tvec, board, supersample=2))
        calibration_images.append(path)
    rvec, tvec = VIEW
    sand = syn.sand()
    plane_image = root / 'plane.png'
    cv2.imwrite(str(plane_image), syn.render(CAMERA, rvec, tvec, syn.checkerboard(PATTERN, SQUARE_M, sand)))
    background = syn.render(CAMERA, rvec, tvec, sand)
    noise = np.random.default_rng(5)

    def frame(index: int) -> np.ndarray:
        image = background
        if index != NO_TARGET_FRAME:
            image = syn.render_disc_frame(background, CAMERA, rvec, tvec, sand, disc_position(index / FPS),
                                          DISC_RADIUS_M)  # fmt: skip
        return np.clip(image + noise.normal(0, 2.0, image.shape), 0, 255).astype(np.uint8)

    video = root / 'run.avi'
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*'MJPG'), FPS, CAMERA.image_size)
    assert writer.isOpened()
    n_frames = int(DURATION_S * FPS) + 1
    folder = root / 'frames'
    folder.mkdir()
    for index in range(n_frames):
        image = frame(index)
        writer.write(image)
        if index % 6 == 0:  # the folder holds the video sampled at 5 Hz, as PNG (lossless)
            cv2.imwrite(str(folder / f'img_{index // 6}.png'), image)
    writer.release()
    return {
        'root': root,
        'calibration_images': calibration_images,
        'plane_image': plane_image,
        'video': video,
        'folder': folder,
        'n_frames': n_frames,
    }


@pytest.fixture(scope='module')
def calibration(scene: Scene) -> CameraCalibration:
    return calibrate_camera(scene['calibration_images'], SQUARE_M, PATTERN)


@pytest.fixture(scope='module')
def plane(scene: Scene, calibration: CameraCalibration) -> GroundPlane:
    return estimate_ground_plane(cv2.imread(str(scene['plane_image'])), calibration, PATTERN, SQUARE_M)


# -- calibration -------------------------------------------------------------------------------------


def test_calibration_recovers_the_camera(calibration: CameraCalibration) -> None:
    fx, fy = calibration.focal_px
    assert fx == pytest.approx(520.0, rel=0.01)
    assert fy == pytest.approx(520.0, rel=0.01)
    assert calibration.camera_matrix[0, 2] == pytest.approx(322.0, abs=5.0)
    assert calibration.camera_matrix[1, 2] == pytest.approx(238.0, abs=5.0)
    k1, _, p1, p2, k3 = calibration.dist_coeffs
    assert k1 == pytest.approx(-0.25, abs=0.02)
    assert (p1, p2, k3) == (0.0, 0.0, 0.0)  # tangential fixed at zero, k3 only on request (eq. 7.7)
    assert calibration.rms_reprojection_px < 0.5
    assert len(calibration.images_used) == 8


def worst_row_bend_px(image: np.ndarray) -> float:
    """Largest distance [px] of a board corner from the line through its row's end corners."""
    _, corners = cv2.findChessboardCorners(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), PATTERN)
    bends = []
    for row in corners.reshape(PATTERN[1], PATTERN[0], 2):
        direction = (row[-1] - row[0]) / np.linalg.norm(row[-1] - row[0])
        bends.append(np.max(np.abs((row - row[0]) @ np.array([-direction[1], direction[0]]))))
    return float(max(bends))


def big_facing_board() -> np.ndarray:
    """Board facing the camera 1 m away, 90 mm squares: it spans ~470x330 px, where k1 bends its
    outer rows by several pixels."""
    half = (PATTERN[0] - 1) * 0.09 / 2, (PATTERN[1] - 1) * 0.09 / 2
    return syn.render(
        CAMERA, np.zeros(3), np.array([-half[0], -half[1], 1.0]), syn.checkerboard(PATTERN, 0.09)
    )


def test_undistortion_straightens_the_board(calibration: CameraCalibration) -> None:
    image = big_facing_board()
    assert worst_row_bend_px(image) > 2.0
    assert worst_row_bend_px(undistort_image(image, calibration)) < 0.5


def test_cli_undistort(tmp_path: Path, calibration: CameraCalibration) -> None:
    calibration_file = tmp_path / 'camera.yaml'
    save_calibration(calibration_file, calibration)
    cv2.imwrite(str(tmp_path / 'board.png'), big_facing_board())
    argv = ['mocap', 'undistort', str(tmp_path / 'board.png'), '--calibration', str(calibration_file),
            '--out', str(tmp_path / 'straight.png')]  # fmt: skip
    assert run_cli(argv) == 0
    straight = cv2.imread(str(tmp_path / 'straight.png'))
    assert straight is not None
    assert worst_row_bend_px(straight) < 0.5


def test_cli_undistort_bad_output_name(
    tmp_path: Path, calibration: CameraCalibration, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration_file = tmp_path / 'camera.yaml'
    save_calibration(calibration_file, calibration)
    cv2.imwrite(str(tmp_path / 'board.png'), np.zeros((480, 640, 3), np.uint8))
    argv = ['mocap', 'undistort', str(tmp_path / 'board.png'), '--calibration', str(calibration_file),
            '--out', str(tmp_path / 'straight.unknown')]  # fmt: skip
    assert run_cli(argv) == 2
    assert 'could not write' in capsys.readouterr().err


def test_calibration_yaml_round_trip(tmp_path: Path, calibration: CameraCalibration) -> None:
    path = tmp_path / 'camera.yaml'
    save_calibration(path, calibration)
    loaded = load_calibration(path)
    np.testing.assert_allclose(loaded.camera_matrix, calibration.camera_matrix, rtol=1e-12)
    np.testing.assert_allclose(loaded.dist_coeffs, calibration.dist_coeffs, rtol=1e-12)
    assert loaded.image_size == (640, 480)
    assert loaded.pattern == PATTERN
    assert loaded.square_size_m == SQUARE_M


def test_no_corners_is_a_clear_error(tmp_path: Path) -> None:
    blank = tmp_path / 'sand.png'
    cv2.imwrite(str(blank), syn.render(CAMERA, *VIEW, syn.sand(), supersample=1))
    with pytest.raises(InputError, match='found in 0 of 3 images'):
        calibrate_camera([blank] * 3, SQUARE_M, PATTERN)


def test_wrong_pattern_rejects_images(scene: Scene) -> None:
    with pytest.raises(InputError, match=r'7x6 inner corners found in 0 of 8'):
        calibrate_camera(scene['calibration_images'], SQUARE_M, (7, 6))


@pytest.mark.parametrize('text', ['9by6', '9x', '1x6', 'x', '', '9x6x2', '-9x6'])
def test_bad_pattern_string(text: str) -> None:
    with pytest.raises(InputError, match='bad pattern'):
        parse_pattern(text)


def test_pattern_string() -> None:
    assert parse_pattern('9x6') == (9, 6)
    assert parse_pattern(' 7X5 ') == (7, 5)


@pytest.mark.parametrize(
    ('content', 'error'),
    [
        ('camera_matrix_px: [[1, 0], [0, 1]]\n', ConfigError),
        ('- just\n- a list\n', ConfigError),
        (': [\n', ConfigError),
    ],
)
def test_bad_calibration_file(tmp_path: Path, content: str, error: type[Exception]) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text(content)
    with pytest.raises(error, match=r'bad\.yaml'):
        load_calibration(path)


def test_missing_calibration_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match='not found'):
        load_calibration(tmp_path / 'none.yaml')


# -- ground plane and target -------------------------------------------------------------------------


def test_ground_plane_maps_pixels_to_metres(calibration: CameraCalibration, plane: GroundPlane) -> None:
    # Project known plane points with the TRUE camera, map them back with the estimated one.
    truth = np.array([[0.0, 0.0, 0.0], [0.4, 0.25, 0.0], [0.7, -0.3, 0.0], [-0.3, 0.6, 0.0]])
    pixels, _ = cv2.projectPoints(truth, *VIEW, CAMERA.camera_matrix, CAMERA.dist_coeffs)
    mapped = pixels_to_plane(pixels.reshape(-1, 2), calibration, plane)
    np.testing.assert_allclose(mapped, truth[:, :2], atol=0.003)
    # camera centre (0.7, 0.125, -1.3) is 1.3 m from the plane Z = 0
    assert plane.camera_height_m == pytest.approx(1.3, rel=0.01)


def test_plane_without_board_is_a_clear_error(calibration: CameraCalibration) -> None:
    with pytest.raises(InputError, match='no 9x6 checkerboard found in the plane image'):
        estimate_ground_plane(
            syn.render(CAMERA, *VIEW, syn.sand(), supersample=1), calibration, PATTERN, SQUARE_M
        )


def test_plane_image_of_another_size_is_refused(calibration: CameraCalibration) -> None:
    with pytest.raises(InputError, match='calibrated at 640x480'):
        estimate_ground_plane(np.zeros((240, 320, 3), np.uint8), calibration, PATTERN, SQUARE_M)


def test_target_detected_and_sand_rejected() -> None:
    rvec, tvec = VIEW
    background = syn.render(CAMERA, rvec, tvec, syn.sand(), supersample=1)
    frame = syn.render_disc_frame(background, CAMERA, rvec, tvec, syn.sand(), (0.3, 0.2), DISC_RADIUS_M)
    found = detect_target(frame, TargetConfig())
    assert isinstance(found, TargetDetection)
    # disc of 50 mm radius ~1.4 m away at f = 520 px: ~18.6 px radius, ~1090 px area
    assert 800 < found.area_px < 1400
    assert found.roundness > 0.8
    miss = detect_target(background, TargetConfig())
    assert isinstance(miss, TargetMiss)
    assert 'no target pixels' in miss.reason


def test_small_or_elongated_blob_is_refused() -> None:
    image = np.full((100, 100, 3), (128, 178, 194), np.uint8)
    image[40:43, 40:43] = (35, 30, 200)
    assert 'px <' in detect_target(image, TargetConfig(min_area_px=30)).reason
    image[40:43, 10:90] = (35, 30, 200)
    assert 'not round' in detect_target(image, TargetConfig()).reason


def test_bad_target_config() -> None:
    with pytest.raises(ConfigError, match='red_min'):
        TargetConfig(red_min=300)
    with pytest.raises(ConfigError, match='min_roundness'):
        TargetConfig(min_roundness=math.nan)


# -- tracking ----------------------------------------------------------------------------------------


def check_run(result: TrackResult, *, expected_samples: int, video_frames_per_index: int = 1) -> None:
    truth_x, truth_y = disc_position(result.time_s)
    error = np.hypot(result.xy_m[:, 0] - truth_x, result.xy_m[:, 1] - truth_y)
    assert error.max() < 0.005  # trace within 5 mm
    assert result.fit.radius_m == pytest.approx(RADIUS_M, rel=0.01)
    assert (result.fit.center_x_m, result.fit.center_y_m) == pytest.approx(CENTRE_M, abs=0.005)
    # Polyline over 5 Hz samples of a 0.55 m circle: 0.0909 rad a step, chord/arc = 0.99966, and
    # across the skipped sample 0.99862; both well inside the 2 % tolerance.
    assert result.speed_m_s == pytest.approx(SPEED_M_S, rel=0.02)
    # the disc's size read back on the plane, the text's check (144.30 mm measured for 144.00 mm)
    np.testing.assert_allclose(result.diameter_m, 2 * DISC_RADIUS_M, atol=0.002)
    assert len(result.time_s) == expected_samples
    assert [index * video_frames_per_index for index, _ in result.skipped] == [NO_TARGET_FRAME]


def test_track_video_sampled_at_5_hz(
    scene: Scene, calibration: CameraCalibration, plane: GroundPlane
) -> None:
    result = track(scene['video'], calibration, plane, sample_hz=SAMPLE_HZ)
    assert result.fps == pytest.approx(FPS)
    # frames 0, 6, ..., 150 are sampled (26), the one at frame 60 has no target
    assert np.all(np.diff(result.frame_index) % 6 == 0)
    check_run(result, expected_samples=25)


def test_track_image_folder(scene: Scene, calibration: CameraCalibration, plane: GroundPlane) -> None:
    result = track(scene['folder'], calibration, plane, fps=SAMPLE_HZ)
    # the folder holds every 6th video frame, so frame 60 of the video is image 10
    check_run(result, expected_samples=25, video_frames_per_index=6)


def test_folder_needs_fps(scene: Scene, calibration: CameraCalibration, plane: GroundPlane) -> None:
    with pytest.raises(InputError, match='pass --fps'):
        track(scene['folder'], calibration, plane)


def test_sample_rate_above_frame_rate_is_refused(
    scene: Scene, calibration: CameraCalibration, plane: GroundPlane
) -> None:
    with pytest.raises(InputError, match='at most the frame rate'):
        track(scene['video'], calibration, plane, sample_hz=60.0)


def test_too_few_detections_is_a_clear_error(
    scene: Scene, calibration: CameraCalibration, plane: GroundPlane
) -> None:
    with pytest.raises(InputError, match='target found in 0 of'):
        track(scene['video'], calibration, plane, target=TargetConfig(min_area_px=5000))


def test_missing_source(tmp_path: Path, calibration: CameraCalibration, plane: GroundPlane) -> None:
    with pytest.raises(InputError, match='not found'):
        track(tmp_path / 'nothing.avi', calibration, plane)


# -- command line ------------------------------------------------------------------------------------


def run_cli(argv: list[str]) -> int:
    """Exit code of ``skidsteer-power ARGV`` run in-process (argparse errors exit via SystemExit)."""
    try:
        return main(argv)
    except SystemExit as stop:
        assert isinstance(stop.code, int), stop.code
        return stop.code


def test_cli_calibrate_then_track(scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    calibration_file = tmp_path / 'camera.yaml'
    argv = ['mocap', 'calibrate', *map(str, scene['calibration_images']), '--square-size', '0.05',
            '--pattern', '9x6', '--out', str(calibration_file), '--json']  # fmt: skip
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary['fx_px'] == pytest.approx(520.0, rel=0.01)
    assert yaml.safe_load(calibration_file.read_text())['pattern_cols_rows'] == [9, 6]

    trace_csv = tmp_path / 'trace.csv'
    argv = ['mocap', 'track', str(scene['video']), '--calibration', str(calibration_file), '--plane',
            str(scene['plane_image']), '--sample-hz', '5', '--csv', str(trace_csv), '--json']  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['radius_m'] == pytest.approx(RADIUS_M, rel=0.01)
    assert out['speed_m_s'] == pytest.approx(SPEED_M_S, rel=0.02)
    assert out['center_m'] == pytest.approx(list(CENTRE_M), abs=0.005)
    assert (out['samples'], out['skipped']) == (25, 1)
    assert out['target_diameter_m'] == pytest.approx(2 * DISC_RADIUS_M, abs=0.001)
    rows = np.loadtxt(trace_csv, delimiter=',', skiprows=1)
    assert rows.shape == (25, 4)
    truth_x, truth_y = disc_position(rows[:, 1])
    assert np.hypot(rows[:, 2] - truth_x, rows[:, 3] - truth_y).max() < 0.005


@pytest.mark.parametrize(
    ('argv', 'message'),
    [
        (['mocap', 'calibrate', 'none.png', '--square-size', '0.05', '--pattern', '9x6', '--out', 'c.yaml'],
         'image not found'),
        (['mocap', 'calibrate', 'none.png', '--square-size', '0.05', '--pattern', '9-6', '--out', 'c.yaml'],
         'bad pattern'),
        (['mocap', 'calibrate', 'none.png', '--square-size', '-1', '--pattern', '9x6', '--out', 'c.yaml'],
         'must be > 0'),
        (['mocap', 'track', 'run.avi', '--calibration', 'none.yaml', '--plane', 'p.png'],
         'calibration file not found'),
    ],
)  # fmt: skip
def test_cli_errors_are_one_line(
    argv: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert run_cli(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert 'Traceback' not in err


def test_cli_plane_size_mismatch(
    scene: Scene, tmp_path: Path, calibration: CameraCalibration, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration_file = tmp_path / 'camera.yaml'
    save_calibration(calibration_file, calibration)
    small = tmp_path / 'small.png'
    cv2.imwrite(str(small), np.zeros((240, 320, 3), np.uint8))
    argv = [
        'mocap',
        'track',
        str(scene['video']),
        '--calibration',
        str(calibration_file),
        '--plane',
        str(small),
    ]
    assert run_cli(argv) == 2
    assert 'calibrated at 640x480' in capsys.readouterr().err


def test_k3_is_fitted_only_on_request(scene: Scene) -> None:
    with_k3 = calibrate_camera(scene['calibration_images'], SQUARE_M, PATTERN, use_k3=True)
    assert with_k3.dist_coeffs[4] != 0.0
    assert with_k3.focal_px[0] == pytest.approx(520.0, rel=0.01)


def test_sampling_picks_the_frame_nearest_each_instant(tmp_path: Path) -> None:
    # 10 images at 10 frames/s sampled at 4 Hz: instants 0, 0.25, 0.5, 0.75 s; the nearest frames
    # (ties to the earlier one) are 0 (0 s), 2 (0.2 s), 5 (0.5 s) and 7 (0.7 s).
    for index in range(10):
        cv2.imwrite(str(tmp_path / f'f{index}.png'), np.zeros((4, 4, 3), np.uint8))
    frames, fps, rate = open_frames(tmp_path, fps=10.0, sample_hz=4.0)
    assert (fps, rate) == (10.0, 4.0)
    assert [frame.index for frame in frames] == [0, 2, 5, 7]


def test_folder_images_in_natural_order(tmp_path: Path) -> None:
    for index in (10, 2, 1):
        cv2.imwrite(str(tmp_path / f'img_{index}.png'), np.full((4, 4, 3), index, np.uint8))
    frames, _, _ = open_frames(tmp_path, fps=1.0)
    images = [frame.image for frame in frames]
    assert all(image is not None for image in images)
    assert [int(image[0, 0, 0]) for image in images if image is not None] == [1, 2, 10]


def test_unreadable_video_is_a_clear_error(
    tmp_path: Path, calibration: CameraCalibration, plane: GroundPlane
) -> None:
    bogus = tmp_path / 'run.avi'
    bogus.write_text('not a video')
    with pytest.raises(InputError, match='cannot open video'):
        track(bogus, calibration, plane)


def test_cli_track_table_output(
    scene: Scene, tmp_path: Path, calibration: CameraCalibration, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration_file = tmp_path / 'camera.yaml'
    save_calibration(calibration_file, calibration)
    argv = ['mocap', 'track', str(scene['folder']), '--calibration', str(calibration_file), '--plane',
            str(scene['plane_image']), '--fps', '5']  # fmt: skip
    assert run_cli(argv) == 0
    lines = {line.split()[0]: line.split()[1:] for line in capsys.readouterr().out.splitlines()}
    assert float(lines['radius_m'][0]) == pytest.approx(RADIUS_M, rel=0.01)
    assert lines['samples'] == ['25']


def test_target_mask_is_the_rgb_and_saturation_thresholds() -> None:
    # Brute force over the whole image: R >= 120, G <= 100, B <= 100 and HSV S >= 120 (OpenCV's
    # 8-bit S = 255 (max - min) / max), on random colours plus a red patch.
    rng = np.random.default_rng(2)
    image = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    image[20:30, 30:45] = (40, 30, 210)
    blue, green, red = (image[:, :, k].astype(int) for k in range(3))
    high, low = image.max(axis=2).astype(int), image.min(axis=2).astype(int)
    saturation = np.where(high > 0, np.round(255 * (high - low) / np.maximum(high, 1)), 0)
    expected = (red >= 120) & (green <= 100) & (blue <= 100) & (saturation >= 120)
    np.testing.assert_array_equal(target_mask(image, TargetConfig()) > 0, expected)


def test_disc_cut_by_the_border_is_refused() -> None:
    image = np.full((100, 100, 3), (128, 178, 194), np.uint8)
    cv2.circle(image, (3, 50), 15, (35, 30, 200), -1)
    assert 'border' in detect_target(image, TargetConfig()).reason
