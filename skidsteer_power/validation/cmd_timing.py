"""How long a recorded cmd_vel command stays in force: stream vs on-change publishing, and the hold.

Two ways of publishing ``cmd_vel`` are common, and they mean different things between messages:

* **stream**: the publisher repeats the command at a steady rate (joystick teleop, navigation
  controllers, a held key's auto-repeat); the robot's controller stops when the stream stops
  (diff_drive_controller: ``cmd_vel_timeout``). A message holds until the next one, for at most a
  few publishing periods.
* **on change**: the publisher sends a message only when the command changes (many keyboard and
  GUI teleop nodes); the robot keeps doing the last command until told otherwise.

:func:`command_timing` tells them apart from the recording itself: a stream repeats identical
values (at least half of all consecutive messages are equal), an on-change publisher almost never
does. The hold it infers (stated in the report):

* stream: the longest ordinary silence of the stream, ``1.05 x`` the 99th percentile of the
  intervals between messages (so a keyboard's 0.5 s auto-repeat delay is bridged), at least three
  median periods and at least ``floor_s`` (the estimator's staleness, 0.5 s);
* on change: until the next command (``inf``), cut short by :func:`hold_ends` where motion data
  (odometry, poses) show the robot at rest.

All times in s from the bag's start; commands (n, 2) are V [m/s] and yaw rate [rad/s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skidsteer_power.errors import InputError

STREAM_REPEAT_FRACTION = 0.5  # at least this share of consecutive messages repeat the value: stream
REST_SPEED_M_S = 0.01  # slower than this [m/s] ...
REST_YAW_RATE_RAD_S = 0.02  # ... and turning slower than this [rad/s]: the robot is at rest
MOVING_GRACE_S = 0.5  # a new command gets this long [s] to set the robot moving before rest ends it
SAME_INSTANT_S = 0.01  # on change: messages closer than this [s] are one command (the last wins)


@dataclass(frozen=True)
class CommandTiming:
    """How the recording's commands were published and how long each is held.

    mode : 'stream' or 'on_change'
    hold_s : a command's longest hold [s] (inf: until the next command)
    period_s : stream: median interval between messages; on change: median interval between
        distinct commands (:func:`distinct_command_period`) [s] (nan with fewer than two)
    repeat_fraction : share of consecutive commands equal to the one before [-]
    inferred : True if ``hold_s`` was inferred from the recording (not given by the user)
    """

    mode: str
    hold_s: float
    period_s: float
    repeat_fraction: float
    inferred: bool

    def describe(self) -> str:
        """One plain sentence for the report."""
        how = (
            f'as a stream (about every {self.period_s:.3g} s, {100 * self.repeat_fraction:.0f} % repeats)'
            if self.mode == 'stream'
            else f'only when they change ({100 * self.repeat_fraction:.0f} % repeats)'
        )
        hold = 'until the next command' if math.isinf(self.hold_s) else f'for at most {self.hold_s:.3g} s'
        source = 'inferred from the recording' if self.inferred else 'given with --cmd-hold'
        return f'Commands were published {how}; each is held {hold} ({source}).'


def command_timing(
    cmd_t: np.ndarray, cmd: np.ndarray, hold_s: float | None = None, floor_s: float = 0.5
) -> CommandTiming:
    """Classify the publishing of commands at times ``cmd_t`` [s] and choose the hold [s].

    ``hold_s`` given (a positive number or inf) is used as is; None infers it (module docstring).
    """
    if hold_s is not None and not (hold_s > 0):
        raise InputError(f'the command hold must be > 0 s (or inf), not {hold_s!r}')
    n = int(cmd_t.size)
    repeats = float(np.mean(np.all(np.diff(cmd, axis=0) == 0, axis=1))) if n > 1 else 0.0
    intervals = np.diff(cmd_t)
    period = float(np.median(intervals)) if n > 1 else math.nan
    mode = 'stream' if repeats >= STREAM_REPEAT_FRACTION else 'on_change'
    if mode == 'on_change':
        period = distinct_command_period(cmd_t, cmd)
    if hold_s is None:
        if mode == 'stream':
            hold_s = max(floor_s, 3.0 * period, 1.05 * float(np.percentile(intervals, 99)))
        else:
            hold_s = math.inf
        inferred = True
    else:
        inferred = False
    return CommandTiming(mode, float(hold_s), period, repeats, inferred)


def distinct_command_period(cmd_t: np.ndarray, cmd: np.ndarray) -> float:
    """Median interval [s] between distinct commands of an on-change publisher: messages closer
    than :data:`SAME_INSTANT_S` are one command (a stop and the new command sent together: the new
    one), and a command equal to the one before is no new command. nan with fewer than two."""
    if cmd_t.size < 2:
        return math.nan
    last_of_burst = np.append(np.diff(cmd_t) >= SAME_INSTANT_S, True)
    t, values = cmd_t[last_of_burst], cmd[last_of_burst]
    changed = np.append(True, np.any(np.diff(values, axis=0) != 0, axis=1))
    t = t[changed]
    return float(np.median(np.diff(t))) if t.size > 1 else math.nan


def at_rest(pose_t: np.ndarray, xy: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(interval start times [s], at rest per interval) from consecutive poses: the robot is at rest
    over an interval if it moved slower than :data:`REST_SPEED_M_S` and turned slower than
    :data:`REST_YAW_RATE_RAD_S` [rad/s] (heading unwrapped)."""
    if pose_t.size < 2:
        return np.zeros(0), np.zeros(0, bool)
    dt = np.diff(pose_t)
    ok = dt > 0
    t, dt = pose_t[:-1][ok], dt[ok]
    speed = np.hypot(*np.diff(xy, axis=0)[ok].T) / dt
    turn = np.abs(np.diff(np.unwrap(yaw))[ok]) / dt
    return t, (speed < REST_SPEED_M_S) & (turn < REST_YAW_RATE_RAD_S)


def hold_ends(
    cmd_t: np.ndarray,
    timing: CommandTiming,
    end_s: float,
    rest: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Time [s] at which each command stops being in force.

    A command holds until the next one, for at most ``timing.hold_s``, never past ``end_s`` (the end
    of the recording). For on-change commands with motion data (``rest`` from :func:`at_rest`), the
    hold also ends at the first interval, later than :data:`MOVING_GRACE_S` after the command, over
    which the robot was at rest: the robot stopped (a driver timeout, an obstacle), so its motors no
    longer do the command.
    """
    if cmd_t.size == 0:
        return cmd_t.copy()
    following = np.append(cmd_t[1:], math.inf)
    ends = np.minimum(np.minimum(following, cmd_t + timing.hold_s), end_s)
    if timing.mode == 'on_change' and rest is not None and rest[0].size:
        rest_t = rest[0][rest[1]]
        if rest_t.size:
            k = np.searchsorted(rest_t, cmd_t + MOVING_GRACE_S, side='left')
            first_rest = np.where(k < rest_t.size, rest_t[np.minimum(k, rest_t.size - 1)], math.inf)
            ends = np.minimum(ends, np.maximum(first_rest, cmd_t))
    held: np.ndarray = np.maximum(ends, cmd_t)  # numpy types it Any
    return held
