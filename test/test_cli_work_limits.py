"""Every input that sets an amount of work has a declared maximum, shown in ``--help``, and a value
beyond it is one clear error (exit 2, one line on stderr, no traceback) before any work starts
(issue 28). The limits live in skidsteer_power.terramechanics.ranges, next to the physical ranges.

The CLI runs in-process (``cli.main.main``); argparse rejects a bad option value by SystemExit.
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

import numpy as np
import pytest
from cli_run import one_line_error

from skidsteer_power.cli.main import build_parser, main
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.missions.routes import MAX_TRACE_STEPS, read_route_csv
from skidsteer_power.terramechanics import ranges
from skidsteer_power.vehicle import load_vehicle

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'test_robot_4wheel_dry_sand.mcap'
MISSION = ['mission', '--vehicle', 'test_robot_track', '--terrain', 'sandy_soil', '--route', 'patrol',
           '--no-cache']  # fmt: skip
SIMULATE = ['simulate', '--vehicle', 'test_robot_track', '--terrain', 'dry_sand']
MAP_BUILD = ['map', 'build', '--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--no-progress']


def _csv(tmp_path: Path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _cases(tmp: Path) -> list[tuple[list[str], str]]:
    legs = _csv(tmp, 'legs.csv', 'length_m,speed_m_s\n1e300,0.2\n')
    long_run = _csv(tmp, 'long.csv', 't_s,speed_m_s,yaw_rate_rad_s\n0,0.2,0\n1e9,0,0\n')
    heavy = tmp / 'heavy.yaml'
    text = (Path(__file__).resolve().parents[1] / 'config/vehicles/test_robot_track.yaml').read_text()
    heavy.write_text(re.sub(r'(?m)^mass_kg:.*$', 'mass_kg: 1.0e+300', text))
    not_zip = tmp / 'plain.npz'
    with not_zip.open('wb') as handle:
        np.save(handle, np.arange(3))  # an .npy array under an .npz name
    out = str(tmp / 'out.mcap')
    return [
        ([*MISSION, '--seed', '-1', '--samples', '2'], 'seed = -1 is outside its range'),
        ([*MISSION, '--samples', '100000000'], 'samples = 100,000,000 is outside its range'),
        ([*MISSION, '--workers', '1000'], 'local workers = 1,000 is outside'),
        (
            [
                'mission',
                '--vehicle',
                str(heavy),
                '--terrain',
                'sandy_soil',
                '--route',
                'patrol',
                '--no-cache',
            ],
            'mass_kg = 1e\\+300 is outside its range',
        ),
        ([*MISSION[:-2], legs, '--no-cache'], 'leg length = 1e\\+300 m is outside its range'),
        ([*SIMULATE, '--route', 'patrol', '--seed', '-1', '-o', out], 'seed = -1 is outside'),
        ([*SIMULATE, '--route', 'patrol', '--speed', '1e300', '-o', out], 'speed = 1e\\+300 m/s is outside'),
        ([*SIMULATE, '--route', 'patrol', '--lead-in', '1e5', '-o', out], 'lead-in = 100000 s is outside'),
        (
            [*SIMULATE, '--route', 'patrol', '--lead-in', '1e300', '-o', out],
            'lead-in = 1e\\+300 s is outside',
        ),
        (
            [*SIMULATE, '--route', 'patrol', '--speed', '0.001', '-o', out],
            'simulated time = 154402 s is outside its range',
        ),  # 154.4 m at 1 mm/s + 2 s of rest
        ([*SIMULATE, '--commands', long_run, '-o', out], 'long.csv:3: t_s: simulated time = 1e\\+09 s'),
        ([*SIMULATE, '--route', legs, '-o', out], 'leg length = 1e\\+300 m is outside'),
        (
            [
                'calibrate',
                str(BAG),
                '--vehicle',
                'test_robot_4wheel',
                '--terrain',
                'dry_sand',
                '--out-terrain',
                str(tmp / 't.yaml'),
                '--seed',
                '-1',
            ],
            'seed = -1 is outside',
        ),
        ([*MAP_BUILD, '--rings', '100000'], 'rings = 100,000 is outside its range'),
        ([*MAP_BUILD, '--angles', '1000000'], 'angles = 1,000,000 is outside its range'),
        ([*MAP_BUILD, '--elements', '100000000'], 'elements = 100,000,000 is outside its range'),
        ([*MAP_BUILD, '--elements', '1e8'], 'not an integer'),
        ([*MAP_BUILD, '--max-speed', '1e300'], 'speed = 1e\\+300 m/s is outside'),
        (['map', 'show', str(not_zip)], 'plain.npz: not a skidsteer_power map'),
        (['replay', str(BAG), '--rate', '1e-300'], 'rate = 1e-300 x is outside its range'),
        (['replay', str(BAG), '--start', '1e300'], 'bag time = 1e\\+300 s is outside its range'),
        (['replay', str(BAG), '--clock-hz', '1e9'], 'clock rate = 1e\\+09 Hz is outside its range'),
        (['design-study', '--workers', '1000'], 'local workers = 1,000 is outside its range'),
        (['run', '--simulate', '--duration', '1e9'], 'duration = 1e\\+09 s is outside its range'),
        (['bridge', '--duration', '1e9'], 'duration = 1e\\+09 s is outside its range'),
        (
            [
                'validate',
                str(BAG),
                '--vehicle',
                'x',
                '--terrain',
                'y',
                '--report',
                str(tmp / 'r'),
                '--jobs',
                '1000',
            ],
            'local workers = 1,000 is outside',
        ),
    ]


def test_each_input_beyond_its_work_limit_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    failures = []
    for argv, match in _cases(tmp_path):
        line = one_line_error(capsys, argv)
        if not re.search(match, line):
            failures.append(f'{" ".join(argv)}\n  -> {line}\n  wanted /{match}/')
    assert not failures, '\n'.join(failures)
    assert not (tmp_path / 'out.mcap').exists()  # nothing was simulated


# (command path, option, its Range): the work-setting options and the limit their help must show
WORK_OPTIONS = [
    (('simulate',), '--lead-in', ranges.LEAD_IN_S),
    (('simulate',), '--speed', ranges.FORWARD_SPEED_M_S),
    (('simulate',), '--seed', ranges.SEED),
    (('mission',), '--samples', ranges.SAMPLES),
    (('mission',), '--seed', ranges.SEED),
    (('mission',), '--workers', ranges.LOCAL_WORKERS),
    (('sensitivity',), '--workers', ranges.LOCAL_WORKERS),
    (('sensitivity',), '--samples', ranges.SAMPLES),
    (('design-study',), '--workers', ranges.LOCAL_WORKERS),
    (('design-study',), '--samples', ranges.SAMPLES),
    (('calibrate',), '--seed', ranges.SEED),
    (('map', 'build'), '--rings', ranges.MAP_RINGS),
    (('map', 'build'), '--angles', ranges.MAP_ANGLES),
    (('map', 'build'), '--elements', ranges.MAP_ELEMENTS),
    (('map', 'build'), '--max-speed', ranges.FORWARD_SPEED_M_S),
    (('map', 'build'), '--max-yaw-rate', ranges.YAW_RATE_RAD_S),
    (('replay',), '--clock-hz', ranges.CLOCK_HZ),
    (('replay',), '--rate', ranges.REPLAY_RATE),
    (('replay',), '--start', ranges.BAG_TIME_S),
    (('replay',), '--duration', ranges.RECORD_DURATION_S),
    (('record',), '--duration', ranges.RECORD_DURATION_S),
    (('run',), '--duration', ranges.RECORD_DURATION_S),
    (('bridge',), '--duration', ranges.RECORD_DURATION_S),
    (('validate',), '--jobs', ranges.LOCAL_WORKERS),
]


def _subparser(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> argparse.ArgumentParser:
    for name in path:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[name]
    return parser


@pytest.mark.parametrize(('path', 'option', 'limits'), WORK_OPTIONS)
def test_work_options_show_their_range_in_help(
    capsys: pytest.CaptureFixture[str], path: tuple[str, ...], option: str, limits: ranges.Range
) -> None:
    with pytest.raises(SystemExit):
        main([*path, '--help'])
    text = ' '.join(capsys.readouterr().out.split())
    assert f'range {limits.text}' in text, (path, option)
    action = next(a for a in _subparser(build_parser(), path)._actions if option in a.option_strings)
    assert f'range {limits.text}' in (action.help or '')


def test_local_workers_are_capped_at_the_cores(capsys: pytest.CaptureFixture[str]) -> None:
    from skidsteer_power.distributed.engine import Engine

    cores = os.cpu_count() or 1
    assert ranges.LOCAL_WORKERS.high == cores
    with pytest.raises(InputError, match='outside its range'):
        Engine(workers=cores + 1)
    Engine(workers=cores)  # not entered: no cluster started


def test_a_route_csv_is_read_row_by_row_and_stops_at_the_point_cap(tmp_path: Path) -> None:
    """The row after the cap is garbage: reading stops at the cap before parsing it."""
    path = tmp_path / 'many.csv'
    with path.open('w') as handle:
        handle.write('length_m,speed_m_s\n')
        handle.write('1,0.2\n' * (MAX_TRACE_STEPS + 1))
        handle.write('not,a number\n')
    with pytest.raises(InputError, match=f'more than {MAX_TRACE_STEPS:,} rows'):
        read_route_csv(path)


def test_an_oversized_route_or_command_csv_is_refused_unread(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    big = tmp_path / 'big.csv'
    with big.open('wb') as handle:
        handle.truncate(ranges.ROUTE_CSV_BYTES + 1)  # sparse: no disk used
    line = one_line_error(capsys, [*MISSION[:-2], str(big), '--no-cache'])
    assert f'{ranges.ROUTE_CSV_BYTES + 1:,} bytes; at most {ranges.ROUTE_CSV_BYTES:,}' in line
    line = one_line_error(capsys, [*SIMULATE, '--commands', str(big), '-o', str(tmp_path / 'o.mcap')])
    assert 'bytes; at most' in line


def test_vehicle_numbers_are_range_checked_when_loading(tmp_path: Path) -> None:
    text = (Path(__file__).resolve().parents[1] / 'config/vehicles/test_robot_track.yaml').read_text()
    cases = [
        ('mass_kg', '1.0e+300', 'mass_kg = 1e\\+300 is outside its range \\(0, 10000\\] kg'),
        ('tread_m', '1.0e+3', 'tread_m = 1000 is outside'),
        ('cg_height_m', '1.0e+6', 'cg_height_m = 1e\\+06 is outside'),
    ]
    for field, value, match in cases:
        path = tmp_path / f'{field}.yaml'
        path.write_text(re.sub(rf'(?m)^{field}:.*$', f'{field}: {value}', text))
        with pytest.raises(ConfigError, match=match):
            load_vehicle(path)


def test_simulate_reports_progress_over_the_whole_run() -> None:
    from skidsteer_power.terramechanics import load_terrain
    from skidsteer_power.twin import Segment, Twin, run_commands

    told: list[float] = []
    twin = Twin(load_vehicle('test_robot_track'), load_terrain('dry_sand'))
    run_commands(twin, [Segment(0.2, 0.0, 0.1), Segment(0.0, 0.0, 0.06)], progress=told.append)
    assert told == pytest.approx([0.1, 0.06])
