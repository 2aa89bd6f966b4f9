"""Clean stops on SIGINT and SIGTERM for long-running commands (record, replay, run).

A command started in the background of a non-interactive shell inherits SIGINT as *ignored*, so
relying on KeyboardInterrupt alone would leave it unstoppable by Ctrl-C-style signals and a SIGTERM
would kill it before it saved anything: the handlers below turn both signals into a flag instead.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


class StopFlag:
    """Set by SIGINT or SIGTERM (see :func:`stop_on_signals`), or by :meth:`set`."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.signal_name = ''

    def set(self, signal_name: str = '') -> None:
        self.signal_name = self.signal_name or signal_name
        self._event.set()

    def is_set(self) -> bool:
        return self._event.is_set()

    def wait(self, timeout: float) -> bool:
        return self._event.wait(timeout)


@contextmanager
def stop_on_signals(flag: StopFlag) -> Iterator[StopFlag]:
    """Within the block, SIGINT and SIGTERM set ``flag`` instead of raising or killing.

    Only possible from the main thread; elsewhere the block runs with the handlers untouched.
    """
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        previous[signum] = signal.signal(signum, lambda num, _frame: flag.set(signal.Signals(num).name))
    try:
        yield flag
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
