"""The drive controller's limits from a recording: commanded twist (or set points) against measured
wheel speeds (no ROS; SI units; docs/DRIVE.md, "Identification").

The wheels follow the controller's set points (a speed loop per side), so measured wheel speeds show
what the controller made of each command, whatever the ground did. :func:`identify`:

1. splits the recording into held commands (a new one where the command moves by more than
   ``COMMAND_TOL``) and takes, in each held long enough, the median of the measured wheel speeds over
   its settled tail (the last half, if flat within the noise): one steady point per held command;
2. fits the steady model of :meth:`DriveController.apply` (velocity limits, then the wheel speed
   ceiling, ``scale`` or ``clip``) to the steady points by coordinate descent over candidate values
   taken from the measurements themselves, with a least-absolute-error loss (robust: one bad point
   moves no limit); a limit counts as reached only where at least ``MIN_EVIDENCE`` steady points sit
   on it, each changed by more than ``EVIDENCE_SIGMAS`` noise standard deviations, else it is
   reported "not reached, kept from the vehicle file" with the prior's value; the mode only where the
   two modes' predictions differ at ``MIN_EVIDENCE`` points;
3. finds the acceleration limits from the ramps after each large step of the measured twist (from
   where it was to where the hold settled): the median |dV/dt| (|dw_z/dt|) of the measured twist
   (the controller's kinematics inverted) while it is between 20 % and 80 % of the step
   (a rate limit gives a constant slope there: one that falls with the distance left, taking
   ``RAMP_SHAPE_RATIO`` times longer for 50-80 % than for 20-50 %, is a lag), leaving out holds
   into or out of the wheel speed ceiling (scaling slows a ramp there); a step crossed in fewer
   than ``MIN_RAMP_SAMPLES`` samples is faster than the recording shows (not reached).

The noise is estimated from the measurements' first differences (MAD), so no threshold is tuned to
one recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from skidsteer_power.drive.controller import CEILING_MODES, DriveController
from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.jsonout import JsonObject

__all__ = ['DriveIdentification', 'IdentifiedValue', 'identify']

COMMAND_TOL = (1e-3, 1e-3)
"""A command moved [m/s, rad/s] by more than this starts a new held command."""
MIN_HOLD_S = 0.3
"""The shortest settled tail a held command needs to give a steady point [s]."""
MIN_EVIDENCE = 2
"""Steady points (or ramps) a limit needs before it counts as reached."""
EVIDENCE_SIGMAS = 4.0
"""A point is evidence of a limit where the limit changes it by more than this many noise sigmas."""
MIN_RAMP_SAMPLES = 3
"""Samples between 20 % and 80 % of a step for its slope to count."""
MAX_SAMPLES = 5_000_000
"""The most samples one call takes (the work is O(N) plus O(points x candidates))."""
NOT_REACHED = 'not reached, kept from the vehicle file'

Kind = Literal['twist', 'setpoints']


@dataclass(frozen=True)
class IdentifiedValue:
    """One identified quantity: value (the prior's when not reached), unit, reached, evidence (steady
    points or ramps on it), note (how it was found or why kept)."""

    name: str
    value: float | str
    unit: str
    reached: bool
    evidence: int
    note: str

    def as_json(self) -> JsonObject:
        value = self.value if isinstance(self.value, str) or math.isfinite(self.value) else None
        return {
            'value': value,
            'unit': self.unit,
            'reached': self.reached,
            'evidence': self.evidence,
            'note': self.note,
        }


@dataclass(frozen=True)
class DriveIdentification:
    """What :func:`identify` found: ``values`` by name (the :class:`DriveController` attribute names
    ``max_speed_m_s``, ``max_yaw_rate_rad_s``, ``max_wheel_rad_s``, ``ceiling``, ``max_accel_m_s2``,
    ``max_yaw_accel_rad_s2``), the prior with them applied (``controller``), the steady points used
    and the wheel speed noise sigma [rad/s]."""

    values: dict[str, IdentifiedValue]
    controller: DriveController
    steady_points: int
    noise_rad_s: float

    def as_json(self) -> JsonObject:
        return {
            'steady_points': self.steady_points,
            'noise_rad_s': self.noise_rad_s,
            'values': {k: v.as_json() for k, v in self.values.items()},
        }

    def vehicle_entries(self, source: str) -> JsonObject:
        """The identified values as vehicle-file keys: ``max_speed_m_s``, ``max_yaw_rate_rad_s`` (top
        level) and a ``drive_controller`` mapping, each reached value with ``source`` as its source."""
        top: JsonObject = {}
        drive: JsonObject = {}
        sources: dict[str, str] = {}
        file_key = {'max_wheel_rad_s': 'max_wheel_speed_rad_s'}
        for name, item in self.values.items():
            if not item.reached:
                continue
            if name in ('max_speed_m_s', 'max_yaw_rate_rad_s'):
                top[name] = item.value
                continue
            key = file_key.get(name, name)
            drive[key] = item.value
            if key != 'ceiling':
                sources[key] = f'{source} ({item.note})'
        if drive:
            drive['sources'] = sources
            top['drive_controller'] = drive
        return top


def identify(
    t_s: ArrayLike,
    commanded: ArrayLike,
    measured_rad_s: ArrayLike,
    *,
    prior: DriveController,
    commanded_kind: Kind = 'twist',
) -> DriveIdentification:
    """Identify the drive controller's limits (module doc).

    t_s : (N,) sample times [s], increasing; commanded : (N, 2) the command in force at each sample,
    (V [m/s], w_z [rad/s]) or, with ``commanded_kind='setpoints'``, (left, right) unlimited wheel set
    points [rad/s]; measured_rad_s : (N, 2) measured (left, right) wheel / axle speeds [rad/s];
    prior : the vehicle file's controller (its geometry is used, its values kept where not reached).
    """
    t, cmd, meas = _checked(t_s, commanded, measured_rad_s)
    if commanded_kind == 'setpoints':
        cmd = np.column_stack(prior.twist_of(cmd))
    elif commanded_kind != 'twist':
        raise InputError(f"commanded_kind must be 'twist' or 'setpoints', not {commanded_kind!r}")
    sigma = _noise(meas)
    starts = _holds(cmd)
    points, cmd_pts, spread = _steady_points(t, cmd, meas, starts, sigma)
    steady, ctrl = _fit_steady(prior, cmd_pts, points, max(sigma, spread))
    ramps, ctrl = _fit_ramps(prior, ctrl, t, cmd, meas, starts, sigma)
    values = {**steady, **ramps}
    return DriveIdentification(values, ctrl, len(points), sigma)


def _checked(t_s: ArrayLike, commanded: ArrayLike, measured: ArrayLike) -> tuple[np.ndarray, ...]:
    t = np.asarray(t_s, dtype=float).ravel()
    cmd = np.asarray(commanded, dtype=float)
    meas = np.asarray(measured, dtype=float)
    if cmd.shape != (len(t), 2) or meas.shape != (len(t), 2):
        raise InputError(f'identify needs (N,) times and (N, 2) commands and wheel speeds, got {t.shape}, '
                         f'{cmd.shape}, {meas.shape}')  # fmt: skip
    if len(t) < 10:
        raise InputError(f'identify needs at least 10 samples, got {len(t)}')
    if len(t) > MAX_SAMPLES:
        raise InputError(f'identify takes at most {MAX_SAMPLES} samples, got {len(t)}')
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(cmd)) and np.all(np.isfinite(meas))):
        raise InputError('identify: times, commands and wheel speeds must be finite')
    if np.any(np.diff(t) <= 0):
        raise InputError('identify: sample times must increase')
    return t, cmd, meas


def _noise(meas: np.ndarray) -> float:
    """Wheel speed noise sigma [rad/s]: MAD of the first differences / sqrt(2) (white noise)."""
    d = np.diff(meas, axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return float(np.max(1.4826 * mad / math.sqrt(2.0)))


def _holds(cmd: np.ndarray) -> np.ndarray:
    """Indices where a held command starts (the first sample, and every move beyond COMMAND_TOL)."""
    starts = [0]
    ref = cmd[0]
    tol = np.array(COMMAND_TOL)
    for k in range(1, len(cmd)):
        if np.any(np.abs(cmd[k] - ref) > tol):
            starts.append(k)
            ref = cmd[k]
    return np.array(starts)


def _steady_points(
    t: np.ndarray, cmd: np.ndarray, meas: np.ndarray, starts: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """(steady wheel speeds (M, 2), their commands (M, 2), the largest tail spread [rad/s])."""
    ends = np.append(starts[1:], len(t))
    points, commands, spreads = [], [], [0.0]
    for a, b in zip(starts, ends, strict=True):
        tail = np.flatnonzero(t[a:b] >= 0.5 * (t[a] + t[b - 1])) + a
        if tail.size < 3 or t[b - 1] - t[tail[0]] < MIN_HOLD_S:
            continue
        seg = meas[tail]
        half = tail.size // 2
        drift = np.abs(np.median(seg[half:], axis=0) - np.median(seg[:half], axis=0))
        if np.any(drift > EVIDENCE_SIGMAS * sigma + 0.02 * np.abs(np.median(seg, axis=0)) + 1e-9):
            continue  # still moving: no steady state in this hold
        points.append(np.median(seg, axis=0))
        commands.append(np.median(cmd[a:b], axis=0))
        spreads.append(float(np.max(np.abs(seg - points[-1]).mean(axis=0))))
    if not points:
        return np.empty((0, 2)), np.empty((0, 2)), 0.0
    return np.array(points), np.array(commands), float(np.median(spreads))


def _loss(ctrl: DriveController, cmd: np.ndarray, points: np.ndarray) -> float:
    sp = ctrl.apply(cmd[:, 0], cmd[:, 1]).setpoint
    return float(np.sum(np.abs(sp - points)))


_STEADY = (('max_speed_m_s', 'm/s'), ('max_yaw_rate_rad_s', 'rad/s'), ('max_wheel_rad_s', 'rad/s'))


def _candidates(name: str, ctrl: DriveController, points: np.ndarray) -> np.ndarray:
    """Values a limit may take: what the steady points measured (their speed, yaw rate or peak wheel)."""
    v, w = ctrl.twist_of(points)
    values = {'max_speed_m_s': np.abs(v), 'max_yaw_rate_rad_s': np.abs(w)}.get(name)
    if values is None:
        values = np.max(np.abs(points), axis=1)
    values = np.unique(values[values > 0])
    if values.size > 400:
        values = np.unique(np.quantile(values, np.linspace(0, 1, 400)))
    return np.append(values, math.inf)


def _fit_steady(
    prior: DriveController, cmd: np.ndarray, points: np.ndarray, sigma: float
) -> tuple[dict[str, IdentifiedValue], DriveController]:
    """Velocity limits, ceiling and mode from the steady points (module doc, step 2)."""
    free = prior.with_values(max_speed_m_s=math.inf, max_yaw_rate_rad_s=math.inf, max_wheel_rad_s=math.inf)
    if len(points) == 0:
        kept = {n: IdentifiedValue(n, getattr(prior, n), u, False, 0, NOT_REACHED + ' (no steady hold)')
                for n, u in (*_STEADY, ('ceiling', ''))}  # fmt: skip
        return kept, prior
    best: tuple[float, DriveController] | None = None
    for mode in CEILING_MODES:
        ctrl = free.with_values(ceiling=mode)
        for _ in range(3):  # coordinate descent: each limit given the others
            for name, _unit in _STEADY:
                cands = _candidates(name, ctrl, points)
                losses = [_loss(ctrl.with_values(**{name: c}), cmd, points) for c in cands]
                ctrl = ctrl.with_values(**{name: float(cands[int(np.argmin(losses))])})
        loss = _loss(ctrl, cmd, points)
        if best is None or loss < best[0] - 1e-12:
            best = (loss, ctrl)
    assert best is not None
    fitted = best[1]
    threshold = EVIDENCE_SIGMAS * sigma + 1e-9
    out: dict[str, IdentifiedValue] = {}
    result = prior
    for name, unit in _STEADY:
        without = fitted.with_values(**{name: math.inf}).apply(cmd[:, 0], cmd[:, 1]).setpoint
        with_it = fitted.apply(cmd[:, 0], cmd[:, 1]).setpoint
        evidence = int(np.sum(np.max(np.abs(without - with_it), axis=1) > threshold))
        value = float(getattr(fitted, name))
        if evidence >= MIN_EVIDENCE and math.isfinite(value):
            out[name] = IdentifiedValue(
                name, value, unit, True, evidence, f'{evidence} steady holds at the limit'
            )
            result = result.with_values(**{name: value})
        else:
            out[name] = IdentifiedValue(name, getattr(prior, name), unit, False, evidence, NOT_REACHED)
    other = fitted.with_values(ceiling='clip' if fitted.ceiling == 'scale' else 'scale')
    a = fitted.apply(cmd[:, 0], cmd[:, 1]).setpoint
    b = other.apply(cmd[:, 0], cmd[:, 1]).setpoint
    differ = int(np.sum(np.max(np.abs(a - b), axis=1) > threshold))
    if out['max_wheel_rad_s'].reached and differ >= MIN_EVIDENCE:
        out['ceiling'] = IdentifiedValue(
            'ceiling', fitted.ceiling, '', True, differ, f'{differ} turning holds at the ceiling'
        )
        result = result.with_values(ceiling=fitted.ceiling)
    else:
        note = 'not determined (no turning hold at the ceiling), kept from the vehicle file'
        out['ceiling'] = IdentifiedValue('ceiling', prior.ceiling, '', False, differ, note)
    return out, result


RAMP_SHAPE_RATIO = 1.5
"""A rate limit crosses 20-50 % and 50-80 % of a step in equal times; a first-order lag takes
ln(2.5) / ln(1.6) = 1.95 times longer for the second: above this ratio the response is a lag."""


def _constant_slope(t: np.ndarray, progress: np.ndarray) -> bool:
    """The step's response is a ramp (constant slope), not a lag: the times to cross 20 %, 50 % and
    80 % (first crossings, interpolated) split into two halves within :data:`RAMP_SHAPE_RATIO`."""
    times = []
    for level in (0.2, 0.5, 0.8):
        k = int(np.argmax(progress >= level))
        if k == 0:
            return False
        p0, p1 = progress[k - 1], progress[k]
        times.append(t[k - 1] + (level - p0) / (p1 - p0) * (t[k] - t[k - 1]))
    first, second = times[1] - times[0], times[2] - times[1]
    return bool(first > 0 and second / first <= RAMP_SHAPE_RATIO)


def _fit_ramps(
    prior: DriveController,
    ctrl: DriveController,
    t: np.ndarray,
    cmd: np.ndarray,
    meas: np.ndarray,
    starts: np.ndarray,
    sigma: float,
) -> tuple[dict[str, IdentifiedValue], DriveController]:
    """Acceleration limits from the ramps after each large step of the limited twist (step 3)."""
    v_m, w_m = ctrl.twist_of(meas)
    at_ceiling = ctrl.apply(cmd[:, 0], cmd[:, 1]).ceiling_reached  # a ramp there is slowed by the ceiling
    r_left, r_right = ctrl.radii_m
    sig_v = sigma * max(r_left, r_right)
    sig_w = 2.0 * sig_v / ctrl.separation_m
    ends = np.append(starts[1:], len(t))
    out: dict[str, IdentifiedValue] = {}
    for name, unit, series, sig in (
        ('max_accel_m_s2', 'm/s^2', v_m, sig_v),
        ('max_yaw_accel_rad_s2', 'rad/s^2', w_m, sig_w),
    ):
        slopes, ramps = [], 0
        rate = np.gradient(series, t)
        for a, b in zip(starts, ends, strict=True):
            if b - a < MIN_RAMP_SAMPLES:
                continue  # a hold too short to ramp in (and an empty slice for the medians)
            start_value = float(np.median(series[max(0, a - 3) : a + 1]))
            end_value = float(np.median(series[b - max(3, (b - a) // 5) : b]))  # where the hold settled
            step = end_value - start_value
            if abs(step) < max(20.0 * sig, 0.05) or at_ceiling[a] or (a > 0 and at_ceiling[a - 1]):
                continue
            progress = (series[a:b] - start_value) / step
            mid = np.flatnonzero((progress >= 0.2) & (progress <= 0.8))
            if mid.size < MIN_RAMP_SAMPLES or np.any(progress[: mid[-1] + 1] > 1.0):
                continue
            if not _constant_slope(t[a:b], progress):
                continue  # a lag (slope falling with the distance left), not a rate limit
            ramps += 1
            slopes.extend(np.abs(rate[a + mid]).tolist())
        if ramps >= 1 and len(slopes) >= MIN_RAMP_SAMPLES:
            value = float(np.median(slopes))
            out[name] = IdentifiedValue(name, value, unit, True, ramps, f'median slope of {ramps} ramp(s)')
            ctrl = ctrl.with_values(**{name: value})
        else:
            out[name] = IdentifiedValue(name, getattr(prior, name), unit, False, ramps, NOT_REACHED)
            ctrl = ctrl.with_values(**{name: getattr(prior, name)})
    return out, ctrl
