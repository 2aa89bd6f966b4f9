"""des_driver's side of the guardian (:mod:`skidsteer_power.des.guardian`): start it at configure, put
its proxy ports in place of the amplifiers' ports, refuse to enable without it, answer its trips.

Behaviour (docs/RELIABILITY.md, "The guardian"):

- configure starts the guardian on ``left_port`` / ``right_port``; the pollers open its proxy ports.
  A guardian that cannot start (a port cannot be opened, no answer) fails configure.
- activate (enabling the power stages) is refused while ``guardian`` is true and the guardian is not
  alive. ``guardian:=false`` is the explicit opt-out (the driver then owns the ports, as before).
- a trip seen by a driver that still runs (it was frozen or too slow for ``guardian_timeout_s``): the
  held command is forgotten and both links are closed, so the pollers reconnect (zero first, then
  enable again, :class:`~skidsteer_power.des.poller.AmplifierPoller`); then the guardian is re-armed.
  Until then it holds both amplifiers at zero, disabled (a latched stop), so the driver and the
  guardian never write to an amplifier at the same time; afterwards only a cmd_vel received after
  the re-arm moves the motors.
- the guardian ending unasked (killed): the driver stops commanding (inactive) and points its pollers
  at the amplifiers' own ports, which zero and disable them; activate stays refused until the node is
  configured again with a live guardian.
- cleanup / shutdown / destroy: the pollers zero and disable through the guardian, then the guardian
  is asked to quit (it sends the same stop frames once more and ends).
- ``guardian_feed`` (dtr, rts; default none): the guardian feeds a hardware watchdog on that modem line
  of both ports; each heartbeat says whether the way is clear (:meth:`DriverGuardian.driving`: a fresh
  command in force, no fault, no link down, active). A port that refuses the line is one warning at
  configure and shown in the diagnostics (the watchdog then drops the enable: the safe side).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Protocol

from skidsteer_power.des.guardian import DEFAULT_TIMEOUT_S, FEED_LINES, GuardianClient, GuardianError
from skidsteer_power.errors import ConfigError
from skidsteer_power.nodes.param_spec import ParamSpec

if TYPE_CHECKING:
    from rclpy.impl.rcutils_logger import RcutilsLogger

    from skidsteer_power.des.poller import AmplifierPoller, DriveCommand
    from skidsteer_power.nodes.parameters import DesDriverParameters


class GuardedDriver(Protocol):
    """What the guardian needs of its driver (:class:`~skidsteer_power.nodes.des_driver.DesDriver`):
    its parameters, held command, pollers and logger (a protocol: des_driver imports this module)."""

    params: DesDriverParameters
    command: DriveCommand | None
    pollers: dict[str, AmplifierPoller]

    def get_logger(self) -> RcutilsLogger: ...


GUARDIAN_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        'guardian',
        True,
        'run the guardian process that owns the ports and stops both amplifiers when the driver dies or '
        'freezes (SIGKILL, SIGSTOP, SIGSEGV, ...); false: no guardian, the driver opens the ports itself',
    ),
    ParamSpec(
        'guardian_timeout_s',
        DEFAULT_TIMEOUT_S,
        'the guardian stops both amplifiers after no heartbeat from the driver for this long [s]',
        (0.05, 5.0),
    ),
    ParamSpec(
        'guardian_feed',
        'none',
        'modem-control line of both amplifier ports that the guardian toggles every 50 ms as the feed of '
        'a hardware watchdog on the enable input, while a fresh command is in force on healthy links: '
        'none, dtr or rts (docs/RELIABILITY.md, the hardware line of defence)',
    ),
)
"""The driver's guardian parameters (appended to its PARAMETERS)."""


class DriverGuardian:
    """The guardian of one DES driver (see the module docstring)."""

    def __init__(self, node: GuardedDriver) -> None:
        self.node = node
        self.client: GuardianClient | None = None
        self.real_ports: dict[str, str] = {}

    def start(self, p: DesDriverParameters) -> DesDriverParameters:
        """Start the guardian (if wanted); the parameters with its proxy ports as the sides' ports."""
        self.close()
        feed = p.guardian_feed.lower()
        if feed not in FEED_LINES:
            raise ConfigError(f'guardian_feed must be one of {", ".join(FEED_LINES)}, not {feed!r}')
        if not p.guardian:
            if feed != 'none':
                raise ConfigError(f'guardian_feed {feed} needs guardian:=true (the guardian feeds it)')
            return p
        self.real_ports = {'left': p.left_port, 'right': p.right_port}
        client = GuardianClient(
            self.real_ports,
            baud=p.baud,
            timeout_s=p.guardian_timeout_s,
            on_trip=self._on_trip,
            on_lost=self._on_lost,
            feed=feed,
            driving=self.driving,
        )
        try:
            proxy = client.start()
        except GuardianError as err:
            raise ConfigError(str(err)) from None
        self.client = client
        for side, error in client.feed_refused.items():
            self.node.get_logger().warning(
                f'guardian_feed {feed}: the {side} port refuses the line ({error}): it feeds no watchdog'
            )
        return dataclasses.replace(p, left_port=proxy['left'], right_port=proxy['right'])

    def refusal(self) -> str:
        """Why the power stages must not be enabled now ('' when they may)."""
        if not self.node.params.guardian:
            return ''
        client = self.client
        if client is None:
            return 'no guardian (guardian:=true): configure again'
        if not client.alive:
            return f'the guardian is not running ({client.lost or "ended"}): configure again'
        return ''

    def close(self) -> None:
        """Ask the guardian to stop both amplifiers and end (after the pollers stopped)."""
        client, self.client = self.client, None
        if client is not None:
            client.close()

    def status(self) -> str:
        """One line for diagnostics."""
        client = self.client
        if not self.node.params.guardian:
            return 'off (guardian:=false)'
        if client is None:
            return 'not running'
        if client.lost:
            return f'LOST: {client.lost}'
        text = f'alive, {client.trips} trip(s)'
        if client.feed != 'none':
            refused = ', '.join(sorted(client.feed_refused))
            text += f'; feed {client.feed.upper()}' + (f' REFUSED by {refused}' if refused else '')
        return text

    def driving(self) -> bool:
        """Whether the watchdog feed may run (asked before each heartbeat): a fresh command is in
        force, active, no fault latched, no link down (either side: an unreachable amplifier is what
        only the hardware stops)."""
        command = self.node.command
        return command is not None and not command.stop_reason() and not command.links_down

    # -- from the heartbeat thread --------------------------------------------------------------

    def _on_trip(self, reason: str) -> None:
        node = self.node
        node.get_logger().error(
            f'{reason}: both amplifiers were zeroed and disabled by the guardian; the held command is '
            'dropped and the links reopened: only a fresh cmd_vel moves the motors'
        )
        command = node.command
        if command is not None:
            command.forget()
        for poller in list(node.pollers.values()):
            poller.amp.close()  # waits for an exchange in flight; the poller reconnects: zero, enable

    def _on_lost(self, reason: str) -> None:
        node = self.node
        node.get_logger().error(
            f'DES guardian lost ({reason}): zeroing and disabling both amplifiers on their own ports; '
            'no enabling until configured again'
        )
        command = node.command
        if command is not None:
            command.active = False
        for side, poller in list(node.pollers.items()):
            if side in self.real_ports:
                poller.amp.link.port = self.real_ports[side]
            poller.amp.close()
