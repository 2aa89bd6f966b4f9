"""Helpers shared by subcommands: JSON output and argument types.

``common`` defines no ``register`` and so adds no subcommand.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
from collections.abc import Iterator, Mapping
from typing import TypeAlias

import numpy as np

Subcommands: TypeAlias = 'argparse._SubParsersAction[argparse.ArgumentParser]'
"""What ``register(subparsers)`` of each command module is given (``add_parser`` makes a command)."""


def _plain(value: object) -> object:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value


def print_json(payload: Mapping[str, object]) -> None:
    """Print ``payload`` as JSON (numpy values converted; NaN -> null, inf -> "inf")."""
    json.dump(_plain(payload), sys.stdout, indent=2)
    sys.stdout.write('\n')


def print_table(payload: Mapping[str, object]) -> None:
    """Print ``key  value`` lines for a human."""
    width = max((len(k) for k in payload), default=0)
    for key, value in payload.items():
        print(f'{key:<{width}}  {_plain(value)}')


def emit(payload: Mapping[str, object], as_json: bool) -> None:
    (print_json if as_json else print_table)(payload)


def _number(text: str, *, allow_inf: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if math.isnan(value) or (math.isinf(value) and not allow_inf):
        raise argparse.ArgumentTypeError(f'not a finite number: {text!r}')
    return value


def finite_float(text: str) -> float:
    """argparse type: a finite float."""
    return _number(text)


def positive_float(text: str) -> float:
    """argparse type: a finite float > 0."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be > 0: {text!r}')
    return value


def nonnegative_float(text: str) -> float:
    """argparse type: a finite float >= 0."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0: {text!r}')
    return value


@contextlib.contextmanager
def native_stdout_to_stderr() -> Iterator[None]:
    """For the block, what native code writes to file descriptor 1 goes to stderr, while Python's
    ``print`` still reaches the real stdout: stdout carries only this program's output. Fast DDS
    prints its log on stdout (e.g. 'RTPS_TRANSPORT_SHM Error ... Failed init_port' when another
    process holds a shared-memory port), which broke ``--json`` output. A no-op when Python's stdout
    is not descriptor 1 (captured in tests, embedded)."""
    try:
        is_fd1 = sys.stdout.fileno() == 1
    except (AttributeError, ValueError, OSError):  # io.UnsupportedOperation is an OSError
        is_fd1 = False
    if not is_fd1:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    original = sys.stdout
    sys.stdout = open(saved, 'w', encoding=original.encoding, errors=original.errors, closefd=False)  # noqa: SIM115
    os.dup2(2, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        sys.stdout = original
        os.dup2(saved, 1)
        os.close(saved)


def add_json_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--json', action='store_true', help='print machine-readable JSON (SI units)')


def add_msg_option(parser: argparse.ArgumentParser) -> None:
    """``--msg PATH`` (repeatable): message definitions for types a bag does not define."""
    parser.add_argument(
        '--msg',
        action='append',
        default=[],
        metavar='PATH',
        help='extra message definitions: <pkg>/msg/<Name>.msg files or folders of them (repeatable)',
    )


def ros_topic(text: str) -> str:
    """argparse type: a valid ROS 2 topic name (rclpy's own rules: tokens of letters, digits and
    underscores between '/', no '//', not starting with a digit), e.g. ``cmd_vel`` or ``/robot/odom``."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_topic_name import validate_topic_name

    try:
        validate_topic_name(text)
    except InvalidTopicNameException as err:
        reason = str(err).splitlines()[0].split(': ', 1)[-1]
        raise argparse.ArgumentTypeError(f'not a ROS topic name: {text!r} ({reason})') from None
    return text


def web_origin(text: str) -> str:
    """argparse type: a web origin ``scheme://host[:port]`` (http or https, no path), e.g.
    ``https://app.foxglove.dev``."""
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(text.strip())
        port = parts.port  # ValueError for a port that is not a number in 0-65535
    except ValueError:
        parts, port = None, None
    if (
        parts is None
        or parts.scheme not in ('http', 'https')
        or not parts.hostname
        or parts.path not in ('', '/')
        or parts.query
        or parts.fragment
        or parts.username
    ):
        raise argparse.ArgumentTypeError(f'not a web origin (scheme://host[:port]): {text!r}')
    del port
    return text.strip().rstrip('/')
