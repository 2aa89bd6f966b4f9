"""Tracebacks and silent acceptance of issue 34: each bad input is one line on stderr and exit 2
(cli_run.one_line_error), and every work-setting input has a maximum shown in --help."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_run import one_line_error

from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.commands import Segment


@pytest.fixture(scope='module')
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('cli3') / 'd.mcap'
    write_drive_bag(path, [Segment(0.1, 0.0, 1.0)], rate_hz=50)
    return path


def test_map_show_on_an_empty_or_truncated_npz(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'empty.npz').write_bytes(b'')
    np.savez(tmp_path / 'full.npz', a=np.arange(1000))
    whole = (tmp_path / 'full.npz').read_bytes()
    (tmp_path / 'trunc.npz').write_bytes(whole[: len(whole) // 2])
    for name in ('empty.npz', 'trunc.npz'):
        assert 'not a skidsteer_power map' in one_line_error(capsys, ['map', 'show', str(tmp_path / name)])


def test_fit_internal_on_a_binary_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / 'bin.csv'
    path.write_bytes(bytes(range(256)) * 2)
    assert 'not a text CSV' in one_line_error(capsys, ['fit-internal', str(path)])


def test_validate_with_joints_the_bag_never_holds(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ['validate', str(drive), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--no-plots']
    line = one_line_error(capsys, [*argv, '--report', str(tmp_path / 'r'), '--left-joints', 'x,y'])
    assert '--left-joints' in line and 'never holds all of x, y' in line


@pytest.mark.parametrize('command', ['validate', 'replay'])
def test_msg_path_that_does_not_exist(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    argv = [command, str(drive), '--msg', '/nonexistent']
    if command == 'validate':
        argv += ['--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--report', str(tmp_path / 'r')]
    assert 'does not exist: /nonexistent' in one_line_error(capsys, argv)


def test_a_manifest_naming_an_unknown_vehicle(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    manifest = tmp_path / 'm.csv'
    manifest.write_text(f'bag,vehicle,terrain\n{drive.name},nosuchvehicle,sand_bin\n')
    argv = ['validate', str(drive), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--no-plots']
    line = one_line_error(capsys, [*argv, '--report', str(tmp_path / 'r'), '--manifest', str(manifest)])
    assert f'manifest {manifest}' in line and 'nosuchvehicle' in line


BAD = {
    'record topic': ['record', '-o', 'x.mcap', '/bad topic!'],
    'replay --topics': ['replay', 'x.mcap', '--topics', '??'],
    'run --speed 1e308': ['run', '--speed', '1e308'],
    'run --yaw-rate 1e308': ['run', '--yaw-rate', '1e308'],
    'bridge --allow-origin': ['bridge', '--allow-origin', 'not a url'],
    'bridge --allow-publish': ['bridge', '--allow-publish', 'bad topic!'],
    'bridge --topics': ['bridge', '--topics', '??'],
    'des probe --timeout 1e9': ['des', 'probe', '--port', '/dev/null', '--timeout', '1e9'],
    'mocap --pattern 100000x100000': ['mocap', 'calibrate', 'x.png', '--square-size', '0.02', '--pattern',
                                      '100000x100000', '--out', 'c.yaml'],
}  # fmt: skip


@pytest.mark.parametrize('argv', BAD.values(), ids=BAD.keys())
def test_bad_arguments_are_refused_by_the_parser(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    line = one_line_error(capsys, argv)
    assert 'error: argument' in line


def test_run_simulate_with_a_hardware_port(capsys: pytest.CaptureFixture[str]) -> None:
    line = one_line_error(capsys, ['run', '--simulate', '--left-port', '/dev/ttyUSB5'])
    assert '--simulate makes its own amplifiers' in line


@pytest.mark.parametrize(
    ('argv', 'shown'),
    [
        (['des', 'probe', '--help'], '10] s'),
        (['mocap', 'calibrate', '--help'], '2 to 100 a side'),
        (['run', '--help'], '|speed| <= 10 m/s'),
    ],
)
def test_maxima_are_in_help(capsys: pytest.CaptureFixture[str], argv: list[str], shown: str) -> None:
    from cli_run import run_cli

    assert run_cli(argv) == 0
    assert shown in ' '.join(capsys.readouterr().out.split())


def test_good_origins_and_topics_still_parse() -> None:
    from skidsteer_power.cli.common import ros_topic, web_origin

    assert web_origin('https://app.foxglove.dev/') == 'https://app.foxglove.dev'
    assert web_origin('http://localhost:8080') == 'http://localhost:8080'
    assert ros_topic('cmd_vel') == 'cmd_vel' and ros_topic('/robot/odom') == '/robot/odom'
