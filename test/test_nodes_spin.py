"""nodes/spin.py over real rclpy and DDS: LeanExecutor runs every callback, timer, service, client
response and QoS event once, does not wake itself after each callback, keeps its wait set until an
entity comes or goes, raises a callback's exception as rclpy does and hands coroutine callbacks to
rclpy's own executor; Batched takes a backlog in batches, every message once and in order;
power_estimator's own main (which spins with both) answers and exits cleanly on SIGTERM and SIGINT."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from rclpy.context import Context
from rclpy.event_handler import QoSRequestedIncompatibleQoSInfo, SubscriptionEventCallbacks
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from skidsteer_power.nodes.spin import Batched, LeanExecutor, node_command

N_MESSAGES = 50


def _spin_until(executor: Executor, condition: Callable[[], object], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, 'condition not met within the time limit'
        executor.spin_once(timeout_sec=0.01)


def _exercise(
    context: Context, executor_type: Callable[..., Executor]
) -> tuple[list[float], int, int, bool, int]:
    """Publish N_MESSAGES, run a timer and a service on ``executor_type``; returns (received values,
    timer ticks, service calls, the response's success, the executor's guard triggers while the
    messages and timer ticks were handled)."""
    ns = f'spin_{uuid.uuid4().hex[:8]}'
    node = rclpy.create_node('lean', namespace=ns, context=context)
    received: list[float] = []
    ticks = [0]
    calls = [0]

    def on_trigger(request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        calls[0] += 1
        response.success = True
        return response

    def on_x(m: Float64) -> None:
        received.append(m.data)

    node.create_subscription(Float64, 'x', on_x, 100)
    node.create_timer(0.01, lambda: ticks.__setitem__(0, ticks[0] + 1))
    node.create_service(Trigger, 'go', on_trigger)
    pub = node.create_publisher(Float64, 'x', 100)
    client = node.create_client(Trigger, 'go')
    executor = executor_type(context=context)
    executor.add_node(node)
    try:
        _spin_until(executor, lambda: pub.get_subscription_count() > 0 and client.service_is_ready())
        triggers = [0]
        trigger: Callable[[], None] = (
            executor._guard.trigger
        )  # count the executor's self wake-ups from here on

        def counted() -> None:
            triggers[0] += 1
            trigger()

        executor._guard.trigger = counted  # type: ignore[method-assign]  # a counting wrapper, on purpose
        for i in range(N_MESSAGES):
            pub.publish(Float64(data=float(i)))
        _spin_until(executor, lambda: len(received) >= N_MESSAGES and ticks[0] >= 3)
        wakeups = triggers[0]  # the service's future may wake the executor: not counted
        future = client.call_async(Trigger.Request())
        _spin_until(executor, future.done)
        for _ in range(20):  # anything still queued would show up as a duplicate now
            executor.spin_once(timeout_sec=0.005)
        return received, ticks[0], calls[0], future.result().success, wakeups
    finally:
        executor.shutdown()
        node.destroy_node()


def test_lean_executor_runs_everything_once_without_waking_itself(ros_context: Context) -> None:
    received, ticks, calls, success, triggers = _exercise(ros_context, LeanExecutor)
    assert received == [float(i) for i in range(N_MESSAGES)]  # each once, in order
    assert ticks >= 3 and calls == 1 and success
    assert triggers == 0
    # the control: rclpy's own executor wakes itself around every callback (what LeanExecutor saves)
    received, _, _, _, triggers = _exercise(ros_context, SingleThreadedExecutor)
    assert received == [float(i) for i in range(N_MESSAGES)]
    assert triggers >= 2 * N_MESSAGES


@contextlib.contextmanager
def _lean_node(context: Context, name: str) -> Iterator[tuple[Node, LeanExecutor]]:
    """A node spun by a LeanExecutor of its own; both shut down afterwards."""
    node = rclpy.create_node(name, namespace=f'{name}_{uuid.uuid4().hex[:8]}', context=context)
    executor = LeanExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()


def test_lean_executor_keeps_its_wait_set_until_an_entity_comes_or_goes(ros_context: Context) -> None:
    with _lean_node(ros_context, 'plan') as (node, executor):
        pub = node.create_publisher(Float64, 'x', 10)
        first: list[float] = []

        def on_first(m: Float64) -> None:
            first.append(m.data)

        sub = node.create_subscription(Float64, 'x', on_first, 10)
        _spin_until(executor, lambda: pub.get_subscription_count() > 0)
        pub.publish(Float64(data=1.0))
        _spin_until(executor, lambda: first == [1.0])
        # the guard fired by create_subscription may cost one more plan; from then on it stays
        _spin_until(executor, lambda: executor._plan is not None)
        plan = executor._plan
        for value in (2.0, 3.0):
            pub.publish(Float64(data=value))

            def arrived(v: float = value) -> bool:
                return first[-1] == v

            _spin_until(executor, arrived)
            assert executor._plan is plan  # the same wait set served every message
        # a new entity while spinning: planned in and served
        second: list[float] = []

        def on_second(m: Float64) -> None:
            second.append(m.data)

        node.create_subscription(Float64, 'x', on_second, 10)
        _spin_until(executor, lambda: pub.get_subscription_count() == 2)
        pub.publish(Float64(data=4.0))
        _spin_until(executor, lambda: first[-1] == 4.0 and second == [4.0])  # both served
        _spin_until(executor, lambda: executor._plan is not None)
        plan_now = executor._plan
        assert plan_now is not None and len(plan_now.by_pointer['subscription']) == 2
        # an entity gone: planned out, its handle released (destroyed), the rest still served
        node.destroy_subscription(sub)
        _spin_until(executor, lambda: pub.get_subscription_count() == 1)
        pub.publish(Float64(data=5.0))
        _spin_until(executor, lambda: second == [4.0, 5.0])
        assert first[-1] == 4.0
        _spin_until(executor, lambda: executor._plan is not None)
        plan_now = executor._plan
        assert plan_now is not None and len(plan_now.by_pointer['subscription']) == 1


def test_lean_executor_runs_qos_events_and_raises_callback_errors_like_rclpy(ros_context: Context) -> None:
    with _lean_node(ros_context, 'events') as (node, executor):
        incompatible: list[QoSRequestedIncompatibleQoSInfo] = []
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        callbacks = SubscriptionEventCallbacks(incompatible_qos=incompatible.append)

        def fail(msg: Float64) -> None:
            raise RuntimeError(f'callback failed on {msg.data}')

        # a reliable reader and a best-effort writer do not match: the reader's QoS event (a
        # waitable) reports it
        node.create_subscription(Float64, 'x', lambda m: None, reliable, event_callbacks=callbacks)
        node.create_publisher(Float64, 'x', best_effort)
        _spin_until(executor, lambda: bool(incompatible))
        assert incompatible[0].total_count >= 1
        node.create_subscription(Float64, 'y', fail, 10)
        pub = node.create_publisher(Float64, 'y', 10)
        _spin_until(executor, lambda: pub.get_subscription_count() > 0)
        pub.publish(Float64(data=7.0))
        with pytest.raises(RuntimeError, match=r'callback failed on 7\.0'):
            _spin_until(executor, lambda: False)


def test_lean_executor_hands_coroutine_callbacks_to_rclpy(ros_context: Context) -> None:
    with _lean_node(ros_context, 'coro') as (node, executor):
        received: list[float] = []

        async def on_message(msg: Float64) -> None:
            received.append(msg.data)

        # rclpy awaits a coroutine callback; its annotation says the callback returns None
        node.create_subscription(Float64, 'x', on_message, 10)  # type: ignore[arg-type]
        pub = node.create_publisher(Float64, 'x', 10)
        _spin_until(executor, lambda: pub.get_subscription_count() > 0)
        pub.publish(Float64(data=1.5))
        _spin_until(executor, lambda: received == [1.5])
        assert executor._plan is None  # rclpy's executor served it


def test_batched_takes_a_backlog_in_batches_every_message_once_in_order(ros_context: Context) -> None:
    received: list[float] = []
    dispatched = [0]  # how often the executor called the subscription's callback
    batched = Batched(lambda m: received.append(m.data), batch=8)

    def counted(msg: Float64) -> None:
        dispatched[0] += 1
        batched(msg)

    with _lean_node(ros_context, 'batched') as (node, executor):
        batched.subscription = node.create_subscription(Float64, 'x', counted, 100)
        pub = node.create_publisher(Float64, 'x', 100)
        _spin_until(executor, lambda: pub.get_subscription_count() > 0)
        for i in range(N_MESSAGES):  # a backlog: nothing is taken while they are published
            pub.publish(Float64(data=float(i)))
        time.sleep(0.2)  # all of them in the subscription's queue (same process, loopback)
        _spin_until(executor, lambda: len(received) >= N_MESSAGES)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.005)
        assert received == [float(i) for i in range(N_MESSAGES)]
        assert dispatched[0] <= N_MESSAGES // 4  # batches of up to 8: about 7 dispatches, not 50
        # no backlog: one message, one dispatch, nothing else taken
        pub.publish(Float64(data=-1.0))
        _spin_until(executor, lambda: len(received) == N_MESSAGES + 1)
        assert received[-1] == -1.0


@pytest.mark.parametrize('stop', [signal.SIGTERM, signal.SIGINT])
def test_power_estimator_main_answers_and_exits_cleanly(
    ros_context: Context, tmp_path: Path, stop: signal.Signals
) -> None:
    ns = f'main_{uuid.uuid4().hex[:8]}'
    params = {'map_cache_dir': tmp_path, 'persist': 'false', 'vehicle': 'test_robot_track'}
    argv = node_command('skidsteer_power.nodes.power_estimator', ns, params)
    proc = subprocess.Popen(
        argv, env=os.environ, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    probe = rclpy.create_node('probe', namespace=ns, context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    try:
        measured: list[JointState] = []
        probe.create_subscription(JointState, 'power/measured', measured.append, 10)
        pub = probe.create_publisher(JointState, 'joint_states', 10)
        _spin_until(executor, lambda: pub.get_subscription_count() > 0, timeout_s=60.0)
        joint = JointState(name=['left_motor', 'right_motor'], velocity=[300.0, 300.0], effort=[0.2, 0.2])

        def answered() -> bool:
            pub.publish(joint)
            return bool(measured)

        _spin_until(executor, answered)
        assert list(measured[-1].velocity) == [300.0, 300.0]  # echoed after the side mapping
        proc.send_signal(stop)
        assert proc.stderr is not None
        assert proc.wait(timeout=15) == 0, proc.stderr.read()
        assert 'Traceback' not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        probe.destroy_node()


# --------------------------------------------------------------------------- rclpy compatibility


def test_the_installed_rclpy_has_every_internal_we_use(ros_context: Context) -> None:
    from skidsteer_power.nodes import rclpy_compat

    support = rclpy_compat.check()
    assert support.tested, f'rclpy {support.version} is not in {rclpy_compat.TESTED_RCLPY}'
    assert support.wait_set and support.change_state_handler
    executor = SingleThreadedExecutor(context=ros_context)
    assert support.lean_executor(executor)
    executor.shutdown()
    assert not support.lean_executor(object())  # an executor without rclpy's attributes


def test_lean_executor_falls_back_to_rclpys_own_where_internals_differ(
    ros_context: Context, monkeypatch: pytest.MonkeyPatch
) -> None:
    from skidsteer_power.nodes import rclpy_compat

    missing = rclpy_compat.RclpySupport('99.0.0', tested=False, wait_set=False, change_state_handler=False)
    monkeypatch.setattr(rclpy_compat, 'check', lambda: missing)

    class Counted(LeanExecutor):
        def __init__(self, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            assert not self.lean  # the stock path

    received, ticks, calls, success, triggers = _exercise(ros_context, Counted)
    assert received == [float(i) for i in range(N_MESSAGES)]
    assert ticks >= 3 and calls == 1 and success
    assert triggers >= 2 * N_MESSAGES  # rclpy's own executor: it wakes itself around each callback


def _ask_transition(context: Context, node_class: Callable[..., Node], transition_id: int) -> Any:
    """Ask a fresh ``node_class`` node for a lifecycle transition over real DDS; the ChangeState
    response (Any: rclpy's Future.result is unannotated)."""
    from lifecycle_msgs.srv import ChangeState

    ns = f'lc_{uuid.uuid4().hex[:8]}'
    node = node_class('lc', namespace=ns, context=context)
    asker = rclpy.create_node('asker', namespace=ns, context=context)
    client = asker.create_client(ChangeState, f'/{ns}/lc/change_state')
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(asker)
    try:
        _spin_until(executor, client.service_is_ready)
        request = ChangeState.Request()
        request.transition.id = transition_id
        future = client.call_async(request)
        _spin_until(executor, future.done)
        return future.result()
    finally:
        executor.shutdown()
        asker.destroy_node()
        node.destroy_node()


def test_invalid_lifecycle_transition_is_refused_through_the_compat_module(ros_context: Context) -> None:
    from lifecycle_msgs.msg import Transition
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.lifecycle import LifecycleNode

    from skidsteer_power.nodes import rclpy_compat

    refused = []

    class Refusing(LifecycleNode):
        pass

    assert rclpy_compat.refuse_invalid_transitions(Refusing, (RCLError,), lambda n, r, e: refused.append(e))
    answer = _ask_transition(ros_context, Refusing, Transition.TRANSITION_ACTIVATE)  # not from unconfigured
    assert answer.success is False and len(refused) == 1
    assert _ask_transition(ros_context, Refusing, Transition.TRANSITION_CONFIGURE).success is True


def test_without_the_handler_the_node_class_stays_stock_rclpy(monkeypatch: pytest.MonkeyPatch) -> None:
    from rclpy.lifecycle import LifecycleNode

    from skidsteer_power.nodes import rclpy_compat

    missing = rclpy_compat.RclpySupport('99.0.0', tested=False, wait_set=True, change_state_handler=False)
    monkeypatch.setattr(rclpy_compat, 'check', lambda: missing)

    class Stock(LifecycleNode):
        pass

    assert not rclpy_compat.refuse_invalid_transitions(Stock, (Exception,), lambda n, r, e: None)
    assert rclpy_compat.CHANGE_STATE_HANDLER not in vars(Stock)
