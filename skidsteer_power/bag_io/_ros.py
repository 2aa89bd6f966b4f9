"""rclpy helpers shared by record, replay and the Foxglove bridge: message classes by type name, QoS
conversion, discovery of the topics on the graph."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from rclpy.node import Node

# Queue depth for recording and replay: deep enough that a 2 kHz burst never overwrites a message
# the other side has not taken yet.
QUEUE_DEPTH = 1000

# Topics every ROS graph carries; recorded or bridged only when named explicitly.
GRAPH_TOPICS = frozenset({'/rosout', '/parameter_events'})


def message_class(msgtype: str) -> type:
    """The rclpy message class of ``pkg/msg/Name``. Raises InputError if it is not installed."""
    parts = msgtype.split('/')
    if len(parts) != 3 or not all(parts):
        raise InputError(f'not a ROS message type name: {msgtype!r}')
    package, kind, name = parts
    try:
        module = importlib.import_module(f'{package}.{kind}')
        cls: type = getattr(module, name)  # a generated message class
        return cls
    except (ImportError, AttributeError) as err:
        raise InputError(f'message type {msgtype} is not installed for Python ({err})') from err


def _qos_time(duration: Duration) -> QosTime:
    sec, nsec = divmod(int(duration.nanoseconds), 1_000_000_000)
    return QosTime(sec, nsec)


def to_bag_qos(profile: QoSProfile) -> Qos:
    """A publisher's rclpy QoS profile as the rosbags record stored in a bag's metadata."""
    return Qos(
        history=QosHistory(int(profile.history)),
        depth=int(profile.depth),
        reliability=QosReliability(int(profile.reliability)),
        durability=QosDurability(int(profile.durability)),
        deadline=_qos_time(profile.deadline),
        lifespan=_qos_time(profile.lifespan),
        liveliness=QosLiveliness(int(profile.liveliness)),
        liveliness_lease_duration=_qos_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def matching_qos(
    reliable: Sequence[bool], transient_local: Sequence[bool], depth: int = QUEUE_DEPTH
) -> QoSProfile:
    """QoS that matches every endpoint described: reliable only if all are, transient-local likewise.

    ``reliable`` and ``transient_local`` hold one flag per known endpoint (empty: reliable, volatile).
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if all(reliable) else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if transient_local and all(transient_local)
        else DurabilityPolicy.VOLATILE,
        liveliness=LivelinessPolicy.AUTOMATIC,
    )


def qos_for_stored(profiles: Sequence[Qos]) -> QoSProfile:
    """Publisher QoS for replay from the profiles a bag stored for the original publishers."""
    return matching_qos(
        [p.reliability != QosReliability.BEST_EFFORT for p in profiles],
        [p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles],
    )


def absolute_topic(name: str) -> str:
    """``name`` with a leading '/' (ROS resolves a relative name against the root namespace here)."""
    return name if name.startswith('/') else f'/{name}'


def discover_topics(
    node: Node,
    wanted: Collection[str],
    known: Callable[[str], bool],
    take: Callable[[str, str], None],
    skip: Callable[[str, str], None],
) -> None:
    """Hand every new topic on ``node``'s graph to ``take(name, type)``, or to ``skip(name, reason)``.

    ``wanted``: absolute topic names, or empty for every topic but :data:`GRAPH_TOPICS`. Topics for
    which ``known(name)`` is true (taken or skipped before) are passed over. A topic published with
    several types is skipped; so is one whose ``take`` raises InputError (e.g. its type is not
    installed), with the error as the reason. Called on a timer, it picks topics up as they appear.
    """
    for name, types in node.get_topic_names_and_types():
        if known(name) or (name not in wanted if wanted else name in GRAPH_TOPICS):
            continue
        if len(types) != 1:
            skip(name, f'published with several types ({", ".join(types)})')
            continue
        try:
            take(name, types[0])
        except InputError as err:
            skip(name, str(err))
