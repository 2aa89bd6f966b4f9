"""No-load speed/current samples for the internal-resistance fit (ch. 7.2), from CSV or a bag.

CSV (header row, one sample per row; column names are case-insensitive)::

    speed    : motor_omega_rad_s | omega_rad_s | speed_rad_s | velocity_rad_s  [rad/s]  or  speed_rpm [rpm]
    load     : current_A [A]  or  torque_Nm | effort_Nm [N m] (= K_t i)
    side     : optional, 'left' | 'right' (default 'all')
    stage    : optional assembly stage, 'motor' | 'gear_train' | 'roller_chain' | 'track' (eqs. 7.3-7.4)

Columns may instead carry a ``left_`` / ``right_`` prefix (``left_speed_rpm, left_current_A, ...``),
one pair per side, as the robot's control software logs both motors in one row.

Bag: ``sensor_msgs/JointState`` messages on ``joint_states`` as the des_driver publishes them
(names ``left_motor``, ``right_motor``; velocity = motor shaft speed [rad/s]; effort = K_t i [N m]).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, cast

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.powertrain.internal import COMPONENTS
from skidsteer_power.powertrain.motor import RPM

SPEED_COLUMNS = {
    'motor_omega_rad_s': 1.0,
    'omega_rad_s': 1.0,
    'speed_rad_s': 1.0,
    'velocity_rad_s': 1.0,
    'speed_rpm': RPM,
}
JOINT_SIDES = {'left_motor': 'left', 'right_motor': 'right'}


@dataclass
class Samples:
    """Speed [rad/s] and torque K_t i [N m] samples grouped by (side, stage)."""

    groups: dict[tuple[str, str], tuple[list[float], list[float]]] = field(default_factory=dict)

    def add(self, side: str, stage: str, omega: float, torque: float) -> None:
        omegas, torques = self.groups.setdefault((side, stage), ([], []))
        omegas.append(omega)
        torques.append(torque)

    def arrays(self) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]:
        return {key: (np.asarray(o), np.asarray(t)) for key, (o, t) in self.groups.items()}


def read_csv(path: str | os.PathLike[str], torque_constant_Nm_A: float) -> Samples:
    """Read a CSV of no-load runs (see module doc); InputError naming the file and row on bad data
    (a binary file included: not UTF-8, or NUL bytes)."""
    try:
        return _read_csv(path, torque_constant_Nm_A)
    except UnicodeDecodeError as err:
        raise InputError(f'{path}: not a text CSV (byte {err.start} is not UTF-8)') from err
    except csv.Error as err:
        raise InputError(f'{path}: not a CSV ({err})') from err


def _read_csv(path: str | os.PathLike[str], torque_constant_Nm_A: float) -> Samples:
    with open(path, newline='', encoding='utf-8') as stream:
        reader = csv.DictReader(stream)
        if not reader.fieldnames:
            raise InputError(f'{path}: empty CSV (need a header row)')
        names = {name.strip().lower(): name for name in reader.fieldnames}
        layouts = _layouts(names, path)
        samples = Samples()
        for row_no, row in enumerate(reader, start=2):
            for side, speed_col, scale, load_col, is_current in layouts:
                side_value = (
                    side or (row.get(names['side'], '') if 'side' in names else '').strip().lower() or 'all'
                )
                stage = (row.get(names['stage'], '') if 'stage' in names else '').strip().lower() or 'all'
                if side_value not in ('left', 'right', 'all'):
                    raise InputError(f'{path}:{row_no}: side must be left or right, not {side_value!r}')
                if stage != 'all' and stage not in COMPONENTS:
                    raise InputError(f'{path}:{row_no}: stage must be one of {", ".join(COMPONENTS)}')
                omega = _number(row.get(speed_col), path, row_no, speed_col) * scale
                load = _number(row.get(load_col), path, row_no, load_col)
                samples.add(side_value, stage, omega, load * torque_constant_Nm_A if is_current else load)
    if not samples.groups:
        raise InputError(f'{path}: no samples')
    return samples


def _layouts(names: dict[str, str], path: object) -> list[tuple[str, str, float, str, bool]]:
    layouts = []
    for prefix, side in (('', ''), ('left_', 'left'), ('right_', 'right')):
        speed = next(((names[prefix + c], s) for c, s in SPEED_COLUMNS.items() if prefix + c in names), None)
        load = next(
            (
                (names[prefix + c], c == 'current_a')
                for c in ('current_a', 'torque_nm', 'effort_nm')
                if prefix + c in names
            ),
            None,
        )
        if speed and load:
            layouts.append((side, speed[0], speed[1], load[0], load[1]))
    if not layouts:
        raise InputError(
            f'{path}: need a speed column ({", ".join(SPEED_COLUMNS)}) and current_A or torque_Nm '
            '(optionally prefixed left_/right_)'
        )
    return layouts


def _number(text: str | None, path: object, row_no: int, column: str) -> float:
    if text is None:  # a short row
        raise InputError(f'{path}:{row_no}: {column} is not a number: None')
    try:
        value = float(text)
    except ValueError:
        raise InputError(f'{path}:{row_no}: {column} is not a number: {text!r}') from None
    if not math.isfinite(value):
        raise InputError(f'{path}:{row_no}: {column} is not finite')
    return value


def read_bag(path: str | os.PathLike[str], topic: str = '/joint_states', stage: str = 'all') -> Samples:
    """Read JointState samples of ``left_motor`` / ``right_motor`` from a rosbag2 bag (MCAP or sqlite3)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if stage != 'all' and stage not in COMPONENTS:
        raise InputError(f'stage must be one of {", ".join(COMPONENTS)}')
    topic = topic if topic.startswith('/') else '/' + topic
    samples = Samples()
    try:
        with AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections:
                raise InputError(f'{path}: no topic {topic} in the bag')
            for connection, _, raw in reader.messages(connections=connections):
                msg = cast('_JointState', reader.deserialize(raw, connection.msgtype))  # rosbags: `object`
                _add_joint_state(samples, msg.name, msg.velocity, msg.effort, stage)
    except InputError:
        raise
    except Exception as err:  # rosbags raises many types for unreadable bags; report them as one line
        raise InputError(f'{path}: cannot read bag ({type(err).__name__}: {err})') from err
    if not samples.groups:
        raise InputError(f'{path}: no left_motor/right_motor samples with velocity and effort on {topic}')
    return samples


class _JointState(Protocol):
    """What :func:`read_bag` reads of a ``sensor_msgs/msg/JointState`` as rosbags decodes it."""

    @property
    def name(self) -> Iterable[str]: ...

    @property
    def velocity(self) -> Iterable[float]: ...

    @property
    def effort(self) -> Iterable[float]: ...


def _add_joint_state(
    samples: Samples, names: Iterable[str], velocity: Iterable[float], effort: Iterable[float], stage: str
) -> None:
    velocity, effort = list(velocity), list(effort)
    for index, name in enumerate(names):
        side = JOINT_SIDES.get(name)
        if side and index < len(velocity) and index < len(effort):
            omega, torque = float(velocity[index]), float(effort[index])
            if math.isfinite(omega) and math.isfinite(torque):
                samples.add(side, stage, omega, torque)
