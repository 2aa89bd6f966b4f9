"""``skidsteer-power mocap calibrate|track``: motion capture with one camera (chapter 7.3.3).

mocap calibrate IMAGE... --square-size M --pattern COLSxROWS --out FILE [--k3] [--json]
mocap undistort IMAGE --calibration FILE --out FILE     (lens distortion removed, Figure 7.29)
mocap track VIDEO|DIR --calibration FILE --plane IMAGE [--fps F] [--sample-hz H] [--csv OUT] --json
    -> radius_m, speed_m_s, center_m, samples, skipped (+ rms_residual_m, duration_s, ...)

center_m is in the frame of the plane board: origin at its first detected inner corner, x along the
pattern's columns, y along its rows (see ``skidsteer_power.mocap.plane``).
"""

from __future__ import annotations

import argparse
import math

from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, positive_float
from skidsteer_power.errors import InputError
from skidsteer_power.mocap.config import MAX_PATTERN_SIDE, TargetConfig, parse_pattern

# The OpenCV-backed modules are imported inside the handlers: every skidsteer-power command builds
# this parser, and only mocap commands need cv2.


def _pattern(text: str) -> tuple[int, int]:
    try:
        return parse_pattern(text)
    except InputError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _byte(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if not 0 <= value <= 255:
        raise argparse.ArgumentTypeError(f'must be within 0..255: {text!r}')
    return value


def _calibrate(args: argparse.Namespace) -> int:
    from skidsteer_power.mocap.calibration import calibrate_camera, save_calibration

    calibration = calibrate_camera(args.images, args.square_size, args.pattern, use_k3=args.k3)
    save_calibration(args.out, calibration)
    emit({'calibration_file': str(args.out), **calibration.summary()}, args.json)
    return 0


def _undistort(args: argparse.Namespace) -> int:
    import cv2

    from skidsteer_power.mocap.calibration import load_calibration, read_image, undistort_image
    from skidsteer_power.mocap.plane import check_image_size

    calibration = load_calibration(args.calibration)
    image = read_image(args.image)
    check_image_size(image, calibration, 'image')
    message = f'could not write {args.out} (unknown image extension or unwritable path)'
    try:
        written = cv2.imwrite(str(args.out), undistort_image(image, calibration))
    except cv2.error as err:
        raise InputError(message) from err
    if not written:
        raise InputError(message)
    return 0


def _track(args: argparse.Namespace) -> int:
    from skidsteer_power.mocap.calibration import load_calibration, read_image
    from skidsteer_power.mocap.plane import estimate_ground_plane
    from skidsteer_power.mocap.tracking import track, write_trace_csv

    calibration = load_calibration(args.calibration)
    pattern = args.pattern or calibration.pattern
    square = args.square_size or calibration.square_size_m
    if min(pattern) < 2 or not math.isfinite(square):
        raise InputError(
            'the calibration file names no board: pass --pattern and --square-size for the plane'
        )
    plane = estimate_ground_plane(read_image(args.plane), calibration, pattern, square)
    config = TargetConfig(
        red_min=args.red_min,
        green_max=args.green_max,
        blue_max=args.blue_max,
        saturation_min=args.saturation_min,
        min_area_px=args.min_area_px,
        min_roundness=args.min_roundness,
    )
    result = track(args.source, calibration, plane, fps=args.fps, sample_hz=args.sample_hz, target=config)
    if args.csv:
        write_trace_csv(args.csv, result)
    emit({**result.summary(), 'plane_reprojection_px': plane.reprojection_px}, args.json)
    return 0


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'mocap', help='motion capture of a red target with one camera (chapter 7.3.3)'
    )
    commands = parser.add_subparsers(
        dest='mocap_command', metavar='{calibrate,undistort,track}', required=True
    )

    calibrate = commands.add_parser('calibrate', help='camera intrinsics from checkerboard images -> YAML')
    calibrate.add_argument('images', nargs='+', metavar='IMAGE', help='checkerboard images')
    calibrate.add_argument('--square-size', type=positive_float, required=True, help='square side [m]')
    calibrate.add_argument(
        '--pattern',
        type=_pattern,
        required=True,
        help=f'inner corners COLSxROWS, e.g. 9x6 (2 to {MAX_PATTERN_SIDE} a side)',
    )
    calibrate.add_argument('--out', required=True, help='calibration YAML to write')
    calibrate.add_argument('--k3', action='store_true', help='also fit k3 (wide-angle lenses, eq. 7.7)')
    add_json_flag(calibrate)
    calibrate.set_defaults(func=_calibrate)

    undistort = commands.add_parser('undistort', help='remove the lens distortion from an image')
    undistort.add_argument('image', metavar='IMAGE', help='image taken by the calibrated camera')
    undistort.add_argument('--calibration', required=True, help='YAML from "mocap calibrate"')
    undistort.add_argument('--out', required=True, help='undistorted image to write (.png, .jpg ...)')
    undistort.set_defaults(func=_undistort)

    defaults = TargetConfig()
    trk = commands.add_parser('track', help='trace, turning radius and speed of the red target')
    trk.add_argument('source', metavar='VIDEO|DIR', help='video file, or folder of images in name order')
    trk.add_argument('--calibration', required=True, help='YAML from "mocap calibrate"')
    trk.add_argument(
        '--plane', required=True, help='image of a checkerboard lying in the plane of the target'
    )
    trk.add_argument(
        '--pattern',
        type=_pattern,
        help=f'plane board inner corners (default: the calibration board; 2 to {MAX_PATTERN_SIDE} a side)',
    )
    trk.add_argument(
        '--square-size', type=positive_float, help='plane board square [m] (default: calibration)'
    )
    trk.add_argument(
        '--fps', type=positive_float, help='frame rate [1/s] (video: from the file; DIR: required)'
    )
    trk.add_argument(
        '--sample-hz', type=positive_float, help='sampling rate [Hz] (video: 5; DIR: every image)'
    )
    trk.add_argument('--csv', help='write the trace (frame, t_s, x_m, y_m) to this CSV file')
    trk.add_argument('--red-min', type=_byte, default=defaults.red_min, help='R >= this (0-255)')
    trk.add_argument('--green-max', type=_byte, default=defaults.green_max, help='G <= this (0-255)')
    trk.add_argument('--blue-max', type=_byte, default=defaults.blue_max, help='B <= this (0-255)')
    trk.add_argument('--saturation-min', type=_byte, default=defaults.saturation_min, help='HSV S >= this')
    trk.add_argument('--min-area-px', type=int, default=defaults.min_area_px, help='smallest blob [px]')
    trk.add_argument('--min-roundness', type=float, default=defaults.min_roundness, help='4 pi A / P^2 (0-1)')
    add_json_flag(trk)
    trk.set_defaults(func=_track)
