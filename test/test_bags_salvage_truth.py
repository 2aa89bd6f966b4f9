"""What was not read is never called complete (issue 28): a salvaged bag says how much of it was
read, fleet rows carry ``complete`` and the counts, ``validate --salvage`` skips and counts a message
it cannot decode (as ``replay --salvage`` does), a healthy bag with a non-ROS (protobuf) channel is
read with that channel skipped, and only commands that have ``--salvage`` suggest it.

The bags are written here: a synthetic drive (bag_io/synthetic.py), then damaged on purpose.
"""

from __future__ import annotations

import csv
import json
import logging
import shutil
import sqlite3
from pathlib import Path
from typing import Any

import pytest

from skidsteer_power.bag_io.reader import open_bag
from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.cli.main import main
from skidsteer_power.commands import Segment

VALIDATE = ['--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--no-plots', '--json']


@pytest.fixture(scope='module')
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('truth') / 'drive.mcap'
    write_drive_bag(path, [Segment(0.1, 0.0, 3.0), Segment(0.1, 0.2, 2.0)], rate_hz=50, odom_hz=10)
    return path


def _copy(src: Path, out: Path, *, storage: str = 'mcap', spoil: int | None = None) -> Path:
    """``src`` rewritten (``storage`` 'mcap' file or 'sqlite3' bag folder); with ``spoil`` = k the
    k-th /joint_states message is replaced by 5 bytes no JointState decodes from."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    with open_bag(src) as bag:
        messages = list(bag.messages())
        types = {t: i.msgtype for t, i in bag.topics.items()}
    if storage == 'sqlite3':
        with Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
            conns = {t: writer.add_connection(t, m, typestore=store) for t, m in types.items()}
            for m in messages:
                writer.write(conns[m.topic], m.timestamp_ns, m.data)
        return out
    seen = 0
    with BagWriter(out) as writer:
        conns = {t: writer.add_topic(t, m) for t, m in types.items()}
        for m in messages:
            data = m.data
            if m.topic == '/joint_states':
                seen += 1
                data = b'\x00\x01\x00\x00\x05' if seen == spoil else data
            writer.write(conns[m.topic], m.timestamp_ns, data)
    return out


def _validate(
    capsys: pytest.CaptureFixture[str], bag: Path, report: Path, *extra: str
) -> tuple[int, dict[str, Any], str]:
    try:
        code = main(['validate', str(bag), *VALIDATE, '--report', str(report), *extra])
    except SystemExit as exit_:
        code = int(exit_.code or 0)
    captured = capsys.readouterr()
    return code, (json.loads(captured.out) if code == 0 else {}), captured.err


def test_a_sqlite_bag_with_half_its_rows_deleted_is_not_complete(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _copy(drive, tmp_path / 'sq', storage='sqlite3')
    with sqlite3.connect(bag / 'sq.db3') as db:
        db.execute('DELETE FROM messages WHERE id % 2 = 0')
        (held,) = db.execute('SELECT COUNT(*) FROM messages').fetchone()
    code, out, _ = _validate(capsys, bag, tmp_path / 'r1', '--salvage')
    assert code == 0
    assert out['complete'] is False and out['messages_read'] == held < out['messages_expected']
    # the bare .db3 has no count of its own (rosbags counts its rows): unknown, so not complete
    shutil.copy(bag / 'sq.db3', tmp_path / 'bare.db3')
    code, out, _ = _validate(capsys, tmp_path / 'bare.db3', tmp_path / 'r2', '--salvage')
    assert code == 0 and out['messages_expected'] is None and out['complete'] is False
    assert out['messages_read'] == held


def test_validate_salvage_skips_and_counts_an_undecodable_message(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _copy(drive, tmp_path / 'spoilt.mcap', spoil=40)
    code, _, err = _validate(capsys, bag, tmp_path / 'r1')
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and 'cannot decode a sensor_msgs/msg/JointState' in lines[0]
    code, out, _ = _validate(capsys, bag, tmp_path / 'r2', '--salvage')
    assert code == 0
    assert out['undecodable'] == {'/joint_states': 1} and out['complete'] is False
    assert out['messages_read'] == out['messages_expected']  # every message was read, one not decoded


def test_fleet_rows_carry_completeness(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = drive.read_bytes()
    folder = tmp_path / 'bags'
    folder.mkdir()
    shutil.copy(drive, folder / 'whole.mcap')
    (folder / 'half.mcap').write_bytes(raw[: len(raw) // 2])
    argv = [
        'validate',
        str(folder),
        *VALIDATE,
        '--report',
        str(tmp_path / 'fleet'),
        '--salvage',
        '--jobs',
        '1',
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    rows = {Path(r['bag']).name: r for r in summary['rows']}
    assert rows['whole.mcap']['ok'] and rows['whole.mcap']['complete'] is True
    half = rows['half.mcap']
    assert (
        half['ok']
        and half['complete'] is False
        and half['messages_read'] < rows['whole.mcap']['messages_read']
    )
    assert summary['incomplete'] == 1
    with (tmp_path / 'fleet' / 'fleet.csv').open() as handle:
        table = {Path(r['bag']).name: r for r in csv.DictReader(handle)}
    assert table['half.mcap']['complete'] == 'False' and table['whole.mcap']['complete'] == 'True'
    assert 'INCOMPLETE' in (tmp_path / 'fleet' / 'summary.md').read_text()


def test_a_healthy_bag_with_a_protobuf_channel_is_read_without_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    from skidsteer_power.bag_io.writer import message_definition

    store = get_typestore(Stores.ROS2_JAZZY)
    string = store.types['std_msgs/msg/String']
    path = tmp_path / 'mixed.mcap'
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        text, _ = message_definition('std_msgs/msg/String')
        ros = writer.register_channel(
            '/s', 'cdr', writer.register_schema('std_msgs/msg/String', 'ros2msg', text.encode())
        )
        proto = writer.register_channel(
            '/p', 'protobuf', writer.register_schema('foo.Bar', 'protobuf', b'\x0a\x03foo')
        )
        for i in range(20):
            data = store.serialize_cdr(string(f'm{i}'), 'std_msgs/msg/String')
            writer.add_message(ros, log_time=10**18 + i * 10**7, data=data, publish_time=10**18 + i * 10**7)
            writer.add_message(proto, log_time=10**18 + i * 10**7 + 1, data=b'\x08\x01', publish_time=10**18)
        writer.finish()
    with caplog.at_level(logging.WARNING), open_bag(path) as bag:
        assert set(bag.topics) == {'/s'} and bag.count_all() == 20 and not bag.damage
        assert bag.integrity()['complete'] is True  # 40 in the file, 20 of them on the skipped channel
    assert any('skipping /p (protobuf)' in r.getMessage() for r in caplog.records)


def test_only_commands_with_salvage_suggest_it(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = drive.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(raw[: len(raw) // 2])
    code, _, err = _validate(capsys, cut, tmp_path / 'r')
    assert code == 2 and '--salvage recovers' in err
    simulate = ['simulate', '--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--commands', str(cut)]
    calibrate = ['calibrate', str(cut), '--vehicle', 'test_robot_track', '--terrain', 'dry_sand']
    for argv in (
        [*simulate, '-o', str(tmp_path / 'o.mcap')],
        [*calibrate, '--out-terrain', str(tmp_path / 't.yaml')],
    ):
        assert main(argv) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and 'truncated or corrupt' in lines[0] and 'salvage' not in lines[0], lines


def test_mission_plot_reports_the_file_it_wrote(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ['mission', '--vehicle', 'test_robot_track', '--terrain', 'sandy_soil', '--route', 'patrol',
            '--cache-dir', str(tmp_path / 'cache'), '--json']  # fmt: skip
    assert main([*base, '--plot', str(tmp_path / 'energy')]) == 0
    reported = Path(json.loads(capsys.readouterr().out)['plot'])
    assert reported == tmp_path / 'energy.png' and reported.read_bytes()[:4] == b'\x89PNG'
    assert main([*base, '--plot', str(tmp_path)]) == 2
    assert 'is a directory' in capsys.readouterr().err
