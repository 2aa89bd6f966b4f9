"""Write rosbag2 (version 9) MCAP bags with message definitions; a killed writer loses at most ~1 s.

Output: ``OUT.mcap`` is one MCAP file (the rosbag2 metadata rides inside it, as the rosbag2 MCAP
plugin writes it); any other name is a rosbag2 directory (``metadata.yaml`` + ``OUT/OUT.mcap``).
No ROS import: usable offline.

``rosbags``' writer keeps the connections and writes the rosbag2 metadata; the MCAP file itself is
written by the ``mcap`` library's :class:`mcap.writer.Writer` (storage plugin :class:`_FlushingMcap`),
because rosbags' own MCAP storage keeps everything in memory until a 1 MiB chunk fills (a recorder
killed before that left a 0-byte file). Here the file is written in place from the start:

- the header, then every schema and channel record as a top-level record, are on disk (flushed and
  fsync'ed) the moment they are added, before any message;
- a chunk is closed when it reaches ``chunk_size`` bytes (``mcap``'s own rule) OR when ``flush_period_s``
  has passed since the last flush (``Writer.flush()``: finish the chunk, write it, flush the stream),
  and the file is fsync'ed: a SIGKILL or a power cut loses at most ``flush_period_s`` of messages plus
  what the OS has not yet received (``BagWriter.flush_if_due`` lets an idle recorder flush too);
- chunks are not compressed, so a damaged chunk can be salvaged record by record
  (:mod:`skidsteer_power.bag_io.reader`); each chunk carries a CRC of its records.

:meth:`BagWriter.close` writes the rosbag2 metadata record, the summary (statistics, chunk and message
indexes) and the footer. A file without them (a killed writer) is read with ``--salvage``.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from collections.abc import Sequence
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Literal, cast

from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapLibWriter
from rosbags.interfaces import Qos
from rosbags.rosbag2 import CompressionMode, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io.reader import build_typestore
from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from rosbags.interfaces import Connection, ConnectionExtRosbag2

ROSBAG2_VERSION: Literal[9] = 9
CHUNK_SIZE = 1 << 20
"""A chunk is closed when its records reach this size [bytes] (the rosbag2 MCAP plugin's default)."""
FLUSH_PERIOD_S = 0.5
"""...or when this much time has passed since the last flush [s]: a kill loses at most about this."""


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


class _FlushingMcap:
    """rosbags storage plugin (its ``StorageWriter`` protocol) on the ``mcap`` library's writer.

    Writes ``file`` in place; see the module docstring for when data reaches the disk.
    """

    def __init__(
        self, file: Path, compression: CompressionMode, chunk_size: int, flush_period_s: float
    ) -> None:
        self.path = file
        self._file = file.open('xb')
        _fsync_dir(file.parent)
        self._mcap = McapLibWriter(
            self._file,
            chunk_size=chunk_size,
            compression=(
                CompressionType.ZSTD if compression == CompressionMode.STORAGE else CompressionType.NONE
            ),
        )
        self._mcap.start(profile='ros2', library=f'skidsteer_power; mcap {version("mcap")}')
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[int, int] = {}
        self._flush_period_s = flush_period_s
        self._last_flush = time.monotonic()
        self.flush()

    def add_msgtype(self, connection: Connection) -> None:
        encoding = 'ros2idl' if connection.msgdef.data.startswith('=' * 80 + '\nIDL: ') else 'ros2msg'
        data = connection.msgdef.data.encode()
        schema_id = self._mcap.register_schema(connection.msgtype, encoding, data)
        self._schema_ids[connection.msgtype] = schema_id
        self._write_now(Schema(id=schema_id, name=connection.msgtype, encoding=encoding, data=data))

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        schema_id = self._schema_ids[connection.msgtype]
        metadata = {'offered_qos_profiles': offered_qos_profiles, 'topic_type_hash': connection.digest}
        ext = cast('ConnectionExtRosbag2', connection.ext)  # a rosbag2 writer's connections
        encoding = ext.serialization_format
        channel_id = self._mcap.register_channel(connection.topic, encoding, schema_id, metadata)
        self._channel_ids[connection.id] = channel_id
        self._write_now(
            Channel(
                id=channel_id,
                topic=connection.topic,
                message_encoding=ext.serialization_format,
                schema_id=schema_id,
                metadata=metadata,
            )
        )

    def _write_now(self, record: Schema | Channel) -> None:
        """Put ``record`` on disk at once as a top-level record (the ``mcap`` writer also keeps it for
        the chunk in progress and the summary; MCAP allows identical repeats)."""
        self._mcap.flush()
        builder = RecordBuilder()
        record.write(builder)
        self._file.write(builder.end())
        self.flush()

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self._mcap.add_message(self._channel_ids[connection.id], timestamp, bytes(data), timestamp)
        self.flush_if_due()

    def flush_if_due(self) -> None:
        if time.monotonic() - self._last_flush >= self._flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress, write it and fsync the file."""
        self._mcap.flush()
        os.fsync(self._file.fileno())
        self._last_flush = time.monotonic()

    def close(self, version: int, metadata: str) -> None:
        _ = version
        self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
        self._mcap.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def _fsync_dir(path: Path) -> None:
    """Make a new directory entry durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class BagWriter:
    """A rosbag2 (version 9) MCAP bag being written; see the module docstring for the output layout.

    ``chunk_size`` [bytes] and ``flush_period_s`` [s]: a chunk is written when either is reached.
    """

    def __init__(
        self, output: str | Path, *, chunk_size: int = CHUNK_SIZE, flush_period_s: float = FLUSH_PERIOD_S
    ) -> None:
        self.output = Path(output)
        if self.output.exists():
            raise InputError(f'output exists already, not overwriting: {self.output}')
        if not self.output.parent.is_dir():
            raise InputError(f'output directory does not exist: {self.output.parent}')
        self.single_file = self.output.suffix == '.mcap'
        if self.single_file:  # rosbags' writer wants a directory: its metadata.yaml is not kept
            self._staging: Path | None = Path(tempfile.mkdtemp(prefix='skidsteer_bag_'))
            bag_dir = self._staging / self.output.stem
            file = self.output
        else:
            self._staging = None
            bag_dir = self.output
            file = bag_dir / f'{bag_dir.name}.mcap'

        self._storage: _FlushingMcap | None = None

        def storage(path: Path, compression: CompressionMode) -> _FlushingMcap:
            self._storage = _FlushingMcap(file, compression, chunk_size, flush_period_s)
            return self._storage

        self._writer = Writer(bag_dir, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        # rosbags types the plugin as a class; it only calls it with (path, compression)
        self._writer.STORAGE_PLUGINS = {StoragePlugin.MCAP: storage}  # type: ignore[dict-item]
        try:
            self._writer.open()
        except (OSError, WriterError) as err:
            raise InputError(f'cannot write {self.output}: {err}') from err
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

    def flush_if_due(self) -> None:
        """Write the chunk in progress if ``flush_period_s`` has passed (call from an idle loop)."""
        if self._storage is not None:
            self._storage.flush_if_due()

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
            shutil.rmtree(self._staging, ignore_errors=True)
        return self.output

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
