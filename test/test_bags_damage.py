"""Damaged bags say so (issue 13): validate and replay compare what they read with the bag's own
statistics; without --salvage a damaged bag is one line on stderr and exit 2; with --salvage every
intact message is recovered (below chunk granularity) and the JSON says how much is missing.

The damage is written here, into a bag this test writes with the project's writer.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from skidsteer_power.bag_io.reader import open_bag
from skidsteer_power.bag_io.salvage import salvage_mcap
from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.cli.main import main
from skidsteer_power.commands import Segment

RUNS = [Segment(0.1, 0.0, 4.0), Segment(0.1, 0.2, 4.0)]
RECORD_OVERHEAD = 1 + 8 + 22  # opcode, length, channel/sequence/log time/publish time [bytes]


@pytest.fixture(scope='module')
def intact(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('damage') / 'intact.mcap'
    write_drive_bag(path, RUNS, rate_hz=200, odom_hz=10)
    return path


def _first_chunk(path: Path) -> tuple[int, int, int]:
    """(chunk start, chunk length, records start) of the first chunk, from the summary."""
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
        index = summary.chunk_indexes[0]
    return (
        index.chunk_start_offset,
        index.chunk_length,
        index.chunk_start_offset + index.chunk_length - (index.compressed_size),
    )


def _damaged(intact: Path, tmp_path: Path, case: str) -> Path:
    raw = bytearray(intact.read_bytes())
    start, length, records = _first_chunk(intact)
    if case == 'chunk header zeroed':
        raw[start : start + 64] = bytes(64)
    elif case == '4 KB zeroed mid-chunk':
        middle = records + (start + length - records) // 2
        raw[middle : middle + 4096] = bytes(4096)
    elif case == '100 bytes flipped':
        for i in random.Random(13).sample(range(8, len(raw) - 8), 100):
            raw[i] ^= 0xFF
    elif case == 'magic only':
        raw = raw[:8]
    path = tmp_path / f'{case.replace(" ", "_")}.mcap'
    path.write_bytes(bytes(raw))
    return path


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    with open_bag(path) as bag:
        return [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]


def _validate(bag: Path, tmp_path: Path, *extra: str) -> list[str]:
    report = tmp_path / f'report_{len(list(tmp_path.iterdir()))}'
    return ['validate', str(bag), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin',
            '--report', str(report), '--no-plots', '--json', *extra]  # fmt: skip


@pytest.mark.parametrize('case', ['chunk header zeroed', '4 KB zeroed mid-chunk', '100 bytes flipped'])
def test_damaged_bag_without_salvage_is_one_line_and_exit_2(
    intact: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    bag = _damaged(intact, tmp_path, case)
    assert main(_validate(bag, tmp_path)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and str(bag) in lines[0] and '--salvage' in lines[0] and not captured.out


def test_zeroed_chunk_header_salvage_recovers_every_message(
    intact: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The summary's chunk index locates the chunk whose header is gone; its records are intact, but
    with the header its CRC is gone: they are unverified (issue 34 item 11), left out by default (the
    bag's one chunk: nothing left, one line, exit 2), read with --include-unverified, never complete."""
    bag = _damaged(intact, tmp_path, 'chunk header zeroed')
    assert main(_validate(bag, tmp_path, '--salvage')) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and 'nothing intact to salvage' in lines[0] and 'unverified' in lines[0]
    assert main(_validate(bag, tmp_path, '--salvage', '--include-unverified')) == 0
    summary = json.loads(capsys.readouterr().out)
    expected = len(_messages(intact))
    assert summary['messages_expected'] == expected and summary['messages_read'] == expected
    assert summary['complete'] is False and summary['messages_unverified'] == expected
    with open_bag(bag, salvage=True, include_unverified=True) as salvaged:
        assert [(m.topic, m.timestamp_ns, m.data) for m in salvaged.messages()] == _messages(intact)


def test_4kb_zeroed_mid_chunk_salvage_recovers_every_intact_message(
    intact: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Only messages touching the 4096 zeroed bytes may be lost: at most 4096 / (smallest record) + 2."""
    bag = _damaged(intact, tmp_path, '4 KB zeroed mid-chunk')
    assert main(_validate(bag, tmp_path, '--salvage', '--include-unverified')) == 0
    summary = json.loads(capsys.readouterr().out)
    written = _messages(intact)
    smallest = min(len(data) for _, _, data in written) + RECORD_OVERHEAD
    assert summary['messages_expected'] == len(written) and summary['complete'] is False
    assert len(written) - 4096 // smallest - 2 <= summary['messages_read'] < len(written)
    assert summary['messages_unverified'] == summary['messages_read']  # all from the CRC-failing chunk
    assert summary['metrics']['energy_predicted_J'] > 0  # a real report, not an empty one
    with open_bag(bag, salvage=True, include_unverified=True) as salvaged:
        recovered = [(m.topic, m.timestamp_ns, m.data) for m in salvaged.messages()]
    assert set(recovered) <= set(written)  # nothing made up: every message is one that was written


@pytest.mark.parametrize('salvage', [(), ('--salvage',)], ids=['plain', 'salvage'])
@pytest.mark.parametrize('command', ['validate', 'replay'])
def test_magic_only_mcap_is_one_clear_error(
    intact: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    salvage: tuple[()] | tuple[str],
    command: str,
) -> None:
    bag = _damaged(intact, tmp_path, 'magic only')
    argv = _validate(bag, tmp_path, *salvage) if command == 'validate' else ['replay', str(bag), *salvage]
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(bag) in lines[-1]
    assert 'MCAP' in lines[-1] or 'salvage' in lines[-1] or 'truncated' in lines[-1]


def test_salvage_of_flipped_bytes_returns_only_written_messages(intact: Path, tmp_path: Path) -> None:
    bag = _damaged(intact, tmp_path, '100 bytes flipped')
    found = salvage_mcap(bag.read_bytes())
    written = _messages(intact)
    assert found.expected == len(written) and found.damage
    assert found.messages == []  # the bag's one chunk fails its CRC: nothing is verified
    stamps = {(t, s) for t, s, _ in written}
    channels = {c.id: c.topic for c in found.channels.values()}
    recovered = {(channels[m.channel_id], m.log_time) for m in found.unverified}
    assert recovered <= stamps and len(recovered) >= len(written) - 100  # at most one lost per flip


def test_replay_salvage_of_flipped_bytes_skips_and_counts_undecodable_messages(
    intact: Path, tmp_path: Path
) -> None:
    """A real `replay --salvage` subprocess: no RCLError traceback; messages rclpy cannot deserialize
    are skipped and counted."""
    bag = _damaged(intact, tmp_path, '100 bytes flipped')
    result = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'replay', str(bag), '--rate', '20', '--salvage',
         '--include-unverified', '--json'],
        capture_output=True, text=True, timeout=120, env=dict(os.environ),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    assert 'Traceback' not in result.stderr
    out = json.loads(result.stdout)
    written = len(_messages(intact))
    skipped = sum(out['undecodable'].values())
    assert out['messages_expected'] == written and out['complete'] is False
    assert out['message_count'] + skipped == out['messages_read'] <= written
    assert out['messages_unverified'] == out['messages_read']  # the one chunk failed its CRC


def test_sqlite_bag_missing_rows_is_measured_against_its_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """rosbag2 sqlite3: metadata.yaml counts the messages; rows lost from the database are missing."""
    import sqlite3

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types['std_msgs/msg/String']
    with Writer(tmp_path / 'sq', version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection('/s', 'std_msgs/msg/String', typestore=store)
        for i in range(200):
            writer.write(conn, 1_700_000_000 * 10**9 + i, store.serialize_cdr(String(f'm{i}'), conn.msgtype))
    with sqlite3.connect(tmp_path / 'sq' / 'sq.db3') as db:
        db.execute('DELETE FROM messages WHERE id % 10 = 0')  # 20 rows lost
    assert main(['replay', str(tmp_path / 'sq'), '--rate', '1000']) == 2
    line = capsys.readouterr().err.strip().splitlines()
    assert len(line) == 1 and 'read 180 of 200 messages (20 missing: /s 180 of 200)' in line[0]
    with open_bag(tmp_path / 'sq', salvage=True) as bag:
        assert bag.count_all() == 180
        assert bag.integrity() == {
            'messages_expected': 200,
            'messages_read': 180,
            'complete': False,
            'undecodable': {},
            'messages_unverified': 0,
        }
