"""Command ``solve``: the steady skid-steering state of a vehicle with any model (DESIGN.md).

skidsteer-power solve --vehicle FILE --terrain T --speed V --turn-radius R --model MODEL --json
    MODEL: fess | wong | steeds | icr | fast
    -> s0_m, omega_outer_rad_s, omega_inner_rad_s, torque_outer_Nm, torque_inner_Nm,
       power_outer_W, power_inner_W, converged, solve_time_s
       and also: model, vehicle, terrain, speed_m_s, turn_radius_m, yaw_rate_rad_s, outer_side,
       torque_left_Nm, torque_right_Nm, omega_left_rad_s, omega_right_rad_s, power_left_W,
       power_right_W, total_power_W, slip_outer, slip_inner, thrust_outer_N, thrust_inner_N,
       sinkage_m, traction_margin (and mu_t where the model gives it)

R = inf is straight running; R > 0 turns left (outer = right side), R < 0 right (the mirror image).
``solve_time_s`` is the wall time of the model call alone. Inputs have physical ranges (shown in
--help; skidsteer_power.terramechanics.ranges), --resolution at most a million nodes, and a sinkage
deeper than the wheel radius (wheels) or the track height (tracks: twice the sprocket radius) is an
error.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import numpy.typing as npt

from skidsteer_power import models
from skidsteer_power.argtypes import range_arg, range_help, turn_radius_arg
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.errors import InputError
from skidsteer_power.jsonout import JsonObject
from skidsteer_power.terramechanics.ranges import (
    FORWARD_SPEED_M_S,
    FRICTION,
    MAX_RESOLUTION_NODES,
    TURN_RADIUS_M,
    check_resolution,
    check_sinkage,
)
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle


def _resolution(text: str) -> tuple[int, ...]:
    """argparse type: integration resolution 'N,M' (two positive integers)."""
    try:
        values = tuple(int(part) for part in text.split(','))
    except ValueError:
        raise argparse.ArgumentTypeError(f'resolution must be two integers like 24,3: {text!r}') from None
    if len(values) != 2 or min(values) < 1:
        raise argparse.ArgumentTypeError(f'resolution must be two positive integers like 24,3: {text!r}')
    try:
        return check_resolution(values)
    except InputError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'solve',
        help='steady skid-steering state of a vehicle (Steeds, ICR, Wong, fast, FESS)',
        description='Solve one steady turn: turning-centre offset, per-side sprocket/axle speed, torque '
        'and mechanical power. R = inf is straight running; R > 0 is a left turn (outer = right).',
    )
    parser.add_argument('--vehicle', required=True, help='vehicle YAML file or a name in config/vehicles/')
    parser.add_argument('--terrain', required=True, help='terrain preset name or YAML file')
    parser.add_argument(
        '--speed',
        required=True,
        type=range_arg(FORWARD_SPEED_M_S),
        help=range_help(FORWARD_SPEED_M_S, 'forward speed V'),
    )
    parser.add_argument(
        '--turn-radius',
        required=True,
        type=turn_radius_arg,
        help=f'signed turning radius R [m], inf = straight, else {TURN_RADIUS_M.text}',
    )
    parser.add_argument('--model', required=True, choices=sorted(models.MODELS), help='skid-steering model')
    parser.add_argument(
        '--mu-t',
        type=range_arg(FRICTION),
        help=range_help(FRICTION, 'steeds: coefficient of lateral resistance (Table 3.1)'),
    )
    parser.add_argument(
        '--mu',
        type=range_arg(FRICTION),
        help=range_help(FRICTION, 'icr: Coulomb friction coefficient (1.12 in the text)'),
    )
    parser.add_argument(
        '--resolution',
        type=_resolution,
        help='wong/icr: integration nodes "along,across" (tracks) or "per-panel,nested" (wheels); '
        f'at most {MAX_RESOLUTION_NODES:,} in all',
    )
    add_json_flag(parser)
    parser.set_defaults(func=run_solve)


def _options(args: argparse.Namespace) -> dict[str, object]:
    options: dict[str, object] = {'raise_on_failure': True}
    if args.mu_t is not None:
        if args.model != 'steeds':
            raise InputError('--mu-t applies to --model steeds only')
        options['mu_t'] = args.mu_t
    if args.mu is not None:
        if args.model != 'icr':
            raise InputError('--mu applies to --model icr only')
        options['mu'] = args.mu
    if args.resolution is not None:
        if args.model not in ('wong', 'icr'):
            raise InputError('--resolution applies to --model wong or icr only')
        options['resolution'] = args.resolution
    return options


def run_solve(args: argparse.Namespace) -> int:
    vehicle = load_vehicle(args.vehicle)
    terrain = load_terrain(args.terrain)
    options = _options(args)
    try:
        start = time.perf_counter()
        state = models.solve(vehicle, terrain, args.speed, args.turn_radius, model=args.model, **options)
        elapsed = time.perf_counter() - start
    except ModuleNotFoundError as err:
        raise InputError(f'model {args.model!r} is not available in this build ({err.name} missing)') from err
    payload = _payload(vehicle.name, terrain.name, state, elapsed)
    if payload['sinkage_m'] is not None:
        if vehicle.is_tracked:
            check_sinkage(
                payload['sinkage_m'], 2 * vehicle.drive_radius_m, 'track height (sprocket diameter)'
            )
        else:
            check_sinkage(payload['sinkage_m'], vehicle.drive_radius_m, 'wheel radius')
    emit(payload, args.json)
    return 0


def _scalar(value: npt.ArrayLike) -> float | bool | None:
    arr = np.asarray(value)
    return arr.reshape(-1)[0].item() if arr.size else None


def _payload(vehicle: str, terrain: str, state: models.SteadyState, elapsed: float) -> JsonObject:
    payload: JsonObject = {
        's0_m': _scalar(state.s0_m),
        'omega_outer_rad_s': _scalar(state.omega_outer_rad_s),
        'omega_inner_rad_s': _scalar(state.omega_inner_rad_s),
        'torque_outer_Nm': _scalar(state.torque_outer_Nm),
        'torque_inner_Nm': _scalar(state.torque_inner_Nm),
        'power_outer_W': _scalar(state.power_outer_W),
        'power_inner_W': _scalar(state.power_inner_W),
        'converged': bool(_scalar(state.converged)),
        'solve_time_s': elapsed,
        'model': state.model,
        'vehicle': vehicle,
        'terrain': terrain,
        'speed_m_s': _scalar(state.speed_m_s),
        'turn_radius_m': _scalar(state.turn_radius_m),
        'yaw_rate_rad_s': _scalar(state.yaw_rate_rad_s),
        'outer_side': 'left' if bool(_scalar(state.outer_is_left)) else 'right',
    }
    for quantity, unit in (('torque', '_Nm'), ('omega', '_rad_s'), ('power', '_W')):
        for side in ('left', 'right'):
            payload[f'{quantity}_{side}{unit}'] = _scalar(state.side(quantity, side))
    payload['total_power_W'] = _scalar(state.total_power_W)
    for name in (
        'slip_outer',
        'slip_inner',
        'thrust_outer_N',
        'thrust_inner_N',
        'sinkage_m',
        'traction_margin',
    ):
        payload[name] = _scalar(getattr(state, name))
    if 'mu_t' in state.extra:
        payload['mu_t'] = _scalar(state.extra['mu_t'])
    return payload
