"""Polls one DES amplifier in a thread and applies the drive command (no ROS).

The ROS node (``skidsteer_power.nodes.des_driver``) only sets targets and reads
:class:`AmplifierSample`; all port I/O, the command watchdog, fault latching and reconnection live
here, away from the executor.
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass, field

from skidsteer_power.des.client import DesAmplifier
from skidsteer_power.des.errors import DesLinkError, DesPortError
from skidsteer_power.des.kinematics import unwrap_counter
from skidsteer_power.des.protocol import DesConfig, DesErrorFlags, Status
from skidsteer_power.des.transport import DesLink, LinkTiming


class DriveCommand:
    """Per-side motor speed targets shared by the pollers, with the watchdog and the halt latch.

    ``set`` stores targets [rpm, amplifier sense] with the time they were given; a target older than
    ``timeout_s`` [s] reads as 0. Any side's fault halts both sides until every fault is cleared.
    """

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self._lock = threading.Lock()
        self._targets: dict[str, float] = {}
        self._stamp = -float('inf')
        self._halted_by: set[str] = set()
        self._clear_requests: set[str] = set()
        self.shutting_down = False

    def set(self, targets: dict[str, float]) -> None:
        with self._lock:
            self._targets = dict(targets)
            self._stamp = time.monotonic()

    def wanted_rpm(self, side: str) -> int:
        """The set point to send now [rpm]: 0 when stale, halted or shutting down."""
        with self._lock:
            if self.shutting_down or self._halted_by or self.timed_out_locked():
                return 0
            return round(self._targets.get(side, 0.0))

    def timed_out(self) -> bool:
        with self._lock:
            return self.timed_out_locked()

    def timed_out_locked(self) -> bool:
        return time.monotonic() - self._stamp > self.timeout_s

    def halt(self, side: str) -> None:
        with self._lock:
            self._halted_by.add(side)

    @property
    def halted_by(self) -> set[str]:
        with self._lock:
            return set(self._halted_by)

    def request_clear(self, sides: list[str]) -> None:
        """Ask each side's poller to clear its amplifier errors and re-enable."""
        with self._lock:
            self._clear_requests.update(sides)

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

    stamp: float = 0.0  # time.monotonic() of the reading [s]
    sequence: int = 0
    connected: bool = False
    velocity_rpm: int = 0  # mean actual speed [rpm]
    setpoint_rpm: int = 0  # set point the amplifier holds [rpm]
    current_ma: int = 0  # mean q-axis current [mA]
    position_counts: int = 0  # unwrapped encoder counter [quadrature counts]
    status: Status = field(default_factory=lambda: Status(0))
    errors: DesErrorFlags = field(default_factory=lambda: DesErrorFlags(0))
    fault_latched: bool = False
    message: str = 'not connected yet'
    poll_rate_hz: float = 0.0
    link: dict[str, int | str] = field(default_factory=dict)


class AmplifierPoller:
    """Thread that keeps one amplifier polled, commanded and connected.

    Each cycle: send the wanted speed if it changed (or the amplifier holds another), read mean
    velocity, mean current and the encoder counter, and every ``status_every`` cycles the status
    word (and the error word if the status says so). An amplifier error halts both sides through
    :class:`DriveCommand`; a lost port, or ``max_failed_cycles`` failed cycles in a row (a silent
    amplifier), closes the link, which is then reopened every ``reconnect_period_s``. On :meth:`stop`
    the motor gets zero velocity, then is disabled.
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
        encoder_resolution: int = 2048,
        max_failed_cycles: int = 5,
    ) -> None:
        self.side = side
        self.encoder_resolution = encoder_resolution
        self.max_failed_cycles = max_failed_cycles
        self._failed_cycles = 0
        self.command = command
        self.amp = DesAmplifier(DesLink(port, config, timing or LinkTiming()))
        self.poll_period_s = poll_period_s
        self.status_every = max(1, status_every)
        self.reconnect_period_s = reconnect_period_s
        self._lock = threading.Lock()
        self._sample = AmplifierSample()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_sent: int | None = None
        self._cycle = 0
        self._counter: int | None = None
        self._counter_time = 0.0
        self._rate_window: list[float] = []

    @property
    def sample(self) -> AmplifierSample:
        """A copy of the latest sample."""
        with self._lock:
            return AmplifierSample(**{**self._sample.__dict__, 'link': dict(self._sample.link)})

    def start(self) -> AmplifierPoller:
        self._thread = threading.Thread(target=self._run, name=f'des-{self.side}', daemon=True)
        self._thread.start()
        return self

    def request_stop(self) -> None:
        """Ask the thread to finish (zero velocity, disable, close) without waiting."""
        self._stop.set()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop polling: zero velocity, then disable, then close the port."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    # -- thread ---------------------------------------------------------------------------------

    def _run(self) -> None:
        next_cycle = time.monotonic()
        while not self._stop.is_set():
            if not self.amp.link.is_open and not self._connect():
                self._stop.wait(self.reconnect_period_s)
                continue
            try:
                self._cycle_once()
                self._failed_cycles = 0
            except DesPortError as err:
                self._lost(err)
                continue
            except DesLinkError as err:
                self._failed_cycles += 1
                if self._failed_cycles >= self.max_failed_cycles:
                    self.amp.close()
                    self._update(connected=False, message=f'amplifier not answering, reconnecting: {err}')
                    continue
                self._update(message=f'link error: {err}')
            next_cycle = max(next_cycle + self.poll_period_s, time.monotonic())
            self._stop.wait(max(0.0, next_cycle - time.monotonic()))
        self._shutdown()

    def _connect(self) -> bool:
        try:
            self.amp.link.open()
            self.amp.set_velocity(0)
            self._last_sent = 0
            self._counter = None
            self._check_errors(force=True)
            if not self._sample.fault_latched:
                self.amp.enable()
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
        self.amp.close()
        self._update(
            connected=False, message=f'port lost, reopening every {self.reconnect_period_s:g} s: {err}'
        )

    def _cycle_once(self) -> None:
        amp, command = self.amp, self.command
        if command.take_clear_request(self.side):
            amp.clear_errors()
            self._update(fault_latched=False, errors=DesErrorFlags(0))
            self._check_errors(force=True)
            if not self._sample.fault_latched:
                command.cleared(self.side)
                amp.enable()
        wanted = command.wanted_rpm(self.side)
        if wanted != self._last_sent:
            amp.set_velocity(wanted)
            self._last_sent = wanted
        velocity = amp.read_velocity()
        if velocity.setpoint_rpm != wanted:
            self._last_sent = None  # the amplifier lost our set point (reset, stop toggle): resend
        current = amp.read_current()
        counter = amp.read_encoder_counter()
        now = time.monotonic()
        position = self._unwrap(counter, velocity.actual_rpm, now)
        self._cycle += 1
        if self._cycle % self.status_every == 1 or self.status_every == 1:
            self._check_errors()
        self._rate_window = [t for t in self._rate_window if now - t < 1.0] + [now]
        self._update(
            stamp=now,
            sequence=self._sample.sequence + 1,
            connected=True,
            velocity_rpm=velocity.actual_rpm,
            setpoint_rpm=velocity.setpoint_rpm,
            current_ma=current,
            position_counts=position,
            poll_rate_hz=len(self._rate_window) / 1.0,
            message='fault latched: motors stopped' if self._sample.fault_latched else 'ok',
        )

    def _unwrap(self, counter: int, rpm: int, now: float) -> int:
        if self._counter is None:
            self._counter, self._counter_time = counter, now
            return self._sample.position_counts
        counts_per_rev = self.amp.config.quadrature_counts_per_count * self.encoder_resolution
        expected = rpm / 60.0 * counts_per_rev * (now - self._counter_time)
        delta = unwrap_counter(self._counter, counter, expected)
        self._counter, self._counter_time = counter, now
        return self._sample.position_counts + delta

    def _check_errors(self, force: bool = False) -> None:
        status = self.amp.read_status()
        errors = self.amp.read_errors() if (force or Status.ERROR in status) else DesErrorFlags(0)
        self._update(status=status, errors=errors)
        if errors and not self._sample.fault_latched:
            self.command.halt(self.side)
            self.amp.set_velocity(0)
            self._last_sent = 0
            self.amp.disable()
            self._update(fault_latched=True, message=f'amplifier error: {errors.describe()}')

    def _shutdown(self) -> None:
        if self.amp.link.is_open:
            with contextlib.suppress(DesLinkError):
                self.amp.set_velocity(0)
            with contextlib.suppress(DesLinkError):
                self.amp.disable()
        self.amp.close()
        self._update(connected=False, message='stopped')

    def _update(self, **values: object) -> None:
        with self._lock:
            for key, value in values.items():
                setattr(self._sample, key, value)
            self._sample.link = self.amp.link.stats.as_dict()
