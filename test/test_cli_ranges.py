"""Inputs outside their physical range, and results outside the model's validity, are one clear error
(exit 2, one line on stderr), never inf/NaN, a silent clamp or an OOM kill (issue 13).

Ranges: skidsteer_power.terramechanics.ranges. The CLI runs in-process (``cli.main.main``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_run import one_line_error

from skidsteer_power.cli.main import main
from skidsteer_power.missions.routes import MAX_TRACE_STEPS, read_route_csv

TRACK = ['track', '--terrain', 'dry_sand', '--load', '300', '--width', '0.1', '--length', '0.5']
WHEEL = [
    'wheel',
    '--terrain',
    'dry_sand',
    '--load',
    '50',
    '--width',
    '0.1',
    '--radius',
    '0.1',
    '--slip',
    '0.1',
]
SOLVE = ['solve', '--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--speed', '0.2',
         '--turn-radius', '2', '--model', 'wong']  # fmt: skip
MISSION = ['mission', '--vehicle', 'test_robot_track', '--terrain', 'sandy_soil', '--route', 'patrol',
           '--no-cache']  # fmt: skip


def _set(argv: list[str], option: str, value: str) -> list[str]:
    out = list(argv)
    if option in out:
        out[out.index(option) + 1] = value
    else:
        out += [option, value]
    return out


@pytest.mark.parametrize(
    ('base', 'option', 'value', 'match'),
    [
        (TRACK, '--load', '1e300', 'load = 1e\\+300 N is outside its range'),
        (TRACK, '--load', '-1', 'outside its range'),
        (TRACK, '--width', '1e-300', 'width = 1e-300 m is outside its range'),
        (TRACK, '--width', '50', 'outside its range'),
        (TRACK, '--length', '1e9', 'length = 1e\\+09 m is outside'),
        (TRACK, '--height', '0', 'track height = 0 m is outside'),
        (WHEEL, '--speed', '1e308', 'speed = 1e\\+308 m/s is outside its range'),
        (WHEEL, '--radius', '1e-9', 'radius = 1e-09 m is outside'),
        (WHEEL, '--load', 'nan', 'outside its range'),
        (SOLVE, '--speed', '1e3', 'speed = 1000 m/s is outside'),
        (SOLVE, '--speed', '0', 'speed = 0 m/s is outside'),
        (SOLVE, '--turn-radius', '1e-9', 'turn radius = 1e-09 m is outside'),
        (SOLVE, '--resolution', '100000,100000', '10,000,000,000 nodes; at most 1,000,000'),
        (MISSION, '--speed', '1e6', 'speed = 1e\\+06 m/s is outside'),
        (MISSION, '--payload-kg', '1e9', 'payload = 1e\\+09 kg is outside'),
    ],
)
def test_an_input_outside_its_range_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], base: list[str], option: str, value: str, match: str
) -> None:
    import re

    line = one_line_error(capsys, _set(base, option, value))
    assert re.search(match, line), line


def test_ranges_are_documented_in_help(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ('track', 'wheel', 'solve', 'mission'):
        with pytest.raises(SystemExit):
            main([command, '--help'])
        text = ' '.join(capsys.readouterr().out.split())
        assert 'range' in text and ('[m]' in text or '[m/s]' in text), command


@pytest.mark.parametrize(('base', 'limit_option'), [(TRACK, '--height'), (WHEEL, '--radius')])
def test_sinkage_beyond_track_height_or_wheel_radius_is_an_error(
    capsys: pytest.CaptureFixture[str], base: list[str], limit_option: str
) -> None:
    """The sinkage is computed first; just above it the answer stands, just below it is an error."""
    heavy = _set(base, '--load', '3000')
    assert main([*_set(heavy, limit_option, '1.5'), '--json']) == 0
    sinkage = json.loads(capsys.readouterr().out)['sinkage_m']
    assert 0.0 < sinkage < 1.5
    if limit_option == '--height':  # the track's sinkage does not depend on its height
        assert main([*_set(heavy, '--height', f'{sinkage * 1.01:.6g}'), '--json']) == 0
        capsys.readouterr()
    line = one_line_error(capsys, _set(heavy, limit_option, f'{sinkage * 0.9:.6g}'))
    assert 'sink' in line and ('track height' in line or 'radius' in line)


@pytest.mark.parametrize('speed', ['1.6', '3', '10'])
def test_a_mission_faster_than_the_robot_is_driven_at_its_limit_and_says_so(
    capsys: pytest.CaptureFixture[str], speed: str
) -> None:
    """test_robot_track's max_speed_m_s is 1.5 (its vehicle file): the drive controller carries a
    faster route out at 1.5 m/s on the same path (issue 36), never a silent clamp of the map: the
    console says so in one line and the JSON counts the segments; the patrol is 154.4 m (ch. 8.1)."""
    assert main([*_set(MISSION, '--speed', speed), '--json']) == 0
    captured = capsys.readouterr()
    payload = json.loads(captured.out)
    assert payload['slowed_segments'] == 21 and payload['clamped_segments'] == 0  # all 21 segments
    assert payload['duration_s'] == pytest.approx(154.4 / 1.5, rel=1e-3)
    warning = captured.err.strip().splitlines()
    assert len(warning) == 1 and '21 of 21 route segments are faster than the drive controller' in warning[0]
    assert 'at most 1.5 m/s' in warning[0]


def test_mission_speed_inside_the_power_map_runs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*_set(MISSION, '--speed', '1.5'), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['clamped_segments'] == 0


@pytest.mark.parametrize(
    ('length', 'radius', 'ok'),
    [('1e5', 'inf', True), ('1e5', '1', False), ('1e5', '-2', False), ('100', '0.5', True)],
)
def test_route_sampling_is_bounded_by_steps_not_length(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], length: str, radius: str, ok: bool
) -> None:
    """A straight segment of the longest leg (1e5 m; a 1e12 m one once exhausted memory, and is now
    outside the leg range) is one step; an arc needs one step per 5 degrees of turn, and a route
    needing more than MAX_TRACE_STEPS is one clear error."""
    csv = tmp_path / 'route.csv'
    csv.write_text(f'length_m,speed_m_s,turn_radius_m\n{length},0.2,{radius}\n')
    if not ok:
        line = one_line_error(capsys, _set(MISSION, '--route', str(csv)))
        assert f'more than {MAX_TRACE_STEPS:,} points' in line
        return
    route = read_route_csv(csv)
    turned = float(length) / abs(float(radius))  # heading change [rad]
    xy = route.xy
    assert xy is not None
    assert len(xy) == 1 + max(1, int(np.ceil(turned / (np.pi / 36))))
    end = xy[-1]
    if radius == 'inf':
        assert end == pytest.approx([float(length), 0.0])
    else:  # exact on the circle: chord 2 R sin(turned / 2) from the start
        assert np.hypot(*end) == pytest.approx(2 * float(radius) * abs(np.sin(turned / 2)), abs=1e-9)
    assert main([*_set(MISSION, '--route', str(csv)), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['distance_m'] == pytest.approx(float(length))


@pytest.mark.parametrize(
    ('row', 'match'),
    [('10,100,inf,0', 'speed = 100 m/s is outside'), ('10,0.2,1e-6,0', 'turn radius = 1e-06 m is outside'),
     ('10,0.2,inf,1e7', 'payload = 1e\\+07 kg is outside')],
)  # fmt: skip
def test_route_csv_rows_have_the_same_ranges(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], row: str, match: str
) -> None:
    import re

    csv = tmp_path / 'route.csv'
    csv.write_text(f'length_m,speed_m_s,turn_radius_m,payload_kg\n{row}\n')
    line = one_line_error(capsys, _set(MISSION, '--route', str(csv)))
    assert re.search(match, line) and 'route.csv:2' in line, line
