"""A Foxglove WebSocket server that forwards ROS 2 topics, for robots without ``foxglove_bridge``.

Each ROS topic becomes one Foxglove channel: schema encoding ``ros2msg`` (the .msg definition text
with its dependencies, as rosbag2 stores it in MCAP; :func:`..bag_io.writer.message_definition`),
message encoding ``cdr`` (the serialized message exactly as DDS delivered it: a raw subscription,
no decoding on the robot). The Foxglove app connects to ``ws://HOST:8765`` (protocol v1, named
``foxglove.sdk.v1`` or ``foxglove.websocket.v1``) and decodes the messages itself. The server is
the ``foxglove-sdk`` package's (:func:`foxglove.start_server`, on loopback), which sends a channel's
messages only to clients that subscribed to it, behind :class:`~skidsteer_power.nodes.
foxglove_front.FrontDoor` (Origin check, both subprotocol names).

Security: it listens on 127.0.0.1 unless told otherwise; there is no authentication, so anyone who
can reach the port reads every bridged topic (docs/ROS.md: expose it through an SSH tunnel). With
``allow_publish`` (off by default), clients may publish to those topics only (Foxglove's Teleop
panel on ``cmd_vel``): the CDR bytes go to ROS as they are, and des_driver checks them like any
other cmd_vel (finite, clamped, slew-limited, watchdog).

Subscriptions are best effort, so every publisher matches (reliable or not), and a slow viewer
never slows the robot down; a topic whose publishers are all transient-local (latched: ``tf_static``,
``robot_description``) is subscribed transient-local, so its last messages reach the app too.
Topics appear as they are discovered (every ``discover_period_s``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypedDict

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from skidsteer_power.bag_io._ros import GRAPH_TOPICS, absolute_topic, discover_topics, message_class
from skidsteer_power.bag_io.writer import message_definition
from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from foxglove import Channel
    from foxglove.websocket import Capability, ChannelView, Client, ClientChannel, WebSocketServer
    from rclpy.publisher import Publisher
    from rclpy.subscription import Subscription

LOG = logging.getLogger(__name__)

DEFAULT_PORT = 8765
EXCLUDED = GRAPH_TOPICS  # bridged only when named explicitly
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'


@dataclass
class Forwarded:
    """One bridged topic: its type, Foxglove channel, raw subscription and message count."""

    topic: str
    msgtype: str
    channel: Channel
    subscription: Subscription | None  # None until made (its callback holds the entry)
    messages: int = 0


class _ClientPublishOptions(TypedDict, total=False):
    """The keyword arguments of ``foxglove.start_server`` for client publishing. Its
    ``server_listener`` is typed ``foxglove.websocket.ServerListener``, a Protocol of 12 callbacks;
    :class:`ClientPublish` has those of client publishing and subscriptions, not the parameter and
    playback ones (capabilities this server does not offer)."""

    capabilities: list[Capability]
    supported_encodings: list[str]
    server_listener: ClientPublish


def _forwarder(entry: Forwarded) -> Callable[[bytes], None]:
    """The raw-subscription callback of ``entry`` (one argument: rclpy passes only the CDR bytes)."""

    def on_message(data: bytes) -> None:
        entry.messages += 1
        entry.channel.log(data, log_time=time.time_ns())

    return on_message


class FoxgloveBridge:
    """Serve the ROS graph seen by ``node`` on a Foxglove WebSocket server at ``host``:``port``.

    ``topics``: only these (absolute names; '' prefix '/' added), else every topic but
    :data:`EXCLUDED`. ``port=0`` picks a free port (see :attr:`port`). ``allowed_origins``: web
    origins accepted besides none and localhost (:mod:`~skidsteer_power.nodes.foxglove_front`).
    ``allow_publish``: topics clients may publish to (CDR of the type they advertise).
    """

    def __init__(
        self,
        node: Node,
        *,
        host: str = '127.0.0.1',
        port: int = DEFAULT_PORT,
        topics: Sequence[str] = (),
        discover_period_s: float = 0.5,
        name: str = 'skidsteer_power',
        allowed_origins: Sequence[str] = (),
        allow_publish: Sequence[str] = (),
    ) -> None:
        import foxglove
        from foxglove.websocket import Capability

        from skidsteer_power.nodes.foxglove_front import FrontDoor, backend_certificate

        self._foxglove = foxglove
        self.node = node
        self.topics = {absolute_topic(t) for t in topics}
        self.forwarded: dict[str, Forwarded] = {}
        self.skipped: dict[str, str] = {}
        self.context = foxglove.Context()
        self.client_publish = ClientPublish(node, allow_publish) if allow_publish else None
        publish: _ClientPublishOptions = {}
        if self.client_publish is not None:
            publish = {
                'capabilities': [Capability.ClientPublish],
                'supported_encodings': [MESSAGE_ENCODING],
                'server_listener': self.client_publish,
            }
        cert, key = backend_certificate()  # the backend speaks TLS to the front door only (issue 34)
        try:
            self.server = foxglove.start_server(
                name=name,
                host='127.0.0.1',
                port=0,
                context=self.context,
                tls_cert=cert,
                tls_key=key,
                **publish,  # type: ignore[arg-type]  # ClientPublish: see _ClientPublishOptions
            )
        except (OSError, RuntimeError) as err:
            raise InputError(f'cannot start the Foxglove server on loopback: {err}') from err
        if self.client_publish is not None:
            self.client_publish.server = self.server  # refusals are answered with a status message
        try:
            upstream = f'wss://127.0.0.1:{self.server.port}'
            self.front = FrontDoor(host, port, upstream, allowed_origins, upstream_certificate=cert)
        except OSError as err:
            self.server.stop()
            raise InputError(f'cannot serve Foxglove on {host}:{port}: {err}') from err
        self.discover()
        self._timer = node.create_timer(discover_period_s, self.discover)

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return self.front.port

    def _known(self, topic: str) -> bool:
        return topic in self.forwarded or topic in self.skipped

    def discover(self) -> None:
        """Bridge every wanted topic that appeared on the graph since the last call."""
        discover_topics(self.node, self.topics, self._known, self._forward, self._skip)

    def _skip(self, topic: str, reason: str) -> None:
        self.skipped[topic] = reason
        LOG.warning('not bridging %s: %s', topic, reason)

    def _forward(self, topic: str, msgtype: str) -> None:
        cls = message_class(msgtype)
        text, _ = message_definition(msgtype)
        schema = self._foxglove.Schema(name=msgtype, encoding=SCHEMA_ENCODING, data=text.encode('utf-8'))
        channel = self._foxglove.Channel(
            topic, schema=schema, message_encoding=MESSAGE_ENCODING, context=self.context
        )
        entry = Forwarded(topic, msgtype, channel, None)
        entry.subscription = self.node.create_subscription(
            cls, topic, _forwarder(entry), self._qos_for(topic), raw=True
        )
        self.forwarded[topic] = entry
        LOG.info('bridging %s (%s)', topic, msgtype)

    def _qos_for(self, topic: str) -> QoSProfile:
        """Best effort, volatile; transient-local (reliable if every publisher is) for latched topics."""
        publishers = [info.qos_profile for info in self.node.get_publishers_info_by_topic(topic)]
        if publishers and all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers):
            reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
            return QoSProfile(
                depth=10,
                durability=DurabilityPolicy.TRANSIENT_LOCAL,
                reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            )
        return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)

    def close(self) -> None:
        """Stop the server and the subscriptions."""
        self._timer.cancel()
        self.front.close()
        for entry in self.forwarded.values():
            self.node.destroy_subscription(entry.subscription)  # type: ignore[arg-type]  # made in _forward
            entry.channel.close()
        self.server.stop()


class ClientPublish:
    """The SDK server listener for client publishing: a client channel on an allowed topic, CDR
    encoded, of an installed message type, gets an rclpy publisher; its messages are published as
    the serialized bytes they are. Anything else is refused with a warning and never published."""

    def __init__(self, node: Node, topics: Sequence[str]) -> None:
        self.node = node
        self.topics = {absolute_topic(t) for t in topics}
        # (client id, client channel id) -> (topic, publisher)
        self.publishers: dict[tuple[int, int], tuple[str, Publisher]] = {}
        self.published: dict[str, int] = dict.fromkeys(sorted(self.topics), 0)
        self.refused = 0
        self.server: WebSocketServer | None = None  # set once it runs

    # The SDK calls every ServerListener method it knows of (foxglove-sdk 0.30: subscribe and
    # unsubscribe for each channel a client views, whatever the capabilities): a missing one logged
    # "Callback failed: AttributeError" for each (issue 37 item 6). Subscriptions need nothing here.
    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        """A client subscribed to a bridged channel (the SDK sends it the channel's messages)."""

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        """A client unsubscribed from a bridged channel."""

    def on_connection_graph_subscribe(self) -> None:
        """Not offered (no connectionGraph capability)."""

    def on_connection_graph_unsubscribe(self) -> None:
        """Not offered (no connectionGraph capability)."""

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        topic = absolute_topic(channel.topic)
        reason = ''
        if topic not in self.topics:
            reason = f'publishing is allowed on {", ".join(sorted(self.topics))} only'
        elif channel.encoding != MESSAGE_ENCODING:
            reason = f'encoding {channel.encoding!r} (only {MESSAGE_ENCODING})'
        else:
            try:
                cls = message_class(channel.schema_name)
            except InputError as err:
                reason = str(err)
        publisher = None
        if not reason:
            try:
                publisher = self.node.create_publisher(cls, topic, 10)
            except RCLError:  # another type on this topic in this process (DDS: one type per topic)
                held = sorted({info.topic_type for info in self.node.get_publishers_info_by_topic(topic)})
                reason = (
                    f'{topic} is {" / ".join(held) or "another type"} in the bridge process, not '
                    f'{channel.schema_name}'
                )
        if publisher is None:
            self._refuse(client, topic, channel.schema_name, reason)
            return
        self.publishers[(client.id, channel.id)] = (topic, publisher)
        LOG.info('client %d publishes %s (%s)', client.id, topic, channel.schema_name)

    def _refuse(self, client: Client, topic: str, schema_name: str, reason: str) -> None:
        """Log the refusal and send it back as a warning status (to every client: foxglove-sdk 0.30
        has no per-client status; the message names the client)."""
        self.refused += 1
        LOG.warning('refused a client channel on %s (%s): %s', topic, schema_name, reason)
        if self.server is not None:
            from foxglove.websocket import StatusLevel

            message = f'client {client.id}: refused channel {topic} ({schema_name}): {reason}'
            self.server.publish_status(message, StatusLevel.Warning)

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        entry = self.publishers.pop((client.id, client_channel_id), None)
        if entry is not None:
            self.node.destroy_publisher(entry[1])

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        entry = self.publishers.get((client.id, client_channel_id))
        if entry is None:
            return
        topic, publisher = entry
        publisher.publish(bytes(data))
        self.published[topic] += 1
