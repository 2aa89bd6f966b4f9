"""Battery energy integration from measured or predicted power.

Power is piecewise constant between samples (zero-order hold): :meth:`EnergyTracker.advance` is called
before each new sample is stored, so a step in power is integrated exactly. Over an interval
[a, b] the sources are used in priority order:

1. ``measured`` -- battery-side power from joint_states, while fresh (age <= ``measured_timeout_s``);
2. ``predicted`` -- the model's battery-side power for the last cmd_vel, while fresh;
3. ``none`` -- neither is fresh: no drive power is drawn (the DES driver stops the motors when
   cmd_vel stops, so the drive train is assumed idle). Nothing is integrated.

An interval is split at the moment a source goes stale, so the result does not depend on how often
``advance`` is called.

Clock steps (issue 34 item 10). The node's clock is ROS time: sim time can be reset, an NTP step moves
the system clock. A step back by more than :data:`CLOCK_STEP_BACK_S` is a gap of zero length: the
held samples keep the freshness they had just before it (their times move with the clock), the
integration goes on from the new time, and the step is counted and shown (:meth:`EnergyTracker
.clock_diagnostics`, a WARN for :data:`CLOCK_STEP_SHOWN_S`). Before, nothing was integrated until
the clock caught up again (1.1 J counted against 215 J drawn in 4 s after a 500 s step back) while
the diagnostics still said "measured". A step forward needs nothing: a held sample is integrated
only while fresh (at most its timeout, 0.5 s by default), then the source is ``none``.

The energy tallies are exact at every call; the battery is stepped with the
mean power of everything integrated since the last :meth:`EnergyTracker.flush` (the node flushes
from its 5 Hz timer): stepping the battery model per message cost ~95 us, half the node's time per
message at 1 kHz, and over 0.2 s the mean power gives the same charge to within the battery's
I^2 R nonlinearity (its resistance loss is ~0.2 % of the power at 100 W). The battery itself
(capacity, voltage, state of charge) is
:class:`skidsteer_power.powertrain.Battery`; this module only decides which power it is stepped with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from skidsteer_power.seams import BatteryModel

SOURCES = ('measured', 'predicted', 'none')
CLOCK_STEP_BACK_S = 0.1
"""A clock going back by more than this between two calls is a clock step [s]; less is jitter (the
overlap is skipped, as for calls out of order)."""
CLOCK_STEP_SHOWN_S = 10.0
"""How long the diagnostics WARN after a clock step back [s, on the new clock]."""


@dataclass
class _Held:
    """The last sample of one power source: value [W], arrival time [s], timeout [s]."""

    timeout_s: float
    power_W: float = 0.0
    time_s: float | None = None

    def fresh_until(self) -> float:
        return -math.inf if self.time_s is None else self.time_s + self.timeout_s


@dataclass
class EnergyTracker:
    """Steps ``battery`` with the best available power; tallies energy per source [J].

    ``filter_s`` is the time constant [s] of the first-order filter on drawn power used for the time
    to empty (the track's power oscillates, 7.3.4).
    """

    battery: BatteryModel
    measured_timeout_s: float = 0.5
    predicted_timeout_s: float = 0.5
    filter_s: float = 5.0
    energy_J: dict[str, float] = field(default_factory=lambda: {'measured': 0.0, 'predicted': 0.0})
    filtered_power_W: float = 0.0
    _measured: _Held = field(init=False)
    _predicted: _Held = field(init=False)
    _time_s: float | None = field(default=None, init=False)
    _pending_J: float = field(default=0.0, init=False)
    _pending_s: float = field(default=0.0, init=False)
    clock_steps_back: int = field(default=0, init=False)
    """How many times the clock stepped back (:data:`CLOCK_STEP_BACK_S`)."""
    clock_step_back_s: float = field(default=0.0, init=False)
    """Size of the latest step back [s]."""
    _clock_step_at_s: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        self._measured = _Held(self.measured_timeout_s)
        self._predicted = _Held(self.predicted_timeout_s)

    def set_measured(self, power_W: float, now_s: float) -> None:
        """Store a measured battery-side power [W] arriving at ``now_s`` [s]."""
        self.advance(now_s)
        self._measured.power_W, self._measured.time_s = float(power_W), now_s

    def set_predicted(self, power_W: float, now_s: float, hold_s: float | None = None) -> None:
        """Store a predicted battery-side power [W] for a command arriving at ``now_s`` [s], held for
        ``hold_s`` [s] (None: ``predicted_timeout_s``)."""
        self.advance(now_s)
        self._predicted.power_W, self._predicted.time_s = float(power_W), now_s
        self._predicted.timeout_s = self.predicted_timeout_s if hold_s is None else float(hold_s)

    def source(self, now_s: float) -> str:
        """Which power the battery is being stepped with at ``now_s``: one of :data:`SOURCES`."""
        if now_s <= self._measured.fresh_until():
            return 'measured'
        if now_s <= self._predicted.fresh_until():
            return 'predicted'
        return 'none'

    def power_W(self, now_s: float) -> float:
        """Battery-side drive power in use at ``now_s`` [W] (0 with no fresh source)."""
        held = {'measured': self._measured, 'predicted': self._predicted}.get(self.source(now_s))
        return 0.0 if held is None else held.power_W

    def advance(self, now_s: float) -> None:
        """Integrate from the last call up to ``now_s`` [s], splitting where a source goes stale."""
        start = self._time_s
        if start is not None and now_s < start - CLOCK_STEP_BACK_S:
            self._clock_stepped_back(start, now_s)
            return
        if start is None or now_s <= start:
            self._time_s = now_s if start is None else max(start, now_s)
            return
        for name, held in (('measured', self._measured), ('predicted', self._predicted)):
            end = min(now_s, held.fresh_until())
            if end > start:
                self._integrate(name, held.power_W, end - start)
                start = end
        if now_s > start:
            self._filter(0.0, now_s - start)
        self._time_s = now_s

    def _clock_stepped_back(self, before_s: float, now_s: float) -> None:
        """The clock went from ``before_s`` back to ``now_s`` [s]: a gap of zero length."""
        shift = now_s - before_s
        for held in (self._measured, self._predicted):
            if held.time_s is not None:
                held.time_s += shift  # as fresh as just before the step
        self._time_s = now_s
        self.clock_steps_back += 1
        self.clock_step_back_s = -shift
        self._clock_step_at_s = now_s

    def clock_diagnostics(self, now_s: float) -> tuple[str, dict[str, str]]:
        """(problem, key/values) about clock steps: the problem is '' unless one came within
        :data:`CLOCK_STEP_SHOWN_S` before ``now_s``."""
        at = self._clock_step_at_s
        recent = at is not None and -CLOCK_STEP_BACK_S <= now_s - at <= CLOCK_STEP_SHOWN_S
        problem = (
            f'clock stepped back {self.clock_step_back_s:.3f} s: counted as a gap of zero length'
            if recent
            else ''
        )
        return problem, {
            'clock_steps_back': str(self.clock_steps_back),
            'clock_step_back_s': f'{self.clock_step_back_s:.3f}',
        }

    def _integrate(self, name: str, power_W: float, dt_s: float) -> None:
        self._pending_J += power_W * dt_s
        self._pending_s += dt_s
        self.energy_J[name] += power_W * dt_s
        self._filter(power_W, dt_s)

    def flush(self) -> None:
        """Step the battery with the mean power [W] integrated since the last flush."""
        if self._pending_s > 0.0:
            self.battery.step(self._pending_J / self._pending_s, self._pending_s)
        self._pending_J = self._pending_s = 0.0

    def _filter(self, power_W: float, dt_s: float) -> None:
        # exact first-order response to a held input over dt
        alpha = 1.0 - math.exp(-dt_s / self.filter_s) if self.filter_s > 0 else 1.0
        self.filtered_power_W += alpha * (power_W - self.filtered_power_W)

    def time_to_empty_s(self) -> float:
        """Time to empty at the filtered drive power [s] (inf when no power is drawn)."""
        self.flush()
        if self.filtered_power_W <= 1e-9:
            return math.inf
        return float(self.battery.time_to_empty_s(self.filtered_power_W))
