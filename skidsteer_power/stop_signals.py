"""Clean stops on every signal that would end the process (record, replay, run, des, the nodes).

SIGINT and SIGTERM, and every other catchable signal whose default action ends the process (SIGHUP
from an SSH disconnect or a closed terminal, SIGQUIT, SIGUSR1/2, SIGALRM, SIGPWR, the real-time
signals, ...: :data:`TERMINATING_SIGNALS`) set a flag instead: the command stops its work, zeroes and
disables the motors, saves what it recorded, and exits. Signals that cannot be caught (SIGKILL, and
the hardware-fault signals SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGSYS, after which the interpreter
cannot run a handler) and power loss are why docs/RELIABILITY.md asks for the amplifiers' enable line.

A command started in the background of a non-interactive shell inherits SIGINT as *ignored*, so
relying on KeyboardInterrupt alone would leave it unstoppable by Ctrl-C-style signals and a SIGTERM
would kill it before it saved anything: SIGINT and SIGTERM are taken even when ignored. The other
signals are taken only where they would end the process (their handler is the default): ``nohup``'s
ignored SIGHUP and Python's ignored SIGPIPE/SIGXFSZ stay ignored, a profiler's SIGPROF stays its.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_DEFAULT_TERMINATES = (
    'SIGHUP',
    'SIGINT',
    'SIGQUIT',
    'SIGTRAP',
    'SIGABRT',
    'SIGUSR1',
    'SIGUSR2',
    'SIGPIPE',
    'SIGALRM',
    'SIGTERM',
    'SIGSTKFLT',
    'SIGXCPU',
    'SIGXFSZ',
    'SIGVTALRM',
    'SIGPROF',
    'SIGIO',
    'SIGPWR',
)  # fmt: skip  (signal(7): default action Term or Core; SIGKILL cannot be caught)
TERMINATING_SIGNALS: tuple[int, ...] = tuple(
    int(getattr(signal, name)) for name in _DEFAULT_TERMINATES if hasattr(signal, name)
) + tuple(range(signal.SIGRTMIN, signal.SIGRTMAX + 1) if hasattr(signal, 'SIGRTMIN') else ())
"""Every catchable signal whose default action ends the process (Linux, signal(7)), less the
hardware-fault signals (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGSYS: no handler can run after them)."""
ALWAYS_TAKEN = (signal.SIGINT, signal.SIGTERM)
"""Taken even when inherited as ignored."""


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:  # a real-time signal between SIGRTMIN and SIGRTMAX
        return f'SIGRTMIN+{signum - signal.SIGRTMIN}'


class StopFlag:
    """Set by a terminating signal (see :func:`stop_on_signals`), or by :meth:`set` with a reason."""

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
    """Within the block, every signal of :data:`TERMINATING_SIGNALS` that would end the process sets
    ``flag`` instead of raising or killing (SIGINT, SIGTERM always).

    Only possible from the main thread; elsewhere the block runs with the handlers untouched.
    """
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = {}
    for signum in TERMINATING_SIGNALS:
        if signum in ALWAYS_TAKEN or signal.getsignal(signum) is signal.SIG_DFL:
            previous[signum] = signal.signal(signum, lambda num, _frame: flag.set(signal_name(num)))
    try:
        yield flag
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
