"""Static types for what rclpy and the ROS message packages leave untyped, for the nodes' annotations.

The message packages (geometry_msgs, sensor_msgs, ...) ship no ``py.typed``: to mypy every rclpy
message class, and so every message, is untyped. A known message type is still named by its class
(``msg: TwistStamped``); :data:`RosMessage` names a message whose type is known only at run time
(a subscription's callback in the shared plumbing, a decoder's result). The Protocols name the
fields the nodes read of messages that come either from rclpy or decoded by rosbags
(:mod:`skidsteer_power.nodes.wire`), whose classes differ but whose fields agree.
:class:`NodeKwargs` is what a node's ``**node_kwargs`` forward to :class:`rclpy.node.Node`.

Type definitions only, no behaviour (the rclpy C-extension handles the lean executor uses are named
in :mod:`skidsteer_power.nodes.rclpy_compat`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, TypedDict

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.parameter import Parameter

RosMessage = Any  # Any: a ROS message of a type known at run time only (see below)
"""An instance of a ROS message class whose type is known at run time only: what a subscription of
the shared plumbing (:class:`~skidsteer_power.nodes.spin.Batched`, the cmd_vel input) hands its
callback, or a rosbags decoder returns for an rclpy class (:func:`~skidsteer_power.nodes.wire.
decoder`): the message packages ship no types (to mypy each rclpy message class is untyped
already) and a decoded message's class depends on the argument; the reader names what it reads by a
Protocol below or by the message's class. The package's one such alias for ROS messages, as
:data:`~skidsteer_power.jsonout.JsonObject` is for JSON objects."""


class NodeKwargs(TypedDict, total=False):
    """The keyword arguments of :class:`rclpy.node.Node` (rclpy 7, Jazzy), which a node class of
    this package takes as ``**node_kwargs`` and hands on (besides its name)."""

    context: Context | None
    cli_args: list[str] | None
    namespace: str | None
    use_global_arguments: bool
    enable_rosout: bool
    start_parameter_services: bool
    parameter_overrides: list[Parameter] | None
    allow_undeclared_parameters: bool
    automatically_declare_parameters_from_overrides: bool
    enable_logger_service: bool


class LifecycleNodeKwargs(NodeKwargs, total=False):
    """The keyword arguments of :class:`rclpy.lifecycle.LifecycleNode`: a node's and its own."""

    enable_communication_interface: bool


class TimeLike(Protocol):
    """builtin_interfaces/Time, rclpy's or rosbags'."""

    @property
    def sec(self) -> int: ...
    @property
    def nanosec(self) -> int: ...


class Vector3Like(Protocol):
    """geometry_msgs/Vector3, rclpy's or rosbags'."""

    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def z(self) -> float: ...


class TwistLike(Protocol):
    """geometry_msgs/Twist, rclpy's or rosbags' (what a TwistStamped's ``twist`` is too)."""

    @property
    def linear(self) -> Vector3Like: ...
    @property
    def angular(self) -> Vector3Like: ...
