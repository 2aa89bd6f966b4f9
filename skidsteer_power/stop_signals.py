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

The job-control stops (SIGTSTP from Ctrl-Z, SIGTTIN, SIGTTOU: :data:`STOPPING_SIGNALS`) would freeze
the process with the motors at their last speed (issue 34: 6 s measured until SIGCONT). Within
:func:`stop_on_signals` they first run every hook registered with :func:`on_pause` (des_driver's:
zero and disable both amplifiers, forget the command), then stop the process as the default action
would; on SIGCONT the hooks' ``resume`` runs (des_driver: enable again, drive only on a fresh command).
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress

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
STOPPING_SIGNALS: tuple[int, ...] = tuple(
    int(getattr(signal, name)) for name in ('SIGTSTP', 'SIGTTIN', 'SIGTTOU') if hasattr(signal, name)
)
"""The catchable signals whose default action stops the process (signal(7): Stop; SIGSTOP cannot be
caught): the motors are made safe first (:func:`on_pause`), then the process stops."""
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


class PauseHook:
    """What to do before a job-control stop (``pause``: must not block for long) and after SIGCONT."""

    def __init__(self, pause: Callable[[str], None], resume: Callable[[], None]) -> None:
        self.pause = pause
        self.resume = resume


_PAUSE_HOOKS: list[PauseHook] = []
_PAUSE_LOCK = threading.Lock()


def on_pause(pause: Callable[[str], None], resume: Callable[[], None]) -> PauseHook:
    """Register ``pause(signal_name)`` to run before the process stops on SIGTSTP/SIGTTIN/SIGTTOU,
    and ``resume()`` after it continues; :func:`remove_pause_hook` takes it away."""
    hook = PauseHook(pause, resume)
    with _PAUSE_LOCK:
        _PAUSE_HOOKS.append(hook)
    return hook


def remove_pause_hook(hook: PauseHook) -> None:
    with _PAUSE_LOCK:
        if hook in _PAUSE_HOOKS:
            _PAUSE_HOOKS.remove(hook)


def _stop_safely(signum: int, _frame: object) -> None:
    """Handler of :data:`STOPPING_SIGNALS`: run the pause hooks, stop as the default action would,
    and after SIGCONT run the resume hooks and take the signal again."""
    with _PAUSE_LOCK:
        hooks = list(_PAUSE_HOOKS)
    for hook in hooks:
        with suppress(Exception):  # a hook's failure must not keep the process from stopping
            hook.pause(signal_name(signum))
    handler = signal.signal(signum, signal.SIG_DFL)
    try:
        os.kill(os.getpid(), signum)  # stops here (the default action) until SIGCONT
    finally:
        signal.signal(signum, handler)
    for hook in hooks:
        with suppress(Exception):
            hook.resume()


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
    for signum in STOPPING_SIGNALS:
        if signal.getsignal(signum) is signal.SIG_DFL:
            previous[signum] = signal.signal(signum, _stop_safely)
    try:
        yield flag
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
