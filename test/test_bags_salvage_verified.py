"""A chunk whose CRC fails is never read as intact, and a metadata.yaml whose counts lie is never
complete (issue 34 items 11 and 12).

Before: ``validate --salvage`` read a CRC-failing chunk record by record and called the bag complete
(500 joint_states efforts raised by 3 N m: 10295 of 10295 messages, 21 253 J measured against the
true 7 711 J); metadata.yaml counts of 100 or -5 against 200 messages read gave ``complete: true``.

The bags are written here with the project's writer in small chunks, then altered on purpose.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import pytest
from cli_run import one_line_error, run_cli
from mcap.reader import make_reader

from skidsteer_power.bag_io.reader import open_bag
from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.commands import Segment

EFFORT_NM = 0.1
"""write_drive_bag's default joint_states effort [N m]."""
RAISED_NM = EFFORT_NM + 3.0
"""The issue's alteration: the effort raised by 3 N m."""
CHUNK_BYTES = 16 * 1024


@pytest.fixture(scope='module')
def chunked(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 s drive at 200 Hz rewritten in 16 KiB chunks (about 40 of them)."""
    folder = tmp_path_factory.mktemp('verified')
    write_drive_bag(folder / 'drive.mcap', [Segment(0.1, 0.0, 4.0), Segment(0.1, 0.2, 4.0)], rate_hz=200)
    out = folder / 'chunked.mcap'
    with open_bag(folder / 'drive.mcap') as bag, BagWriter(out, chunk_size=CHUNK_BYTES) as writer:
        topics = {t: writer.add_topic(t, i.msgtype) for t, i in bag.topics.items()}
        for m in bag.messages():
            writer.write(topics[m.topic], m.timestamp_ns, m.data)
    return out


def _chunks(path: Path) -> list[Any]:
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def _in_chunk(path: Path, chunk: Any) -> int:
    """Messages whose log time lies in ``chunk``'s time range (their records are in it: one writer)."""
    with open_bag(path) as bag:
        return sum(
            chunk.message_start_time <= m.timestamp_ns <= chunk.message_end_time for m in bag.messages()
        )


def _raise_efforts(intact: Path, out: Path, chunk: Any) -> int:
    """``intact`` with every joint_states effort in ``chunk`` raised by 3 N m; how many were raised."""
    raw = bytearray(intact.read_bytes())
    start, end = chunk.chunk_start_offset, chunk.chunk_start_offset + chunk.chunk_length
    old, new = struct.pack('<d', EFFORT_NM), struct.pack('<d', RAISED_NM)
    region = bytes(raw[start:end])
    raised = region.count(old)
    raw[start:end] = region.replace(old, new)
    out.write_bytes(bytes(raw))
    return raised


def _validate(path: Path, tmp_path: Path, *extra: str) -> dict[str, Any]:
    report = tmp_path / f'report_{len(list(tmp_path.iterdir()))}'
    argv = ['validate', str(path), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--no-plots']
    code, out = _run_json([*argv, '--report', str(report), '--json', *extra])
    assert code == 0
    return out


def _run_json(argv: list[str]) -> tuple[int, dict[str, Any]]:
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = run_cli(argv)
    return code, (json.loads(buffer.getvalue()) if code == 0 else {})


def test_a_chunk_with_raised_efforts_is_left_out_not_read_as_intact(chunked: Path, tmp_path: Path) -> None:
    chunks = _chunks(chunked)
    assert len(chunks) >= 10
    target = chunks[len(chunks) // 2]
    altered = tmp_path / 'altered.mcap'
    raised = _raise_efforts(chunked, altered, target)
    in_chunk = _in_chunk(chunked, target)
    assert raised > 10  # joint_states in that chunk, each with two efforts
    intact = _validate(chunked, tmp_path)
    assert intact['complete'] is True and intact['messages_unverified'] == 0
    salvaged = _validate(altered, tmp_path, '--salvage')
    assert salvaged['complete'] is False
    assert salvaged['messages_unverified'] == in_chunk
    assert salvaged['messages_read'] == intact['messages_read'] - in_chunk
    assert salvaged['messages_expected'] == intact['messages_read']
    # the altered efforts are not in the metrics: measured energy no larger than the intact bag's
    measured = salvaged['metrics']['energy_measured_J']
    assert measured <= intact['metrics']['energy_measured_J'] + 1e-9
    # opting in reads them (and shows what the default protects from), and is still not complete
    included = _validate(altered, tmp_path, '--salvage', '--include-unverified')
    assert included['complete'] is False and included['messages_unverified'] == in_chunk
    assert included['messages_read'] == intact['messages_read']
    assert included['metrics']['energy_measured_J'] > intact['metrics']['energy_measured_J']


def test_without_salvage_a_crc_failure_is_one_line_and_exit_2(
    chunked: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    altered = tmp_path / 'altered.mcap'
    _raise_efforts(chunked, altered, _chunks(chunked)[3])
    argv = ['validate', str(altered), '--vehicle', 'test_robot_track', '--terrain', 'sand_bin']
    line = one_line_error(capsys, [*argv, '--report', str(tmp_path / 'r'), '--no-plots'])
    assert str(altered) in line and '--salvage' in line


def test_include_unverified_needs_salvage(chunked: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert 'needs --salvage' in one_line_error(capsys, ['replay', str(chunked), '--include-unverified'])


def test_flipped_bits_in_one_chunk_never_add_messages_that_were_not_recorded(
    chunked: Path, tmp_path: Path
) -> None:
    """100 bits flipped inside one chunk: every message salvaged is one that was written, byte for
    byte (before: 85 altered payloads and 2 messages never recorded were read as good)."""
    import random

    from skidsteer_power.bag_io.salvage import salvage_mcap

    target = _chunks(chunked)[5]
    raw = bytearray(chunked.read_bytes())
    rng = random.Random(34)
    records = target.chunk_start_offset + target.chunk_length - target.compressed_size
    for at in rng.sample(range(records, target.chunk_start_offset + target.chunk_length), 100):
        raw[at] ^= 1 << rng.randrange(8)
    found = salvage_mcap(bytes(raw))
    with open_bag(chunked) as bag:
        written = {(m.timestamp_ns, m.data) for m in bag.messages()}
    assert {(m.log_time, bytes(m.data)) for m in found.messages} <= written
    assert len(found.messages) == len(written) - _in_chunk(chunked, target)
    assert found.unverified and any('CRC mismatch' in d for d in found.damage)


# --- item 12: metadata.yaml that lies ---------------------------------------------------------------
@pytest.fixture
def bag_dir(tmp_path: Path) -> Path:
    """A rosbag2 MCAP bag directory (rosbags' writer: metadata.yaml + one .mcap) of 200 Strings."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    string = store.types['std_msgs/msg/String']
    with Writer(tmp_path / 'b', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/s', 'std_msgs/msg/String', typestore=store)
        for i in range(200):
            writer.write(
                conn, 1_700_000_000 * 10**9 + i * 10**7, store.serialize_cdr(string(f'm{i}'), conn.msgtype)
            )
    return tmp_path / 'b'


def _set_counts(bag: Path, value: str) -> None:
    meta = bag / 'metadata.yaml'
    text = meta.read_text()
    assert text.count('message_count: 200') == 3  # total, per file, per topic
    meta.write_text(text.replace('message_count: 200', f'message_count: {value}'))


LIES = {'100': 'read more messages', '5000': 'read 200 of 5000', '-5': 'not counts', '1e12': 'not counts',
        '200.0': 'not counts'}  # fmt: skip


@pytest.mark.parametrize('value', LIES)
def test_metadata_counts_that_lie_are_exit_2_without_salvage(
    bag_dir: Path, capsys: pytest.CaptureFixture[str], value: str
) -> None:
    _set_counts(bag_dir, value)
    line = one_line_error(capsys, ['replay', str(bag_dir), '--rate', '1000'])
    assert LIES[value] in line and str(bag_dir) in line


@pytest.mark.parametrize('value', LIES)
def test_metadata_counts_that_lie_are_never_complete_with_salvage(bag_dir: Path, value: str) -> None:
    _set_counts(bag_dir, value)
    code, out = _run_json(['replay', str(bag_dir), '--rate', '1000', '--salvage', '--json'])
    assert code == 0 and out['complete'] is False and out['messages_read'] == 200


def test_a_total_that_is_not_the_sum_of_the_topics_is_damage(
    bag_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meta = bag_dir / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('message_count: 200', 'message_count: 300', 1))  # the total
    assert 'its topics add up to 200' in one_line_error(capsys, ['replay', str(bag_dir), '--rate', '1000'])


def test_the_true_counts_are_complete(bag_dir: Path) -> None:
    """The control: the unaltered directory is complete."""
    code, out = _run_json(['replay', str(bag_dir), '--rate', '1000', '--json'])
    assert code == 0 and out['complete'] is True and out['messages_expected'] == out['messages_read'] == 200


@pytest.mark.parametrize(
    'content',
    [b'\x00\xff garbage: [\n', b'just a string\n', b'rosbag2_bagfile_information:\n  a: 1\n  a: 2\n'],
    ids=['binary', 'a string', 'duplicate key'],
)
def test_a_garbage_metadata_yaml_is_one_line(
    bag_dir: Path, capsys: pytest.CaptureFixture[str], content: bytes
) -> None:
    (bag_dir / 'metadata.yaml').write_bytes(content)
    line = one_line_error(capsys, ['replay', str(bag_dir), '--rate', '1000'])
    assert str(bag_dir) in line
