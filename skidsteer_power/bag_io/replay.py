"""Replay a bag: publish its stored CDR bytes with the original timing.

Each message is due at ``t0 + (stamp - first stamp) / rate`` on ``time.monotonic()``; the loop sleeps
until just before that deadline (the last :data:`SPIN_S` spun), then hands the stored bytes to
``publisher.publish(bytes)``, so subscribers get the recorded message byte for byte. Publisher QoS
follows the QoS the bag stored for the original publishers (reliable unless they were all
best-effort; transient-local if they all were).

A topic whose message type is not installed for Python (rclpy needs the generated type support to
create a publisher) is skipped with a warning; so is a bag topic not named in ``topics``. With
``clock`` the bag time is published on ``/clock`` (rosgraph_msgs/Clock) at ``clock_hz``.

A salvaged bag (``--salvage``) may hold messages whose frame survived but whose bytes did not: each of
its messages is first deserialized with rclpy, and one that fails (or that the middleware refuses to
publish) is skipped and counted in ``ReplayResult.undecodable``, with one warning per topic.
"""

from __future__ import annotations

import gc
import itertools
import logging
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.bag_io._ros import matching_qos, message_class, qos_for_stored
from skidsteer_power.bag_io.reader import BagMessage, BagReader
from skidsteer_power.errors import InputError
from skidsteer_power.stop_signals import StopFlag

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile
    from rosbags.interfaces import Qos

LOG = logging.getLogger(__name__)

NO_TYPE_SUPPORT = (
    "; rclpy cannot publish even raw CDR without the type's generated type support (create_publisher "
    "needs the class's _TYPE_SUPPORT; a stand-in type of the same layout would carry another DDS type "
    'name and match no subscriber): install its ROS package, or pass --topics without it (tf2_msgs, '
    'for /tf and /tf_static, is not on PyPI: `make tf2-msgs` builds it into the venv, '
    'docs/ROS.md; apt ros-jazzy-tf2-msgs on a ROS install)'
)
"""Why a topic of an uninstalled type is not replayed even as raw bytes (checked with rclpy 7.1.6:
``create_publisher`` of a class without ``_TYPE_SUPPORT`` raises AttributeError; issue 37 item 7).
With tf2_msgs built (``make tf2-msgs``, interfaces/tf2_msgs) /tf and /tf_static are replayed like any
other topic: their stored bytes, published as tf2_msgs/msg/TFMessage."""

NS = 1_000_000_000
ACK_TIMEOUT_S = 5.0  # longest wait at the end for subscribers to acknowledge [s]
MATCH_SETTLE_S = 0.3  # pause after the publishers matched (or the wait ended), before the first message [s]
SPIN_S = 0.0002
"""The last part of each wait that is spun instead of slept [s]: a timed wait wakes 0.1-0.15 ms after
its deadline (median, measured at 200 Hz), a spin on time. Longer spins buy nothing measurable: on a
loaded machine the worst lateness is the scheduler's wake-up delay, which a sleep before the spin
meets all the same (benchmarks/bench_bags.py measures it beside the replay: 'sleep-only probe')."""


@dataclass(frozen=True)
class ReplayOptions:
    """How to replay.

    rate : playback speed factor [-] (> 0; 2 = twice as fast)
    loop : start over at the end until stopped
    topics : bag topics to publish (None: all publishable)
    start_s : skip this much of the bag from its first message [s]
    duration_s : publish only this much bag time from ``start_s`` [s] (None: to the end)
    clock : publish /clock with the bag time
    clock_hz : /clock publish rate [Hz]
    wait_for_subscribers_s : before the first message, wait up to this long until every publisher
        has a subscriber [s] (0: do not wait)
    """

    rate: float = 1.0
    loop: bool = False
    topics: Sequence[str] | None = None
    start_s: float = 0.0
    duration_s: float | None = None
    clock: bool = False
    clock_hz: float = 40.0
    wait_for_subscribers_s: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate) and self.rate > 0):
            raise InputError(f'rate must be a finite number > 0, got {self.rate}')
        if not (np.isfinite(self.start_s) and self.start_s >= 0):
            raise InputError(f'start must be >= 0 s, got {self.start_s}')
        if self.duration_s is not None and not (np.isfinite(self.duration_s) and self.duration_s > 0):
            raise InputError(f'duration must be > 0 s, got {self.duration_s}')
        if not (np.isfinite(self.clock_hz) and self.clock_hz > 0):
            raise InputError(f'clock rate must be > 0 Hz, got {self.clock_hz}')


@dataclass
class ReplayResult:
    """What a replay did: messages per topic, skipped topics with reason, passes, lateness [s]."""

    counts: dict[str, int]
    skipped: dict[str, str]
    passes: int
    wall_s: float
    late_s: np.ndarray = field(repr=False)
    log: list[tuple[str, float, float]] = field(default_factory=list, repr=False)
    undecodable: dict[str, int] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    @property
    def max_late_s(self) -> float:
        """Largest delay of a publish after its deadline [s]."""
        return float(self.late_s.max()) if self.late_s.size else 0.0


@contextmanager
def _no_gc_pauses() -> Iterator[None]:
    """Keep the cyclic garbage collector out of the timed loop: a full collection over a large heap
    stalls the interpreter for milliseconds, longer than the gap between messages at kHz rates
    (benchmarks/bench_bags.py: the worst timing error vs the bag fell from 5.2 to 3.7 ms with it).
    The loop itself makes almost no reference cycles."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def deadlines(stamps_ns: Sequence[int], window_start_ns: int, rate: float, t0: float = 0.0) -> np.ndarray:
    """Publish deadlines [s on the monotonic clock] of messages stamped ``stamps_ns`` [ns].

    ``t0 + (stamp - window_start) / rate``: the bag's timing, scaled by ``rate``.
    """
    offsets = (np.asarray(stamps_ns, dtype=np.int64) - np.int64(window_start_ns)).astype(float) / NS
    return t0 + offsets / rate


LATCHED_BY_CONVENTION = ('/tf_static',)
"""Topics replayed transient-local when the bag stored no QoS for them: tf2_ros' static broadcaster
always offers transient-local (reliable, depth 1), and a volatile replay would miss every listener
that starts after the bag's first message (a transient-local publisher matches volatile subscribers
too)."""


def replay_qos(topic: str, stored: Sequence[Qos]) -> QoSProfile:
    """Publisher QoS for ``topic``: that of the original publishers (:func:`qos_for_stored`), or for
    a latched-by-convention topic with nothing stored, reliable transient-local."""
    if stored or topic not in LATCHED_BY_CONVENTION:
        return qos_for_stored(stored)
    return matching_qos([True], [True])


def window_ns(bag: BagReader, options: ReplayOptions) -> tuple[int, int | None]:
    """[start, stop) bag time to replay [ns]; stop None means to the end."""
    start = bag.start_ns + round(options.start_s * NS)
    if bag.message_count and start > bag.end_ns:
        raise InputError(f'start {options.start_s} s is past the end of the bag ({bag.duration_s:.3f} s)')
    stop = None if options.duration_s is None else start + round(options.duration_s * NS)
    return start, stop


class Replayer:
    """Publishers for a bag's topics on ``node``; :meth:`run` replays until done or stopped."""

    def __init__(self, bag: BagReader, node: Node, options: ReplayOptions | None = None) -> None:
        self.bag = bag
        self.node = node
        self.options = options or ReplayOptions()
        self.skipped: dict[str, str] = {}
        self.publishers: dict[str, Publisher] = {}
        self.classes: dict[str, type] = {}
        self.undecodable: dict[str, int] = {}
        wanted = list(bag.topics) if self.options.topics is None else list(self.options.topics)
        missing = [t for t in wanted if t not in bag.topics]
        if missing:
            raise InputError(f'{bag.path}: no topic {", ".join(missing)} in the bag')
        for topic in wanted:
            info = bag.topics[topic]
            try:
                cls = message_class(info.msgtype)
            except InputError as err:
                self.skipped[topic] = f'{err}{NO_TYPE_SUPPORT}'
                LOG.warning('not replaying %s: %s%s', topic, err, NO_TYPE_SUPPORT)
                continue
            self.publishers[topic] = node.create_publisher(cls, topic, replay_qos(topic, info.qos))
            self.classes[topic] = cls
        self._clock_pub = None
        if self.options.clock:
            from rosgraph_msgs.msg import Clock

            self._clock_pub = node.create_publisher(Clock, '/clock', 10)
        if not self.publishers:
            raise InputError(f'{bag.path}: nothing to replay (no topic with an installed message type)')

    def wait_for_subscribers(self, stop: StopFlag) -> bool:
        """Wait up to ``options.wait_for_subscribers_s`` until every publisher is matched with every
        subscription to its topic on the graph (a recorder that just joined included)."""
        end = time.monotonic() + self.options.wait_for_subscribers_s
        while time.monotonic() < end and not stop.is_set() and not self._all_matched():
            time.sleep(0.01)
        matched = self._all_matched()
        if any(pub.get_subscription_count() > 0 for pub in self.publishers.values()):
            # DDS matching is two-sided: our writer can see a reader before that reader has
            # discovered the writer, and a volatile reader then skips what came before. A short
            # pause lets the other side finish (as ``ros2 bag play --delay`` would), for every topic
            # that matched, also when the wait ran out on another (a late joiner)
            stop.wait(MATCH_SETTLE_S)
        return matched

    def _all_matched(self) -> bool:
        """Every publisher has a subscriber, and is matched with every subscription the graph shows."""
        return all(
            pub.get_subscription_count() >= max(1, self.node.count_subscribers(topic))
            for topic, pub in self.publishers.items()
        )

    def _messages(self, start: int, stop: int | None) -> Iterator[BagMessage]:
        return self.bag.messages(list(self.publishers), start_ns=start, stop_ns=stop)

    def run(
        self,
        stop: StopFlag | None = None,
        *,
        keep_log: bool = False,
        on_message: Callable[[BagMessage], None] | None = None,
    ) -> ReplayResult:
        """Replay (looping if asked) until the window ends or ``stop`` is set.

        ``keep_log``: record (topic, deadline, publish time) per message [s, monotonic] in the result.
        """
        stop = stop or StopFlag()
        if self.options.wait_for_subscribers_s > 0 and not self.wait_for_subscribers(stop):
            LOG.warning('not every replayed topic has a subscriber yet; replaying anyway')
        with _no_gc_pauses():
            return self._run(stop, keep_log, on_message)

    def _run(
        self, stop: StopFlag, keep_log: bool, on_message: Callable[[BagMessage], None] | None
    ) -> ReplayResult:
        start, stop_ns = window_ns(self.bag, self.options)
        counts = dict.fromkeys(self.publishers, 0)
        late: list[float] = []
        log: list[tuple[str, float, float]] = []
        rate = self.options.rate
        # the first message is read before the clock starts: opening the bag's reader at it takes
        # 2.4-4 ms, which made the first message the latest of a replay (benchmarks/bench_bags.py)
        messages = self._primed(start, stop_ns)
        began = t0 = time.monotonic()
        passes = 0
        self._next_clock = t0
        while not stop.is_set():
            passes += 1
            last, published = start, 0
            for message in messages:
                deadline = t0 + (message.timestamp_ns - start) / NS / rate
                if self.bag.salvage and not self._decodes(message, passes == 1):
                    continue
                if not self._sleep_until(deadline, t0, start, stop):
                    break
                if not self._publish(message, passes == 1):
                    continue
                now = time.monotonic()
                late.append(now - deadline)
                counts[message.topic] += 1
                published += 1
                last = message.timestamp_ns
                if keep_log:
                    log.append((message.topic, deadline, now))
                if on_message is not None:
                    on_message(message)
            if not self.options.loop or stop.is_set() or not published:
                break
            t0 += ((stop_ns if stop_ns is not None else last) - start) / NS / rate
            messages = self._primed(start, stop_ns)
        wall = time.monotonic() - began
        self.wait_for_acks(ACK_TIMEOUT_S)
        return ReplayResult(
            counts, dict(self.skipped), passes, wall, np.array(late), log, dict(self.undecodable)
        )

    def _primed(self, start: int, stop: int | None) -> Iterator[BagMessage]:
        """The window's messages, the first already read."""
        messages = self._messages(start, stop)
        first = next(messages, None)
        return messages if first is None else itertools.chain((first,), messages)

    def _decodes(self, message: BagMessage, count: bool) -> bool:
        """Whether rclpy can deserialize ``message`` (checked for salvaged bags only)."""
        from rclpy.serialization import deserialize_message

        try:
            deserialize_message(message.data, self.classes[message.topic])
        except Exception as err:  # rclpy raises assorted errors for bad bytes: skip and count
            self._count_bad(message.topic, f'cannot deserialize ({err})', count)
            return False
        return True

    def _publish(self, message: BagMessage, count: bool) -> bool:
        from rclpy._rclpy_pybind11 import RCLError

        try:
            self.publishers[message.topic].publish(message.data)
        except RCLError as err:  # the middleware refused the bytes (damaged CDR)
            if not self.bag.salvage:
                raise InputError(f'{message.topic}: a message cannot be published ({err})') from err
            self._count_bad(message.topic, f'refused by the middleware ({err})', count)
            return False
        return True

    def _count_bad(self, topic: str, why: str, count: bool) -> None:
        if not count:
            return
        if topic not in self.undecodable:
            LOG.warning('%s: skipping damaged messages: %s', topic, why)
        self.undecodable[topic] = self.undecodable.get(topic, 0) + 1

    def wait_for_acks(self, timeout_s: float) -> bool:
        """Wait until reliable subscribers have acknowledged every message, up to ``timeout_s`` [s].

        Without this, a replay that exits right after its last publish can take messages still in
        flight with it.
        """
        from rclpy.duration import Duration

        end = time.monotonic() + timeout_s
        acked = True
        for publisher in self.publishers.values():
            remaining = max(0.0, end - time.monotonic())
            acked &= publisher.wait_for_all_acked(Duration(nanoseconds=round(remaining * NS)))
        return acked

    def _sleep_until(self, deadline: float, t0: float, start_ns: int, stop: StopFlag) -> bool:
        """Sleep until ``deadline`` [s, monotonic], publishing /clock ticks due before it."""
        while True:
            if stop.is_set():
                return False
            clock_first = self._clock_pub is not None and self._next_clock <= deadline
            due = self._next_clock if clock_first else deadline
            remaining = due - time.monotonic()
            if remaining > SPIN_S:
                stop.wait(remaining - SPIN_S)
                continue
            while time.monotonic() < due:  # the last SPIN_S: spun, not slept
                pass
            if not clock_first:
                return True
            self._publish_clock(t0, start_ns)

    def _publish_clock(self, t0: float, start_ns: int) -> None:
        from rosgraph_msgs.msg import Clock

        bag_ns = start_ns + round((self._next_clock - t0) * self.options.rate * NS)
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(bag_ns, NS)
        assert self._clock_pub is not None
        self._clock_pub.publish(msg)
        self._next_clock += 1.0 / self.options.clock_hz


def replay(
    bag: BagReader,
    options: ReplayOptions | None = None,
    *,
    stop: StopFlag | None = None,
    context: Context | None = None,
    node_name: str = 'skidsteer_replay',
) -> ReplayResult:
    """Replay ``bag`` on a node of its own; ``context`` None initialises (and shuts down) one here."""
    import rclpy
    import rclpy.utilities
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    own_context = context is None
    if own_context:
        context = Context()
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(node_name, context=context)
    try:
        return Replayer(bag, node, options).run(stop)
    finally:
        node.destroy_node()
        if own_context:
            rclpy.utilities.try_shutdown(context=context)
