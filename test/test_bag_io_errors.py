"""Where bag damage is told from a bug (issue 38): rosbags' parsers' built-in errors on bad bytes are
bag damage (salvaged or one clear line), the same errors from this package's own code propagate."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io import reader as reader_module
from skidsteer_power.bag_io.reader import BagBytesError, BagDamageError
from skidsteer_power.bag_io.synthetic import START_NS
from skidsteer_power.bag_io.writer import BagWriter

STORE = get_typestore(Stores.ROS2_JAZZY)
String = STORE.types['std_msgs/msg/String']


def _bag(path: Path, n: int = 200) -> Path:
    with BagWriter(path) as writer:
        conn = writer.add_topic('/a', 'std_msgs/msg/String')
        for i in range(n):
            data = STORE.serialize_cdr(String(f'{i:06d}' + 'x' * 200), 'std_msgs/msg/String')
            writer.write(conn, START_NS + i * 1_000_000, data)
    return path


def test_a_parser_type_error_is_damage_in_words() -> None:
    with (
        pytest.raises(BagBytesError, match='the file ends inside a record') as caught,
        reader_module._parsing(),
    ):
        raise TypeError("'NoneType' object is not subscriptable")  # rosbags past a record's end
    assert isinstance(caught.value.__cause__, TypeError)


@pytest.mark.parametrize('bug', [KeyError, TypeError, AssertionError, IndexError])
def test_a_bug_while_opening_propagates_not_as_damage(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bug: type[Exception]
) -> None:
    bag = _bag(tmp_path / 'bagdir')  # a directory: opened through rosbags, even with salvage

    def broken(*_args: object) -> None:
        raise bug('a bug in this package, not in the bag')

    monkeypatch.setattr(reader_module, '_topic_infos', broken)
    with pytest.raises(bug, match='a bug in this package'):
        open_bag(bag, salvage=True)  # salvage would have hidden it as "damage" before


def test_a_bug_while_reading_propagates_not_as_salvage(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = _bag(tmp_path / 'bagdir')  # a directory: opened through rosbags, even with salvage

    class Broken(reader_module.BagMessage):
        def __new__(cls, *args: object) -> Broken:
            raise KeyError('a bug in this package')

    with open_bag(bag, salvage=True) as opened:
        monkeypatch.setattr(reader_module, 'BagMessage', Broken)
        with pytest.raises(KeyError, match='a bug in this package'):
            list(opened.messages())
        assert opened.damage == ''  # nothing was "salvaged"


def test_damaged_bytes_still_are_damage(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'cut.mcap')
    data = bag.read_bytes()
    bag.write_bytes(data[: len(data) // 2])  # cut inside a record: rosbags' parser fails on it
    with pytest.raises(BagDamageError, match='truncated or corrupt'), open_bag(bag) as opened:
        list(opened.messages())
    with open_bag(bag, salvage=True) as opened:
        assert 0 < len(list(opened.messages())) < 200
        assert opened.damage
