"""Per-side motor currents from a vendor status topic instead of joint_states effort.

Real skid-steer robots report motor current on their own topics, not in joint_states: the Husky A200
on ``status`` (husky_msgs/HuskyStatus: ``left_driver_current``, ``right_driver_current`` [A]),
Clearpath's newer software on ``platform/mcu/status/power`` (clearpath_platform_msgs/Power:
``measured_currents[A200_LEFT_DRIVER_CURRENT = 1]``, ``[A200_RIGHT_DRIVER_CURRENT = 2]`` [A]). A
vehicle file's ``joints:`` section names them under ``side_currents`` (a list: the first source
present is used)::

    side_currents:
      - {topic: status, type: husky_msgs/msg/HuskyStatus,
         left: left_driver_current, right: right_driver_current}
      - {topic: platform/mcu/status/power, type: clearpath_platform_msgs/msg/Power,
         left: 'measured_currents[1]', right: 'measured_currents[2]'}

Each joint_states message then takes, as its effort, the latest side currents no older than
``max_age_s`` (default 1.5 s; older or none yet: the message is "no data", NaN in every field): the
side's current on its first joint, 0 A on the others, so that the side's torque (the sum over its
joints, :class:`~skidsteer_power.estimator.inputs.JointReader`) is Kt G I of one motor per side with
``effort_is: current``. Speeds still come from joint_states.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.errors import ConfigError

if TYPE_CHECKING:
    from skidsteer_power.bag_io.reader import BagReader

_FIELD = re.compile(r'^([A-Za-z_]\w*)(?:\[(\d+)\])?$')
DEFAULT_MAX_AGE_S = 1.5


@dataclass(frozen=True)
class FieldRef:
    """A number in a message: ``name`` or ``name[index]`` (an element of an array field)."""

    name: str
    index: int | None = None

    @classmethod
    def parse(cls, text: object) -> FieldRef:
        match = _FIELD.match(str(text).strip()) if isinstance(text, str) else None
        if match is None:
            raise ConfigError(f"side_currents: a field is 'name' or 'name[index]', not {text!r}")
        return cls(match.group(1), None if match.group(2) is None else int(match.group(2)))

    def read(self, msg: object) -> float:
        """The field's value as a float (NaN if the message lacks it or the array is short)."""
        value = getattr(msg, self.name, None)
        if value is not None and self.index is not None:
            value = value[self.index] if self.index < len(value) else None
        try:
            return float(value) if value is not None else math.nan
        except (TypeError, ValueError):
            return math.nan

    def __str__(self) -> str:
        return self.name if self.index is None else f'{self.name}[{self.index}]'


@dataclass(frozen=True)
class SideCurrentSource:
    """One topic with both sides' motor currents [A]."""

    topic: str
    msgtype: str
    left: FieldRef
    right: FieldRef
    max_age_s: float = DEFAULT_MAX_AGE_S

    @classmethod
    def from_config(cls, config: object) -> SideCurrentSource:
        if not isinstance(config, dict):
            raise ConfigError(f'side_currents: each entry is a mapping, not {config!r}')
        unknown = sorted(set(config) - {'topic', 'type', 'left', 'right', 'max_age_s'})
        missing = sorted({'topic', 'type', 'left', 'right'} - set(config))
        if unknown or missing:
            raise ConfigError(f'side_currents: unknown keys {unknown}, missing keys {missing}')
        msgtype = str(config['type'])
        if msgtype.count('/') == 1:  # 'pkg/Name' -> 'pkg/msg/Name'
            msgtype = msgtype.replace('/', '/msg/')
        max_age = config.get('max_age_s', DEFAULT_MAX_AGE_S)
        if not (isinstance(max_age, (int, float)) and math.isfinite(max_age) and 0 < max_age <= 60):
            raise ConfigError(f'side_currents: max_age_s must be in (0, 60] s, not {max_age!r}')
        return cls(
            str(config['topic']).lstrip('/'),
            msgtype,
            FieldRef.parse(config['left']),
            FieldRef.parse(config['right']),
            float(max_age),
        )

    def read(self, msg: object) -> tuple[float, float]:
        """(left, right) current [A] of one message."""
        return self.left.read(msg), self.right.read(msg)


def parse_sources(config: object) -> tuple[SideCurrentSource, ...]:
    """The ``side_currents`` list of a drivetrain section (None or empty: none)."""
    if config is None:
        return ()
    if isinstance(config, dict):
        config = [config]
    if not isinstance(config, list):
        raise ConfigError(f'side_currents must be a list of mappings, not {config!r}')
    return tuple(SideCurrentSource.from_config(c) for c in config)


def side_efforts(currents: tuple[float, float], n_left: int, n_joints: int) -> list[float]:
    """joint_states effort for the mapped joints: each side's current on its first joint, 0 A on the
    others (their sum is the side's current)."""
    effort = [0.0] * n_joints
    effort[0], effort[n_left] = currents
    return effort


def efforts_at(
    js_t: np.ndarray,
    current_t: np.ndarray,
    currents: np.ndarray,
    n_left: int,
    n_joints: int,
    max_age_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(effort (n, n_joints) [A], fresh (n,)) for joint_states at times ``js_t`` [s] from the side
    currents (m, 2) [A] at ``current_t`` [s]: the latest at or before each row, if at most
    ``max_age_s`` old (else ``fresh`` is False and the row NaN)."""
    effort = np.full((js_t.size, n_joints), np.nan)
    if current_t.size == 0:
        return effort, np.zeros(js_t.size, bool)
    k = np.searchsorted(current_t, js_t, side='right') - 1
    fresh = (k >= 0) & (js_t - current_t[np.maximum(k, 0)] <= max_age_s)
    latest = currents[np.maximum(k, 0)]
    effort[fresh] = 0.0
    effort[fresh, 0] = latest[fresh, 0]
    effort[fresh, n_left] = latest[fresh, 1]
    return effort, fresh


def decode_side_currents(
    bag: BagReader, source: SideCurrentSource, t0_ns: int
) -> tuple[np.ndarray, np.ndarray]:
    """(t [s] from ``t0_ns``, currents (m, 2) [A]) of ``source`` in ``bag`` (a BagReader)."""
    topic = next(t for t in bag.topics if t.lstrip('/') == source.topic)
    t, currents = [], []
    for message in bag.messages([topic]):
        t.append((message.timestamp_ns - t0_ns) * 1e-9)
        currents.append(source.read(bag.deserialize(message)))
    return np.array(t, dtype=float), np.array(currents, dtype=float).reshape(-1, 2)


def source_in(bag: BagReader, sources: Sequence[SideCurrentSource]) -> tuple[SideCurrentSource | None, str]:
    """(the first of ``sources`` whose topic the bag holds with the declared type and can decode,
    why none if none)."""
    held = {name.lstrip('/'): info for name, info in bag.topics.items()}
    undecodable = []
    for source in sources:
        info = held.get(source.topic)
        if info is None or info.msgtype != source.msgtype:
            continue
        if not info.decodable:
            undecodable.append(f'{source.topic} ({source.msgtype})')
            continue
        return source, ''
    if undecodable:
        return None, f'no definition of {", ".join(undecodable)} in the bag: pass it with --msg'
    wanted = ', '.join(f'{s.topic} ({s.msgtype})' for s in sources)
    return None, f'no side-current topic in the bag (wanted {wanted})'
