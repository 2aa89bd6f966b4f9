"""Energy-state file: written atomically, read back on start so a restart loses nothing.

The state is JSON. A write goes to a temporary file in the same directory, is flushed and fsync'ed,
then replaces the old file with :func:`os.replace` (atomic on POSIX), so a crash or power cut
mid-write leaves either the old or the new state, never a torn file.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from skidsteer_power.errors import ConfigError

FORMAT_VERSION = 1


def save_state(path: str | os.PathLike, state: dict[str, Any]) -> None:
    """Atomically write ``state`` (JSON-serializable) to ``path``, creating parent directories."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    payload = json.dumps({'format_version': FORMAT_VERSION, **state}, indent=1, sort_keys=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.tmp', dir=target.parent)
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as tmp:
            tmp.write(payload)
            tmp.flush()
            os.fsync(tmp.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


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
    try:
        state = json.loads(text)
    except json.JSONDecodeError as err:
        raise ConfigError(f'energy state {source} is not valid JSON ({err.msg}, line {err.lineno})') from err
    if not isinstance(state, dict) or state.get('format_version') != FORMAT_VERSION:
        raise ConfigError(f'energy state {source} has an unknown format (expected version {FORMAT_VERSION})')
    return state
