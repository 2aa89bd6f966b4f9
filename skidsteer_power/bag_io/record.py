"""Record topics into a rosbag2-compatible MCAP bag with message definitions.

Subscriptions are raw (``raw=True``): the CDR bytes DDS delivers go to disk untouched. Each topic's type
is taken from the ROS graph (``get_topic_names_and_types``) and its QoS is matched to the publishers
found (reliable only if all are; transient-local likewise), as ``ros2 bag record`` does. Message
definitions come from the rosbags Jazzy type store, or from the ``.msg`` file the Python message
package installs, so Foxglove/Lichtblick, PlotJuggler and ``ros2 bag`` can decode the bag.

Output layout: see :mod:`skidsteer_power.bag_io.writer`. A clean stop (SIGINT, SIGTERM, end of
``duration``) first takes every message still queued, then writes the index. The file is written in
place from the start: header and schemas at once, then a chunk at least every
:data:`~skidsteer_power.bag_io.writer.FLUSH_PERIOD_S` (also while no message arrives), so a recorder
killed by SIGKILL or a power cut leaves an MCAP missing at most about that much at its end, readable
with ``--salvage``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.bag_io._ros import (
    GRAPH_TOPICS,
    absolute_topic,
    discover_topics,
    message_class,
    qos_for_stored,
    to_bag_qos,
)
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.errors import InputError
from skidsteer_power.stop_signals import StopFlag

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import Executor
    from rclpy.node import Node
    from rclpy.subscription import Subscription
    from rosbags.interfaces import Connection

LOG = logging.getLogger(__name__)

DEFAULT_EXCLUDED = GRAPH_TOPICS  # recorded only when named explicitly


@dataclass
class _Topic:
    name: str
    msgtype: str
    connection: Connection
    subscription: Subscription


@dataclass
class Recorder:
    """Raw subscriptions on ``node`` writing into ``writer``.

    ``topics`` empty: every topic on the graph except :data:`DEFAULT_EXCLUDED`, discovered as it
    appears. Named topics not yet on the graph are subscribed once a publisher shows up.
    """

    node: Node
    writer: BagWriter
    topics: Sequence[str] = ()
    recorded: dict[str, _Topic] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.topics = [absolute_topic(t) for t in self.topics]
        self.discover()
        self._timer = self.node.create_timer(0.2, self.discover)

    def _known(self, name: str) -> bool:
        return name in self.recorded or name in self.skipped

    def discover(self) -> None:
        """Subscribe to every wanted topic that has appeared on the graph since the last call."""
        discover_topics(self.node, self.topics, self._known, self._subscribe, self._skip)

    def _skip(self, name: str, reason: str) -> None:
        self.skipped[name] = reason
        LOG.warning('not recording %s: %s', name, reason)

    def _subscribe(self, name: str, msgtype: str) -> None:
        cls = message_class(msgtype)
        publishers = self.node.get_publishers_info_by_topic(name)
        profiles = [to_bag_qos(info.qos_profile) for info in publishers]
        qos = qos_for_stored(profiles)
        connection = self.writer.add_topic(name, msgtype, profiles)

        def on_message(data: bytes, info: object, connection: Connection = connection) -> None:
            stamp = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
            self.writer.write(connection, stamp or time.time_ns(), data)

        # rclpy types the callback as (msg) only, but also calls one taking (msg, message info)
        subscription = self.node.create_subscription(cls, name, on_message, qos, raw=True)  # type: ignore[arg-type]
        self.recorded[name] = _Topic(name, msgtype, connection, subscription)
        LOG.info('recording %s (%s)', name, msgtype)

    def missing(self) -> list[str]:
        """Named topics not subscribed yet (no publisher seen)."""
        return [t for t in self.topics if t not in self.recorded and t not in self.skipped]

    def drain(self, executor: Executor, *, quiet_s: float = 0.25, limit_s: float = 3.0) -> None:
        """Take messages still queued or in flight: spin until ``quiet_s`` pass with none [s]."""
        deadline = time.monotonic() + limit_s
        last_count, last_change = self.writer.message_count, time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - last_change < quiet_s:
            executor.spin_once(timeout_sec=0.02)
            if self.writer.message_count != last_count:
                last_count, last_change = self.writer.message_count, time.monotonic()

    def close(self) -> None:
        self._timer.cancel()
        for topic in self.recorded.values():
            self.node.destroy_subscription(topic.subscription)


@dataclass
class RecordResult:
    """What a recording wrote: bag path, messages per topic, topics skipped with the reason."""

    path: Path
    counts: dict[str, int]
    skipped: dict[str, str]
    stopped_by: str


def record(
    output: str | Path,
    topics: Sequence[str] = (),
    *,
    stop: StopFlag | None = None,
    duration_s: float | None = None,
    context: Context | None = None,
    node_name: str = 'skidsteer_recorder',
    on_ready: Callable[[Recorder], None] | None = None,
) -> RecordResult:
    """Record ``topics`` (all if empty) into ``output`` until ``stop`` is set or ``duration_s`` passes.

    ``context``: an initialised rclpy Context, or None to initialise (and shut down) one here.
    ``on_ready`` is called once the subscriptions to the topics found at start exist.
    """
    import rclpy
    import rclpy.utilities
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    if duration_s is not None and not duration_s > 0:
        raise InputError(f'duration must be > 0 s, got {duration_s}')
    stop = stop or StopFlag()
    writer = BagWriter(output)  # a bad output path fails here, before any ROS set-up
    own_context = context is None
    if context is None:
        context = Context()
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(node_name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    recorder = None
    try:
        recorder = Recorder(node, writer, topics)
        if on_ready is not None:
            on_ready(recorder)
        end = time.monotonic() + duration_s if duration_s is not None else float('inf')
        while not stop.is_set() and time.monotonic() < end and context.ok():
            executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))
            writer.flush_if_due()
        recorder.drain(executor)
    finally:
        if recorder is not None:
            recorder.close()
        path = writer.close()
        executor.shutdown()
        node.destroy_node()
        if own_context:
            rclpy.utilities.try_shutdown(context=context)
    return RecordResult(
        path=path,
        counts=dict(writer.counts),
        skipped=dict(recorder.skipped) if recorder else {},
        stopped_by=stop.signal_name or ('duration' if duration_s is not None else 'stop'),
    )
