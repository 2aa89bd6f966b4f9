"""Command ``predict``: what the robot does for a command (FESS at the command's wheel speed set points).

skidsteer-power predict --vehicle V --terrain T --speed V --yaw-rate W [--direct] [--json]
    -> speed_cmd_m_s, yaw_rate_cmd_rad_s, setpoint_left_rad_s, setpoint_right_rad_s, speed_m_s,
       yaw_rate_rad_s, turn_radius_m, omega_left_rad_s, omega_right_rad_s, torque_left_Nm,
       torque_right_Nm, slip_left, slip_right, sinkage_m, current_left_A, current_right_A,
       battery_power_W, limited, clamped, reason

The set points are the driver's (axle speeds, left and right); the motion, torques and currents are
FESS's steady state at those side speeds: by default the vehicle x terrain's set-point map
(:mod:`skidsteer_power.maps.setpoint_map`, built once and cached, as the robot queries it),
with ``--direct`` the solve itself (:mod:`skidsteer_power.models.predict`). turn_radius_m is +-inf
straight, 0 spinning in place, null at rest.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.maps.setpoint_map import SetpointQuery, load_or_build
from skidsteer_power.models.predict import JSON_KEYS, CommandPredictor
from skidsteer_power.terramechanics.ranges import COMMAND_YAW_RATE_RAD_S, SPEED_M_S
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'predict',
        help='what the robot does for a command: FESS at its wheel speed set points',
        description='Predict the motion, torques, currents and battery power a command (V, yaw rate) '
        'really produces: the amplifiers hold the side speeds, the terrain decides the motion.',
    )
    parser.add_argument('--vehicle', required=True, help='vehicle YAML file or a name in config/vehicles/')
    parser.add_argument('--terrain', required=True, help='terrain preset name or YAML file')
    parser.add_argument(
        '--speed', required=True, type=SPEED_M_S.arg(), help=SPEED_M_S.help('commanded speed V')
    )
    parser.add_argument(
        '--yaw-rate',
        required=True,
        type=COMMAND_YAW_RATE_RAD_S.arg(),
        help=COMMAND_YAW_RATE_RAD_S.help('commanded yaw rate'),
    )
    parser.add_argument(
        '--direct',
        action='store_true',
        help='solve FESS for this command (default: the cached set-point map)',
    )
    add_json_flag(parser)
    parser.set_defaults(func=run_predict)


def run_predict(args: argparse.Namespace) -> int:
    vehicle, terrain = load_vehicle(args.vehicle), load_terrain(args.terrain)
    if args.direct:
        record = CommandPredictor(vehicle, terrain).predict(args.speed, args.yaw_rate).record(0)
    else:
        smap, _ = load_or_build(vehicle, terrain)
        record = _map_record(args.speed, args.yaw_rate, smap.query(args.speed, args.yaw_rate))
    radius = record['turn_radius_m']
    if isinstance(radius, float) and math.isnan(radius):
        record['turn_radius_m'] = None  # at rest: no turning radius
    emit({key: record[key] for key in JSON_KEYS}, args.json)
    return 0


def _map_record(speed: float, yaw_rate: float, q: SetpointQuery) -> dict[str, Any]:
    record: dict[str, Any] = {
        'speed_cmd_m_s': speed,
        'yaw_rate_cmd_rad_s': yaw_rate,
        'turn_radius_m': q.turn_radius_m,
        'omega_left_rad_s': q.setpoint_left_rad_s,
        'omega_right_rad_s': q.setpoint_right_rad_s,
    }
    for key in JSON_KEYS:
        record.setdefault(key, getattr(q, key, None))
    return record
