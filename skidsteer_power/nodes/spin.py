"""How the nodes spin: the one ``main`` every node shares (ros2/demos style: init, spin, clean
shutdown, one error line), and for the per-message nodes a lean executor (:class:`LeanExecutor`),
publishers without QoS-event handlers (:class:`QuietNode`) and backlogs taken in batches
(:class:`Batched`)."""

from __future__ import annotations

import dataclasses
import inspect
import sys
from collections.abc import Callable, Coroutine, Generator, Mapping, Sequence
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, TypedDict, TypeVar, cast

import rclpy
import rclpy.logging
import rclpy.utilities
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.utilities import timeout_sec_to_nsec
from rclpy.waitable import NumberOfEntities, Waitable

from skidsteer_power.errors import SkidsteerError
from skidsteer_power.nodes import rclpy_compat
from skidsteer_power.nodes.rclpy_compat import _rclpy
from skidsteer_power.stop_signals import StopFlag, stop_on_signals

if TYPE_CHECKING:
    from typing import Any, Unpack

    from rclpy.callback_groups import CallbackGroup
    from rclpy.client import Client
    from rclpy.context import Context, ContextHandle
    from rclpy.guard_condition import GuardCondition
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.qos import QoSProfile
    from rclpy.qos_overriding_options import QoSOverridingOptions
    from rclpy.service import Service

    from skidsteer_power.nodes.rclpy_compat import (
        ClientHandle,
        EntityHandle,
        ServiceHandle,
        ServiceInfo,
        SubscriptionHandle,
        TimerHandle,
        WaitSetHandle,
    )
    from skidsteer_power.nodes.ros_types import RosMessage

    _KindEntity = Any  # Any: a Timer, Subscription, Service or Client: the one its dict key names
    """An entity in a dict by kind ('timer', 'subscription', 'service', 'client'), whose values are
    of the key's kind (a str-keyed dict cannot say which: each kind is read by its own key)."""
    _EntityT = TypeVar('_EntityT', Timer, Subscription, Service, Client)
    _HandleT = TypeVar('_HandleT')
    _TakenT = TypeVar('_TakenT')
    _GoneT = TypeVar('_GoneT')


class LeanExecutor(SingleThreadedExecutor):
    """A single-threaded executor that keeps its wait set from one wait to the next.

    rclpy's executor (7.1.x) rebuilds its wait set in Python before every wait: it walks every
    node's entities, filters them by callback group, enters each handle, allocates a new wait set,
    wraps each ready callback in a coroutine Task and wakes itself twice around it. For a node whose
    own work per message is ~100 us, that bookkeeping was most of its CPU (issue 18). This executor
    builds the entity lists and the wait set once, and again only after its guard condition fired
    (rclpy fires it whenever a node or an entity is added or removed). Before each wait it re-adds the
    same handles (a few C calls); after it, it calls the ready callbacks directly, in rclpy's order:
    timers, subscriptions, services, clients, then waitables (QoS events) by their own ``execute``.

    It relies on rclpy internals (``_rclpy.WaitSet``, the entities' ``handle``, the executor's
    attributes in :data:`~skidsteer_power.nodes.rclpy_compat.EXECUTOR_INTERNALS`), checked against
    the installed rclpy by :mod:`skidsteer_power.nodes.rclpy_compat`;
    ``test/test_nodes_spin.py`` exercises every kind of entity over real DDS. It is for nodes whose
    callbacks are plain functions: while a node has a coroutine callback or a guard condition, or a
    Task is pending (a future's done-callback), it spins with rclpy's own code; with another rclpy it
    is rclpy's executor unchanged.
    """

    def __init__(self, *, context: Context | None = None) -> None:
        super().__init__(context=context)
        self.lean = rclpy_compat.check().lean_executor(self)
        if not self.lean:  # another rclpy: its own executor, unchanged (correct, only slower)
            rclpy.logging.get_logger('spin').warning(
                f"LeanExecutor: rclpy {rclpy_compat.check().version}'s executor internals differ; "
                'using its own executor unchanged'
            )
        self._plan: _WaitPlan | None = None

    def spin_once(self, timeout_sec: float | None = None) -> None:
        if self._is_shutdown:
            return
        if not self.lean or self._tasks:
            super().spin_once(timeout_sec)
            return
        if self._plan is None:
            self._plan = _WaitPlan.build(self.get_nodes(), (self._guard, self._sigint_gc), self._context)
        if self._plan.wait_set is None:  # something only rclpy's own executor runs
            self._plan = None
            super().spin_once(timeout_sec)
            return
        generator: Generator[object, None, None] | None = self._cb_iter
        if generator is not None:  # rclpy's, from a spin it served: it may hold entities' handles
            generator.close()
            self._cb_iter = None
        ready = self._plan.wait(timeout_sec_to_nsec(timeout_sec))
        if self._shut_down():  # by another thread, during the wait
            return
        if not self._context.ok():
            raise ExternalShutdownException()
        if ready.rebuild:  # a node or an entity came or went, or a handle is gone
            self._plan = None
        with self._work_tracker:  # what shutdown(timeout_sec) waits for, as in rclpy
            ready.run(self)

    def _shut_down(self) -> bool:
        return self._is_shutdown


@dataclasses.dataclass
class _Ready:
    """What one wait found ready; taken and run after the wait set's handles were released."""

    rebuild: bool = False
    timers: list[Timer] = dataclasses.field(default_factory=list)
    subscriptions: list[Subscription] = dataclasses.field(default_factory=list)
    services: list[Service] = dataclasses.field(default_factory=list)
    clients: list[Client] = dataclasses.field(default_factory=list)
    waitables: list[Waitable] = dataclasses.field(default_factory=list)

    def run(self, executor: Executor) -> None:
        """Take each ready entity's data and call its callback (what rclpy's ``_take_*`` do)."""
        for timer in self.timers:
            if _taken(timer, _call_timer, False):
                timer.callback()
        for sub in self.subscriptions:
            info = _taken(sub, _take_message, None)
            if info is not None:
                message_only = sub._callback_type is Subscription.CallbackType.MessageOnly
                sub.callback(*(info[:1] if message_only else info))
        for srv in self.services:
            request, header = _taken(srv, _take_request, (None, None))
            if header is not None:
                # rclpy 7 types srv_type and callback by TypeVars its Service does not bind (as below)
                srv.send_response(srv.callback(request, srv.srv_type.Response()), header)  # type: ignore[arg-type, attr-defined]  # rclpy TypeVars
        for client in self.clients:
            header, response = _taken(client, _take_response, (None, None))
            if header is None:
                continue
            try:
                future = client.get_pending_request(header.request_id.sequence_number)
            except KeyError:  # the request was cancelled
                continue
            future._set_executor(executor)
            future.set_result(response)
        for waitable in self.waitables:
            data = waitable.take_data()
            for future in waitable._futures:
                future._set_executor(executor)
            _run_to_end(waitable.execute(data))


def _taken(entity: _EntityT, take: Callable[[_HandleT, _EntityT], _TakenT], gone: _GoneT) -> _TakenT | _GoneT:
    """``take(handle, entity)`` with the entity's handle held; ``gone`` if it was destroyed."""
    try:
        with entity.handle:
            return take(entity.handle, entity)
    except InvalidHandle:
        return gone


def _call_timer(handle: TimerHandle, timer: Timer) -> bool:
    """Mark a ready timer as called; False if it is not ready after all (cancelled, as in rclpy)."""
    if not handle.is_timer_ready():
        return False
    handle.call_timer()
    return True


def _take_message(handle: SubscriptionHandle, sub: Subscription) -> tuple[RosMessage, object] | None:
    return handle.take_message(sub.msg_type, sub.raw)


# rclpy 7 types Service.srv_type and Client.srv_type by a TypeVar the class does not bind: to mypy the
# service class has no Request or Response


def _take_request(handle: ServiceHandle, srv: Service) -> tuple[RosMessage, ServiceInfo | None]:
    return handle.service_take_request(srv.srv_type.Request)  # type: ignore[attr-defined]  # rclpy TypeVar


def _take_response(handle: ClientHandle, client: Client) -> tuple[ServiceInfo | None, RosMessage]:
    return handle.take_response(client.srv_type.Response)  # type: ignore[attr-defined]  # rclpy TypeVar


def _run_to_end(coroutine: Coroutine[object, None, object]) -> None:
    """Run a coroutine that never suspends (a waitable's ``execute`` with a plain callback)."""
    try:
        coroutine.send(None)
    except StopIteration:
        return
    coroutine.close()
    raise RuntimeError("LeanExecutor: a waitable awaited something; it needs rclpy's own executor")


@dataclasses.dataclass
class _WaitPlan:
    """The entities a LeanExecutor waits on and the wait set that holds them, built once.

    ``wait_set`` is None when a node has something the plan does not run (a coroutine callback, a
    guard condition of its own): rclpy's executor spins then."""

    wait_set: WaitSetHandle | None
    handles: Sequence[AbstractContextManager[object]]  # entered around each wait, the context's last
    # (wait_set.add_*, handle), once per wait
    adders: list[tuple[Callable[[EntityHandle], None], EntityHandle]]
    waitables: list[Waitable]
    by_pointer: dict[str, dict[int, _KindEntity]]  # entity kind -> handle pointer -> entity
    guard_pointer: int

    KINDS = ('timer', 'subscription', 'service', 'client')

    @classmethod
    def build(
        cls, nodes: list[Node], guards: tuple[GuardCondition, GuardCondition], context: Context
    ) -> _WaitPlan:
        entities: dict[str, list[_KindEntity]] = {kind: [] for kind in cls.KINDS}
        waitables: list[Waitable] = []
        unsupported = False
        for node in nodes:
            entities['timer'] += node.timers
            entities['subscription'] += node.subscriptions
            entities['service'] += node.services
            entities['client'] += node.clients
            waitables += node.waitables
            unsupported |= bool(list(node.guards))
        callbacks = [e.callback for kind in ('timer', 'subscription', 'service') for e in entities[kind]]
        unsupported |= any(inspect.iscoroutinefunction(cb) for cb in callbacks)
        empty = cls(None, [], [], [], {}, 0)
        if unsupported:
            return empty
        try:
            count = NumberOfEntities(
                len(entities['subscription']),
                len(guards),
                len(entities['timer']),
                len(entities['client']),
                len(entities['service']),
            )
            for waitable in waitables:
                with waitable:
                    count += waitable.get_num_entities()
            wait_set: WaitSetHandle = _rclpy.WaitSet(
                count.num_subscriptions,
                count.num_guard_conditions,
                count.num_timers,
                count.num_clients,
                count.num_services,
                count.num_events,
                context.handle,
            )
            adders: list[tuple[Callable[[EntityHandle], None], EntityHandle]] = []
            by_pointer: dict[str, dict[int, _KindEntity]] = {}
            for kind in cls.KINDS:
                add = getattr(wait_set, f'add_{kind}')
                adders += [(add, e.handle) for e in entities[kind]]
                by_pointer[kind] = {e.handle.pointer: e for e in entities[kind]}
            adders += [(wait_set.add_guard_condition, gc.handle) for gc in guards]
            # a live context has a handle (rclpy types it Optional: None before init)
            handles = [handle for _, handle in adders] + [cast('ContextHandle', context.handle)]
            return cls(wait_set, handles, adders, waitables, by_pointer, guards[0].handle.pointer)
        except InvalidHandle:  # destroyed while being planned: plan again on the next spin
            return empty

    def wait(self, timeout_nsec: int) -> _Ready:
        """Wait up to ``timeout_nsec`` [ns] (-1: forever) and return what is ready."""
        wait_set: WaitSetHandle = self.wait_set  # type: ignore[assignment]  # spin_once waits on one
        entered: list[AbstractContextManager[object]] = []
        try:
            for handle in (*self.handles, *self.waitables):
                handle.__enter__()
                entered.append(handle)
            wait_set.clear_entities()
            for add, handle in self.adders:
                add(handle)
            for waitable in self.waitables:
                waitable.add_to_wait_set(wait_set)
            wait_set.wait(timeout_nsec)
            ready = {kind: wait_set.get_ready_entities(kind) for kind in self.KINDS}
            guards_ready = wait_set.get_ready_entities('guard_condition')
            waitables = [w for w in self.waitables if w.is_ready(wait_set)]
        except InvalidHandle:
            return _Ready(rebuild=True)
        finally:
            for handle in reversed(entered):
                handle.__exit__(None, None, None)
        entities = {kind: [self.by_pointer[kind][p] for p in ready[kind]] for kind in self.KINDS}
        return _Ready(
            self.guard_pointer in guards_ready,
            entities['timer'],
            entities['subscription'],
            entities['service'],
            entities['client'],
            waitables,
        )


class QuietNode(Node):
    """A node whose publishers (rclpy's parameter-events one too) carry no QoS-event handlers.

    rclpy gives every publisher two default handlers (incompatible QoS, incompatible type); each is a
    waitable the executor walks in Python on every wait (46 of power_estimator's 52 waitables; without
    them its CPU per input message fell by about a quarter, issue 18). A subscriber with an
    incompatible QoS or type still reports it on its side, and subscriptions keep their handlers.
    """

    if TYPE_CHECKING:  # rclpy 7 leaves these unannotated; their types, for subclasses' calls

        def get_logger(self) -> RcutilsLogger: ...
        def destroy_node(self) -> None: ...

    def create_publisher(
        self,
        msg_type: type,
        topic: str,
        qos_profile: QoSProfile | int,
        *,
        event_callbacks: PublisherEventCallbacks | None = None,
        **kwargs: Unpack[PublisherOptions],
    ) -> Publisher:
        quiet = event_callbacks or PublisherEventCallbacks(use_default_callbacks=False)
        return super().create_publisher(msg_type, topic, qos_profile, event_callbacks=quiet, **kwargs)


class PublisherOptions(TypedDict, total=False):
    """The other keyword arguments of :meth:`rclpy.node.Node.create_publisher` (rclpy 7)."""

    callback_group: CallbackGroup | None
    qos_overriding_options: QoSOverridingOptions | None
    publisher_class: type[Publisher]


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

    def __init__(self, callback: Callable[[RosMessage], None], batch: int = 8) -> None:
        self.callback = callback
        self.batch = batch
        self.subscription: Subscription = None  # type: ignore[assignment]  # set by its creator (class doc)

    def __call__(self, msg: RosMessage) -> None:
        self.callback(msg)
        sub = self.subscription
        for _ in range(self.batch - 1):
            with sub.handle:  # what rclpy's executor does to take one (pinned rclpy 7.1.6)
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                return
            self.callback(taken[0])


def node_command(module: str, namespace: str, params: Mapping[str, object] | None = None) -> list[str]:
    """The command line that runs a node module's ``main`` in a process of its own, as ``ros2 run``
    would: ``python -m module --ros-args -r __ns:=/namespace -p name:=value ...``."""
    argv = [sys.executable, '-m', module, '--ros-args', '-r', f'__ns:=/{namespace.lstrip("/")}']
    for name, value in (params or {}).items():
        argv += ['-p', f'{name}:={value}']
    return argv


SIGNAL_CHECK_S = 0.05
"""Longest wait of the spin loop [s]: a signal's Python handler runs only once the main thread is
back from the middleware's wait, so an idle node still sees a signal within this time."""


def spin_node(
    make_node: Callable[[], Node],
    name: str,
    args: list[str] | None = None,
    executor: Callable[[], Executor] | None = None,
) -> None:
    """Create the node with ``make_node`` and spin it until a signal or an external shutdown.

    ``executor`` makes the executor (None: rclpy's SingleThreadedExecutor). Every signal that would
    end the process (:data:`~skidsteer_power.stop_signals.TERMINATING_SIGNALS`, SIGINT and SIGTERM
    included: rclpy's own handlers are not installed) stops the spin, and stays caught until the node
    is destroyed, so a second one cannot cut the safe stop short. A bad configuration
    (``SkidsteerError`` or a rejected parameter) is one line on stderr and exit code 2; the node is
    always destroyed (its ``destroy_node`` does the safe stop) and rclpy shut down.
    """
    with stop_on_signals(StopFlag()) as stop:
        _spin_until_stopped(make_node, name, args, executor, stop)


def _spin_until_stopped(
    make_node: Callable[[], Node],
    name: str,
    args: list[str] | None,
    executor: Callable[[], Executor] | None,
    stop: StopFlag,
) -> None:
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    exit_code = 0
    try:
        node = make_node()
        spinner = executor() if executor is not None else SingleThreadedExecutor()
        spinner.add_node(node)
        while not stop.is_set():  # an external shutdown raises ExternalShutdownException from the wait
            spinner.spin_once(timeout_sec=SIGNAL_CHECK_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SkidsteerError, ParameterException) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        exit_code = 2
    except Exception:
        # an external shutdown (rclpy.shutdown from elsewhere) can invalidate the context while a
        # callback was publishing ("publisher's context is invalid"): that is the shutdown, not a failure
        if rclpy.utilities.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
            unsafe = getattr(node, 'unsafe_stop', '')  # des_driver: a motor possibly still enabled
            if unsafe:
                print(f'{name}: error: motors not confirmed stopped: {unsafe}', file=sys.stderr)
                exit_code = exit_code or 1
        rclpy.utilities.try_shutdown()
    if exit_code:
        sys.exit(exit_code)
