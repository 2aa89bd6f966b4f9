"""One live process per energy-state file (issue 37 item 8): an advisory lock (``flock``) on
``<state file>.lock``, held from the estimator's start to its end.

Two estimators writing one file each restore the other's energy and overwrite it; the second one is
refused at start instead, with one clear error naming the holder's pid. ``flock`` locks belong to the
open file: the kernel drops them when the process ends, however it ends (SIGKILL included), so a
stale lock file never blocks a restart.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from skidsteer_power.errors import ConfigError


class StateLock:
    """The held lock of one state file (:meth:`take`); :meth:`release` drops it (idempotent)."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    @classmethod
    def take(cls, state_file: Path) -> StateLock:
        """Lock ``state_file`` for this process; ConfigError if another process holds it."""
        path = state_file.with_name(state_file.name + '.lock')
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
        except OSError as err:
            raise ConfigError(f'cannot lock the energy state file {state_file}: {err.strerror}') from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors='replace').strip() or '?'
            os.close(fd)
            raise ConfigError(
                f'energy state file {state_file} is in use by another estimator (pid {holder}): give '
                'each robot its own namespace or state_file (run: --state-file)'
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f'{os.getpid()}\n'.encode(), 0)
        return cls(path, fd)

    def release(self) -> None:
        """Drop the lock (the lock file stays: removing it would race with a new holder)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
