"""Bag reading (no ROS graph): MCAP file and directory, sqlite3, damage, unknown types, the real bag."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io import load_msg_definitions, open_bag
from skidsteer_power.bag_io.reader import BagDamageError
from skidsteer_power.bag_io.synthetic import START_NS, write_drive_bag
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError

STORE = get_typestore(Stores.ROS2_JAZZY)
String = STORE.types['std_msgs/msg/String']


def _strings(n: int, size: int = 200) -> list[bytes]:
    return [STORE.serialize_cdr(String(f'{i:06d}' + 'x' * size), 'std_msgs/msg/String') for i in range(n)]


def _write_two_topics(path: Path, n: int) -> list[tuple[str, int, bytes]]:
    """n messages alternating /a and /b, 1 ms apart; returns what was written in time order."""
    written = []
    with BagWriter(path) as writer:
        conns = {t: writer.add_topic(t, 'std_msgs/msg/String') for t in ('/a', '/b')}
        for i, data in enumerate(_strings(n)):
            topic = '/a' if i % 2 == 0 else '/b'
            writer.write(conns[topic], START_NS + i * 1_000_000, data)
            written.append((topic, START_NS + i * 1_000_000, data))
    return written


@pytest.mark.parametrize('name', ['one.mcap', 'bagdir'])
def test_mcap_round_trip_keeps_bytes_order_and_times(tmp_path: Path, name: str) -> None:
    written = _write_two_topics(tmp_path / name, 500)
    with open_bag(tmp_path / name) as bag:
        assert bag.storage == 'mcap'
        assert bag.message_count == 500
        assert {t: i.count for t, i in bag.topics.items()} == {'/a': 250, '/b': 250}
        assert bag.start_ns == START_NS and bag.end_ns == START_NS + 499_000_000
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
        assert got == written
        assert bag.deserialize(bag.messages(['/b']).__next__()).data.startswith('000001')


def test_single_file_output_has_no_leftovers_and_embeds_definitions(tmp_path: Path) -> None:
    _write_two_topics(tmp_path / 'x.mcap', 4)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['x.mcap']
    with open_bag(tmp_path / 'x.mcap') as bag:
        assert bag.topics['/a'].msgdef.strip() == 'string data'
        assert bag.topics['/a'].decodable


def test_time_window_selects_half_open_interval(tmp_path: Path) -> None:
    _write_two_topics(tmp_path / 'w.mcap', 100)
    with open_bag(tmp_path / 'w.mcap') as bag:
        stamps = [
            m.timestamp_ns
            for m in bag.messages(start_ns=START_NS + 10_000_000, stop_ns=START_NS + 20_000_000)
        ]
    assert stamps == [START_NS + i * 1_000_000 for i in range(10, 20)]


def test_sqlite3_bag_reads_through_the_same_api(tmp_path: Path) -> None:
    data = _strings(30)
    with Writer(tmp_path / 'sq', version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection('/s', 'std_msgs/msg/String', typestore=STORE)
        for i, raw in enumerate(data):
            writer.write(conn, START_NS + i, raw)
    with open_bag(tmp_path / 'sq') as bag:
        assert bag.storage == 'sqlite3'
        assert [m.data for m in bag.messages()] == data


def test_truncated_mcap_is_a_clear_error_and_the_prefix_is_salvaged(tmp_path: Path) -> None:
    written = _write_two_topics(tmp_path / 'full.mcap', 20_000)  # ~4.5 MB: several 1 MiB chunks
    raw = (tmp_path / 'full.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(BagDamageError, match=r'cut\.mcap: bag is truncated or corrupt'):
        open_bag(cut)  # (validate and replay add "--salvage recovers every intact message")
    with open_bag(cut, salvage=True) as bag:
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
        assert bag.damage
    # Whole chunks before the cut survive: at least one 1 MiB chunk, and exactly a prefix of what was written.
    assert 1000 < len(got) < len(written)
    assert got == written[: len(got)]


def test_corrupt_record_in_indexed_mcap_is_an_error_and_salvage_recovers_all_else(tmp_path: Path) -> None:
    written = _write_two_topics(tmp_path / 'full.mcap', 20_000)
    raw = bytearray((tmp_path / 'full.mcap').read_bytes())
    # Smash the record header (opcode, length, channel, sequence, times: 1+8+2+4+8+8 = 31 bytes, plus
    # the 4-byte CDR string length and 4-byte encapsulation) in front of message 10000's payload.
    payload = raw.index(b'010000xxxx')
    raw[payload - 39 : payload - 8] = b'\xff' * 31
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(bytes(raw))
    with pytest.raises(InputError, match='truncated or corrupt'), open_bag(bad) as bag:
        list(bag.messages())
    # The damaged chunk's CRC fails: its messages are unverified, left out by default (issue 34 item 11)
    with open_bag(bad, salvage=True) as bag:
        got = [(m.topic, m.timestamp_ns, bytes(m.data)) for m in bag.messages()]
        integrity = bag.integrity()
    lost = 20_000 - len(got)
    assert integrity == {
        'messages_expected': 20_000,
        'messages_read': 20_000 - lost,
        'complete': False,
        'undecodable': {},
        'messages_unverified': lost - 1,  # the chunk's others; the smashed one is not found at all
    }
    assert 1 < lost < 20_000 and set(got) < {
        (t, s, bytes(d)) for t, s, d in written
    }  # one chunk of several, nothing made up
    # Read record by record with --include-unverified: only the smashed message is lost (salvage.py).
    with open_bag(bad, salvage=True, include_unverified=True) as bag:
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
        assert bag.damage and bag.integrity()['messages_read'] == 19_999 and not bag.complete
    assert got == written[:10_000] + written[10_001:]


def test_truncated_sqlite3_is_a_clear_error(tmp_path: Path) -> None:
    with Writer(tmp_path / 'sq', version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection('/s', 'std_msgs/msg/String', typestore=STORE)
        for i, raw in enumerate(_strings(5000)):
            writer.write(conn, START_NS + i, raw)
    db = tmp_path / 'sq' / 'sq.db3'
    db.write_bytes(db.read_bytes()[: db.stat().st_size // 2])
    with pytest.raises(InputError, match=r'sq.*truncated or corrupt'), open_bag(tmp_path / 'sq') as bag:
        list(bag.messages())


@pytest.mark.parametrize(
    ('content', 'pattern'),
    [(b'', 'truncated or corrupt'), (b'not a bag at all' * 10, 'truncated or corrupt')],
)
def test_garbage_file_is_a_clear_error(tmp_path: Path, content: bytes, pattern: str) -> None:
    path = tmp_path / 'junk.mcap'
    path.write_bytes(content)
    with pytest.raises(InputError, match=pattern):
        open_bag(path)


def test_missing_bag_and_unknown_topic_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match='bag not found'):
        open_bag(tmp_path / 'nope.mcap')
    _write_two_topics(tmp_path / 'w.mcap', 4)
    with open_bag(tmp_path / 'w.mcap') as bag, pytest.raises(InputError, match='no topic /zzz'):
        list(bag.messages(['/zzz']))


ACCEL_MSG = 'float32 accel_x\nfloat32 accel_y\nfloat32 accel_z\n'  # fields from ../shared/realbags/README.md


def _unknown_type_bag(path: Path) -> bytes:
    """An sqlite3 bag (no stored definitions) with a type no store knows; returns its one message."""
    store = get_typestore(Stores.ROS2_JAZZY)
    from rosbags.typesys import get_types_from_msg

    store.register(get_types_from_msg(ACCEL_MSG, 'neato2_interfaces/msg/Accel'))
    raw = store.serialize_cdr(
        store.types['neato2_interfaces/msg/Accel'](1.5, -2.0, 9.75), 'neato2_interfaces/msg/Accel'
    )
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        no_hash = 'RIHS01_' + '0' * 64
        conn = writer.add_connection('/accel', 'neato2_interfaces/msg/Accel', msgdef='', rihs01=no_hash)
        writer.write(conn, START_NS, raw)
    return raw


def test_unknown_type_is_kept_as_bytes_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    raw = _unknown_type_bag(tmp_path / 'u')
    with caplog.at_level(logging.WARNING), open_bag(tmp_path / 'u') as bag:
        assert bag.undecodable_topics == ['/accel']
        (message,) = bag.messages()
        assert message.data == raw
        with pytest.raises(InputError, match='neato2_interfaces/msg/Accel is unknown'):
            bag.deserialize(message)
    assert 'neato2_interfaces/msg/Accel' in caplog.text


def test_extra_msg_definitions_make_unknown_types_decodable(tmp_path: Path) -> None:
    _unknown_type_bag(tmp_path / 'u')
    msg_dir = tmp_path / 'defs' / 'neato2_interfaces' / 'msg'
    msg_dir.mkdir(parents=True)
    (msg_dir / 'Accel.msg').write_text(ACCEL_MSG)
    extra = load_msg_definitions([tmp_path / 'defs'])
    assert list(extra) == ['neato2_interfaces/msg/Accel']
    with open_bag(tmp_path / 'u', extra_types=extra) as bag:
        decoded = bag.deserialize(next(bag.messages()))
    assert (decoded.accel_x, decoded.accel_y, decoded.accel_z) == (1.5, -2.0, 9.75)


def test_msg_definition_paths_are_checked(tmp_path: Path) -> None:
    with pytest.raises(InputError, match='does not exist'):
        load_msg_definitions([tmp_path / 'missing'])
    stray = tmp_path / 'Thing.msg'
    stray.write_text('int32 a\n')
    with pytest.raises(InputError, match=r'<package>/msg/<Name>\.msg'):
        load_msg_definitions([stray])


def test_synthetic_drive_bag_has_expected_topics_and_counts(tmp_path: Path) -> None:
    samples = write_drive_bag(
        tmp_path / 'd.mcap', [Segment(0.1, 0.0, 1.0), Segment(0.2, 0.1, 1.0)], rate_hz=50
    )
    with open_bag(tmp_path / 'd.mcap') as bag:
        # 2 s at 50 Hz = 100 commands and joint states; odometry at 10 Hz = every 5th sample = 20.
        assert {t: i.count for t, i in bag.topics.items()} == {
            '/cmd_vel': 100,
            '/joint_states': 100,
            '/odom': 20,
        }
        twists = [bag.deserialize(m) for m in bag.messages(['/cmd_vel'])]
    assert np.allclose([t.linear.x for t in twists], samples.speed)


def test_table_7_3_command_sets() -> None:
    from skidsteer_power.real_robot import table_7_3_segments

    runs = [s for s in table_7_3_segments() if s.speed_m_s != 0]
    # Table 7.3: 8 sets at 0.1 m/s (yaw 0 ... 0.2 rad/s) and 11 at 0.2 m/s (yaw 0 ... 0.35 rad/s).
    assert len(runs) == 19
    assert max(s.yaw_rate_rad_s for s in runs if s.speed_m_s == 0.1) == 0.2
    assert max(s.yaw_rate_rad_s for s in runs if s.speed_m_s == 0.2) == 0.35


def test_vectorized_twist_decoding_matches_the_type_store(tmp_path: Path) -> None:
    from skidsteer_power.bag_io.decode import twists_vectorized

    write_drive_bag(tmp_path / 'v.mcap', [Segment(0.1, -0.25, 1.0), Segment(-0.2, 0.35, 1.0)], rate_hz=20)
    with open_bag(tmp_path / 'v.mcap') as bag:
        messages = list(bag.messages(['/cmd_vel']))
        generic = np.array([(t.linear.x, t.angular.z) for t in map(bag.deserialize, messages)])
    fast = twists_vectorized([m.data for m in messages])
    assert fast is not None and np.array_equal(fast, generic)
    assert twists_vectorized([messages[0].data[:-1]]) is None  # not a plain Twist: generic path


def test_real_sqlite3_bag_reads_with_unknown_types_skipped(
    neato_bag: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING), open_bag(neato_bag) as bag:
        # Counts from ../shared/realbags/README.md.
        assert bag.storage == 'sqlite3'
        assert bag.message_count == 2306
        assert bag.topics['/cmd_vel'].count == 739 and bag.topics['/odom'].count == 181
        assert bag.undecodable_topics == ['/accel', '/bump']
        odom = [bag.deserialize(m) for m in bag.messages(['/odom'])]
        assert abs(bag.duration_s - 46.1) < 0.1
    assert len(odom) == 181
    assert all(np.isfinite(o.pose.pose.position.x) for o in odom)
    assert 'neato2_interfaces/msg/Accel' in caplog.text


def test_real_bag_unknown_types_decode_with_definitions_from_the_readme(
    neato_bag: Path, tmp_path: Path
) -> None:
    pkg = tmp_path / 'neato2_interfaces' / 'msg'
    pkg.mkdir(parents=True)
    (pkg / 'Accel.msg').write_text(ACCEL_MSG)
    (pkg / 'Bump.msg').write_text('uint8 left_front\nuint8 left_side\nuint8 right_front\nuint8 right_side\n')
    with open_bag(neato_bag, extra_types=load_msg_definitions([tmp_path])) as bag:
        assert bag.undecodable_topics == []
        accel = [bag.deserialize(m) for m in bag.messages(['/accel'])]
        bumps = [bag.deserialize(m) for m in bag.messages(['/bump'])]
    assert len(accel) == 181 and len(bumps) == 181
    # A robot at rest on the floor: gravity dominates one axis (|a| ~ 1 g in whatever unit the driver uses).
    magnitudes = np.array([np.hypot(np.hypot(a.accel_x, a.accel_y), a.accel_z) for a in accel])
    assert np.all(np.isfinite(magnitudes)) and np.median(magnitudes) > 0
    assert {b.left_front for b in bumps} <= {0, 1}


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', *args], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize(
    ('args', 'message'),
    [
        (['replay', 'MISSING.mcap'], 'bag not found'),
        (['replay', 'BAG', '--topics', '/nope'], 'no topic /nope'),
        (['replay', 'BAG', '--rate', '0'], 'rate = 0 x is outside its range'),
        (['replay', 'JUNK'], 'truncated or corrupt'),
        (['record', '-o', 'BAG', '/a'], 'output exists already'),
        (['replay', 'BAG', '--msg', 'MISSING'], 'does not exist'),
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    _write_two_topics(tmp_path / 'b.mcap', 4)
    (tmp_path / 'junk.mcap').write_bytes(b'\x89MCAP0\r\n' + b'garbage' * 10)
    paths = {'BAG': tmp_path / 'b.mcap', 'JUNK': tmp_path / 'junk.mcap', 'MISSING': tmp_path / 'missing'}
    run = _cli(*[str(paths.get(a, a)).replace('MISSING.mcap', str(tmp_path / 'missing.mcap')) for a in args])
    assert run.returncode == 2
    lines = [line for line in run.stderr.splitlines() if not line.startswith('WARNING')]
    assert len(lines) == 1 and message in lines[0], run.stderr
