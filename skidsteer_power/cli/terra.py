"""Commands ``track``, ``wheel`` and ``terrains``: chapter 2 single track / single wheel and presets.

skidsteer-power track  --terrain T --load N --width M --length M [--slip S] --json
    -> sinkage_m, compaction_resistance_N, drawbar_pull_N (at --slip), tractive_effort_N, slip
skidsteer-power wheel  --terrain T --load N --width M --radius M --slip S [--speed V] --json
    -> sinkage_m, drawbar_pull_N, torque_Nm, entry_angle_rad, exit_angle_rad, max_stress_angle_rad,
       slip; with --speed also wheel_speed_rad_s and shaft_power_W
skidsteer-power terrains [--json]
    -> every preset with its values in SI units, the units and the table it came from; then every
       other shipped terrain file (config/terrains/: rigid ground and snow) with its contact
       (soil | rigid), its fields and its source (JSON key ``files``)

Every number has a physical range (skidsteer_power.terramechanics.ranges, shown in --help); a
sinkage deeper than the track height (--height, default 0.2 m) or the wheel radius is an error.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import TypedDict

from skidsteer_power import resources
from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, finite_float
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import (
    DEFAULT_TRACK_HEIGHT_M,
    HEIGHT_M,
    LENGTH_M,
    LOAD_N,
    RADIUS_M,
    SPEED_M_S,
    WIDTH_M,
    check_sinkage,
)
from skidsteer_power.terramechanics.terrain import PRESET_SOURCES, PRESETS, load_terrain, terrain_fields
from skidsteer_power.terramechanics.track import single_track
from skidsteer_power.terramechanics.wheel import wheel_at_slip

UNITS = {
    'n': '-',
    'kc': 'N/m^(n+1)',
    'kphi': 'N/m^(n+2)',
    'c': 'Pa',
    'phi': 'rad',
    'K': 'm',
    'shear_type': '',
    'Kr': '-',
    'Kw': 'm',
    'a0': '-',
    'a1': '-',
    'b0': '-',
    'b1': '-',
    'contact': '',
    'mu_longitudinal': '-',
    'mu_lateral': '-',
    'rolling_resistance': '-',
}


def slip_float(text: str) -> float:
    """argparse type: a slip ratio in [-1, 1] (eq. 2.13)."""
    value = finite_float(text)
    if not -1.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f'slip must lie in [-1, 1]: {text!r}')
    return value


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--terrain', required=True, help='preset name or YAML terrain file')
    parser.add_argument(
        '--load', required=True, type=range_arg(LOAD_N), help=range_help(LOAD_N, 'normal load W')
    )
    parser.add_argument(
        '--width', required=True, type=range_arg(WIDTH_M), help=range_help(WIDTH_M, 'contact width b')
    )
    add_json_flag(parser)


def register(subparsers: Subcommands) -> None:
    track = subparsers.add_parser('track', help='single track on deformable terrain (eqs. 2.6-2.18)')
    _common(track)
    track.add_argument(
        '--length', required=True, type=range_arg(LENGTH_M), help=range_help(LENGTH_M, 'contact length l')
    )
    track.add_argument(
        '--height',
        type=range_arg(HEIGHT_M),
        default=DEFAULT_TRACK_HEIGHT_M,
        help=range_help(
            HEIGHT_M, f'track height; a deeper sinkage is an error (default {DEFAULT_TRACK_HEIGHT_M:g})'
        ),
    )
    track.add_argument('--slip', type=slip_float, default=0.0, help='slip ratio s in [-1, 1] (default 0)')
    track.set_defaults(func=run_track)

    wheel = subparsers.add_parser(
        'wheel',
        help='single rigid wheel, Wong-Reece (eqs. 2.19-2.34)',
        description='Sinkage from the vertical balance at the given slip, then drawbar pull F_x (eq. 2.27) '
        'and torque_Nm, the axle torque that drives the wheel (= -M_y of eq. 2.34; > 0 when driving).',
    )
    _common(wheel)
    wheel.add_argument(
        '--radius', required=True, type=range_arg(RADIUS_M), help=range_help(RADIUS_M, 'wheel radius r')
    )
    wheel.add_argument('--slip', required=True, type=slip_float, help='slip ratio s in [-1, 1]')
    wheel.add_argument(
        '--speed',
        type=range_arg(SPEED_M_S),
        help=range_help(SPEED_M_S, 'forward speed V (adds wheel speed, power)'),
    )
    wheel.set_defaults(func=run_wheel)

    terrains = subparsers.add_parser(
        'terrains', help='list terrain presets and shipped terrain files (soil | rigid) with values and units'
    )
    add_json_flag(terrains)
    terrains.set_defaults(func=run_terrains)


def run_track(args: argparse.Namespace) -> int:
    terrain = load_terrain(args.terrain)
    state = single_track(terrain, args.load, args.width, args.length, args.slip)
    check_sinkage(float(state.sinkage_m), args.height, 'track height')
    emit(
        {
            'terrain': terrain.name,
            'slip': args.slip,
            'sinkage_m': float(state.sinkage_m),
            'compaction_resistance_N': float(state.compaction_resistance_N),
            'tractive_effort_N': float(state.tractive_effort_N),
            'drawbar_pull_N': float(state.drawbar_pull_N),
        },
        args.json,
    )
    return 0


def run_wheel(args: argparse.Namespace) -> int:
    terrain = load_terrain(args.terrain)
    state = wheel_at_slip(terrain, args.load, args.slip, args.radius, args.width)
    check_sinkage(float(state.sinkage_m), args.radius, 'wheel radius')
    payload: dict[str, float | str] = {
        'terrain': terrain.name,
        'slip': args.slip,
        'sinkage_m': float(state.sinkage_m),
        'drawbar_pull_N': float(state.drawbar_pull_N),
        'torque_Nm': float(state.drive_torque_Nm),
        'entry_angle_rad': float(state.theta_f),
        'exit_angle_rad': float(state.theta_r),
        'max_stress_angle_rad': float(state.theta_m),
    }
    if args.speed is not None:
        omega = wheel_speed(args.speed, args.slip, args.radius)
        payload['wheel_speed_rad_s'] = omega
        payload['shaft_power_W'] = float(state.drive_torque_Nm) * omega
    emit(payload, args.json)
    return 0


def wheel_speed(speed: float, slip: float, radius: float) -> float:
    """Wheel angular speed w [rad/s] from forward speed V [m/s] and slip s (eq. 2.13 inverted)."""
    if slip == 1.0:
        raise InputError('at slip 1 the wheel speed is not set by --speed (the vehicle stands still)')
    if slip >= 0:
        return speed / (radius * (1.0 - slip))
    return speed * (1.0 + slip) / radius


class TerrainEntry(TypedDict):
    """One terrain of ``terrains``: its fields (SI; phi also as ``phi_deg`` [deg]; ``shear_type`` and
    ``contact`` are words) and where its values come from."""

    values: dict[str, float | str]
    source: str


def _shipped_terrain_files() -> dict[str, TerrainEntry]:
    """Shipped terrain files that are not a preset's copy (config/terrains/): name -> {values (SI,
    :func:`terrain_fields`), source (the file's ``source``)}."""
    import yaml

    out: dict[str, TerrainEntry] = {}
    for name, path in resources.shipped('terrains', ('.yaml', '.yml')).items():
        if name in PRESETS or name.startswith('example'):
            continue
        terrain = load_terrain(str(path))
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
        out[name] = {'values': terrain_fields(terrain), 'source': str(data.get('source', path.name))}
    return out


def run_terrains(args: argparse.Namespace) -> int:
    payload: dict[str, TerrainEntry] = {}  # preset name -> {values, source}
    for name, terrain in PRESETS.items():
        values = {k: v for k, v in dataclasses.asdict(terrain).items() if k != 'name' and v is not None}
        values['phi_deg'] = terrain.phi_deg
        payload[name] = {'values': values, 'source': PRESET_SOURCES[name]}
    files = _shipped_terrain_files()
    if args.json:
        emit({'presets': payload, 'files': files, 'units': {**UNITS, 'phi_deg': 'deg'}}, True)
        return 0
    for name, entry in {**payload, **files}.items():
        print(f'{name}  ({entry["source"]})')
        for key, value in entry['values'].items():
            unit = 'deg' if key == 'phi_deg' else UNITS[key]
            print(
                f'    {key:<18} {value:<14.6g} {unit}'
                if not isinstance(value, str)
                else f'    {key:<18} {value}'
            )
    return 0
