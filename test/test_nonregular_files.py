"""A FIFO, a device or an oversized file as a bag or a state file (issue 34 item 13): refused in one
line, never a hang, never an endless read.

Before the fix a FIFO hung the estimator, ``run``, validate, calibrate and replay (open blocks until a
writer comes); a state file linked to /dev/zero was read at 400 MB/s (its size is 0, so the 64 KB
limit let it through) and ``validate --salvage /dev/zero`` reached 5 GB in 12 s. Every case runs in a
process of its own with a timeout, so a regression fails instead of hanging the test run.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError
from skidsteer_power.safe_read import read_capped

TIMEOUT_S = 120.0
"""Far beyond the second these take: a hang or an endless read fails here."""


def _cli(*argv: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, '-m', 'skidsteer_power.cli.main', *argv]
    return subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S, check=False)


def _one_line_exit_2(result: subprocess.CompletedProcess[str]) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and 'Traceback' not in result.stderr, result.stderr
    return lines[0]


@pytest.fixture
def odd_files(tmp_path: Path) -> dict[str, Path]:
    """A FIFO, a symlink to /dev/zero, and a bag directory whose .mcap is a FIFO."""
    fifo = tmp_path / 'fifo.mcap'
    os.mkfifo(fifo)
    zero = tmp_path / 'zero.mcap'
    zero.symlink_to('/dev/zero')
    folder = tmp_path / 'bag_dir'
    folder.mkdir()
    (folder / 'metadata.yaml').symlink_to('/dev/zero')
    os.mkfifo(folder / 'bag_dir_0.mcap')
    return {'FIFO': fifo, 'character device': zero, 'bag directory of a FIFO': folder}


KINDS = {'FIFO': 'a FIFO', 'character device': 'a character device', 'bag directory of a FIFO': ''}


@pytest.mark.parametrize('kind', KINDS)
@pytest.mark.parametrize('salvage', [False, True], ids=['plain', 'salvage'])
def test_validate_refuses_a_bag_that_is_not_a_regular_file(
    odd_files: dict[str, Path], tmp_path: Path, kind: str, salvage: bool
) -> None:
    path = odd_files[kind]
    argv = ['validate', str(path), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin']
    argv += ['--report', str(tmp_path / 'report'), '--no-plots'] + (['--salvage'] if salvage else [])
    if kind == 'bag directory of a FIFO':  # validate takes a directory of bags: give the bag itself
        argv[1] = str(path / 'metadata.yaml')
    line = _one_line_exit_2(_cli(*argv))
    assert 'not a regular file: refused' in line and (KINDS[kind] in line)


def test_validate_salvage_of_dev_zero_is_refused() -> None:
    argv = ['validate', '/dev/zero', '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--salvage']
    line = _one_line_exit_2(_cli(*argv, '--report', '/nonexistent/report'))
    assert line.endswith('bag /dev/zero is a character device, not a regular file: refused')


@pytest.mark.parametrize('command', ['replay', 'calibrate'])
def test_replay_and_calibrate_refuse_a_fifo(odd_files: dict[str, Path], tmp_path: Path, command: str) -> None:
    fifo = str(odd_files['FIFO'])
    argv = [command, fifo]
    if command == 'calibrate':
        argv += [
            '--vehicle',
            'test_robot_track',
            '--terrain',
            'sand_bin',
            '--out-terrain',
            str(tmp_path / 't.yaml'),
        ]
    assert 'is a FIFO, not a regular file: refused' in _one_line_exit_2(_cli(*argv))


def test_a_bag_directory_is_checked_file_by_file(odd_files: dict[str, Path]) -> None:
    line = _one_line_exit_2(_cli('replay', str(odd_files['bag directory of a FIFO'])))
    assert 'metadata.yaml is a character device' in line or 'bag_dir_0.mcap is a FIFO' in line


@pytest.mark.parametrize('target', ['fifo', '/dev/zero'])
def test_a_state_file_that_is_a_fifo_or_dev_zero_is_unusable_not_a_hang(tmp_path: Path, target: str) -> None:
    """The estimator's state loader in a process of its own (it would block or read forever)."""
    state = tmp_path / 'energy.json'
    if target == 'fifo':
        os.mkfifo(state)
    else:
        state.symlink_to(target)
    code = (
        'import sys; from skidsteer_power.estimator.persistence import load_or_quarantine\n'
        'state, warning = load_or_quarantine(sys.argv[1], lambda s: None)\n'
        'print(state, warning)'
    )
    result = subprocess.run(
        [sys.executable, '-c', code, str(state)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=True,
    )
    kind = 'a FIFO' if target == 'fifo' else 'a character device'
    assert (
        result.stdout.startswith('None unusable energy state')
        and f'is {kind}, not a regular' in result.stdout
    )
    moved = list(tmp_path.glob('energy.json.corrupt-*'))
    assert not os.path.lexists(state) and len(moved) == 1  # moved aside, so the next save is a file


@pytest.mark.slow
def test_run_with_a_fifo_state_file_starts_fresh_and_stops_on_sigterm(tmp_path: Path) -> None:
    state = tmp_path / 'e.json'
    os.mkfifo(state)
    command = [
        sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--simulate', '--duration', '60',
        '--json', '--quiet', '--map-cache', str(tmp_path), '--state-file', str(state),
    ]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(900):
            if list(tmp_path.glob('e.json.corrupt-*')) and state.is_file():
                break  # the FIFO moved aside and a first save made
            assert process.poll() is None
            time.sleep(0.1)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=TIMEOUT_S)
    finally:
        process.kill()
    assert process.returncode == 0, stderr[-2000:]
    assert stderr.count('unusable energy state') == 1 and 'is a FIFO' in stderr
    assert json.loads(state.read_text())['format_version'] == 1


def test_read_capped_counts_bytes_not_st_size(tmp_path: Path) -> None:
    path = tmp_path / 'big'
    path.write_bytes(b'x' * 1001)
    assert read_capped(path, 1001) == b'x' * 1001
    with pytest.raises(InputError, match='larger than 1,000 bytes'):
        read_capped(path, 1000)
    with pytest.raises(InputError, match='a directory, not a regular file'):
        read_capped(tmp_path, 1000)


def test_a_regular_bag_still_reads(tmp_path: Path) -> None:
    """The control: the same commands on an ordinary bag are not refused."""
    bag = tmp_path / 'drive.mcap'
    write_drive_bag(bag, [Segment(0.1, 0.0, 1.0)], rate_hz=50, odom_hz=10)
    result = _cli('validate', str(bag), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin',
                  '--report', str(tmp_path / 'r'), '--no-plots', '--json')  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['complete'] is True
