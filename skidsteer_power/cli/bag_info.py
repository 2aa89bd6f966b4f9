"""``skidsteer-power info BAG``: what is in a bag, as ``ros2 bag info`` prints it (issue 37 item 7).

    skidsteer-power info BAG [--json]

Text: the bag's files, size, storage id, duration, start and end (local time and seconds since the
epoch), the message count and one line per topic (name, type, count, serialization format), in
``ros2 bag info``'s layout. ``--json``: ``bag``, ``files``, ``size_bytes``, ``storage``, ``duration_s``,
``start_ns``, ``end_ns``, ``messages``, ``topics`` (a list of ``topic``, ``type``, ``count``,
``serialization_format``). Read from the bag's summary (MCAP) or index (sqlite3): no message is decoded.
"""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path
from typing import TypedDict

from skidsteer_power.cli.common import Subcommands, add_json_flag, add_msg_option, emit


class TopicLine(TypedDict):
    """One topic of :class:`BagInfo`: its name, ROS type, message count and serialization format."""

    topic: str
    type: str
    count: int
    serialization_format: str


class BagInfo(TypedDict):
    """The ``--json`` keys of ``info`` (sizes in bytes, times in ns since the epoch)."""

    bag: str
    files: list[str]
    size_bytes: int
    storage: str
    duration_s: float
    start_ns: int
    end_ns: int
    messages: int
    topics: list[TopicLine]


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'info',
        help="a bag's topics, types, counts, duration and storage (as ros2 bag info)",
        description="A bag's files, size, storage, duration, start/end and per topic its type and message "
        'count, as `ros2 bag info` prints them.',
    )
    parser.add_argument('bag', metavar='BAG', help='bag file (.mcap/.db3) or rosbag2 directory')
    add_msg_option(parser)
    add_json_flag(parser)
    parser.set_defaults(func=_cmd_info)


def bag_info(path: str, msg: list[str] | None = None) -> BagInfo:
    """The ``--json`` keys of ``info`` for the bag at ``path`` (InputError if it cannot be opened)."""
    from skidsteer_power.bag_io.reader import load_msg_definitions, open_bag

    with open_bag(path, extra_types=load_msg_definitions(msg or [])) as bag:
        root = Path(path)
        files = (
            sorted(p for p in root.iterdir() if p.suffix in ('.mcap', '.db3')) if root.is_dir() else [root]
        )
        return {
            'bag': str(bag.path),
            'files': [str(p) for p in files],
            'size_bytes': sum(p.stat().st_size for p in files),
            'storage': bag.storage,
            'duration_s': bag.duration_s,
            'start_ns': bag.start_ns,
            'end_ns': bag.end_ns,
            'messages': bag.message_count,
            'topics': [
                {'topic': t.name, 'type': t.msgtype, 'count': t.count, 'serialization_format': 'cdr'}
                for t in sorted(bag.topics.values(), key=lambda t: t.name)
            ],
        }


def _size_text(size: int) -> str:
    value, unit = float(size), 'B'
    for unit in ('B', 'KiB', 'MiB', 'GiB', 'TiB'):
        if value < 1024 or unit == 'TiB':
            break
        value /= 1024
    return f'{value:.1f} {unit}' if unit != 'B' else f'{size} B'


def _time_text(ns: int) -> str:
    when = datetime.datetime.fromtimestamp(ns * 1e-9)
    return f'{when:%b %d %Y %H:%M:%S}.{ns % 1_000_000_000 // 1_000_000:03d} ({ns // 10**9}.{ns % 10**9:09d})'


def info_text(info: BagInfo) -> str:
    """``ros2 bag info``'s layout (rosbag2 Jazzy: labels padded to 19 columns)."""
    topics = info['topics']
    lines = [
        f'Files:             {"  ".join(Path(f).name for f in info["files"])}',
        f'Bag size:          {_size_text(info["size_bytes"])}',
        f'Storage id:        {info["storage"]}',
        f'Duration:          {info["duration_s"]:.9f}s',
        f'Start:             {_time_text(info["start_ns"])}',
        f'End:               {_time_text(info["end_ns"])}',
        f'Messages:          {info["messages"]}',
    ]
    width = max((len(t['topic']) for t in topics), default=0)
    type_width = max((len(t['type']) for t in topics), default=0)
    for k, t in enumerate(topics):
        label = 'Topic information: ' if k == 0 else ' ' * 19
        lines.append(
            f'{label}Topic: {t["topic"]:<{width}} | Type: {t["type"]:<{type_width}} | Count: {t["count"]} | '
            f'Serialization Format: {t["serialization_format"]}'
        )
    if not topics:
        lines.append('Topic information: ')
    return '\n'.join(lines)


def _cmd_info(args: argparse.Namespace) -> int:
    info = bag_info(args.bag, args.msg)
    if args.json:
        emit(info, True)
    else:
        print(info_text(info))
    return 0
