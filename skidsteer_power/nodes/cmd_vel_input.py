"""``cmd_vel`` in, for ``des_driver`` and ``power_estimator`` alike: Twist or TwistStamped, stamps
checked, slow commands reported (issues 37 items 1-2 and 34 item 5).

Type (parameter ``cmd_vel_type``)
    ``auto`` (default) follows the publishers on the graph: ROS 2 Jazzy's diff_drive_controller,
    teleop_twist_keyboard ``stamped:=true`` and Nav2 publish geometry_msgs/TwistStamped, older tools
    and Foxglove's Teleop panel geometry_msgs/Twist. A timer (:data:`GRAPH_CHECK_PERIOD_S`) asks the
    graph which types the publishers of the (resolved) topic offer
    (``Node.get_publishers_info_by_topic``); when they all offer the other type, the subscription is
    re-made with it. ``twist`` / ``twist_stamped`` pin the type. Whatever the type, a publisher
    offering another one is named in one warning (its commands are refused: DDS matches a reader
    only with writers of its own type) and counted (``cmd_vel_refused_publishers`` in diagnostics).
    One process has one type per topic (Fast DDS refuses a second type on a topic name with
    ``incompatible type``), so the subscriptions of every node in one context switch together
    (:class:`_TypeGroup`); when something else in the process holds the old type (e.g. ``run
    --speed``'s own publisher) the switch is given up with a warning.
    The old parameters ``twist_stamped`` (des_driver) and ``cmd_vel_stamped`` (power_estimator) are
    deprecated aliases: ``true`` means ``cmd_vel_type: twist_stamped``, with a warning.

Stamps (TwistStamped only; :class:`StampCheck`)
    A command stamped more than ``cmd_timeout_s`` before the node's clock (ROS time: sim time with
    ``use_sim_time``) is refused as stale, one stamped more than ``cmd_vel_stamp_tolerance_s`` after
    it as from the future (a clock that is not synchronized): a warning (rate-limited) and a count.
    A zero stamp (0 s, 0 ns) is what some teleop tools send when they do not fill the header: it is
    taken as unstamped (receive time), with one warning. The choice: refusing it would make those
    tools silently useless, and a zero stamp says "no time", not "a very old time".

Slow commands (:class:`CommandGaps`)
    A stream of commands whose gaps exceed ``cmd_timeout_s`` means the watchdog stops the robot
    between two commands (Foxglove's Teleop panel publishes at 1 Hz by default against the driver's
    0.5 s: the robot moves about half of the time). Each such gap (up to :data:`MAX_STREAM_GAP_S`,
    beyond which it is a new session, not a slow stream) after a non-zero command is counted and
    logged, rate-limited.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypedDict

from geometry_msgs.msg import Twist, TwistStamped
from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node

from skidsteer_power.errors import ConfigError
from skidsteer_power.nodes.param_spec import ParamSpec

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile
    from rclpy.qos_overriding_options import QoSOverridingOptions
    from rclpy.subscription import Subscription
    from rclpy.topic_endpoint_info import TopicEndpointInfo

    from skidsteer_power.nodes.ros_types import RosMessage, TwistLike

TYPES: dict[str, type] = {'twist': Twist, 'twist_stamped': TwistStamped}
"""``cmd_vel_type`` values that pin the type -> the rclpy message class."""
ROS_TYPE_NAMES = {'twist': 'geometry_msgs/msg/Twist', 'twist_stamped': 'geometry_msgs/msg/TwistStamped'}
MODES = ('auto', *TYPES)

GRAPH_CHECK_PERIOD_S = 0.5
"""How often ``auto`` asks the graph which types the cmd_vel publishers offer [s]."""
MAX_STREAM_GAP_S = 10.0
"""A gap between two commands longer than this starts a new session, not a slow stream [s]."""
WARN_PERIOD_S = 5.0
"""Least time between two warnings of one kind [s]."""

PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        'cmd_vel_type',
        'auto',
        "cmd_vel message type: 'auto' (follow the publishers on the graph), 'twist' "
        "(geometry_msgs/Twist) or 'twist_stamped' (geometry_msgs/TwistStamped)",
    ),
    ParamSpec(
        'cmd_vel_stamp_tolerance_s',
        0.2,
        'a TwistStamped stamped more than this after the node clock is refused [s]',
        (0.0, 60.0),
    ),
)
"""The parameters every node with a cmd_vel input declares (one name, one meaning)."""


def cmd_vel_mode(node: Node, configured: str, deprecated_name: str, deprecated_value: bool) -> str:
    """The effective ``cmd_vel_type``: ``configured``, or ``twist_stamped`` from the deprecated
    boolean ``deprecated_name`` (with a warning). ConfigError on an unknown value."""
    if configured not in MODES:
        raise ConfigError(f'cmd_vel_type must be one of {", ".join(MODES)}, not {configured!r}')
    if deprecated_value:
        node.get_logger().warning(
            f'parameter {deprecated_name} is deprecated: use cmd_vel_type:=twist_stamped '
            f'(or auto, the default, which follows the publishers)'
        )
        if configured == 'auto':
            return 'twist_stamped'
    return configured


@dataclass
class StampCheck:
    """Checks a TwistStamped's stamp against the receiver's clock (all times in seconds)."""

    timeout_s: float
    """Older than this: stale, refused [s] (the watchdog's cmd_timeout_s)."""
    tolerance_s: float
    """Ahead of the clock by more than this: refused [s]."""
    zero_stamps: int = 0
    refused_stale: int = 0
    refused_future: int = 0

    def check(self, sec: int, nanosec: int, now_s: float) -> str:
        """'' if the stamp (``sec``, ``nanosec``) is acceptable at ``now_s``; 'zero' for a zero
        stamp (taken as unstamped, counted); else why it is refused (counted)."""
        if sec == 0 and nanosec == 0:
            self.zero_stamps += 1
            return 'zero'
        age_s = now_s - (sec + nanosec * 1e-9)
        if not math.isfinite(age_s) or age_s > self.timeout_s:
            self.refused_stale += 1
            return f'stamped {age_s:.3f} s ago (stale: cmd_timeout_s {self.timeout_s:g} s)'
        if -age_s > self.tolerance_s:
            self.refused_future += 1
            return (
                f'stamped {-age_s:.3f} s in the future (cmd_vel_stamp_tolerance_s {self.tolerance_s:g} s:'
                ' are the clocks synchronized?)'
            )
        return ''


@dataclass
class CommandGaps:
    """Counts gaps between commands longer than the watchdog's timeout (times in seconds)."""

    timeout_s: float
    slow_gaps: int = 0
    last_gap_s: float = 0.0
    _last_s: float | None = None
    _last_moving: bool = False

    def note(self, now_s: float, moving: bool) -> float | None:
        """A command at ``now_s`` (``moving``: non-zero): the gap since the previous one [s] if the
        watchdog will have stopped the robot in it (previous command non-zero), else None."""
        last, was_moving = self._last_s, self._last_moving
        self._last_s, self._last_moving = now_s, moving
        if last is None or not was_moving:
            return None
        gap = now_s - last
        if self.timeout_s < gap <= MAX_STREAM_GAP_S:
            self.slow_gaps += 1
            self.last_gap_s = gap
            return gap
        return None


class _TypeGroup:
    """Every :class:`CmdVelInput` of one context on one topic: they share one message type."""

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.members: list[CmdVelInput] = []
        self.lock = threading.Lock()
        self.blocked: set[str] = set()  # types a switch to failed (something in the process holds another)

    def switch(self, mode: str, by: CmdVelInput) -> bool:
        """Re-make every member's subscription with ``mode``; on failure go back (False)."""
        with self.lock:
            if mode == self.mode:
                return True
            if mode in self.blocked:
                return False
            old = self.mode
            for member in self.members:
                member._unsubscribe()
            try:
                for member in self.members:
                    member._subscribe(mode)
            except RCLError as err:
                for member in self.members:
                    member._unsubscribe()
                for member in self.members:
                    member._subscribe(old)
                self.blocked.add(mode)
                by.node.get_logger().warning(
                    f'cmd_vel: cannot follow the publishers to {ROS_TYPE_NAMES[mode]}: this process holds '
                    f'{ROS_TYPE_NAMES[old]} on the topic ({str(err).splitlines()[0]}); staying with it'
                )
                return False
            self.mode = mode
            for member in self.members:
                member.node.get_logger().info(
                    f'cmd_vel: the publishers offer {ROS_TYPE_NAMES[mode]}: subscribed with it'
                )
            return True


class _SubscriptionOptions(TypedDict, total=False):
    """The keyword arguments :meth:`CmdVelInput._subscribe` gives ``Node.create_subscription``."""

    raw: bool
    qos_overriding_options: QoSOverridingOptions


_GROUPS: dict[tuple[int, str], _TypeGroup] = {}
_GROUPS_LOCK = threading.Lock()


@dataclass(eq=False)
class CmdVelInput:
    """The cmd_vel subscription of ``node``: type by ``mode`` (see the module), ``callback`` called
    with each message (an rclpy message, or with ``decode`` the bytes' decoding: ``decode(msg_type)``
    returns the function that decodes that type's bytes, and the subscription is raw).
    ``make_callback`` wraps the callback once per subscription (e.g. :class:`~skidsteer_power.nodes
    .spin.Batched`: it is given the callback and returns the subscription's callback, whose
    ``subscription`` attribute is set if it has one)."""

    node: Node
    mode: str
    callback: Callable[[RosMessage], None]
    qos: QoSProfile | int
    timeout_s: float
    tolerance_s: float
    decode: Callable[[type], Callable[[bytes], RosMessage | None]] | None = None
    make_callback: Callable[[Callable[[RosMessage], None]], Callable[[RosMessage], None]] | None = None
    qos_overriding_options: QoSOverridingOptions | None = None
    topic: str = 'cmd_vel'
    stamps: StampCheck = field(init=False)
    gaps: CommandGaps = field(init=False)
    refused_publishers: dict[str, str] = field(default_factory=dict)
    subscription: Subscription | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        self.stamps = StampCheck(self.timeout_s, self.tolerance_s)
        self.gaps = CommandGaps(self.timeout_s)
        self._zero_warned = False
        self.resolved = self.node.resolve_topic_name(self.topic)
        key = (id(self.node.context), self.resolved)
        with _GROUPS_LOCK:
            group = _GROUPS.get(key)
            if group is None or not group.members:
                group = _GROUPS[key] = _TypeGroup(self._initial_mode())
            self.group = group
        with group.lock:
            if self.mode != 'auto' and group.mode != self.mode:
                raise ConfigError(
                    f'cmd_vel_type {self.mode} on {self.resolved}, but this process already takes '
                    f'{ROS_TYPE_NAMES[group.mode]} there (one type per topic in one process)'
                )
            try:
                self._subscribe(group.mode)
            except RCLError:  # the process holds the other type on the topic (auto, first member)
                if self.mode != 'auto' or len(group.members) > 0:
                    raise
                group.mode = 'twist_stamped' if group.mode == 'twist' else 'twist'
                self._subscribe(group.mode)
            group.members.append(self)
        self.timer = self.node.create_timer(GRAPH_CHECK_PERIOD_S, self.check_graph)
        self.check_graph()

    def _initial_mode(self) -> str:
        if self.mode != 'auto':
            return self.mode
        modes = self._offered(self.node.get_publishers_info_by_topic(self.resolved))
        return modes.pop() if len(modes) == 1 else 'twist'

    @staticmethod
    def _offered(publishers: list[TopicEndpointInfo]) -> set[str]:
        known = {name: mode for mode, name in ROS_TYPE_NAMES.items()}
        return {known[info.topic_type] for info in publishers if info.topic_type in known}

    @property
    def current(self) -> str:
        """The type subscribed now: 'twist' or 'twist_stamped'."""
        return self.group.mode

    def _subscribe(self, mode: str) -> None:
        msg_type = TYPES[mode]
        callback: Callable[[RosMessage], None] = self.callback
        if self.decode is not None:
            decode, inner = self.decode(msg_type), self.callback

            def callback(data: bytes) -> None:
                msg = decode(data)
                if msg is not None:  # a guarded decoder (nodes/malformed.py) drops a malformed one
                    inner(msg)

        if self.make_callback is not None:
            callback = self.make_callback(callback)
        kwargs: _SubscriptionOptions = {'raw': self.decode is not None}
        if self.qos_overriding_options is not None:
            kwargs['qos_overriding_options'] = self.qos_overriding_options
        self.subscription = self.node.create_subscription(msg_type, self.topic, callback, self.qos, **kwargs)
        if hasattr(callback, 'subscription'):
            callback.subscription = self.subscription

    def _unsubscribe(self) -> None:
        if self.subscription is not None:
            self.node.destroy_subscription(self.subscription)
            self.subscription = None

    def check_graph(self) -> None:
        """Follow the publishers' type (``auto``); name every publisher whose type is refused."""
        try:
            publishers = self.node.get_publishers_info_by_topic(self.resolved)
        except RCLError:  # the context is going down
            return
        modes = self._offered(publishers)
        if self.mode == 'auto' and len(modes) == 1 and self.current not in modes:
            self.group.switch(modes.pop(), self)
        wanted = ROS_TYPE_NAMES[self.current]
        refused = {}
        for info in publishers:
            if info.topic_type != wanted:
                name = f'{info.node_namespace.rstrip("/")}/{info.node_name}'
                refused[name] = info.topic_type
        for name, msg_type in refused.items():
            if self.refused_publishers.get(name) != msg_type:
                self.node.get_logger().warning(
                    f'cmd_vel: publisher {name} offers {msg_type}, this node takes {wanted} on '
                    f'{self.resolved} (cmd_vel_type: {self.mode}): its commands are refused'
                )
        self.refused_publishers = refused

    def accept(self, msg: RosMessage, now_s: float) -> TwistLike | None:
        """The twist of ``msg`` (Twist or TwistStamped, rclpy or rosbags) if it is to be taken at
        ``now_s`` (the node clock [s]), else None (a refused stamp, warned and counted). Also notes
        the gap since the previous command (:class:`CommandGaps`)."""
        header = getattr(msg, 'header', None)
        twist: TwistLike = msg if header is None else msg.twist
        if header is not None:
            reason = self.stamps.check(int(header.stamp.sec), int(header.stamp.nanosec), now_s)
            if reason == 'zero':
                if not self._zero_warned:
                    self._zero_warned = True
                    self.node.get_logger().warning(
                        'cmd_vel: a TwistStamped with a zero stamp: taken as unstamped (receive time); '
                        'said once'
                    )
            elif reason:
                self.node.get_logger().warning(
                    f'cmd_vel refused: {reason} (stale {self.stamps.refused_stale}, '
                    f'future {self.stamps.refused_future} so far)',
                    throttle_duration_sec=WARN_PERIOD_S,
                )
                return None
        moving = twist.linear.x != 0.0 or twist.angular.z != 0.0
        gap = self.gaps.note(now_s, moving)
        if gap is not None:
            self.node.get_logger().warning(
                f'cmd_vel came {gap:.2f} s after the previous command, slower than cmd_timeout_s '
                f'{self.timeout_s:g} s: the watchdog stops the robot between commands; publish at '
                f'{2.0 / self.timeout_s:g} Hz or more (Foxglove Teleop: its publish rate) '
                f'({self.gaps.slow_gaps} slow gaps so far)',
                throttle_duration_sec=WARN_PERIOD_S,
            )
        return twist

    def diagnostics(self) -> dict[str, str]:
        """Key/values for a diagnostics status (counts since start)."""
        return {
            'cmd_vel_type': ROS_TYPE_NAMES[self.current] + (' (auto)' if self.mode == 'auto' else ''),
            'cmd_vel_refused_publishers': ', '.join(f'{n} ({t})' for n, t in self.refused_publishers.items())
            or 'none',
            'cmd_vel_refused_stale_stamp': str(self.stamps.refused_stale),
            'cmd_vel_refused_future_stamp': str(self.stamps.refused_future),
            'cmd_vel_zero_stamp': str(self.stamps.zero_stamps),
            'cmd_vel_slow_gaps': str(self.gaps.slow_gaps),
        }

    def close(self) -> None:
        """Leave the type group; destroy the subscription and the timer."""
        with self.group.lock:
            if self in self.group.members:
                self.group.members.remove(self)
            self._unsubscribe()
        self.node.destroy_timer(self.timer)
