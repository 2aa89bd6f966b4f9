"""Energy-state file: written atomically, read back on start so a restart loses nothing.

The state is JSON. A write goes to a temporary file in the same directory, is flushed and fsync'ed,
then replaces the old file with :func:`os.replace` (atomic on POSIX), so a crash or power cut
mid-write leaves either the old or the new state, never a torn file.

A state file that cannot be used (garbage bytes, torn JSON, another schema, another vehicle) is never
overwritten: :func:`load_or_quarantine` moves it aside to ``<file>.corrupt-<UTC time>`` and returns one
warning naming both files, and the caller starts from a fresh battery.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from skidsteer_power.cache import atomic_file
from skidsteer_power.errors import ConfigError

FORMAT_VERSION = 1


def save_state(path: str | os.PathLike, state: dict[str, Any]) -> None:
    """Atomically write ``state`` (JSON-serializable) to ``path``, creating parent directories."""
    payload = json.dumps({'format_version': FORMAT_VERSION, **state}, indent=1, sort_keys=True)
    with atomic_file(path) as tmp:
        tmp.write(payload.encode('utf-8'))


def load_state(path: str | os.PathLike) -> dict[str, Any] | None:
    """Read a state written by :func:`save_state`; None if the file does not exist.

    Raises ConfigError for an unreadable, corrupt or foreign file (the caller decides whether to
    start fresh, and says so).
    """
    source = Path(path)
    try:
        text = source.read_text(encoding='utf-8')
    except FileNotFoundError:
        return None
    except OSError as err:
        raise ConfigError(f'cannot read energy state {source}: {err.strerror or err}') from err
    except UnicodeDecodeError as err:
        raise ConfigError(f'energy state {source} is not text (byte {err.start} is not UTF-8)') from err
    try:
        state = json.loads(text)
    except json.JSONDecodeError as err:
        raise ConfigError(f'energy state {source} is not valid JSON ({err.msg}, line {err.lineno})') from err
    if not isinstance(state, dict) or state.get('format_version') != FORMAT_VERSION:
        raise ConfigError(f'energy state {source} has an unknown format (expected version {FORMAT_VERSION})')
    return state


def quarantine(path: str | os.PathLike) -> Path:
    """Move ``path`` aside to ``<path>.corrupt-<UTC time>`` (a free name); returns the new path."""
    source = Path(path)
    stamp = time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())
    target = source.with_name(f'{source.name}.corrupt-{stamp}')
    n = 1
    while target.exists():
        n += 1
        target = source.with_name(f'{source.name}.corrupt-{stamp}-{n}')
    os.replace(source, target)
    return target


def load_or_quarantine(
    path: str | os.PathLike, accept: Callable[[dict[str, Any]], None]
) -> tuple[dict[str, Any] | None, str]:
    """Load the state at ``path`` and hand it to ``accept`` (which raises ConfigError to refuse it).

    Returns (state, '') when accepted, (None, '') when there is no file, and (None, warning) when the
    file is unusable: it was moved aside (:func:`quarantine`) and the one-line warning names both
    paths, so nothing is lost and the next save does not overwrite it.
    """
    try:
        state = load_state(path)
        if state is not None:
            accept(state)
        return state, ''
    except ConfigError as err:
        reason = str(err)
    try:
        moved = f'moved it aside to {quarantine(path)}'
    except OSError as err:
        moved = f'could not move it aside ({err.strerror or err})'
    return None, f'unusable energy state {path}: {reason}; {moved}; starting from a fresh battery'
