"""The one ``main`` every node shares (ros2/demos style): init, spin, clean shutdown, one error line."""

from __future__ import annotations

import inspect
import sys
from collections.abc import Callable
from typing import Any

import rclpy
import rclpy.logging
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Task

from skidsteer_power.errors import SkidsteerError


class LeanExecutor(SingleThreadedExecutor):
    """rclpy's SingleThreadedExecutor without its two guard-condition wake-ups per callback.

    rclpy (7.1.x) triggers the executor's guard condition twice around every callback, so that a
    wait set being built in another thread re-reads the entity; in a single thread no wait is in
    progress while a callback runs, so each trigger only makes the next wait return at once with
    nothing to do, and the whole wait set (every subscription, timer, service and waitable, built in
    Python) is rebuilt once more: about half of the executor's CPU per message (issue 18). This is
    rclpy's own ``_make_handler`` minus the triggers. It relies on that private method (pinned rclpy
    7.1.6; ``test/test_nodes_spin.py`` checks callbacks, timers, services and shutdown run with it) and
    is only for nodes whose callbacks are plain functions that never await.
    """

    _PRIVATE = ('_tasks', '_tasks_lock', '_work_tracker', '_is_shutdown')

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        base = getattr(SingleThreadedExecutor, '_make_handler', None)
        expected = ['self', 'entity', 'node', 'take_from_wait_list']
        self.lean = (
            base is not None
            and list(inspect.signature(base).parameters) == expected
            and all(hasattr(self, name) for name in self._PRIVATE)
        )
        if not self.lean:  # another rclpy: its own executor, unchanged (correct, only slower)
            rclpy.logging.get_logger('spin').warning(
                "LeanExecutor: this rclpy's executor internals differ from 7.1.6; using it unchanged"
            )

    def _make_handler(self, entity: Any, node: Any, take_from_wait_list: Callable[[Any], Any]) -> Task:
        if not self.lean:
            return super()._make_handler(entity, node, take_from_wait_list)
        entity._executor_event = True  # not back in the wait set until taken, as in rclpy

        async def handler(entity: Any, is_shutdown: bool, work_tracker: Any) -> None:
            if is_shutdown or not entity.callback_group.beginning_execution(entity):
                entity._executor_event = False
                return
            with work_tracker:
                call_coroutine = take_from_wait_list(entity)
                entity._executor_event = False
                try:
                    if call_coroutine is not None:
                        await call_coroutine()
                finally:
                    entity.callback_group.ending_execution(entity)

        task = Task(handler, (entity, self._is_shutdown, self._work_tracker), executor=self)
        with self._tasks_lock:
            self._tasks.append((task, entity, node))
        return task


class Batched:
    """A subscription callback that, after its message, also takes up to ``batch - 1`` messages
    already queued on the same subscription and handles them at once, in order.

    Each message the executor dispatches costs a wait-set build in Python (about as much as the
    estimator's own work per message); when inputs come faster than they are handled, a backlog
    builds up and every message pays it again. Taking the queued ones here keeps every message and its
    order but pays once per batch (issue 18: CPU per message at 1 kHz under load 0.72x). Without a
    backlog nothing changes (the first take finds the queue empty). ``batch`` bounds how long the other
    inputs wait. Set ``subscription`` to the subscription created with this callback.
    """

    def __init__(self, callback: Callable[[Any], None], batch: int = 8) -> None:
        self.callback = callback
        self.batch = batch
        self.subscription: Any = None

    def __call__(self, msg: Any) -> None:
        self.callback(msg)
        sub = self.subscription
        for _ in range(self.batch - 1):
            with sub.handle:  # what rclpy's executor does to take one (pinned rclpy 7.1.6)
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                return
            self.callback(taken[0])


def spin_node(
    make_node: Callable[[], Node],
    name: str,
    args: list[str] | None = None,
    executor: Callable[[], Any] | None = None,
) -> None:
    """Create the node with ``make_node`` and spin it until Ctrl-C or an external shutdown.

    ``executor`` makes the executor (None: rclpy's global one). A bad configuration
    (``SkidsteerError`` or a rejected parameter) is one line on stderr and exit code 2; the node is
    always destroyed (its ``destroy_node`` does the safe stop) and rclpy shut down.
    """
    rclpy.init(args=args)
    node = None
    exit_code = 0
    try:
        node = make_node()
        rclpy.spin(node, executor() if executor is not None else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SkidsteerError, ParameterException) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        exit_code = 2
    except Exception:
        # SIGINT/SIGTERM shut the context down from rclpy's signal handler, possibly while a callback
        # was publishing ("publisher's context is invalid"): that is the shutdown, not a failure
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if exit_code:
        sys.exit(exit_code)
