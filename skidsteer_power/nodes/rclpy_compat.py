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
from typing import Any

import rclpy.logging
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle.node import LifecycleNodeMixin

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

_rclpy: Any = rclpy_implementation
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


Refused = Callable[[Any, Any, Exception], None]
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

    def on_change_state(self: Any, request: Any, response: Any) -> Any:
        try:
            return stock(self, request, response)
        except errors as err:
            on_refused(self, request, err)
            response.success = False
            return response

    setattr(node_class, CHANGE_STATE_HANDLER, on_change_state)
    return True
