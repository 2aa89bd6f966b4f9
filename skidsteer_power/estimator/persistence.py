"""Energy-state file: written atomically, read back on start so a restart loses nothing.

The state is JSON. A write goes to a temporary file in the same directory, is flushed and fsync'ed,
then replaces the old file with :func:`os.replace` (atomic on POSIX), so a crash or power cut
mid-write leaves either the old or the new state, never a torn file.

A state file that cannot be used (garbage bytes, torn JSON, another schema, another vehicle) is never
overwritten: :func:`load_or_quarantine` moves it aside to ``<file>.corrupt-<UTC time>`` and returns one
warning naming both files, and the caller starts from a fresh battery.

The file keeps tallies only (issue 28): the battery's state of charge, time and energy drawn, and the
measured and predicted energy. The battery's configuration (capacity, cells, curve) comes from the
vehicle's configuration, never from the file (a file saying ``capacity_Ah: 10`` once turned the test
robot's battery into 449.7 Wh, ``1e308`` into inf Wh). Every restored number is range-checked
(:data:`TALLY_RANGES`); a file over :data:`MAX_STATE_BYTES` (counted while reading: ``/dev/zero``
says it has 0 bytes), not a regular file (a FIFO would block the start), or nested deeper than JSON's
recursion limit is unusable, never fatal.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.cache import atomic_file
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.safe_read import read_capped
from skidsteer_power.terramechanics.ranges import Range

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

FORMAT_VERSION = 1
MAX_STATE_BYTES = 64 * 1024
"""Largest state file read [bytes]; one is about 0.5 KB."""
TALLY_RANGES = {
    'soc': Range('state of charge', 0.0, 1.0, ''),
    'elapsed_s': Range('elapsed time', 0.0, 1e10, 's'),  # 317 years
    'drawn_J': Range('energy drawn', -1e12, 1e12, 'J'),  # 278 MWh either way
    'measured': Range('measured energy', -1e12, 1e12, 'J'),
    'predicted': Range('predicted energy', -1e12, 1e12, 'J'),
}
"""Range of each restored number (far beyond any small robot's battery; they stop nan, inf, 1e308)."""


def battery_tallies(state: Mapping[str, float]) -> dict[str, float]:
    """The battery numbers a restart keeps, from a battery's state dict: soc, elapsed_s, drawn_J."""
    return {k: float(state[k]) for k in ('soc', 'elapsed_s', 'drawn_J')}


def restored_tallies(state: JsonObject) -> tuple[dict[str, float], dict[str, float]]:
    """(battery tallies, energy tallies [J]) of a loaded state, each range-checked; ConfigError if
    a number is missing, not a number or outside its range (:data:`TALLY_RANGES`)."""
    try:
        battery = battery_tallies(state['battery']['state'])
        energy = {k: float(state['energy_J'][k]) for k in ('measured', 'predicted')}
        for key, value in (battery | energy).items():
            TALLY_RANGES[key].check(value)
    except (KeyError, TypeError, ValueError) as err:  # InputError is a ValueError
        reason = str(err) if isinstance(err, InputError) else f'missing or not a number: {err}'
        raise ConfigError(f'saved energy state does not fit this battery: {reason}') from err
    return battery, energy


def save_state(path: str | os.PathLike[str], state: JsonObject) -> None:
    """Atomically write ``state`` (JSON-serializable) to ``path``, creating parent directories."""
    payload = json.dumps({'format_version': FORMAT_VERSION, **state}, indent=1, sort_keys=True)
    with atomic_file(path) as tmp:
        tmp.write(payload.encode('utf-8'))


class StateWriter:
    """Writes energy states to ``path`` in a thread of its own, newest first (issue 34 item 9).

    The node saves every ``save_period_s`` (0.5 s), so a SIGKILL loses at most that much energy; one
    atomic write with its fsync took 0.5 ms median, 1.0 ms p95, 4.8 ms max on this machine's disk
    (200 writes of the 190-byte state, see docs/RELIABILITY.md), and on a robot's SD card it can take
    tens of ms: :meth:`submit` only hands the state over (the executor never waits for the disk), a
    state not yet written is replaced by a newer one, and a state equal to the last one written
    (a robot standing) is not written again. ``on_error`` gets every OSError's one-line message.
    """

    def __init__(self, path: str | os.PathLike[str], on_error: Callable[[str], object]) -> None:
        self.path = Path(path)
        self.on_error = on_error
        self.writes = 0
        self._last: JsonObject | None = None
        self._pending: JsonObject | None = None
        self._closed = False
        self._io = threading.Lock()  # one write at a time (the thread's and write_now's)
        self._wake = threading.Condition()
        self._thread = threading.Thread(target=self._run, name='energy-state-writer', daemon=True)
        self._thread.start()

    def submit(self, state: JsonObject) -> None:
        """Write ``state`` soon (a JSON-serializable dict; ``saved_unix_s`` is added when written)."""
        with self._wake:
            self._pending = state
            self._wake.notify()

    def _run(self) -> None:
        while True:
            with self._wake:
                while self._pending is None and not self._closed:
                    self._wake.wait()
                state, self._pending = self._pending, None
            if state is None:
                return
            self._write(state)

    def write_now(self, state: JsonObject) -> bool:
        """Write ``state`` in the calling thread (reset, shutdown); True when the file holds it."""
        with self._wake:
            self._pending = None  # older than this one
        return self._write(state)

    def _write(self, state: JsonObject) -> bool:
        with self._io:
            if state == self._last:
                return True
            try:
                save_state(self.path, {**state, 'saved_unix_s': time.time()})
            except OSError as err:
                self.on_error(f'cannot save the energy state to {self.path}: {err.strerror or err}')
                return False
            self._last = state
            self.writes += 1
            return True

    def close(self, final: JsonObject | None = None) -> None:
        """Stop the thread after the pending write; then write ``final`` here (shutdown)."""
        with self._wake:
            self._closed = True
            self._wake.notify()
        self._thread.join()
        if final is not None:
            self._write(final)


def load_state(path: str | os.PathLike[str]) -> JsonObject | None:
    """Read a state written by :func:`save_state`; None if the file does not exist.

    Raises ConfigError for an unreadable, corrupt or foreign file (the caller decides whether to
    start fresh, and says so).
    """
    source = Path(path)
    if not os.path.lexists(source):
        return None
    try:  # a FIFO or /dev/zero is refused, and at most MAX_STATE_BYTES are read (issue 34 item 13)
        text = read_capped(source, MAX_STATE_BYTES, 'energy state').decode('utf-8')
    except InputError as err:
        raise ConfigError(str(err)) from err
    except UnicodeDecodeError as err:
        raise ConfigError(f'energy state {source} is not text (byte {err.start} is not UTF-8)') from err
    try:
        state = json.loads(text)
    except json.JSONDecodeError as err:
        raise ConfigError(f'energy state {source} is not valid JSON ({err.msg}, line {err.lineno})') from err
    except RecursionError as err:
        raise ConfigError(f'energy state {source} is nested too deeply to be a state') from err
    if not isinstance(state, dict) or state.get('format_version') != FORMAT_VERSION:
        raise ConfigError(f'energy state {source} has an unknown format (expected version {FORMAT_VERSION})')
    return state


def quarantine(path: str | os.PathLike[str]) -> Path:
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
    path: str | os.PathLike[str], accept: Callable[[JsonObject], None]
) -> tuple[JsonObject | None, str]:
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
