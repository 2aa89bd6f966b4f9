"""The one "hold a command for a while" type: forward speed V and yaw rate held for a duration.

Routes (missions), synthetic drive bags, the energy monitor's case mode and trace analysis all
describe a drive as a sequence of :class:`Segment`. Sign convention (REP 103): yaw rate > 0 turns
left; the signed turning radius is R = V / yaw rate (inf straight, 0 spinning in place).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from skidsteer_power.errors import InputError


@dataclass(frozen=True)
class Segment:
    """Hold forward speed ``speed_m_s`` [m/s] and yaw rate ``yaw_rate_rad_s`` [rad/s] for
    ``duration_s`` [s], carrying ``payload_kg`` [kg]. Raises InputError for non-finite values,
    a duration <= 0 s or a negative payload."""

    speed_m_s: float
    yaw_rate_rad_s: float
    duration_s: float
    payload_kg: float = 0.0

    def __post_init__(self) -> None:
        values = (self.speed_m_s, self.yaw_rate_rad_s, self.duration_s, self.payload_kg)
        if not all(math.isfinite(v) for v in values):
            raise InputError(f'segment values must be finite numbers, got {values}')
        if self.duration_s <= 0:
            raise InputError(f'segment duration must be > 0 s, got {self.duration_s:g}')
        if self.payload_kg < 0:
            raise InputError(f'payload must be >= 0 kg, got {self.payload_kg:g}')

    @classmethod
    def along(
        cls,
        speed_m_s: float,
        turn_radius_m: float = math.inf,
        *,
        length_m: float | None = None,
        duration_s: float | None = None,
        payload_kg: float = 0.0,
    ) -> Segment:
        """A path piece: speed V > 0 [m/s] on a signed turning radius R [m] (+ left, - right, inf
        straight, |R| > 0) for ``length_m`` [m] or ``duration_s`` [s] (exactly one)."""
        if length_m is not None and duration_s is None:
            given = float(length_m)
        elif duration_s is not None and length_m is None:
            given = float(duration_s)
        else:
            raise InputError('a segment needs exactly one of length_m and duration_s')
        if not (math.isfinite(given) and given > 0):
            raise InputError(f'segment length/duration must be finite and > 0, got {given}')
        if not (math.isfinite(speed_m_s) and speed_m_s > 0):
            raise InputError(f'segment speed must be finite and > 0 m/s, got {speed_m_s}')
        if turn_radius_m == 0 or math.isnan(turn_radius_m):
            raise InputError('segment turning radius must be non-zero (inf = straight)')
        duration = duration_s if duration_s is not None else given / speed_m_s
        return cls(speed_m_s, speed_m_s / turn_radius_m, duration, payload_kg)

    @property
    def turn_radius_m(self) -> float:
        """Signed turning radius R = V / yaw rate [m]: inf straight, 0 spinning in place."""
        if self.yaw_rate_rad_s == 0:
            return math.copysign(math.inf, self.yaw_rate_rad_s)  # -0.0 keeps a route's R = -inf
        return self.speed_m_s / self.yaw_rate_rad_s

    @property
    def length_m(self) -> float:
        """Path length |V| x duration [m]."""
        return abs(self.speed_m_s) * self.duration_s

    @property
    def is_turning(self) -> bool:
        return self.yaw_rate_rad_s != 0
