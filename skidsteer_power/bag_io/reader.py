"""One reading API over rosbag2 bags: MCAP (file or directory) and sqlite3 (directory or .db3 file).

Built on ``rosbags``. Types come from, in order of precedence: the definitions stored in the bag
(MCAP schemas), extra ``.msg`` definitions given by the caller, and the ROS 2 Jazzy type store.
A topic whose type none of them knows stays readable as raw CDR bytes (replay needs nothing more);
only deserializing it fails, and :func:`open_bag` warns once about such topics.

Damage: the reader compares what it read with what the bag says it holds (the MCAP statistics record,
or the message counts of the rosbag2 metadata): ``messages_expected``, ``messages_read``, ``complete``.
Without ``salvage`` a bag that cannot be opened, or a full pass that reads fewer messages than the bag
holds, raises :class:`~skidsteer_power.errors.InputError` naming the file and how much is missing.
With ``salvage=True`` an MCAP file is read by :func:`skidsteer_power.bag_io.salvage.salvage_mcap`, which
recovers every intact message (below chunk granularity: a damaged chunk is read record by record), in
time order; ``damage`` says what was damaged and one warning says how much is missing. An sqlite3
file is salvaged by a plain table scan, which keeps the rows sqlite can still reach.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import struct
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypeAlias, TypeGuard

from rosbags.interfaces import MessageDefinitionFormat, Qos
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import ReaderError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

from skidsteer_power.errors import InputError
from skidsteer_power.safe_read import check_regular, read_capped

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.interfaces.typing import Typesdict
    from rosbags.typesys.store import Typestore

    from skidsteer_power.jsonout import JsonObject

LOG = logging.getLogger(__name__)

RosMessage: TypeAlias = Any  # Any: a rosbags message, its class chosen at run time by the type name
"""A decoded message (:meth:`BagReader.deserialize`): a ``rosbags`` dataclass of the topic's type,
read by field (``msg.twist.linear.x``). Which class depends on the topic's type name in the bag,
known only at run time (rosbags itself returns ``object``)."""

DEFAULT_STORE = Stores.ROS2_JAZZY
ROS_ENCODING = 'cdr'  # message encoding of ROS 2 channels; others (protobuf, json) are skipped
_IDL_SEPARATOR = '=' * 80 + '\n'
MAX_METADATA_BYTES = 16 << 20
"""Largest metadata.yaml read [bytes] (16 MiB; one of a 10-topic bag is about 5 KB)."""
_PARSE_ERRORS: tuple[type[BaseException], ...] = (
    struct.error,
    EOFError,
    ValueError,
    KeyError,
    IndexError,
    AssertionError,
    ArithmeticError,
    MemoryError,  # a damaged record length asks for petabytes
    TypeError,  # rosbags' MCAP reader on a file that ends inside a record
)
"""What rosbags' parsers raise on bytes that are not a valid bag. Translated into
:class:`BagBytesError` by :func:`_parsing` around the calls that read a bag's bytes, and only there:
the same errors raised by this package's own code are bugs and propagate."""
_DAMAGE_ERRORS: tuple[type[BaseException], ...] = (ReaderError, sqlite3.Error)
"""Failures that mean "the bytes on disk are not a valid bag" (a :class:`BagBytesError` is a
ReaderError), reported as :class:`BagDamageError` or salvaged."""
try:  # rosbags reads sqlite3 through apsw when it is installed
    import apsw

    _DAMAGE_ERRORS += (apsw.Error,)
except ImportError:  # pragma: no cover - depends on the rosbags build
    pass


class BagBytesError(ReaderError):
    """A rosbags parser failed on a bag's bytes with a built-in error (see :data:`_PARSE_ERRORS`);
    the message says what was wrong in words, the original error is its ``__cause__``."""


@contextmanager
def _parsing() -> Iterator[None]:
    """Around a call into rosbags that reads a bag's bytes (open, the next message): its parsers'
    built-in errors become :class:`BagBytesError`, as rosbags' own reader turns KeyError and
    TypeError into ReaderError where it reads bytes."""
    try:
        yield
    except _PARSE_ERRORS as err:
        reason = one_line(str(err)) or type(err).__name__
        if isinstance(err, TypeError):  # rosbags reading past the end of a record
            reason = 'the file ends inside a record'
        if isinstance(err, MemoryError) or 'ssize_t' in reason:
            reason = 'a record length field is damaged'
        raise BagBytesError(reason) from err


def _read_through(
    reader: Rosbag2Reader, connections: list[Connection], start_ns: int | None, stop_ns: int | None
) -> Iterator[tuple[Connection, int, bytes]]:
    """rosbags' messages of ``connections``, each read inside :func:`_parsing`."""
    with _parsing():
        stream = iter(reader.messages(connections=connections, start=start_ns, stop=stop_ns))
    while True:
        with _parsing():
            item = next(stream, None)
        if item is None:
            return
        yield item


class BagDamageError(InputError):
    """The bag is damaged or holds fewer messages than it says. Commands that offer ``--salvage``
    add that hint to the message (cli/bags.py); the others do not suggest a flag they lack."""


class BagMessage(NamedTuple):
    """One stored message: topic, receive time [ns since the epoch], CDR bytes, ROS type name."""

    topic: str
    timestamp_ns: int
    data: bytes
    msgtype: str


@dataclass(frozen=True)
class TopicInfo:
    """A topic in a bag: its type, message count, offered QoS profiles and stored definition."""

    name: str
    msgtype: str
    count: int
    qos: tuple[Qos, ...] = ()
    msgdef: str = ''
    decodable: bool = False


def load_msg_definitions(paths: Iterable[str | os.PathLike[str]]) -> dict[str, str]:
    """Read extra ``.msg`` definitions: files laid out as ``<pkg>/msg/<Name>.msg`` or trees of them.

    Returns ``{'pkg/msg/Name': text}``. Raises InputError for a missing path or a file whose package
    cannot be told from its location.
    """
    found: dict[str, str] = {}
    for entry in map(Path, paths):
        if not entry.exists():
            raise InputError(f'message definition path does not exist: {entry}')
        files = sorted(entry.rglob('*.msg')) if entry.is_dir() else [entry]
        for file in files:
            if file.suffix != '.msg' or file.parent.name != 'msg' or not file.parent.parent.name:
                raise InputError(f'{file}: expected a .msg file at <package>/msg/<Name>.msg')
            found[f'{file.parent.parent.name}/msg/{file.stem}'] = file.read_text(encoding='utf-8')
    return found


def _types_from_definition(msgtype: str, fmt: MessageDefinitionFormat, text: str) -> Typesdict:
    if fmt == MessageDefinitionFormat.MSG:
        return get_types_from_msg(text, msgtype)
    if text.startswith(f'{_IDL_SEPARATOR}IDL: '):
        types: Typesdict = {}
        for section in text.split(_IDL_SEPARATOR)[1:]:
            types.update(get_types_from_idl(section.split('\n', 1)[1]))
        return types
    return get_types_from_idl(text)


def build_typestore(
    stored: Iterable[tuple[str, MessageDefinitionFormat, str]] = (),
    extra: Mapping[str, str] | None = None,
) -> Typestore:
    """A type store: Jazzy's types, overridden by ``extra`` .msg texts, overridden by ``stored`` ones.

    ``stored`` holds (type name, definition format, definition text) as found in a bag. A stored
    definition that does not parse is skipped with a warning (the Jazzy or extra one, if any, stays).
    """
    fielddefs: Typesdict = dict(get_typestore(DEFAULT_STORE).fielddefs)
    for name, text in (extra or {}).items():
        try:
            fielddefs.update(get_types_from_msg(text, name))
        except TypesysError as err:
            raise InputError(f'message definition of {name} does not parse: {err}') from err
    for name, fmt, text in stored:
        if fmt == MessageDefinitionFormat.NONE or not text:
            continue
        try:
            fielddefs.update(_types_from_definition(name, fmt, text))
        except (TypesysError, IndexError, ValueError) as err:
            LOG.warning('stored definition of %s does not parse (%s); using the type store', name, err)
    store = get_typestore(Stores.EMPTY)
    store.register(fielddefs)
    return store


def one_line(text: str) -> str:
    """A multi-line library message (ruamel.yaml's is 8 lines) as one line: the lines that say what
    is wrong, without the source excerpts, caret lines and links."""
    noise = ('To suppress', 'http')
    kept = [line.strip() for line in text.splitlines() if line.strip() and not line[0].isspace()]
    return '; '.join(line for line in kept if not line.startswith(noise))


def _damage_text(path: Path, err: BaseException) -> str:
    reason = one_line(str(err)) or type(err).__name__
    if path.is_file() and path.stat().st_size <= 8:
        reason = f'only {path.stat().st_size} bytes: no records after the MCAP magic'
    if 'ssize_t' in reason:
        reason = 'a record length field is damaged'

    return f'{path}: bag is truncated or corrupt ({reason})'


@dataclass
class BagReader:
    """An open bag. Use as a context manager or call :meth:`close`.

    Attributes: ``path``; ``storage`` ('mcap' | 'sqlite3'); ``topics`` by name; ``start_ns`` and
    ``end_ns`` (first and last receive time, ns since the epoch); ``message_count``; ``typestore``;
    ``damage`` ('' for an intact bag, else what stopped a salvage read).
    """

    path: Path
    storage: str
    topics: dict[str, TopicInfo]
    start_ns: int
    end_ns: int
    message_count: int
    typestore: Typestore
    damage: str = ''
    salvage: bool = False
    messages_expected: int | None = None
    messages_read: int | None = None
    undecodable: dict[str, int] = field(default_factory=dict)
    unverified: int = 0
    """Messages of chunks whose CRC failed (or could not be checked), left out (salvage only)."""
    include_unverified: bool = False
    """Yield the unverified messages too (:func:`open_bag`'s ``include_unverified``)."""
    counts_valid: bool = True
    """False when the bag's own counts are not counts (salvage read of a damaged metadata.yaml)."""
    _reader: Rosbag2Reader | None = None
    _connections: list[Connection] = field(default_factory=list)
    _salvaged: list[BagMessage] | None = None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last message [s]."""
        return max(0, self.end_ns - self.start_ns) * 1e-9

    @property
    def complete(self) -> bool:
        """True only when a full pass read every message the bag says it holds and each could be
        decoded (False when that count is unknown, no full pass was made, or one was skipped)."""
        return (
            self.messages_expected is not None
            and self.messages_read is not None
            and self.messages_read == self.messages_expected  # more than it says is a lie too
            and not self.undecodable
            and not self.unverified
        )

    def integrity(self) -> JsonObject:
        """``messages_expected`` (the bag's own count; None if unknown), ``messages_read``, ``complete``,
        ``undecodable`` (messages skipped per topic because they could not be decoded; salvage only),
        ``messages_unverified`` (messages of chunks whose CRC failed, left out; salvage only)."""
        return {
            'messages_expected': self.messages_expected,
            'messages_read': self.messages_read,
            'complete': self.complete,
            'undecodable': dict(self.undecodable),
            'messages_unverified': self.unverified,
        }

    def count_all(self) -> int:
        """Read every message once (raises InputError, without ``salvage``, if any is missing)."""
        return sum(1 for _ in self.messages())

    @property
    def undecodable_topics(self) -> list[str]:
        """Topics whose type no definition describes (readable as bytes only)."""
        return sorted(name for name, info in self.topics.items() if not info.decodable)

    def messages(
        self,
        topics: Sequence[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[BagMessage]:
        """Messages in time order, optionally only ``topics`` and ``start_ns <= t < stop_ns`` [ns].

        Raises InputError for an unknown topic, or (after yielding what precedes it) at damage found
        while reading.
        """
        wanted = set(self.topics if topics is None else topics)
        unknown = wanted - set(self.topics)
        if unknown:
            raise InputError(f'{self.path}: no topic {", ".join(sorted(unknown))} in the bag')
        if self._salvaged is not None:
            if topics is None and start_ns is None and stop_ns is None:
                self.messages_read = len(self._salvaged)
            for message in self._salvaged:
                if (
                    message.topic in wanted
                    and (start_ns is None or message.timestamp_ns >= start_ns)
                    and (stop_ns is None or message.timestamp_ns < stop_ns)
                ):
                    yield message
            return
        assert self._reader is not None
        connections = [c for c in self._connections if c.topic in wanted]
        if not connections:
            return
        last: tuple[int, int] = (-1, 0)  # (timestamp, messages yielded at it)
        read: dict[str, int] = dict.fromkeys(wanted, 0)
        try:
            for connection, timestamp, data in _read_through(self._reader, connections, start_ns, stop_ns):
                last = (timestamp, last[1] + 1 if timestamp == last[0] else 1)
                read[connection.topic] += 1
                yield BagMessage(connection.topic, timestamp, data, connection.msgtype)
        except _DAMAGE_ERRORS as err:
            if not self.salvage:
                raise BagDamageError(_damage_text(self.path, err)) from err
            yield from self._salvage_after(err, last, wanted, start_ns, stop_ns)
            return
        if start_ns is None and stop_ns is None:
            self._check_pass(read)

    def _check_pass(self, read: dict[str, int]) -> None:
        """After a full pass over some topics: did it read all the bag holds of them?"""
        short = {t: (n, self.topics[t].count) for t, n in read.items() if n < self.topics[t].count}
        extra = {t: (n, self.topics[t].count) for t, n in read.items() if n > self.topics[t].count}
        if set(read) == set(self.topics):
            self.messages_read = sum(read.values())
        if not self.counts_valid or (not short and not extra):
            return
        if short:
            got, held = sum(n for n, _ in short.values()), sum(m for _, m in short.values())
            detail = ', '.join(f'{t} {n} of {m}' for t, (n, m) in sorted(short.items()))
            text = f'{self.path}: read {got} of {held} messages ({held - got} missing: {detail})'
            text += '; the bag is damaged'
        else:  # issue 34 item 12: a count below what is there is a damaged or forged metadata.yaml
            detail = ', '.join(f'{t} {n} where it says {m}' for t, (n, m) in sorted(extra.items()))
            text = (
                f'{self.path}: read more messages than the bag says it holds ({detail}); its counts are wrong'
            )
        if not self.salvage:
            raise BagDamageError(text)
        self.damage = self.damage or text
        LOG.warning('%s', text)

    def _salvage_after(
        self,
        err: BaseException,
        last: tuple[int, int],
        wanted: set[str],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> Iterator[BagMessage]:
        """Damage met while reading through the index: stream the file and go on after ``last``."""
        file = _single_file(self.path, err)
        if file.suffix == '.db3':
            messages = _scan_sqlite(file)[1]
        else:
            scan = _scan_mcap(file, self.include_unverified)
            messages, self.unverified = scan[1], scan[5]
        self._salvaged = messages
        if wanted == set(self.topics) and start_ns is None and stop_ns is None:
            self.messages_read = len(messages)
        self.damage = (
            f'damaged ({one_line(str(err)) or type(err).__name__}); read by streaming up to the damage'
        )
        LOG.warning('%s: %s', self.path, self.damage)
        skip = last[1]
        for message in messages:
            if message.topic not in wanted or message.timestamp_ns < last[0]:
                continue
            if message.timestamp_ns == last[0] and skip:
                skip -= 1
                continue
            if (start_ns is None or message.timestamp_ns >= start_ns) and (
                stop_ns is None or message.timestamp_ns < stop_ns
            ):
                yield message

    def deserialize(self, message: BagMessage) -> RosMessage:
        """The message as a ``rosbags`` object. Raises InputError if its type is unknown or bytes bad."""
        info = self.topics[message.topic]
        if not info.decodable:
            raise InputError(f'{message.topic}: type {message.msgtype} is unknown; give its .msg definition')
        try:
            return self.typestore.deserialize_cdr(message.data, message.msgtype)
        except Exception as err:  # rosbags raises assorted errors for bad bytes; report one clear line
            raise InputError(f'{message.topic}: cannot decode a {message.msgtype} message: {err}') from err

    def decoded(self, topic: str) -> Iterator[tuple[BagMessage, RosMessage]]:
        """(message, decoded message) of ``topic`` in time order. A message that cannot be decoded
        raises InputError, or, in a salvage read, is skipped and counted in ``undecodable`` (as
        ``replay --salvage`` does), with one warning per topic."""
        for message in self.messages([topic]):
            try:
                yield message, self.deserialize(message)
            except InputError as err:
                if not self.salvage or not self.topics[topic].decodable:
                    raise
                if topic not in self.undecodable:
                    LOG.warning('%s: skipping messages that cannot be decoded (%s)', self.path, err)
                self.undecodable[topic] = self.undecodable.get(topic, 0) + 1

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


BAG_FILE_SUFFIXES = ('.mcap', '.db3', '.yaml')
"""Files of a bag directory that are checked to be regular files before anything reads them."""
MAX_SALVAGE_BYTES = 4 << 30
"""Largest MCAP file a salvage read takes into memory [bytes] (4 GiB; counted while reading)."""


def _check_regular_files(path: Path) -> None:
    """InputError unless ``path`` and every bag file in it (``*.mcap``, ``*.db3``, metadata.yaml) is a
    regular file: a FIFO there made every reader hang, ``/dev/zero`` read forever (issue 34 item 13)."""
    if not path.is_dir():
        check_regular(path, 'bag')
        return
    for entry in sorted(path.iterdir()):
        if entry.suffix in BAG_FILE_SUFFIXES and not entry.is_dir():
            check_regular(entry, 'bag file')


def _resolve(path: Path) -> Path:
    """A bag directory without metadata.yaml (a crashed recorder) is opened through its one file."""
    if path.is_dir() and not (path / 'metadata.yaml').exists():
        files = sorted(path.glob('*.mcap')) + sorted(path.glob('*.db3'))
        if len(files) == 1:
            return files[0]
        raise InputError(f'{path}: not a bag (no metadata.yaml and not exactly one .mcap/.db3 file)')
    return path


def _storage_of(path: Path) -> str:
    if path.is_file():
        return 'sqlite3' if path.suffix == '.db3' else 'mcap'
    files = list(path.glob('*.db3'))
    return 'sqlite3' if files else 'mcap'


def open_bag(
    path: str | os.PathLike[str],
    *,
    extra_types: Mapping[str, str] | None = None,
    salvage: bool = False,
    warn_unknown: bool = True,
    include_unverified: bool = False,
) -> BagReader:
    """Open a rosbag2 bag (MCAP file, .db3 file, or bag directory) for reading.

    Parameters
    ----------
    path : bag file or directory
    extra_types : ``{'pkg/msg/Name': msg text}`` for types neither the bag nor Jazzy defines
        (see :func:`load_msg_definitions`)
    salvage : read a damaged bag up to the damage instead of raising
    warn_unknown : log one warning naming topics whose type is unknown
    include_unverified : (salvage) also yield the messages of chunks whose CRC failed or could not
        be checked, which are left out by default (their payload may be altered); the bag stays
        incomplete (``messages_unverified`` counts them)

    Raises
    ------
    InputError for a missing path, a path that is not a bag, or (without ``salvage``) a damaged bag.
    """
    bag_path = Path(path)
    if not bag_path.exists():
        raise InputError(f'bag not found: {bag_path}')
    _check_regular_files(bag_path)
    bag_path = _resolve(bag_path)
    try:
        if salvage and _storage_of(bag_path) == 'mcap' and bag_path.is_file():
            bag = _open_salvage(bag_path, extra_types, None, include_unverified=include_unverified)
        elif _storage_of(bag_path) == 'mcap' and _has_foreign_channels(bag_path):
            bag = _open_salvage(bag_path, extra_types, None, warn=False)  # rosbags cannot open it
            bag.salvage = False
            if bag.damage:
                raise BagDamageError(f'{bag_path}: bag is truncated or corrupt ({bag.damage})')
        else:
            bag = _open_intact(bag_path, extra_types, salvage)
            bag.salvage = salvage
    except BagDamageError:
        raise
    except _DAMAGE_ERRORS as err:
        if _FOREIGN_PROFILE in str(err) and bag_path.is_file():
            bag = _open_foreign_profile(bag_path, extra_types, salvage)
        elif not salvage:
            raise BagDamageError(_damage_text(bag_path, err)) from err
        else:
            bag = _open_salvage(bag_path, extra_types, err, include_unverified=include_unverified)
    except FileNotFoundError as err:
        raise InputError(f'{bag_path}: {err}') from err
    bag.include_unverified = include_unverified
    if warn_unknown and bag.undecodable_topics:
        LOG.warning(
            '%s: no definition for the type of %s; these topics are kept as raw bytes only',
            bag_path,
            ', '.join(f'{t} ({bag.topics[t].msgtype})' for t in bag.undecodable_topics),
        )
    return bag


_FOREIGN_PROFILE = 'Profile is not ros2'  # rosbags' ReaderError for any other MCAP header profile
_ROS2_SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')


def _open_foreign_profile(path: Path, extra_types: Mapping[str, str] | None, salvage: bool) -> BagReader:
    """An MCAP file whose header profile is not 'ros2' (several writers leave it empty) but whose
    schemas are ROS 2 message definitions and messages CDR: read with the MCAP scanner of
    :mod:`skidsteer_power.bag_io.salvage` (the whole file in memory), with a warning about the
    profile. Other encodings are refused with one clear InputError; so is damage without ``salvage``."""
    from mcap.reader import make_reader

    try:
        with path.open('rb') as stream:
            reader = make_reader(stream)
            profile = reader.get_header().profile
            summary = reader.get_summary()
    except Exception as err:  # the mcap library's own errors; damage is the scanner's to describe
        summary, profile = None, '?'
        if not salvage:
            raise BagDamageError(_damage_text(path, err)) from err
    if summary is not None:
        foreign = sorted(
            {f'message encoding {c.message_encoding}' for c in summary.channels.values()}
            - {'message encoding cdr'}
        ) + sorted(
            {f'schema encoding {s.encoding}' for s in summary.schemas.values()}
            - {f'schema encoding {e}' for e in _ROS2_SCHEMA_ENCODINGS}
        )
        if foreign:
            raise InputError(f'{path}: not a ROS 2 bag (MCAP profile {profile!r}; {", ".join(foreign)})')
    bag = _open_salvage(path, extra_types, None)
    if bag.damage and not salvage:
        raise BagDamageError(f'{path}: bag is truncated or corrupt ({bag.damage})')
    bag.salvage = salvage
    LOG.warning(
        '%s: MCAP header profile is %r, not "ros2"; its schemas are ROS 2 definitions and its messages '
        'CDR: read as a ROS 2 bag',
        path,
        profile,
    )
    return bag


def _has_foreign_channels(path: Path) -> bool:
    """Whether an MCAP file's summary mixes ROS 2 CDR channels with others (e.g. protobuf), which
    rosbags' reader refuses (KeyError); False when there is no readable summary or no CDR channel at
    all (not a ROS 2 bag: the ordinary path says so)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    files = [path] if path.is_file() else sorted(path.glob('*.mcap'))
    if len(files) != 1:
        return False
    try:
        with files[0].open('rb') as stream:
            summary = make_reader(stream).get_summary()
    except (McapError, OSError, ValueError, KeyError, struct.error):
        return False
    if summary is None:
        return False
    encodings = {c.message_encoding for c in summary.channels.values()}
    return ROS_ENCODING in encodings and len(encodings) > 1


def _is_count(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _not_counts(path: Path, named: Sequence[tuple[str, object]]) -> str:
    bad = [f'{name} {value!r}' for name, value in named if not _is_count(value)]
    if not bad:
        return ''
    return f'{path}: the message counts of the bag are not counts ({", ".join(bad)}); the bag is damaged'


def _metadata_problem(folder: Path, per_topic: Sequence[tuple[str, int]]) -> str:
    """'' when a bag directory's metadata.yaml states a total and per-file counts that are counts and
    agree with the topics' (rosbags' MCAP storage takes its counts from the file and never reads
    these); else one line."""
    import yaml

    with _parsing():
        text = read_capped(folder / 'metadata.yaml', MAX_METADATA_BYTES, 'bag metadata').decode('utf-8')
        info = yaml.safe_load(text)
    info = info.get('rosbag2_bagfile_information', info) if isinstance(info, dict) else None
    if not isinstance(info, dict):
        return ''  # rosbags opened it; nothing more to compare
    listed = info.get('files')
    files: list[object] = listed if isinstance(listed, list) else []
    named: list[tuple[str, object]] = [('total', info.get('message_count'))]
    named += [
        (f'file {f.get("path", k)}', f.get('message_count'))
        for k, f in enumerate(files)
        if isinstance(f, dict)
    ]
    problem = _not_counts(folder, named)
    if problem:
        return problem
    counts = [value for _, value in named if _is_count(value)]
    total, in_files, topics = counts[0], sum(counts[1:]), sum(n for _, n in per_topic)
    if total != topics or (len(counts) > 1 and in_files != total):
        return (
            f'{folder}: metadata.yaml says {total} messages, {in_files} in its files, its topics add up '
            f'to {topics}; the bag is damaged'
        )
    return ''


def _count_problem(path: Path, total: object, per_topic: Sequence[tuple[str, object]]) -> str:
    """'' when the bag's own counts (metadata.yaml or MCAP statistics) are whole numbers >= 0 that
    add up; else one line saying which is not (issue 34 item 12: -5 and 1e12 were taken as counts)."""
    problem = _not_counts(path, [*per_topic, ('total', total)])
    if problem:
        return problem
    added = sum(n for _, n in per_topic if _is_count(n))
    if per_topic and added != total:
        return f'{path}: the bag says it holds {total} messages, its topics add up to {added}; damaged'
    return ''


def _open_intact(path: Path, extra_types: Mapping[str, str] | None, salvage: bool = False) -> BagReader:
    with _parsing():
        reader = Rosbag2Reader(path)
        reader.open()
    try:
        connections = list(reader.connections)
        store = build_typestore(
            ((c.msgtype, c.msgdef.format, c.msgdef.data) for c in connections), extra_types
        )
        topics = _topic_infos(
            (c.topic, c.msgtype, c.msgcount, getattr(c.ext, 'offered_qos_profiles', ()), c.msgdef.data)
            for c in connections
        )
        topics = {k: _with_decodable(v, store) for k, v in topics.items()}
        count = reader.message_count
        # a bare .db3 has no count of its own (rosbags counts its rows): nothing to call it complete by
        own_count = _storage_of(path) != 'sqlite3' or (path.is_dir() and (path / 'metadata.yaml').exists())
        per_topic: list[tuple[str, object]] = [(c.topic, c.msgcount) for c in connections]
        problem = _count_problem(path, count, per_topic) if own_count else ''
        if own_count and not problem and path.is_dir():  # rosbags' MCAP storage counts from the file
            problem = _metadata_problem(path, [(t, n) for t, n in per_topic if _is_count(n)])
        if problem and not salvage:
            raise BagDamageError(problem)
        if problem:
            LOG.warning('%s', problem)
        return BagReader(
            path=path,
            storage=_storage_of(path),
            topics=topics,
            start_ns=reader.start_time if count else 0,
            end_ns=max(reader.end_time - 1, reader.start_time) if count else 0,
            message_count=count,
            typestore=store,
            messages_expected=count if own_count and not problem else None,
            damage=problem,
            counts_valid=not problem,
            _reader=reader,
            _connections=connections,
        )
    except BaseException:
        reader.close()
        raise


def _topic_infos(rows: Iterable[tuple[str, str, int, Sequence[Qos], str]]) -> dict[str, TopicInfo]:
    """Merge connections per topic (a topic may have several connections of one type)."""
    topics: dict[str, TopicInfo] = {}
    for name, msgtype, count, qos, msgdef in rows:
        if name in topics:
            old = topics[name]
            if old.msgtype != msgtype:
                raise InputError(f'topic {name} is stored with two types: {old.msgtype}, {msgtype}')
            topics[name] = TopicInfo(name, msgtype, old.count + count, old.qos, old.msgdef or msgdef)
        else:
            topics[name] = TopicInfo(name, msgtype, count, tuple(qos), msgdef)
    return topics


def _with_decodable(info: TopicInfo, store: Typestore) -> TopicInfo:
    decodable = info.msgtype in store.fielddefs
    return TopicInfo(info.name, info.msgtype, info.count, info.qos, info.msgdef, decodable)


def _single_file(path: Path, cause: BaseException) -> Path:
    if path.is_dir():
        files = sorted(path.glob('*.mcap')) + sorted(path.glob('*.db3'))
        if len(files) != 1:
            raise InputError(f'{_damage_text(path, cause)}; cannot salvage a multi-file bag') from cause
        return files[0]
    return path


def _open_salvage(
    path: Path,
    extra_types: Mapping[str, str] | None,
    cause: BaseException | None,
    *,
    warn: bool = True,
    include_unverified: bool = False,
) -> BagReader:
    bag_dir = path if path.is_dir() else None
    path = _single_file(path, cause or InputError('salvage'))
    unverified = 0
    if path.suffix == '.db3':
        topics, messages, damage = _scan_sqlite(path)
        stored: list[tuple[str, MessageDefinitionFormat, str]] = []
        expected = _metadata_count(bag_dir or path.parent)
    else:
        topics, messages, damage, stored, expected, unverified = _scan_mcap(path, include_unverified)
    store = build_typestore(stored, extra_types)
    topics = {k: _with_decodable(v, store) for k, v in topics.items()}
    if not damage and cause is not None:
        damage = f'unreadable index ({one_line(str(cause)) or type(cause).__name__})'
    held = 'an unknown number of' if expected is None else f'{expected}'
    if not messages:
        raise InputError(f'{path}: nothing intact to salvage (0 of {held} messages; {damage or "no data"})')
    if warn and (damage or expected is None or len(messages) != expected):
        LOG.warning(
            '%s: salvaged %d of %s messages%s; %s',
            path,
            len(messages),
            held,
            f' ({unverified} unverified {"kept" if include_unverified else "left out"})'
            if unverified
            else '',
            damage or 'no count',
        )
    stamps = [m.timestamp_ns for m in messages]
    return BagReader(
        path=path,
        storage='sqlite3' if path.suffix == '.db3' else 'mcap',
        topics=topics,
        start_ns=min(stamps, default=0),
        end_ns=max(stamps, default=0),
        message_count=len(messages),
        typestore=store,
        damage=damage,
        salvage=True,
        messages_expected=expected,
        messages_read=len(messages),
        unverified=unverified,
        _salvaged=messages,
    )


def _metadata_count(folder: Path) -> int | None:
    """Message count in a rosbag2 directory's metadata.yaml (None if absent or unreadable)."""
    import yaml

    from skidsteer_power.bag_io.salvage import message_count_of

    try:
        text = read_capped(folder / 'metadata.yaml', MAX_METADATA_BYTES, 'bag metadata').decode('utf-8')
        return message_count_of(yaml.safe_load(text))
    except (InputError, UnicodeDecodeError, yaml.YAMLError):
        return None


def _scan_mcap(
    path: Path, include_unverified: bool = False
) -> tuple[
    dict[str, TopicInfo],
    list[BagMessage],
    str,
    list[tuple[str, MessageDefinitionFormat, str]],
    int | None,
    int,
]:
    """Every intact message of an MCAP file, in time order (:mod:`skidsteer_power.bag_io.salvage`),
    with the unverified ones too if ``include_unverified``, and how many unverified ones there are."""
    from skidsteer_power.bag_io.salvage import salvage_mcap

    found = salvage_mcap(read_capped(path, MAX_SALVAGE_BYTES, 'bag'))
    formats = {'ros2msg': MessageDefinitionFormat.MSG, 'ros2idl': MessageDefinitionFormat.IDL}
    schemas = found.schemas
    channels = {k: c for k, c in found.channels.items() if c.message_encoding == ROS_ENCODING}
    foreign = {k: c for k, c in found.channels.items() if k not in channels}
    messages: list[BagMessage] = []
    counts: dict[int, int] = {}
    skipped = 0
    for record in found.messages + (found.unverified if include_unverified else []):
        if record.channel_id not in channels:
            skipped += 1
            continue
        channel = channels[record.channel_id]
        schema = schemas.get(channel.schema_id)
        msgtype = schema.name if schema else ''
        messages.append(BagMessage(channel.topic, record.log_time, bytes(record.data), msgtype))
        counts[channel.id] = counts.get(channel.id, 0) + 1
    messages.sort(key=lambda m: m.timestamp_ns)
    topics: dict[str, TopicInfo] = {}
    for channel in channels.values():
        schema = schemas.get(channel.schema_id)
        qos_text = channel.metadata.get('offered_qos_profiles', '')
        try:
            qos = tuple(parse_qos(qos_text)) if qos_text else ()
        except Exception:  # QoS is advisory; a salvage read goes on without it
            qos = ()
        old = topics.get(channel.topic)
        topics[channel.topic] = TopicInfo(
            channel.topic,
            schema.name if schema else '',
            counts.get(channel.id, 0) + (old.count if old else 0),
            qos,
            schema.data.decode(errors='replace') if schema else '',
        )
    stored = [
        (s.name, formats[s.encoding], s.data.decode(errors='replace'))
        for s in schemas.values()
        if s.encoding in formats
    ]
    expected = found.expected
    if foreign:
        LOG.warning(
            '%s: skipping %s (not ROS 2 CDR: %d messages)',
            path,
            ', '.join(f'{c.topic} ({c.message_encoding})' for c in foreign.values()),
            skipped,
        )
        expected = None if expected is None else expected - skipped  # of the ROS channels
    return topics, messages, '; '.join(found.damage), stored, expected, len(found.unverified)


def _scan_sqlite(path: Path) -> tuple[dict[str, TopicInfo], list[BagMessage], str]:
    """Table-scan an sqlite3 bag's rows in storage order; stop where sqlite reports damage."""
    topics: dict[str, TopicInfo] = {}
    messages: list[BagMessage] = []
    names: dict[int, tuple[str, str]] = {}
    damage = ''
    try:
        connection = sqlite3.connect(f'file:{path}?mode=ro', uri=True)
    except sqlite3.Error as err:
        return topics, messages, f'not readable by sqlite ({err})'
    try:
        for topic_id, name, msgtype in connection.execute('SELECT id, name, type FROM topics'):
            names[topic_id] = (name, msgtype)
        for topic_id, stamp, data in connection.execute('SELECT topic_id, timestamp, data FROM messages'):
            name, msgtype = names[topic_id]
            messages.append(BagMessage(name, stamp, bytes(data), msgtype))
    except (sqlite3.Error, KeyError) as err:
        damage = f'sqlite stopped after {len(messages)} rows ({err})'
    finally:
        connection.close()
    messages.sort(key=lambda m: m.timestamp_ns)
    counts: dict[str, int] = {}
    for message in messages:
        counts[message.topic] = counts.get(message.topic, 0) + 1
    for name, msgtype in names.values():
        topics[name] = TopicInfo(name, msgtype, counts.get(name, 0))
    return topics, messages, damage
