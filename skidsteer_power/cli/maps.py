"""Command ``map build|show``: FESS look-up maps over (forward speed, yaw rate).

skidsteer-power map build --vehicle V --terrain T [--out FILE | --cache-dir DIR] [--max-speed V]
                          [--max-yaw-rate W] [--rings 16] [--angles 101] [--elements N]
                          [--min-radius M] [--no-progress] [--json]
    -> path, build_time_s, vehicle, terrain, model_version, converged_points, total_points, ...
skidsteer-power map show (FILE | --vehicle V --terrain T [--cache-dir DIR])
                         [--speed V --yaw-rate W] [--json]
    -> the map's metadata and extent; with --speed/--yaw-rate the interpolated values there

Defaults are the library's (skidsteer_power.maps.build_options: the vehicle's command envelope,
the 16 x 101 grid): a map built here with defaults is the very file the estimator and missions load,
and a map built with other options is cached under another name.
A file built for another vehicle, terrain or model version is refused (one error line, exit 2).
The progress bar goes to stderr, so ``--json`` output on stdout stays clean.
"""

from __future__ import annotations

import argparse
import sys
import time
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, finite_float
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.maps import PowerMap, cache_path
from skidsteer_power.maps.power_map import DEFAULT_SHAPE
from skidsteer_power.terramechanics.ranges import (
    FORWARD_SPEED_M_S,
    MAP_ANGLES,
    MAP_ELEMENTS,
    MAP_RINGS,
    MIN_RADIUS_M,
    YAW_RATE_RAD_S,
)
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from rich.progress import Progress


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser('map', help='build or show FESS look-up maps over (speed, yaw rate)')
    sub = parser.add_subparsers(dest='map_command', metavar='ACTION', parser_class=type(parser))
    sub.required = True

    build = sub.add_parser('build', help='solve a map with FESS and store it (.npz)')
    build.add_argument('--vehicle', required=True, help='vehicle YAML file or a name in config/vehicles/')
    build.add_argument('--terrain', required=True, help='terrain preset name or YAML file')
    where = build.add_mutually_exclusive_group()
    where.add_argument('--out', type=Path, help='output .npz file (default: the cache)')
    where.add_argument(
        '--cache-dir',
        type=Path,
        help='cache directory (default $SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power)',
    )
    # every option that sets the build's work or the map's extent has a range (terramechanics.ranges)
    options = (
        ('--max-speed', FORWARD_SPEED_M_S, "largest |forward speed| (default: the vehicle file's)"),
        ('--max-yaw-rate', YAW_RATE_RAD_S, "largest |yaw rate| (default: the vehicle file's)"),
        ('--rings', MAP_RINGS, f'grid rings of command magnitude (default {DEFAULT_SHAPE[0]})'),
        ('--angles', MAP_ANGLES, f'grid turn angles, -90..90 deg (default {DEFAULT_SHAPE[1]})'),
        ('--elements', MAP_ELEMENTS, 'FESS elements per contact (default 40)'),
        ('--min-radius', MIN_RADIUS_M, 'small-radius limit (default 2 x tread)'),
    )
    for flag, limits, what in options:
        build.add_argument(flag, type=range_arg(limits), help=range_help(limits, what))
    build.add_argument('--no-progress', action='store_true', help='no progress bar')
    add_json_flag(build)
    build.set_defaults(func=run_build)

    show = sub.add_parser('show', help='describe a stored map, or query it at one command')
    show.add_argument('file', nargs='?', type=Path, help='map .npz file (or give --vehicle and --terrain)')
    show.add_argument('--vehicle', help='vehicle the map must be built for (file or name)')
    show.add_argument('--terrain', help='terrain the map must be built for (preset or YAML)')
    show.add_argument('--cache-dir', type=Path, help='cache directory to look in (with --vehicle/--terrain)')
    show.add_argument('--speed', type=finite_float, help='query: forward speed V [m/s]')
    show.add_argument('--yaw-rate', type=finite_float, help='query: yaw rate [rad/s] (+ = left)')
    add_json_flag(show)
    show.set_defaults(func=run_show)


def _progress_bar(enabled: bool) -> Progress | None:
    """A rich progress bar on stderr (None when disabled or stderr is not a terminal)."""
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn('building map'),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn('steps (rings, then the cell check)'),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    )


def run_build(args: argparse.Namespace) -> int:
    vehicle = load_vehicle(args.vehicle)
    terrain = load_terrain(args.terrain)
    options = {
        'max_speed': args.max_speed,
        'max_yaw_rate': args.max_yaw_rate,
        'shape': None
        if args.rings is None and args.angles is None
        else (args.rings or DEFAULT_SHAPE[0], args.angles or DEFAULT_SHAPE[1]),
        'n': args.elements,
        'min_radius': args.min_radius,
    }
    target = args.out if args.out is not None else cache_path(vehicle, terrain, args.cache_dir, **options)
    bar = _progress_bar(not args.no_progress)
    start = time.perf_counter()
    if bar is None:
        power_map = PowerMap.build(vehicle, terrain, **options)
    else:
        with bar:
            task = bar.add_task('build', total=args.rings or DEFAULT_SHAPE[0])
            power_map = PowerMap.build(
                vehicle, terrain, **options, progress=lambda done, total: bar.update(task, completed=done)
            )
    elapsed = time.perf_counter() - start
    try:
        power_map.save(target)
    except OSError as err:
        raise ConfigError(f'cannot write map {target}: {err.strerror or err}') from err
    emit({**power_map.summary(), 'build_time_s': elapsed}, args.json)
    return 0


def run_show(args: argparse.Namespace) -> int:
    vehicle = load_vehicle(args.vehicle) if args.vehicle else None
    terrain = load_terrain(args.terrain) if args.terrain else None
    path = args.file
    if path is None:
        if vehicle is None or terrain is None:
            raise InputError('give a map file, or --vehicle and --terrain to find the cached map')
        path = cache_path(vehicle, terrain, args.cache_dir)
        if not path.exists():  # built with other options: same name up to the options' digest
            others = sorted(
                path.parent.glob(path.name.rsplit('_', 1)[0] + '_*.npz'), key=lambda p: p.stat().st_mtime
            )
            if not others:
                raise ConfigError(f'no cached map for {vehicle.name} on {terrain.name} (run: map build)')
            path = others[-1]  # the newest
    try:
        power_map = PowerMap.load(path, vehicle, terrain)
    except (EOFError, zipfile.BadZipFile) as err:  # empty / truncated: PowerMap.load lets these pass
        # (caught here, not there: a change to maps/ changes the physics digest and every cached map)
        raise ConfigError(f'{path}: not a skidsteer_power map ({err or type(err).__name__})') from err
    if (args.speed is None) != (args.yaw_rate is None):
        raise InputError('give both --speed and --yaw-rate to query the map')
    payload = power_map.summary()
    if args.speed is not None:
        q = power_map.query(args.speed, args.yaw_rate)
        payload = {
            'speed_m_s': args.speed,
            'yaw_rate_rad_s': args.yaw_rate,
            **vars(q),
            'total_power_W': q.total_power_W,
            'map': str(path),
        }
    emit(payload, args.json)
    return 0
