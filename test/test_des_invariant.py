"""The driver's invariant under random input: no path leaves a motor turning without a fresh, valid
command (see ``skidsteer_power/nodes/des_driver.py``).

Hypothesis throws sequences of steps at a real des_driver node (real rclpy and DDS) driving two
simulated DES 70/10 amplifiers on ptys: cmd_vel with any float (NaN, inf, 1e308, random finite),
silences, link faults from the simulator's fault injection (port unplugged, amplifier silent, dropped
/ refused / corrupted exchanges, amplifier error bits) and their repair, lifecycle transitions through
``~/change_state`` (valid or not) and ``~/clear_faults``. After every step, once each reachable
amplifier has been polled twice:

- every amplifier's speed set point is an integer within what the limits allow (always);
- it is zero, unless the node is active, a valid command younger than ``cmd_timeout_s`` is in force,
  no amplifier error is latched and (stop_both_on_link_loss) both links are up;
- after deactivate or cleanup the power stages are off too.

A side whose link the step broke cannot be reached (the real amplifier would keep its last set point
just the same); the check applies to it again once the link is repaired.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from typing import Any

import pytest
from des_harness import Harness
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.context import Context

from skidsteer_power.des.protocol import DesErrorFlags
from skidsteer_power.des.simulator import Fault, SimulatedPair

pytestmark = pytest.mark.ros

CMD_TIMEOUT_S = 0.3
POLL_HZ = 50.0
# Limits (node defaults): |V| <= 1.5 m/s, |yaw rate| <= 2 rad/s; test_robot_track.yaml: tread 0.426 m,
# sprocket 0.1 m, 12:1. Fastest side: 1.5 + 2.0 * 0.426 / 2 = 1.926 m/s -> 1.926 / 0.1 * 12 rad/s
# = 231.1 rad/s = 2207 rpm at the motor (below max_motor_rpm 4000).
LIMIT_RPM = (1.5 + 2.0 * 0.426 / 2) / 0.1 * 12 * 60 / (2 * math.pi)
# A command counts as stale for the check once it is older than the timeout plus this margin (two
# poll periods and the exchange of the zero set point on a 38400-baud line) [s].
STALE_MARGIN_S = 0.15
SIDES = ('left', 'right')
CONFIGURE, CLEANUP, ACTIVATE, DEACTIVATE = 1, 2, 3, 4  # lifecycle_msgs/Transition ids

number = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1e9]),
    st.floats(-3.0, 3.0),
)
Step = tuple[Any, ...]
"""One drawn step: (kind, *arguments); the arguments' types depend on the kind (see ``step``)."""
step = st.one_of(
    st.tuples(st.just('twist'), number, number, st.integers(1, 4)),
    st.tuples(st.just('silence'), st.floats(0.0, 0.6)),
    st.tuples(
        st.just('fault'),
        st.sampled_from(SIDES),
        st.sampled_from(['unplug', 'silent', 'drop', 'nak', 'crc', 'error']),
    ),
    st.tuples(st.just('repair')),
    st.tuples(st.just('transition'), st.sampled_from([CONFIGURE, ACTIVATE, DEACTIVATE, CLEANUP])),
    st.tuples(st.just('clear_faults')),
)


class Oracle:
    """What the test knows independently of the driver: its lifecycle state, the cmd_vel stream it
    publishes (a teleop at 20 Hz; None: silent), which links it broke, which errors it raised."""

    def __init__(self) -> None:
        self.state = 'active'
        self.twist: tuple[float, float] | None = None
        self.valid_until = -math.inf  # time.monotonic() the stream stopped being valid
        self.broken: set[str] = set()  # sides with a hard link fault (unplugged, silent)
        self.transient: set[str] = set()  # sides with counted exchange faults
        self.errors: set[str] = set()  # sides with amplifier error bits raised

    def valid(self) -> bool:
        return self.twist is not None and all(math.isfinite(x) for x in self.twist)

    def stream(self, h: Harness, twist: tuple[float, float] | None) -> None:
        if self.valid():
            self.valid_until = time.monotonic()
        self.twist = h.twist = twist

    def must_be_zero(self, now: float) -> bool | None:
        """True: zero required; None: a fresh valid command may be in force (no claim)."""
        if self.state != 'active' or self.errors or self.broken:
            return True
        if self.valid():
            return None
        return now - self.valid_until > CMD_TIMEOUT_S + STALE_MARGIN_S


def polled_twice(h: Harness, sides: Iterable[str]) -> bool:
    """Spin until each reachable side has completed two poll cycles (a wait, not a timing check)."""
    marks = {s: h.driver.pollers[s].sample.sequence for s in sides if s in h.driver.pollers}
    return h.spin_until(
        lambda: all(h.driver.pollers[s].sample.sequence >= m + 2 for s, m in marks.items()
                    if s in h.driver.pollers),
        timeout_s=2.0,
    )  # fmt: skip


def check(h: Harness, pair: SimulatedPair, oracle: Oracle, what: str) -> None:
    sims = {'left': pair.left, 'right': pair.right}
    reachable = [s for s in SIDES if s not in oracle.broken and s not in oracle.transient]
    if oracle.state in ('active', 'inactive'):
        assert polled_twice(h, reachable), f'{what}: a reachable amplifier is not polled'
    now = time.monotonic()
    for side, sim in sims.items():
        rpm = sim.speed_setpoint_rpm
        assert isinstance(rpm, int) and abs(rpm) <= LIMIT_RPM + 1, f'{what}: {side} set point {rpm} rpm'
    if oracle.state == 'unconfigured' and not oracle.errors:
        # Never configured (or cleaned up): nothing was ever sent, or zero and disable before closing.
        for side in reachable:
            assert not sims[side].powered or sims[side].speed_setpoint_rpm == 0, what
        return
    zero = oracle.must_be_zero(now)
    if zero:  # zero within a bounded reaction time (measured in benchmarks/bench_des.py), not at once
        h.spin_until(
            lambda: all(sims[s].speed_setpoint_rpm == 0 or not sims[s].powered for s in reachable), 2.0
        )
    for side in reachable:
        sim = sims[side]
        if zero:
            assert sim.speed_setpoint_rpm == 0 or not sim.powered, (
                f'{what}: {side} set point {sim.speed_setpoint_rpm} rpm, powered, although '
                f'state {oracle.state}, cmd_vel stream {oracle.twist} '
                f'(valid until {now - oracle.valid_until:.2f} s ago), '
                f'broken {oracle.broken}, errors {oracle.errors}'
            )
        if oracle.state in ('inactive', 'finalized'):
            assert not sim.enabled, f'{what}: {side} enabled while {oracle.state}'


def run_step(h: Harness, pair: SimulatedPair, oracle: Oracle, item: Step) -> None:
    sims = {'left': pair.left, 'right': pair.right}
    kind = item[0]
    if kind == 'twist':
        _, v, w, repeat = item
        if oracle.state in ('active', 'inactive'):  # the driver subscribes while configured
            assert h.spin_until(lambda: h.cmd_pub.get_subscription_count() > 0)
        oracle.stream(h, (v, w))
        h.spin_until(lambda: False, timeout_s=0.05 * repeat)
    elif kind == 'silence':
        oracle.stream(h, None)
        h.spin_until(lambda: False, timeout_s=item[1])
    elif kind == 'fault':
        _, side, fault = item
        sim = sims[side]
        if fault == 'unplug':
            sim.close_port()
            oracle.broken.add(side)
        elif fault == 'silent':
            sim.inject(Fault.SILENT, -1)
            oracle.broken.add(side)
        elif fault == 'error':
            sim.raise_error(DesErrorFlags.OVER_CURRENT)
            oracle.errors.add(side)
            if oracle.state in ('active', 'inactive') and side not in oracle.broken | oracle.transient:
                # The status word is read every 5th poll: the latch must follow within a bounded time.
                assert h.spin_until(lambda: side in h.drive_command().halted_by, timeout_s=3.0)
        else:
            sim.inject({'drop': Fault.DROP, 'nak': Fault.NAK, 'crc': Fault.CORRUPT_CRC}[fault], 3)
            oracle.transient.add(side)
        if side in oracle.broken and oracle.state in ('active', 'inactive'):
            # The driver must notice a dead link within a bounded time (here: generously 3 s).
            assert h.spin_until(lambda: side in h.drive_command().links_down, timeout_s=3.0)
    elif kind == 'repair':
        for sim in sims.values():
            sim.clear_faults()
            sim.reopen_port()
        oracle.broken.clear()
        oracle.transient.clear()
        if oracle.state in ('active', 'inactive'):  # both links back within a bounded time
            assert h.spin_until(lambda: not h.drive_command().links_down, timeout_s=5.0)
    elif kind == 'transition':
        before = oracle.state
        ok = h.transition(item[1])
        expected = {
            (CONFIGURE, 'unconfigured'): 'inactive',
            (ACTIVATE, 'inactive'): 'active',
            (DEACTIVATE, 'active'): 'inactive',
            (CLEANUP, 'inactive'): 'unconfigured',
        }.get((item[1], before))
        if expected is None:
            assert not ok, f'transition {item[1]} from {before} succeeded'
        elif ok:
            oracle.state = expected
        else:
            assert item[1] == CONFIGURE and oracle.broken | oracle.transient, 'configure failed'
        assert h.state() == oracle.state
        if ok and item[1] == CONFIGURE and oracle.errors:
            pass  # configure reads the error word: the latch is back, still zero
    elif kind == 'clear_faults':
        from std_srvs.srv import Trigger

        answer = h.call(h.clear_client, Trigger.Request())
        if answer.success:
            assert not any(sims[s].errors for s in SIDES), answer.message
        # The amplifier's own error word says which errors are left (the driver clears only after
        # reading it back as zero).
        oracle.errors = {s for s in oracle.errors if sims[s].errors}


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(steps=st.lists(step, min_size=1, max_size=7))
def test_no_motor_turns_without_a_fresh_valid_command(ros_context: Context, steps: list[Step]) -> None:
    with SimulatedPair(38400) as pair:
        h = Harness(
            ros_context,
            pair,
            cmd_timeout_s=CMD_TIMEOUT_S,
            poll_rate_hz=POLL_HZ,
            ack_timeout_s=0.05,
            reconnect_period_s=0.1,
            configure_timeout_s=1.0,
            diagnostics_rate_hz=1.0,
        )
        oracle = Oracle()
        try:
            assert h.spin_until(lambda: h.cmd_pub.get_subscription_count() > 0)  # DDS discovery
            check(h, pair, oracle, 'start')
            for i, item in enumerate(steps):
                run_step(h, pair, oracle, item)
                check(h, pair, oracle, f'step {i} {item}')
        finally:
            h.close()
        # Destroyed: zero and disabled wherever the link allows.
        for side, sim in (('left', pair.left), ('right', pair.right)):
            if side not in oracle.broken and side not in oracle.transient:
                assert (sim.speed_setpoint_rpm == 0 or not sim.powered) and not sim.enabled
