"""Polls one DES amplifier in a thread and applies the drive command (no ROS).

The ROS node (``skidsteer_power.nodes.des_driver``) only sets targets and reads
:class:`AmplifierSample`; all port I/O, the command watchdog, fault latching and reconnection live
here, away from the executor.
"""

from __future__ import annotations

import atexit
import builtins
import contextlib
import logging
import math
import threading
import time
import traceback
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

from skidsteer_power.des.client import DesAmplifier
from skidsteer_power.des.command import CheckedTwist, CommandLimits, DriveGeometry, SlewLimiter, limit_twist
from skidsteer_power.des.errors import DesLinkError, DesPortError
from skidsteer_power.des.kinematics import set_point_limit_rpm, unwrap_counter
from skidsteer_power.des.motor_model import default_motor
from skidsteer_power.des.protocol import DesConfig, DesErrorFlags, Status
from skidsteer_power.des.transport import DesLink, LinkTiming
from skidsteer_power.powertrain.motor import MotorConstants

FAULT_REPORT_HOLD_S = 10.0
"""A poller fault keeps its side's diagnostics at ERROR this long after the restart [s]."""
MAX_BACKOFF_S = 10.0
"""Longest wait before restarting a poller that keeps failing [s]."""
_log = logging.getLogger(__name__)
_T = TypeVar('_T')


class DriveCommand:
    """Per-side motor speed targets shared by the pollers: the one place that decides a set point.

    Targets come as a body twist (:meth:`set_twist`: checked, clamped and slew-limited by
    :mod:`~skidsteer_power.des.command`, converted by a :class:`DriveGeometry`) or directly as
    motor speeds (:meth:`set`, [rpm, amplifier sense]). :meth:`wanted_rpm` gives 0 unless every
    condition for motion holds: active (lifecycle), not shutting down, no amplifier fault latched on
    either side, a command younger than ``timeout_s`` [s], this side's link up, and with
    ``stop_both_on_link_loss`` the other side's link up too (a link is up after a good poll cycle and
    for ``stall_timeout_s`` [s] after the latest one, so a hung poller counts as a lost link). A set
    point is always a finite integer within +-``max_rpm``, itself at most :func:`set_point_limit_rpm`
    of ``motor`` (the vehicle's powertrain motor; default: the test robot's, read from its files,
    :func:`~skidsteer_power.des.motor_model.default_motor`). Every time is read from ``clock`` [s]
    (default time.monotonic; a test steps its own, like the estimator core's ``now_s``).
    """

    def __init__(
        self,
        timeout_s: float,
        *,
        max_rpm: float | None = None,
        motor: MotorConstants | None = None,
        geometry: DriveGeometry | None = None,
        limits: CommandLimits | None = None,
        stop_both_on_link_loss: bool = True,
        active: bool = True,
        sides: tuple[str, ...] = ('left', 'right'),
        stall_timeout_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.clock = clock
        self.timeout_s = timeout_s
        self.motor_limit_rpm = set_point_limit_rpm(motor or default_motor())
        self.max_rpm = self.motor_limit_rpm if max_rpm is None else min(max_rpm, self.motor_limit_rpm)
        self.geometry = geometry
        self.limits = limits or CommandLimits()
        self.stop_both_on_link_loss = stop_both_on_link_loss
        self._lock = threading.Lock()
        self._targets: dict[str, float] = {}
        self._twist: tuple[float, float] | None = None
        self._slew = SlewLimiter(self.limits)
        self._stamp = -math.inf
        self._halted_by: set[str] = set()
        self._down: dict[str, str] = dict.fromkeys(sides, 'not connected yet')  # up after a good cycle
        self._up_at: dict[str, float] = {}  # self.clock() of each side's last good cycle [s]
        self.stall_timeout_s = stall_timeout_s
        self._clear_requests: set[str] = set()
        self._active = active
        self._shutting_down = False
        self._paused = ''  # the signal that stopped the process (SIGTSTP ...), '' when running
        self._listeners: list[threading.Event] = []  # each poller's wake-up (see add_listener)
        self.generation = 0
        self.nonfinite_setpoints = 0

    # -- inputs ---------------------------------------------------------------------------------

    def set(self, targets: dict[str, float]) -> None:
        """Motor speed targets [rpm, amplifier sense] per side, fresh from now."""
        with self._lock:
            self._targets, self._twist = dict(targets), None
            self._stamp = self.clock()

    def set_twist(self, linear_m_s: float, yaw_rate_rad_s: float) -> CheckedTwist:
        """A body twist (V [m/s], w_z [rad/s]), fresh from now: InputError if non-finite, clamped
        to the limits otherwise (the result says whether it was)."""
        if self.geometry is None:
            raise RuntimeError('DriveCommand.set_twist needs a DriveGeometry')
        checked = limit_twist(linear_m_s, yaw_rate_rad_s, self.limits)
        with self._lock:
            self._twist = (checked.linear_m_s, checked.yaw_rate_rad_s)
            self._stamp = self.clock()
        return checked

    def forget(self) -> None:
        """Drop the held command: nothing moves until the next fresh one."""
        with self._lock:
            self._stamp = -math.inf
            self._twist, self._targets = None, {}
            self.generation += 1
        self._notify()

    # -- wake-ups: a stop never waits for the next poll (issue 34) --------------------------------

    def add_listener(self, event: threading.Event) -> None:
        """``event`` is set whenever a condition for motion may have failed (inactive, shutting
        down, paused, a fault, a link down, a clear request): a poller waiting between cycles wakes
        at once instead of at its next poll."""
        with self._lock:
            self._listeners.append(event)

    def _notify(self) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for event in listeners:
            event.set()

    def stale_at(self) -> float:
        """When the held command goes stale (the watchdog's zero) [s, ``clock``]; -inf without one."""
        with self._lock:
            return self._stamp + self.timeout_s

    def must_stop(self, side: str) -> bool:
        """Whether this side must hold zero now (every condition of :meth:`wanted_rpm` but the value)."""
        with self._lock:
            now = self.clock()
            return bool(self._stop_reason_locked(now)) or side in self._down_locked(now)

    @property
    def shutting_down(self) -> bool:
        return self._shutting_down

    @shutting_down.setter
    def shutting_down(self, value: bool) -> None:
        self._shutting_down = bool(value)
        self._notify()

    def pause(self, reason: str) -> None:
        """The process is about to stop (SIGTSTP, SIGTTIN, SIGTTOU): zero, disable, forget the command."""
        with self._lock:
            self._paused = reason or 'paused'
            self._stamp, self._twist, self._targets = -math.inf, None, {}
            self.generation += 1
        self._notify()

    def resume(self) -> None:
        """The process continued (SIGCONT): power stages on again, motion only on a fresh command."""
        with self._lock:
            self._paused = ''
            self._stamp, self._twist, self._targets = -math.inf, None, {}
            self.generation += 1
        self._notify()

    @property
    def active(self) -> bool:
        return self._active

    @active.setter
    def active(self, value: bool) -> None:
        """Lifecycle state: inactive means zero speed and the power stages disabled."""
        with self._lock:
            self._active = bool(value)
            self._stamp, self._twist, self._targets = -math.inf, None, {}
            self.generation += 1
        self._notify()

    @property
    def enable_wanted(self) -> bool:
        """Whether the power stages should be enabled (active and not shutting down)."""
        return self._active and not self._shutting_down and not self._paused

    # -- the set point --------------------------------------------------------------------------

    def wanted_rpm(self, side: str) -> int:
        """The set point to send now [rpm, amplifier sense]; 0 whenever a condition for motion fails."""
        with self._lock:
            now = self.clock()
            if self._stop_reason_locked(now):
                self._slew.reset(now)
                return 0
            if side in self._down_locked(now):
                return 0
            if self._twist is not None:
                assert self.geometry is not None
                rpm = self.geometry.motor_rpm(*self._slew.step(*self._twist, now))[side]
            else:
                rpm = self._targets.get(side, 0.0)
            if not math.isfinite(rpm):
                self.nonfinite_setpoints += 1
                return 0
            return round(max(-self.max_rpm, min(self.max_rpm, rpm)))

    def stop_reason(self) -> str:
        """Why both sides hold zero speed now ('' when a command may drive them)."""
        with self._lock:
            return self._stop_reason_locked(self.clock())

    def _stop_reason_locked(self, now: float) -> str:
        if self._shutting_down:
            return 'shutting down'
        if self._paused:
            return f'process stopped by {self._paused}'
        if not self._active:
            return 'inactive'
        if self._halted_by:
            return f'amplifier fault on {", ".join(sorted(self._halted_by))}'
        down = self._down_locked(now)
        if self.stop_both_on_link_loss and down:
            return f'link down: {", ".join(f"{s} ({r})" for s, r in sorted(down.items()))}'
        if now - self._stamp > self.timeout_s:
            return 'no fresh command'
        return ''

    def timed_out(self) -> bool:
        with self._lock:
            return self.clock() - self._stamp > self.timeout_s

    # -- faults and links -----------------------------------------------------------------------

    def halt(self, side: str) -> None:
        with self._lock:
            self._halted_by.add(side)
        self._notify()

    @property
    def halted_by(self) -> builtins.set[str]:  # in the class body `set` is the method above
        with self._lock:
            return set(self._halted_by)

    def link_down(self, side: str, reason: str) -> None:
        """This side cannot be commanded now (port lost, not answering, poller fault)."""
        with self._lock:
            self._down[side] = reason
        self._notify()

    def link_up(self, side: str) -> None:
        """A good cycle on this side (a heartbeat: without one for ``stall_timeout_s`` the side
        counts as down, so a hung poller stops the other side too)."""
        with self._lock:
            self._down.pop(side, None)
            self._up_at[side] = self.clock()

    @property
    def links_down(self) -> dict[str, str]:
        with self._lock:
            return self._down_locked(self.clock())

    def _down_locked(self, now: float) -> dict[str, str]:
        down = dict(self._down)
        for side, at in self._up_at.items():
            if side not in down and now - at > self.stall_timeout_s:
                down[side] = f'poller stalled for {now - at:.1f} s'
        return down

    def request_clear(self, sides: list[str]) -> None:
        """Ask each side's poller to clear its amplifier errors and re-enable."""
        with self._lock:
            self._clear_requests.update(sides)
            self.generation += 1
        self._notify()

    def withdraw_clear_requests(self) -> None:
        """Forget clear requests no poller took (a side that was unreachable must not clear later)."""
        with self._lock:
            self._clear_requests.clear()

    def has_clear_request(self, side: str) -> bool:
        with self._lock:
            return side in self._clear_requests

    def take_clear_request(self, side: str) -> bool:
        with self._lock:
            if side in self._clear_requests:
                self._clear_requests.discard(side)
                return True
            return False

    def cleared(self, side: str) -> None:
        with self._lock:
            self._halted_by.discard(side)


@dataclass
class AmplifierSample:
    """Latest readings of one amplifier, amplifier sense (no polarity applied)."""

    stamp: float = 0.0  # the poller's clock() at the reading [s]
    sequence: int = 0
    connected: bool = False
    enabled: bool = False  # the power stage as last commanded by this poller
    velocity_rpm: int = 0  # mean actual speed [rpm]
    setpoint_rpm: int = 0  # set point the amplifier holds [rpm]
    current_ma: int = 0  # mean q-axis current [mA]
    position_counts: int = 0  # unwrapped encoder counter [quadrature counts]
    status: Status = field(default_factory=lambda: Status(0))
    errors: DesErrorFlags = field(default_factory=lambda: DesErrorFlags(0))
    fault_latched: bool = False
    message: str = 'not connected yet'
    poll_rate_hz: float = 0.0
    poller_faults: int = 0  # exceptions caught in the poller thread (each: zero, disable, restart)
    last_poller_fault: str = ''
    poller_fault_at: float = -math.inf  # the poller's clock() at the last poller fault [s]
    link: dict[str, int | str] = field(default_factory=dict)

    def poller_fault_recent(self, now: float) -> bool:
        """A poller fault within :data:`FAULT_REPORT_HOLD_S` seconds before ``now`` (the poller's
        ``clock()``, the clock that stamped it) [s]."""
        return now - self.poller_fault_at < FAULT_REPORT_HOLD_S


_LIVE_POLLERS: weakref.WeakSet[AmplifierPoller] = weakref.WeakSet()


@atexit.register
def _stop_live_pollers() -> None:
    """Last line of defence at interpreter exit: zero and disable every amplifier still polled."""
    for poller in list(_LIVE_POLLERS):
        poller.stop()


class AmplifierPoller:
    """Thread that keeps one amplifier polled, commanded and connected.

    Each cycle: enable or disable the power stage as :class:`DriveCommand` wants (zero speed first),
    send the wanted speed if it changed (or the amplifier holds another), read mean velocity, mean
    current and the encoder counter, and every ``status_every`` cycles the status word (and the error
    word if the status says so). An amplifier error halts both sides through :class:`DriveCommand`;
    a failed cycle marks the side's link down (the other side stops too, by default); a lost port,
    or ``max_failed_cycles`` failed cycles in a row (a silent amplifier), closes the link, which is
    then reopened every ``reconnect_period_s``. Any other exception in the thread (a bug) zeroes and
    disables the amplifier, closes the link, is reported in the sample (and logged with its
    traceback through ``log_error``) and the polling restarts after a back-off that doubles up to
    :data:`MAX_BACKOFF_S`. On :meth:`stop` the motor gets zero velocity, then is disabled; a stop that
    could not be confirmed (the port gone, an exchange failing) is kept in :attr:`unsafe_stop`.

    A stop never waits for the next poll (issue 34): between cycles the thread wakes on every stop
    condition (:meth:`DriveCommand.add_listener`) and when the held command goes stale; within a cycle
    it sends zero before a read exchange when the command says stop or would go stale before the read
    could end (the longest recent read's time), and a read's retries end when a stop is due
    (``DesLink.abort``). An amplifier found with its power stage off while it should be on and its
    set point not ours (it reset itself) halts both sides and latches until a clear request.
    ``encoder_resolution``: encoder lines per motor turn [-] (default: the test robot's motor's).
    """

    def __init__(
        self,
        side: str,
        port: str,
        command: DriveCommand,
        *,
        config: DesConfig,
        timing: LinkTiming | None = None,
        poll_period_s: float = 0.02,
        status_every: int = 5,
        reconnect_period_s: float = 0.5,
        encoder_resolution: int | None = None,
        max_failed_cycles: int = 5,
        log_error: Callable[[str], None] | None = None,
    ) -> None:
        self.clock = command.clock  # stamps and fault times; the thread's own waits are real time
        self.side = side
        self.encoder_resolution = encoder_resolution or default_motor().encoder_counts_per_turn
        self.max_failed_cycles = max_failed_cycles
        self._failed_cycles = 0
        self.command = command
        self.amp = DesAmplifier(DesLink(port, config, timing or LinkTiming()))
        self.poll_period_s = poll_period_s
        self.status_every = max(1, status_every)
        self.reconnect_period_s = reconnect_period_s
        self.log_error = log_error or _log.error
        self._lock = threading.Lock()
        self._applied = threading.Condition()
        self._applied_generation = -1
        self._sample = AmplifierSample()
        self.unsafe_stop = ''  # why the stop could not be confirmed ('' when it was)
        self.self_resets = 0  # times the amplifier reset itself (power stage off unasked)
        self._possibly_enabled = False  # an enable was sent and no disable acknowledged since
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_sent: int | None = None
        self._enabled: bool | None = None
        self._cycle = 0
        self._counter: int | None = None
        self._counter_time = 0.0
        self._rate_window: list[float] = []
        self._backoff_s = reconnect_period_s
        self._wake = threading.Event()
        self._read_s = 0.0  # longest recent read exchange [s, real time]: how far ahead to zero
        command.add_listener(self._wake)
        self.amp.link.abort = self._stop_due  # a stop ends an exchange's retries (transport)
        command.link_down(side, 'not connected yet')

    @property
    def sample(self) -> AmplifierSample:
        """A copy of the latest sample."""
        with self._lock:
            return AmplifierSample(**{**self._sample.__dict__, 'link': dict(self._sample.link)})

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> AmplifierPoller:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f'des-{self.side}', daemon=True)
        _LIVE_POLLERS.add(self)
        self._thread.start()
        return self

    def request_stop(self) -> None:
        """Ask the thread to finish (zero velocity, disable, close) without waiting."""
        self._stop.set()
        self._wake.set()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop polling: zero velocity, then disable, then close the port."""
        self._stop.set()
        self._wake.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            if thread.is_alive():
                self.unsafe_stop = f'{self.side} poller busy after {timeout_s:g} s: motor may be enabled'
        _LIVE_POLLERS.discard(self)

    def wait_applied(self, generation: int, timeout_s: float) -> bool:
        """Wait until a cycle that began at ``command.generation >= generation`` completed (True), or
        the side is not connected or the time is up (False)."""
        with self._applied:
            return (
                self._applied.wait_for(
                    lambda: self._applied_generation >= generation or not self._sample.connected, timeout_s
                )
                and self._applied_generation >= generation
            )

    # -- thread ---------------------------------------------------------------------------------

    def _run(self) -> None:
        next_cycle = time.monotonic()
        while not self._stop.is_set():
            wait_s = self.poll_once()
            if wait_s is not None:
                self._stop.wait(wait_s)
                continue
            next_cycle = max(next_cycle + self.poll_period_s, time.monotonic())
            self._idle_until(next_cycle)
        self._shutdown()

    def _idle_until(self, deadline: float) -> None:
        """Wait for the next cycle, but wake at once when this side must stop (a fault, a transition,
        a signal, a clear request) and when the held command goes stale: the watchdog's zero never
        waits for a poll (issue 34: at 1 Hz polling it took 1.37 s)."""
        while not self._stop.is_set():
            self._wake.clear()
            if self._stop_due() or self._enable_due() or self.command.has_clear_request(self.side):
                return
            left = deadline - time.monotonic()
            if self._last_sent not in (None, 0):
                left = min(left, self.command.stale_at() - self.clock())
            if left <= 0:
                return
            self._wake.wait(left)

    def _stop_due(self) -> bool:
        """A non-zero set point is held where the command says zero (or the thread is stopping)."""
        if self._stop.is_set():
            return True
        return self._last_sent not in (None, 0) and self.command.must_stop(self.side)

    def _enable_due(self) -> bool:
        """The power stage is not as the command wants it (a transition, a pause, a resume)."""
        return self._enabled is (not self.command.enable_wanted)

    def _zero_now_if_due(self) -> None:
        """Before a read exchange: send zero first when the command says stop, or when it goes stale
        before the read could end (a slow link: one exchange of four turn-arounds took 64 ms at the
        FTDI default 16 ms latency; issue 34 item 3)."""
        if self._last_sent in (None, 0):
            return
        if not self.command.must_stop(self.side):
            left = self.command.stale_at() - self.clock()
            if left > self._read_s:
                return
            self._wake.clear()
            self._wake.wait(max(0.0, left))  # one wait: a stepped clock (tests) does not move here
            if not self.command.must_stop(self.side):
                return
        self.amp.set_velocity(0)
        self._last_sent = 0

    def _timed_read(self, read: Callable[[], _T]) -> _T:
        self._zero_now_if_due()
        start = time.monotonic()
        value = read()
        took = time.monotonic() - start
        self._read_s = max(took, 0.9 * self._read_s)  # the longest recent one, decaying
        return value

    def poll_once(self) -> float | None:
        """One turn of the thread: (re)connect if needed and run one cycle, every failure handled.

        Returns None after a cycle (the next is due one poll period after this one began), else how
        long to wait before the next turn [s] (reconnect period, a poller fault's back-off, 0).
        """
        try:
            if not self.amp.link.is_open and not self._connect():
                return self.reconnect_period_s
            self._cycle_once()
            self._failed_cycles = 0
        except DesPortError as err:
            self._lost(err)
            return 0.0
        except DesLinkError as err:
            self._failed_cycles += 1
            self.command.link_down(self.side, f'link error: {err}')
            if self._failed_cycles >= self.max_failed_cycles:
                self.amp.close()
                self._update(connected=False, message=f'amplifier not answering, reconnecting: {err}')
                return 0.0
            self._update(message=f'link error: {err}')
        except Exception as err:  # a bug here must never leave the motor turning
            return self._fault(err)
        return None

    def _fault(self, err: Exception) -> float:
        """An unexpected exception: zero, disable, close, report; the back-off before polling again [s]."""
        self.command.link_down(self.side, f'poller fault: {type(err).__name__}')
        with contextlib.suppress(Exception):
            self._zero_and_disable()
        with contextlib.suppress(Exception):
            self.amp.close()
        now = self.clock()
        if now - self._sample.poller_fault_at > 3.0 * MAX_BACKOFF_S:
            self._backoff_s = self.reconnect_period_s
        backoff, self._backoff_s = self._backoff_s, min(MAX_BACKOFF_S, 2.0 * self._backoff_s)
        text = f'{type(err).__name__}: {err}'
        with contextlib.suppress(Exception):
            self.log_error(
                f'DES {self.side} poller fault, motor zeroed and disabled, restarting in {backoff:g} s: '
                f'{text}\n{traceback.format_exc()}'
            )
        with contextlib.suppress(Exception):
            self._update(
                connected=False,
                poller_faults=self._sample.poller_faults + 1,
                last_poller_fault=text,
                poller_fault_at=now,
                message=f'poller fault (motor zeroed, disabled; restart in {backoff:g} s): {text}',
            )
        return backoff

    def _zero_and_disable(self) -> None:
        if self.amp.link.is_open:
            try:
                self.amp.set_velocity(0)
            finally:
                self._last_sent = None
                self.amp.disable()
                self._enabled = False
                self._possibly_enabled = False

    def _connect(self) -> bool:
        self._last_sent, self._enabled, self._counter = None, None, None
        try:
            self.amp.link.open()
            self.amp.set_velocity(0)
            self._last_sent = 0
            self._check_errors(force=True)
        except DesPortError as err:
            self._lost(err)
            return False
        except DesLinkError as err:
            self.amp.close()
            self._update(connected=False, message=f'port open but amplifier not answering: {err}')
            return False
        self._update(connected=True, message='ok')
        return True

    def _lost(self, err: Exception) -> None:
        self.command.link_down(self.side, 'port lost')
        self.amp.close()
        what = 'port lost' if self._sample.sequence else 'no port'
        self._update(connected=False, message=f'{what}, retrying every {self.reconnect_period_s:g} s: {err}')

    def _cycle_once(self) -> None:
        amp, command = self.amp, self.command
        generation = command.generation
        if command.take_clear_request(self.side):
            amp.clear_errors()
            self._update(fault_latched=False, errors=DesErrorFlags(0))
            self._check_errors(force=True)
            if not self._sample.fault_latched:
                command.cleared(self.side)
        enable = command.enable_wanted and not self._sample.fault_latched
        if not enable and self._enabled is not False:
            self._zero_and_disable()
            self._last_sent = 0
        wanted = command.wanted_rpm(self.side) if enable else 0
        if wanted != self._last_sent:
            amp.set_velocity(wanted)
            self._last_sent = wanted
        if enable and self._enabled is not True:
            self._possibly_enabled = True  # from the moment it is sent, until a disable is acknowledged
            amp.enable()
            self._enabled = True
        velocity = self._timed_read(amp.read_velocity)
        if velocity.setpoint_rpm != self._last_sent:
            self._last_sent = None  # the amplifier lost our set point (reset, stop toggle): resend
            if self._enabled and Status.ENABLED not in self._timed_read(amp.read_status):
                self._self_reset()
        current = self._timed_read(amp.read_current)
        counter = self._timed_read(amp.read_encoder_counter)
        now = self.clock()
        position = self._unwrap(counter, velocity.actual_rpm, now)
        self._cycle += 1
        if self._cycle % self.status_every == 1 or self.status_every == 1:
            self._check_errors()
        self._rate_window = [t for t in self._rate_window if now - t < 1.0] + [now]
        command.link_up(self.side)
        self._update(
            stamp=now,
            sequence=self._sample.sequence + 1,
            connected=True,
            enabled=bool(self._enabled),
            velocity_rpm=velocity.actual_rpm,
            setpoint_rpm=velocity.setpoint_rpm,
            current_ma=current,
            position_counts=position,
            poll_rate_hz=len(self._rate_window) / 1.0,
            # a latched fault keeps the message that says why (an error word, a self-reset) until cleared
            message=self._sample.message if self._sample.fault_latched else 'ok',
        )
        with self._applied:
            self._applied_generation = generation
            self._applied.notify_all()

    def _unwrap(self, counter: int, rpm: int, now: float) -> int:
        if self._counter is None:
            self._counter, self._counter_time = counter, now
            return self._sample.position_counts
        counts_per_rev = self.amp.config.quadrature_counts_per_count * self.encoder_resolution
        expected = rpm / 60.0 * counts_per_rev * (now - self._counter_time)
        delta = unwrap_counter(self._counter, counter, expected)
        self._counter, self._counter_time = counter, now
        return self._sample.position_counts + delta

    def _self_reset(self) -> None:
        """The amplifier switched its power stage off and dropped our set point by itself (a reset,
        a brown-out): stop both sides and latch it until ~/clear_faults (issue 34 item 7)."""
        # latched in the sample first: the other side zeroes within one exchange of the halt, before
        # this side's own zero and disable are through (a reader saw the stop but not the latch)
        self._update(
            fault_latched=True,
            message='amplifier reset itself (power stage off, set point 0): both sides stopped, '
            'clear_faults to re-enable',
        )
        self.command.halt(self.side)
        self.self_resets += 1
        self._zero_and_disable()
        self._last_sent = 0

    def _check_errors(self, force: bool = False) -> None:
        status = self._timed_read(self.amp.read_status)
        if self._enabled and Status.ENABLED not in status and not self._sample.fault_latched:
            self._self_reset()
        errors = self.amp.read_errors() if (force or Status.ERROR in status) else DesErrorFlags(0)
        self._update(status=status, errors=errors)
        if errors and not self._sample.fault_latched:
            self.command.halt(self.side)
            self._zero_and_disable()
            self._last_sent = 0
            self._update(fault_latched=True, message=f'amplifier error: {errors.describe()}')

    def _shutdown(self) -> None:
        self.command.link_down(self.side, 'stopped')
        if self.amp.link.is_open:
            self.amp.link.abort = None  # the stop itself is never cut short
            problems = []
            steps: tuple[tuple[str, Callable[[], None]], ...] = (
                ('zero', lambda: self.amp.set_velocity(0)),
                ('disable', self.amp.disable),
            )
            for what, step in steps:
                try:
                    step()
                except Exception as err:
                    problems.append(f'{what}: {type(err).__name__}: {err}')
            if not problems:
                self._possibly_enabled = False
            elif self._possibly_enabled:
                self.unsafe_stop = f'{self.side} amplifier not confirmed stopped ({"; ".join(problems)})'
        elif self._possibly_enabled:
            self.unsafe_stop = f'{self.side} amplifier unreachable at the stop: it may still be enabled'
        self.amp.close()
        self._enabled = False
        self._update(connected=False, enabled=False, message='stopped')
        with self._applied:
            self._applied.notify_all()

    def _update(self, **values: object) -> None:
        with self._lock:
            for key, value in values.items():
                setattr(self._sample, key, value)
            self._sample.link = self.amp.link.stats.as_dict()
        if 'connected' in values and not values['connected']:
            with self._applied:
                self._applied.notify_all()
