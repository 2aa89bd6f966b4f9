"""Command ``predict``: what the robot does for a command (FESS at the command's wheel speed set points).

skidsteer-power predict --vehicle V --terrain T --speed V --yaw-rate W [--direct] [--json]
skidsteer-power predict --vehicle V --terrain T --commands FILE.csv [--direct] [--json]
    (columns speed_m_s,yaw_rate_rad_s: a JSON list, one object per row; without --json a CSV)
    -> speed_cmd_m_s, yaw_rate_cmd_rad_s, setpoint_left_rad_s, setpoint_right_rad_s, speed_m_s,
       yaw_rate_rad_s, turn_radius_m, omega_left_rad_s, omega_right_rad_s, torque_left_Nm,
       torque_right_Nm, slip_left, slip_right, sinkage_m, current_left_A, current_right_A,
       battery_power_W, limited, clamped, reason

The set points are the robot's drive controller's (:mod:`skidsteer_power.drive`; axle speeds, left
and right); the motion, torques and currents are
FESS's steady state at those side speeds: by default the vehicle x terrain's set-point map
(:mod:`skidsteer_power.maps.setpoint_map`, built once and cached, as the robot queries it),
with ``--direct`` the solve itself (:mod:`skidsteer_power.models.predict`). turn_radius_m is +-inf
straight, 0 spinning in place, null at rest.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import COMMAND_YAW_RATE_RAD_S, SPEED_M_S, check_file_size

if TYPE_CHECKING:
    from skidsteer_power.maps.setpoint_map import SetpointQuery
    from skidsteer_power.models.predict import PredictRecord
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

# The heavy parts (maps, models: numpy, scipy) are imported in run_predict: `skidsteer-power --help`
# stays fast (cli/main.py).
MAX_COMMAND_ROWS = 200_000
"""Most rows ``--commands`` reads from the set-point map (about 10-40 us a row)."""
MAX_DIRECT_ROWS = 2_000
"""Most rows ``--commands`` solves with ``--direct`` (one batched FESS solve, about 1-5 ms a row)."""
COMMAND_CSV_BYTES = 32 * 2**20
"""Largest ``--commands`` file read [bytes]."""
COLUMNS = ('speed_m_s', 'yaw_rate_rad_s')


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'predict',
        help='what the robot does for a command: FESS at its wheel speed set points',
        description='Predict the motion, torques, currents and battery power a command (V, yaw rate) '
        'really produces: the amplifiers hold the side speeds, the terrain decides the motion.',
    )
    parser.add_argument('--vehicle', required=True, help='vehicle YAML file or a name in config/vehicles/')
    parser.add_argument('--terrain', required=True, help='terrain preset name or YAML file')
    parser.add_argument('--speed', type=range_arg(SPEED_M_S), help=range_help(SPEED_M_S, 'commanded speed V'))
    parser.add_argument(
        '--yaw-rate',
        type=range_arg(COMMAND_YAW_RATE_RAD_S),
        help=range_help(COMMAND_YAW_RATE_RAD_S, 'commanded yaw rate'),
    )
    parser.add_argument(
        '--commands',
        metavar='FILE.csv',
        help='many commands at once instead of --speed/--yaw-rate: a CSV with columns speed_m_s, '
        f'yaw_rate_rad_s (each in the ranges above); at most {MAX_COMMAND_ROWS:,} rows from the map, '
        f'{MAX_DIRECT_ROWS:,} with --direct, {COMMAND_CSV_BYTES // 2**20} MiB',
    )
    parser.add_argument(
        '--direct',
        action='store_true',
        help='solve FESS for this command (default: the cached set-point map)',
    )
    add_json_flag(parser)
    parser.set_defaults(func=run_predict)


def run_predict(args: argparse.Namespace) -> int:
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    single = args.speed is not None or args.yaw_rate is not None
    if args.commands is not None and single:
        raise InputError('give either --commands or --speed and --yaw-rate, not both')
    if args.commands is None and (args.speed is None or args.yaw_rate is None):
        raise InputError('give --speed and --yaw-rate (or --commands FILE.csv)')
    vehicle, terrain = load_vehicle(args.vehicle), load_terrain(args.terrain)
    if args.commands is None:
        emit(predict_records(vehicle, terrain, [(args.speed, args.yaw_rate)], args.direct)[0], args.json)
        return 0
    limit = MAX_DIRECT_ROWS if args.direct else MAX_COMMAND_ROWS
    records = predict_records(vehicle, terrain, read_commands(Path(args.commands), limit), args.direct)
    if args.json:  # a JSON list, one object a line
        import json

        from skidsteer_power.cli.common import _plain

        sys.stdout.write('[\n' + ',\n'.join(json.dumps(_plain(r)) for r in records) + '\n]\n')
    else:
        print(','.join(JSON_KEYS))
        for record in records:
            print(','.join(_csv_cell(record[key]) for key in JSON_KEYS))
    return 0


def predict_records(
    vehicle: Vehicle, terrain: Terrain, commands: list[tuple[float, float]], direct: bool
) -> list[PredictRecord]:
    """predict's record (keys ``JSON_KEYS``) of each command (V [m/s], w_z [rad/s]): one batched
    direct solve, or one set-point map query each (the map built once and cached)."""
    from skidsteer_power.maps.setpoint_map import load_or_build
    from skidsteer_power.models.predict import CommandPredictor

    if direct:
        pred = CommandPredictor(vehicle, terrain).predict([c[0] for c in commands], [c[1] for c in commands])
        records = [pred.record(k) for k in range(len(commands))]
    else:
        smap, _ = load_or_build(vehicle, terrain)
        speeds, yaw_rates = [c[0] for c in commands], [c[1] for c in commands]
        answers = smap.query_many(speeds, yaw_rates)  # the exact cells' commands: one batched solve
        records = [_map_record(v, w, q) for (v, w), q in zip(commands, answers, strict=True)]
    out = []
    for record in records:
        radius = record['turn_radius_m']
        if isinstance(radius, float) and math.isnan(radius):
            record['turn_radius_m'] = None  # at rest: no turning radius
        out.append({key: record[key] for key in JSON_KEYS})
    return out


def read_commands(path: Path, max_rows: int) -> list[tuple[float, float]]:
    """(V [m/s], w_z [rad/s]) of each row of a command CSV (:data:`COLUMNS`); InputError naming the
    line for a bad row, past ``max_rows`` rows (before reading further) or past the size limit."""
    import csv

    try:
        check_file_size(path, COMMAND_CSV_BYTES)
        with path.open(newline='', encoding='utf-8') as handle:
            reader = csv.DictReader(handle)
            missing = set(COLUMNS) - set(reader.fieldnames or ())
            if missing:
                raise InputError(
                    f'{path}: missing column(s) {", ".join(sorted(missing))} (need {", ".join(COLUMNS)})'
                )
            rows: list[tuple[float, float]] = []
            for line, row in enumerate(reader, start=2):
                if len(rows) >= max_rows:
                    raise InputError(f'{path}: more than {max_rows:,} rows')
                rows.append(_command(path, line, row))
    except OSError as err:
        raise InputError(f'cannot read command file {path}: {err.strerror or err}') from err
    except (csv.Error, UnicodeDecodeError) as err:
        raise InputError(f'{path}: not a command CSV ({err})') from err
    if not rows:
        raise InputError(f'{path}: no commands')
    return rows


def _command(path: Path, line: int, row: Mapping[str, str]) -> tuple[float, float]:
    try:
        speed, yaw_rate = (float(row[k]) for k in COLUMNS)
    except (TypeError, ValueError):  # TypeError: csv gives a short row's missing cells as None
        raise InputError(f'{path}:{line}: {" and ".join(COLUMNS)} must be numbers') from None
    try:
        return SPEED_M_S.check(speed), COMMAND_YAW_RATE_RAD_S.check(yaw_rate)
    except InputError as err:
        raise InputError(f'{path}:{line}: {err}') from None


def _csv_cell(value: object) -> str:
    if value is None:
        return ''
    if isinstance(value, str):
        return '"' + value.replace('"', '""') + '"' if (',' in value or '"' in value) else value
    return repr(value) if isinstance(value, float) else str(value)


JSON_KEYS = (
    'speed_cmd_m_s',
    'yaw_rate_cmd_rad_s',
    'setpoint_left_rad_s',
    'setpoint_right_rad_s',
    'speed_m_s',
    'yaw_rate_rad_s',
    'turn_radius_m',
    'omega_left_rad_s',
    'omega_right_rad_s',
    'torque_left_Nm',
    'torque_right_Nm',
    'slip_left',
    'slip_right',
    'sinkage_m',
    'current_left_A',
    'current_right_A',
    'battery_power_W',
    'limited',
    'clamped',
    'reason',
)
"""The keys of predict's records (DESIGN.md); the same as ``models.predict.JSON_KEYS`` (a test checks),
written here so that the command's module imports no model."""


def _map_record(speed: float, yaw_rate: float, q: SetpointQuery) -> PredictRecord:
    record: PredictRecord = {
        'speed_cmd_m_s': speed,
        'yaw_rate_cmd_rad_s': yaw_rate,
        'turn_radius_m': q.turn_radius_m,
        'omega_left_rad_s': q.setpoint_left_rad_s,
        'omega_right_rad_s': q.setpoint_right_rad_s,
    }
    for key in JSON_KEYS:
        record.setdefault(key, getattr(q, key, None))
    return record
