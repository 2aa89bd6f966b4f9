"""Input checks for the estimator: finite, physically plausible values only; staleness.

A rejected input raises :class:`~skidsteer_power.errors.InputError` with one clear reason; the caller
counts it (:class:`RejectCounter`) and warns at a throttled rate. Nothing is clipped silently.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

from skidsteer_power.errors import InputError

JOINT_NAMES = ('left_motor', 'right_motor')


@dataclass(frozen=True)
class InputLimits:
    """Largest magnitudes accepted as physical; beyond them an input is 'absurd' and rejected.

    Attributes
    ----------
    max_speed_m_s : forward speed command |V| [m/s]
    max_yaw_rate_rad_s : yaw-rate command |r| [rad/s]
    max_motor_speed_rad_s : motor shaft speed |omega| [rad/s] (EC-45: 10,000 rpm = 1047 rad/s, 7.1.2)
    max_motor_torque_Nm : motor torque Kt * I [N m] (DES 70/10: 10 A peak class, 7.1.2; with margin)
    """

    max_speed_m_s: float = 5.0
    max_yaw_rate_rad_s: float = 10.0
    max_motor_speed_rad_s: float = 1200.0
    max_motor_torque_Nm: float = 5.0

    def __post_init__(self) -> None:
        for name in ('max_speed_m_s', 'max_yaw_rate_rad_s', 'max_motor_speed_rad_s', 'max_motor_torque_Nm'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f'{name} must be a finite number > 0, got {value!r}')


def _finite_within(name: str, value: float, limit: float, unit: str) -> float:
    value = float(value)
    if math.isnan(value):
        raise InputError(f'{name} is NaN')
    if math.isinf(value):
        raise InputError(f'{name} is infinite')
    if abs(value) > limit:
        raise InputError(f'{name} = {value:g} {unit} exceeds the plausible limit {limit:g} {unit}')
    return value


def check_command(speed: float, yaw_rate: float, limits: InputLimits) -> tuple[float, float]:
    """Return (V [m/s], yaw rate [rad/s]) if both are finite and plausible; else raise InputError."""
    return (
        _finite_within('cmd_vel linear.x', speed, limits.max_speed_m_s, 'm/s'),
        _finite_within('cmd_vel angular.z', yaw_rate, limits.max_yaw_rate_rad_s, 'rad/s'),
    )


def check_joint_state(
    names: Sequence[str], velocity: Sequence[float], effort: Sequence[float], limits: InputLimits
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Pick left/right motor shaft speed [rad/s] and torque Kt*I [N m] out of a joint_states message.

    Returns ((omega_left, omega_right), (torque_left, torque_right)). Raises InputError when a motor
    is missing, arrays are short, or a value is NaN, infinite or beyond ``limits``.
    """
    index = {name: i for i, name in enumerate(names)}
    missing = [n for n in JOINT_NAMES if n not in index]
    if missing:
        raise InputError(f'joint_states lacks {", ".join(missing)}')
    omegas, torques = [], []
    for name in JOINT_NAMES:
        i = index[name]
        if i >= len(velocity) or i >= len(effort):
            raise InputError(f'joint_states has no velocity/effort for {name}')
        omegas.append(_finite_within(f'{name} velocity', velocity[i], limits.max_motor_speed_rad_s, 'rad/s'))
        torques.append(_finite_within(f'{name} effort', effort[i], limits.max_motor_torque_Nm, 'N m'))
    return (omegas[0], omegas[1]), (torques[0], torques[1])


@dataclass
class RejectCounter:
    """Counts rejected inputs per topic and decides when a warning may be logged again.

    ``period_s`` is the least time between two warnings for the same topic [s].
    """

    period_s: float = 2.0
    counts: Counter = field(default_factory=Counter)
    _last_warned: dict[str, float] = field(default_factory=dict)

    def reject(self, topic: str, now_s: float) -> bool:
        """Count one rejection on ``topic`` at time ``now_s`` [s]; True if a warning should be logged."""
        self.counts[topic] += 1
        last = self._last_warned.get(topic)
        if last is None or now_s - last >= self.period_s:
            self._last_warned[topic] = now_s
            return True
        return False


@dataclass
class Freshness:
    """Tracks when an input last arrived; stale after ``timeout_s`` [s] without one."""

    timeout_s: float
    last_s: float | None = None

    def mark(self, now_s: float) -> None:
        self.last_s = now_s

    def age_s(self, now_s: float) -> float:
        """Seconds since the last input (inf if none ever arrived)."""
        return math.inf if self.last_s is None else max(0.0, now_s - self.last_s)

    def is_fresh(self, now_s: float) -> bool:
        return self.age_s(now_s) <= self.timeout_s
