"""maxon DES 70/10 amplifier: protocol (pure bytes), transport, typed client, poller, simulator.

Layers, bottom up: :mod:`~skidsteer_power.des.protocol` (frames, CRC-16/XMODEM, flags, the
incremental decoder, :class:`DesConfig` with every UNCONFIRMED protocol item),
:mod:`~skidsteer_power.des.transport` (:class:`DesLink`, the only code that touches the port),
:mod:`~skidsteer_power.des.client` (:class:`DesAmplifier`, typed calls),
:mod:`~skidsteer_power.des.poller` (threads used by the ``des_driver`` node) and
:mod:`~skidsteer_power.des.simulator` (:class:`SimulatedDes` on a pty; imported on demand).
"""

from __future__ import annotations

from skidsteer_power.des.client import DesAmplifier, Velocity, Version
from skidsteer_power.des.errors import (
    DesCrcError,
    DesError,
    DesFault,
    DesFrameError,
    DesLinkError,
    DesNak,
    DesPortError,
    DesTimeout,
)
from skidsteer_power.des.protocol import DesConfig, DesErrorFlags, OpCode, Param, Status
from skidsteer_power.des.transport import DesLink, LinkTiming

__all__ = [
    'DesAmplifier',
    'DesConfig',
    'DesCrcError',
    'DesError',
    'DesErrorFlags',
    'DesFault',
    'DesFrameError',
    'DesLink',
    'DesLinkError',
    'DesNak',
    'DesPortError',
    'DesTimeout',
    'LinkTiming',
    'OpCode',
    'Param',
    'Status',
    'Velocity',
    'Version',
]
