"""Write rosbag2 (version 9) MCAP bags with message definitions through ``rosbags``' writer.

Output: ``OUT.mcap`` is one MCAP file (the rosbag2 metadata rides inside it, as the rosbag2 MCAP
plugin writes it); any other name is a rosbag2 directory (``metadata.yaml`` + ``OUT/OUT.mcap``).
While writing a single file, data goes to ``OUT.mcap.partial/``; :meth:`BagWriter.close` writes the
index and moves the file into place. No ROS import: usable offline.
"""

from __future__ import annotations

import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.interfaces import Qos
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bags.reader import build_typestore
from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

ROSBAG2_VERSION = 9


def message_definition(msgtype: str) -> tuple[str, str]:
    """(ros2msg definition text with dependencies, RIHS01 hash) of ``pkg/msg/Name``.

    From the rosbags Jazzy type store, else from the ``.msg`` file installed with the Python message
    package (``share/<pkg>/msg/<Name>.msg``). Raises InputError if neither has it.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    if msgtype not in store.fielddefs:
        store = build_typestore(extra={msgtype: _installed_msg_text(msgtype)})
    try:
        text, _ = store.generate_msgdef(msgtype, ros_version=2)
        return text, store.hash_rihs01(msgtype)
    except Exception as err:  # a dependency missing from the store: say which type
        raise InputError(f'no complete message definition for {msgtype}: {err}') from err


def _installed_msg_text(msgtype: str) -> str:
    package, _, name = msgtype.split('/')
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        share = Path(get_package_share_directory(package))
    except (ImportError, PackageNotFoundError, LookupError, OSError):  # OSError: AMENT_PREFIX_PATH unset
        share = Path(sys.prefix) / 'share' / package
    path = share / 'msg' / f'{name}.msg'
    if not path.exists():
        raise InputError(f'no message definition for {msgtype} (looked for {path})')
    return path.read_text(encoding='utf-8')


class BagWriter:
    """A rosbag2 (version 9) MCAP bag being written; see the module docstring for the output layout."""

    def __init__(self, output: str | Path) -> None:
        self.output = Path(output)
        if self.output.exists():
            raise InputError(f'output exists already, not overwriting: {self.output}')
        if not self.output.parent.is_dir():
            raise InputError(f'output directory does not exist: {self.output.parent}')
        self.single_file = self.output.suffix == '.mcap'
        if self.single_file:
            self._staging = self.output.with_name(self.output.name + '.partial')
            if self._staging.exists():
                raise InputError(f'a partial recording is in the way: {self._staging}')
            self._staging.mkdir()
            bag_dir = self._staging / self.output.stem
        else:
            self._staging = None
            bag_dir = self.output
        self._writer = Writer(bag_dir, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._bag_dir = bag_dir
        self.counts: dict[str, int] = {}
        self._closed = False

    def add_topic(
        self,
        topic: str,
        msgtype: str,
        qos_profiles: Sequence[Qos] = (),
        msgdef: tuple[str, str] | None = None,
    ) -> Connection:
        """Register ``topic`` of ``msgtype``; ``msgdef`` = (definition, RIHS01) overrides the lookup."""
        text, rihs01 = msgdef if msgdef is not None else message_definition(msgtype)
        self.counts.setdefault(topic, 0)
        return self._writer.add_connection(
            topic, msgtype, msgdef=text, rihs01=rihs01, offered_qos_profiles=list(qos_profiles)
        )

    def write(self, connection: Connection, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Append one serialized message received at ``timestamp_ns`` [ns since the epoch]."""
        self._writer.write(connection, timestamp_ns, data)
        self.counts[connection.topic] += 1

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    def close(self) -> Path:
        """Write index and metadata, move the bag into place; returns the bag's path."""
        if self._closed:
            return self.output
        self._closed = True
        try:
            self._writer.close()
        except WriterError as err:
            raise InputError(f'could not finish {self.output}: {err}') from err
        if self._staging is not None:
            (self._bag_dir / f'{self.output.stem}.mcap').replace(self.output)
            shutil.rmtree(self._staging)
        return self.output

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
