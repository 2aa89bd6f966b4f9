"""Every rclpy internal the package relies on, in one place, checked against the installed rclpy.

Two speed-ups and one safety net reach below rclpy's public API:

- :class:`~skidsteer_power.nodes.spin.LeanExecutor` keeps its wait set between waits (issue 18):
  it needs ``_rclpy.WaitSet`` and the executor attributes in :data:`EXECUTOR_INTERNALS`;
- :class:`~skidsteer_power.nodes.spin.Batched` takes queued messages with the subscription's handle;
- the DES driver answers ``success: false`` to a lifecycle transition the current state does not
  have, where rclpy's change_state handler raises (and ends the spin). It replaces the name-mangled
  handler ``LifecycleNodeMixin.__on_change_state`` (:data:`CHANGE_STATE_HANDLER`).

:func:`check` looks at the installed rclpy once per process (its version and whether each internal
is where :data:`TESTED_RCLPY` had it) and logs one warning for each path that falls back to stock
rclpy: the executor spins as rclpy's own ``SingleThreadedExecutor`` (correct, only slower), and an
invalid transition raises as in stock rclpy (the driver's exception path still zeroes the motors).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.metadata
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import rclpy.logging
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle.node import LifecycleNodeMixin

if TYPE_CHECKING:
    from lifecycle_msgs.srv import ChangeState
    from rclpy.destroyable import DestroyableType
    from rclpy.lifecycle import LifecycleNode

    from skidsteer_power.nodes.ros_types import RosMessage

TESTED_RCLPY = ('7.1.5', '7.1.6')
"""rclpy versions these internals were read from and tested with (ROS 2 Jazzy)."""
EXECUTOR_INTERNALS = (
    '_guard',
    '_sigint_gc',
    '_tasks',
    '_context',
    '_is_shutdown',
    '_cb_iter',
    '_work_tracker',
)
"""Attributes of rclpy's ``Executor`` the lean executor reads."""
CHANGE_STATE_HANDLER = '_LifecycleNodeMixin__on_change_state'
"""rclpy's lifecycle change_state service handler (``LifecycleNodeMixin.__on_change_state``)."""


# The C-extension handles, for annotations only: this module imports (and check() falls back) on
# an rclpy without rclpy.destroyable too
if TYPE_CHECKING:

    class EntityHandle(DestroyableType, Protocol):
        """The C-extension handle of an rclpy entity (its ``handle``: ``_rclpy.Timer``, ``Subscription``,
        ``Service``, ``Client``, ``GuardCondition``): held (a context manager) while used, and its address.
        pybind11 objects without Python types; rclpy's :class:`~rclpy.destroyable.DestroyableType` and
        these Protocols name what is used."""

        @property
        def pointer(self) -> int: ...

    class TimerHandle(EntityHandle, Protocol):
        """``_rclpy.Timer``."""

        def is_timer_ready(self) -> bool: ...
        def call_timer(self) -> None: ...

    class SubscriptionHandle(EntityHandle, Protocol):
        """``_rclpy.Subscription``: ``take_message`` gives (message or bytes, message info), or None."""

        def take_message(self, msg_type: object, raw: bool) -> tuple[RosMessage, object] | None: ...

    class RequestId(Protocol):
        """rmw's request id in a service info."""

        @property
        def sequence_number(self) -> int: ...

    class ServiceInfo(Protocol):
        """rmw's service info (the header of a request or a response)."""

        @property
        def request_id(self) -> RequestId: ...

    class ServiceHandle(EntityHandle, Protocol):
        """``_rclpy.Service``: ``service_take_request`` gives (request, header), or (None, None)."""

        def service_take_request(self, request_type: object) -> tuple[RosMessage, ServiceInfo | None]: ...

    class ClientHandle(EntityHandle, Protocol):
        """``_rclpy.Client``: ``take_response`` gives (header, response), or (None, None)."""

        def take_response(self, response_type: object) -> tuple[ServiceInfo | None, RosMessage]: ...

    class WaitSetHandle(Protocol):
        """``_rclpy.WaitSet``: entities added by their handles, a wait, the ready ones by pointer."""

        def clear_entities(self) -> None: ...
        def add_guard_condition(self, handle: EntityHandle) -> None: ...
        def wait(self, timeout_nsec: int) -> None: ...
        def get_ready_entities(self, kind: str) -> list[int]: ...

    class RclpyExtension(Protocol):
        """What the lean executor uses of rclpy's C extension (where :func:`check` found it)."""

        def WaitSet(  # the extension's class, called as a constructor
            self,
            subscriptions: int,
            guard_conditions: int,
            timers: int,
            clients: int,
            services: int,
            events: int,
            context: object,
        ) -> WaitSetHandle: ...


_rclpy: RclpyExtension = rclpy_implementation
"""rclpy's C extension (``WaitSet``, entity handles), for the lean executor."""


@dataclasses.dataclass(frozen=True)
class RclpySupport:
    """What the installed rclpy offers of the internals this package uses.

    Attributes
    ----------
    version : the installed rclpy's version ('unknown' if its metadata is missing)
    tested : True if it is one of :data:`TESTED_RCLPY`
    wait_set : rclpy's C extension has ``WaitSet`` (the lean executor can build its own)
    change_state_handler : ``LifecycleNodeMixin`` has the mangled change_state handler
    """

    version: str
    tested: bool
    wait_set: bool
    change_state_handler: bool

    def lean_executor(self, executor: object) -> bool:
        """True if the lean executor can run on ``executor`` (an rclpy ``Executor`` instance)."""
        return self.wait_set and all(hasattr(executor, name) for name in EXECUTOR_INTERNALS)


def rclpy_version() -> str:
    """The installed rclpy's version (from its package metadata), or 'unknown'."""
    for distribution in ('rclpy', 'ros-rclpy'):
        try:
            return importlib.metadata.version(distribution)
        except importlib.metadata.PackageNotFoundError:
            continue
    return 'unknown'


@functools.cache
def check() -> RclpySupport:
    """Look at the installed rclpy (once per process); log a warning for each fallback."""
    version = rclpy_version()
    support = RclpySupport(
        version=version,
        tested=version in TESTED_RCLPY,
        wait_set=hasattr(_rclpy, 'WaitSet'),
        change_state_handler=callable(getattr(LifecycleNodeMixin, CHANGE_STATE_HANDLER, None)),
    )
    logger = rclpy.logging.get_logger('rclpy_compat')
    if not support.tested:
        logger.info(f'rclpy {version} is not one of {", ".join(TESTED_RCLPY)}: its internals are checked')
    if not support.wait_set:
        logger.warning(f"rclpy {version} has no _rclpy.WaitSet: the lean executor runs as rclpy's own")
    if not support.change_state_handler:
        logger.warning(
            f'rclpy {version} has no {CHANGE_STATE_HANDLER}: an invalid lifecycle transition raises as in '
            'stock rclpy instead of answering success: false'
        )
    return support


Refused = Callable[['LifecycleNode', 'ChangeState.Request', Exception], None]
"""``on_refused(node, request, error)``: told of a transition answered with ``success: false``."""


def refuse_invalid_transitions(
    node_class: type, errors: tuple[type[Exception], ...], on_refused: Refused
) -> bool:
    """Make ``node_class`` (a ``LifecycleNodeMixin`` subclass) answer ``success: false`` to a
    transition rclpy's handler raises one of ``errors`` for, and tell ``on_refused``.

    Returns False (and leaves the class as stock rclpy) if this rclpy has no such handler.
    """
    if not check().change_state_handler:
        return False
    stock = getattr(LifecycleNodeMixin, CHANGE_STATE_HANDLER)

    def on_change_state(
        self: LifecycleNode, request: ChangeState.Request, response: ChangeState.Response
    ) -> ChangeState.Response:
        try:
            return stock(self, request, response)
        except errors as err:
            on_refused(self, request, err)
            response.success = False
            return response

    setattr(node_class, CHANGE_STATE_HANDLER, on_change_state)
    return True
