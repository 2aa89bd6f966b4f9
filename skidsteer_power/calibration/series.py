"""Steady segments of a recording held as arrays (a CSV log, e.g. BorealTC): wheel speed set points,
optionally the measured electrical power per side and a gyro's yaw rate.

Many robots log no command: their controller holds wheel speeds, so the recorded wheel speeds are the
set points (the drive controller's output). A hold is a run of samples in which each side's set point
stays within ``tol_rad_s`` of the run's first sample [rad/s at the axle]; its first ``settle_s`` [s]
are dropped and what is left must last at least ``min_s`` [s] with at least ``min_samples`` samples.
The hold's command is the twist of its mean set points through the vehicle's drive controller
(:meth:`DriveController.twist_of`), so that predicting it gives those set points back; its measured
motion is the gyro's mean yaw rate over the window (the forward speed is not measured: NaN).

Measured power (``power_W``, battery side: V x I per side [W]) is kept per segment in
:attr:`SeriesSegment.power_W`; the motor torque is unknown (NaN): such segments feed a motion fit
(``fit_to='motion'``) and a power comparison at the battery, not a torque fit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from skidsteer_power.calibration.segments import SteadyWindow
from skidsteer_power.errors import InputError

MAX_SAMPLES = 10_000_000  # samples of one series at most (declared maximum of the work)


@dataclass(frozen=True)
class Series:
    """One recording as arrays, SI units, times in s from its start.

    t_s (n,); setpoint_rad_s (n, 2): axle speed set points (left, right) [rad/s]; power_W (n, 2) or
    None: measured electrical power per side [W]; gyro_t_s (m,), yaw_rate_rad_s (m,) or None: the
    body's yaw rate from a gyro [rad/s].
    """

    source: str
    t_s: np.ndarray
    setpoint_rad_s: np.ndarray
    power_W: np.ndarray | None = None
    gyro_t_s: np.ndarray | None = None
    yaw_rate_rad_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = self.t_s.size
        if n > MAX_SAMPLES:
            raise InputError(f'{self.source}: {n} samples, at most {MAX_SAMPLES}')
        if self.setpoint_rad_s.shape != (n, 2):
            raise InputError(f'{self.source}: set points must be ({n}, 2), not {self.setpoint_rad_s.shape}')
        if self.power_W is not None and self.power_W.shape != (n, 2):
            raise InputError(f'{self.source}: power must be ({n}, 2), not {self.power_W.shape}')
        if n > 1 and not np.all(np.diff(self.t_s) > 0):
            raise InputError(f'{self.source}: times must increase')


@dataclass(frozen=True)
class SeriesSegment:
    """A steady segment (:class:`SteadyWindow`, torque NaN) with the measured power per side [W] (NaN when
    none) and its set points (2,) [rad/s]."""

    segment: SteadyWindow
    power_W: tuple[float, float]
    setpoint_rad_s: tuple[float, float]


def holds(setpoint: np.ndarray, tol_rad_s: float) -> list[tuple[int, int]]:
    """(first, end) sample indices of runs whose set points stay within ``tol_rad_s`` of the run's
    first sample, on both sides."""
    runs: list[tuple[int, int]] = []
    first = 0
    for i in range(1, len(setpoint) + 1):
        if i == len(setpoint) or np.any(np.abs(setpoint[i] - setpoint[first]) > tol_rad_s):
            runs.append((first, i))
            first = i
    return runs


def steady_segments(
    series: Series,
    twist_of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    *,
    tol_rad_s: float,
    settle_s: float = 0.5,
    min_s: float = 1.0,
    min_samples: int = 5,
    standing_rad_s: float = 1e-3,
) -> tuple[list[SeriesSegment], dict[str, int]]:
    """The steady segments of ``series`` (module doc) and the count of holds dropped per reason.

    ``twist_of`` : the drive controller's set points -> (V, w_z) map (``DriveController.twist_of``).
    """
    dropped = {'standing': 0, 'too_short': 0}
    out: list[SeriesSegment] = []
    t, sp = series.t_s, series.setpoint_rad_s
    period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    for a, b in holds(sp, tol_rad_s):
        mean_sp = sp[a:b].mean(axis=0)
        if np.all(np.abs(mean_sp) <= standing_rad_s):
            dropped['standing'] += 1
            continue
        lo, hi = t[a] + settle_s, (t[b] if b < t.size else t[b - 1] + period)
        sel = (t >= lo) & (t < hi)
        if hi - lo < min_s or int(sel.sum()) < min_samples:
            dropped['too_short'] += 1
            continue
        window_sp = sp[sel].mean(axis=0)
        speed, yaw = twist_of(window_sp[None, :])
        measured_yaw, source = math.nan, 'command'
        if series.gyro_t_s is not None and series.yaw_rate_rad_s is not None:
            g = (series.gyro_t_s >= lo) & (series.gyro_t_s < hi)
            if int(g.sum()) >= 3:
                measured_yaw, source = float(series.yaw_rate_rad_s[g].mean()), 'imu yaw rate'
        power = (math.nan, math.nan)
        if series.power_W is not None:
            pw = series.power_W[sel].mean(axis=0)
            power = (float(pw[0]), float(pw[1]))
        nan2 = (math.nan, math.nan)
        segment = SteadyWindow(
            source=series.source,
            start_s=float(lo),
            duration_s=float(hi - lo),
            command=(float(np.asarray(speed)[0]), float(np.asarray(yaw)[0])),
            speed_m_s=math.nan if source != 'command' else float(np.asarray(speed)[0]),
            yaw_rate_rad_s=measured_yaw if source != 'command' else float(np.asarray(yaw)[0]),
            motion_source=source,
            samples=int(sel.sum()),
            motor_torque_Nm=nan2,
            motor_omega_rad_s=nan2,
            torque_std_Nm=nan2,
            battery_W=power,
        )
        out.append(SeriesSegment(segment, power, (float(window_sp[0]), float(window_sp[1]))))
    return out, dropped


def segments_of(items: Sequence[SeriesSegment]) -> list[SteadyWindow]:
    """The plain :class:`SteadyWindow` of each item."""
    return [item.segment for item in items]
