"""Model-based test of the driver's safety rules (issue 28), on the layer that decides and sends every
set point: :class:`DriveCommand` and two :class:`AmplifierPoller` (their own per-turn code,
:meth:`AmplifierPoller.poll_once`, exceptions and reconnects included) against two simulated DES
70/10 amplifiers on ptys (real serial I/O, the simulator's own view of its set point). Time is a
stepped clock injected into the command and the pollers, so a run does not depend on the machine's
load; the pollers turn once per poll period of that clock, as their threads would.

Hypothesis (RuleBasedStateMachine) throws cmd_vel values of any kind (NaN, inf, 1e308, random),
waits, link faults (port unplugged, amplifier silent), poller exceptions, amplifier error words,
repairs and finally, sometimes, a signal at them. The model keeps what the test knows independently
of the driver (when the last valid command came, which side faulted when) and checks the safety
rules after every poll period:

1. watchdog: no valid command for longer than ``cmd_timeout_s`` plus one poll period -> every
   reachable amplifier holds zero;
2. slew: between two poll periods a non-zero set point changes by at most what ``max_accel_m_s2``
   and ``max_yaw_accel_rad_s2`` allow in that time (plus 1 rpm of rounding); a stop may be a step;
3. one side's fault (link lost, poller exception) -> both sides zero within 100 ms, as long as the
   fault lasts (an amplifier error word: within the status read period plus one poll); the time
   counts while that side's poller takes its turns (a hung poller cannot see a fault on its own
   line: rule 5 covers that side's faults then), for an error word while it reaches the amplifier
   (not cut off, not still reconnecting after a repair);
4. a signal (the node's stop path: shutting down, then every poller's stop) -> every reachable
   amplifier at zero and disabled;
5. a hung poller (its thread stops taking turns, as if stuck in an exchange) -> the other side at
   zero within the stall timeout plus two poll periods, as long as it hangs;
6. deactivate (the lifecycle transition) -> every reachable amplifier at zero and disabled after
   one poll period, and it stays so until activated again.

Each rule fails on a copy of the code with its fault planted (watchdog 5x slower, watchdog removed,
acceleration limit removed, ``stop_both_on_link_loss`` ignored, hung-poller detection removed,
deactivate not zeroing), on every seed tried: test/planted_des_faults.sh, the table in
docs/RELIABILITY.md ("Planted faults").
"""

from __future__ import annotations

import math
import os

from des_harness import Clock
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from skidsteer_power.des.command import CommandLimits, DriveGeometry
from skidsteer_power.des.poller import AmplifierPoller, DriveCommand
from skidsteer_power.des.protocol import DesConfig, DesErrorFlags
from skidsteer_power.des.simulator import Fault, SimulatedPair
from skidsteer_power.des.transport import LinkTiming
from skidsteer_power.errors import InputError

SIDES = ('left', 'right')
CMD_TIMEOUT_S = 0.3
POLL_S = 0.02  # 50 Hz, the node's default
STATUS_EVERY = 5  # the node's default: the status word every 5th cycle
RECONNECT_S = 0.5  # the node's default reconnect_period_s (also the first poller-fault back-off)
BOTH_ZERO_S = 0.1  # rule 3
STALL_S = 1.0  # rule 5: the stall timeout given to the DriveCommand (the node's at 50 Hz)
LIMITS = CommandLimits()  # node defaults: 1.5 m/s, 2 rad/s, 1 m/s^2, 4 rad/s^2
# test_robot_track.yaml: tread 0.426 m, sprocket radius 0.1 m, 12:1; right side mirrored
GEOMETRY = DriveGeometry(0.426, 0.1, 12.0, {'left': 1, 'right': -1}, max_rpm=10000.0)
RPM_PER_M_S = 12.0 / 0.1 * 60.0 / (2.0 * math.pi)  # side speed [m/s] -> motor [rpm]: 1145.9
# A side's speed is V +- w B / 2 (kinematics), so it changes by at most a + alpha B / 2 per second:
# (1.0 + 4.0 * 0.426 / 2) m/s^2 * 1145.9 rpm per m/s = 2122 rpm/s, 42.4 rpm per 20 ms poll period.
MAX_RPM_PER_S = (LIMITS.max_accel_m_s2 + LIMITS.max_yaw_accel_rad_s2 * 0.426 / 2) * RPM_PER_M_S
EXAMPLES = int(os.environ.get('DES_MODEL_EXAMPLES', '60'))
SIGNAL_AFTER = 8  # steps before a signal may end an example (it ends every later step's use)

number = st.one_of(
    st.floats(-2.5, 2.5),
    st.sampled_from([0.0, 0.2, -0.2, 1.0, -1.5, 1e308, -1e308, math.nan, math.inf, -math.inf]),
    st.floats(allow_nan=True, allow_infinity=True),
)


class DriverModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.clock = Clock(1000.0)
        self.pair = SimulatedPair(38400, emulate_baud=False).start()
        self.sims = {'left': self.pair.left, 'right': self.pair.right}
        self.command = DriveCommand(
            CMD_TIMEOUT_S, geometry=GEOMETRY, limits=LIMITS, clock=self.clock, stall_timeout_s=STALL_S
        )
        timing = LinkTiming()  # the node's defaults: shorter ones time out on a loaded machine
        self.pollers = {
            side: AmplifierPoller(
                side, sim.port, self.command, config=DesConfig(baudrate=38400), timing=timing,
                poll_period_s=POLL_S, status_every=STATUS_EVERY, reconnect_period_s=RECONNECT_S,
                log_error=lambda text: None,
            )
            for side, sim in self.sims.items()
        }  # fmt: skip
        self.next_turn = dict.fromkeys(SIDES, self.clock.now)
        self.valid_at = -math.inf  # clock time of the last valid (finite) command
        self.link_fault_at: dict[str, float] = {}  # unplugged or silent since (unreachable)
        self.poller_fault_at: dict[str, float] = {}  # a poller exception raised at
        self.error_at: dict[str, float] = {}  # amplifier error word raised at
        self.reconnecting_until: dict[str, float] = {}  # repaired, the poller not yet back
        self.previous = {side: 0 for side in SIDES}
        self.previous_reachable: list[str] = []
        self.steps = 0
        self.stopped = False
        self.hung_at: dict[str, float] = {}  # a poller that stopped taking turns, since
        # rule 3: per fault (kind, side), the time its side's poller has been free to see it since it
        # began [s]: not while that poller hangs; for an error word, only while it reaches the amplifier
        self.fault_age: dict[tuple[str, str], float] = {}
        self.inactive = False  # deactivated (lifecycle)

    def teardown(self) -> None:
        self.command.shutting_down = True
        for poller in self.pollers.values():
            poller.amp.close()
        self.pair.stop()

    # -- the clock and the pollers -----------------------------------------------------------------

    def _tick(self) -> None:
        """One poll period: each poller takes its turn when due, then the rules are checked."""
        self.clock.now += POLL_S
        faults = [('link', s) for s in self.link_fault_at] + [('poller', s) for s in self.poller_fault_at]
        faults = [key for key in faults if key[1] not in self.hung_at]
        reachable = self._reachable()  # an error word is read only from an amplifier the poller reaches
        faults += [('error', s) for s in self.error_at if s in reachable]
        for key in faults:
            self.fault_age[key] = self.fault_age.get(key, 0.0) + POLL_S
        for side, poller in self.pollers.items():
            if side in self.hung_at:
                continue  # stuck: it neither sends nor reads
            if self.clock.now + 1e-9 >= self.next_turn[side]:
                wait_s = poller.poll_once()
                self.next_turn[side] = self.clock.now + (POLL_S if wait_s is None else wait_s)
        self._check_rules()

    def _reachable(self) -> list[str]:
        """Sides whose amplifier hears the driver: no link fault, and after a repair the reconnect
        period is over (until then an amplifier keeps what it held, as a real one would)."""
        now = self.clock.now
        return [
            s
            for s in SIDES
            if s not in self.link_fault_at
            and s not in self.hung_at
            and now >= self.reconnecting_until.get(s, 0.0)
        ]

    def _check_rules(self) -> None:
        now = self.clock.now
        self.poller_fault_at = {s: t for s, t in self.poller_fault_at.items() if now < t + RECONNECT_S - 1e-9}
        live = {('link', s) for s in self.link_fault_at} | {('poller', s) for s in self.poller_fault_at}
        live |= {('error', s) for s in self.error_at}
        self.fault_age = {key: age for key, age in self.fault_age.items() if key in live}
        age = self.fault_age
        setpoints = {side: self.sims[side].speed_setpoint_rpm for side in SIDES}
        what = (
            f'at {now - 1000:.2f} s: set points {setpoints}, last valid command '
            f'{now - self.valid_at:.2f} s ago, link faults {self.link_fault_at}, poller faults '
            f'{self.poller_fault_at}, errors {self.error_at}'
        )
        for side in self._reachable():
            rpm = setpoints[side]
            if now - self.valid_at > CMD_TIMEOUT_S + POLL_S:  # rule 1
                assert rpm == 0, f'watchdog: {side} not at zero {what}'
            if rpm != 0 and side in self.previous_reachable:  # rule 2
                step = abs(rpm - self.previous[side])
                assert step <= MAX_RPM_PER_S * POLL_S + 1, f'slew: {side} jumped {step} rpm {what}'
            due = [age.get(('link', s), 0.0) >= BOTH_ZERO_S - 1e-9 for s in self.link_fault_at]
            due += [age.get(('poller', s), 0.0) >= BOTH_ZERO_S - 1e-9 for s in self.poller_fault_at]
            due += [age.get(('error', s), 0.0) >= (STATUS_EVERY + 1) * POLL_S - 1e-9 for s in self.error_at]
            if any(due):  # rule 3
                assert rpm == 0, f'a fault: {side} not at zero {what}'
            if any(now >= t + STALL_S + 2 * POLL_S - 1e-9 for t in self.hung_at.values()):  # rule 5
                assert rpm == 0, f'hung poller: {side} not at zero {what}, hung {self.hung_at}'
            if self.inactive:  # rule 6
                sim = self.sims[side]
                assert rpm == 0 and not sim.enabled, f'deactivated: {side} still driven {what}'
        self.previous, self.previous_reachable = setpoints, self._reachable()

    # -- rules ------------------------------------------------------------------------------------

    @initialize()
    def connect(self) -> None:
        for _ in range(3):  # open the ports, read the amplifiers, enable
            self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(linear=number, yaw_rate=number, polls=st.integers(1, 5))
    def cmd_vel(self, linear: float, yaw_rate: float, polls: int) -> None:
        try:
            self.command.set_twist(linear, yaw_rate)
            self.valid_at = self.clock.now
        except InputError:
            pass  # rejected: does not refresh the command
        for _ in range(polls):
            self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(
        speed=st.floats(0.1, 1.5),
        yaw_rate=st.floats(-2.0, 2.0),
        reverse=st.booleans(),
        polls=st.integers(3, 10),
        silence_s=st.sampled_from([0.34, 0.5, 1.0]),
    )
    def drive_then_silence(
        self, speed: float, yaw_rate: float, reverse: bool, polls: int, silence_s: float
    ) -> None:
        """A teleop drives, then goes quiet (its link dropped, a crashed node): the watchdog's case."""
        for _ in range(polls):  # a stream of the same valid command, one per poll period
            self.command.set_twist(-speed if reverse else speed, yaw_rate)
            self.valid_at = self.clock.now
            self._tick()
        for _ in range(round(silence_s / POLL_S)):
            self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(seconds=st.sampled_from([0.1, 0.34, 0.4, 0.5, 1.0]))
    def wait(self, seconds: float) -> None:
        for _ in range(round(seconds / POLL_S)):
            self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(side=st.sampled_from(SIDES), kind=st.sampled_from(['unplug', 'silent']))
    def link_fault(self, side: str, kind: str) -> None:
        if side in self.link_fault_at:
            return
        if kind == 'unplug':
            self.sims[side].close_port()
        else:
            self.sims[side].inject(Fault.SILENT, -1)
        self.link_fault_at[side] = self.clock.now
        self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(side=st.sampled_from(SIDES))
    def poller_exception(self, side: str) -> None:
        """The poller's next cycle raises (a bug inside it): caught by poll_once, like in the thread."""
        amp = self.pollers[side].amp
        real = amp.read_current

        def broken(*args: object, **kwargs: object) -> int:
            del amp.read_current  # once
            self.poller_fault_at.setdefault(side, self.clock.now)
            raise ZeroDivisionError('planted in the poller')

        amp.read_current = broken  # type: ignore[method-assign]
        for _ in range(3):
            self._tick()
        if 'read_current' in amp.__dict__:  # the side was not polled (unreachable): take it back
            del amp.read_current
        assert amp.read_current == real

    @precondition(lambda self: not self.stopped)
    @rule(side=st.sampled_from(SIDES))
    def amplifier_error(self, side: str) -> None:
        self.sims[side].raise_error(DesErrorFlags.OVER_CURRENT)
        self.error_at.setdefault(side, self.clock.now)
        self._tick()

    @precondition(lambda self: not self.stopped)
    @rule(
        side=st.sampled_from(SIDES),
        polls=st.integers(1, 80),
        speed=st.one_of(st.none(), st.floats(-1.5, 1.5)),
    )
    def hang(self, side: str, polls: int, speed: float | None) -> None:
        """A poller stops taking turns (stuck in an exchange, a deadlock) for ``polls`` periods: its
        amplifier keeps what it held (the guardian's case); the other side must stop (rule 5), also
        while a teleop keeps sending ``speed`` [m/s] (None: no command meanwhile)."""
        self.hung_at.setdefault(side, self.clock.now)
        for _ in range(polls):
            if speed is not None:
                self.command.set_twist(speed, 0.0)
                self.valid_at = self.clock.now
            self._tick()

    @precondition(lambda self: not self.stopped and not self.inactive)
    @rule(speed=st.floats(-1.5, 1.5), polls=st.integers(0, 10))
    def deactivate(self, speed: float, polls: int) -> None:
        """The lifecycle's deactivate (DriveCommand.active = False, as des_driver's on_deactivate),
        after ``polls`` periods of driving at ``speed`` [m/s] (0 polls: whatever was going on)."""
        for _ in range(polls):
            self.command.set_twist(speed, 0.0)
            self.valid_at = self.clock.now
            self._tick()
        self.command.active = False
        self.inactive = True
        self._tick()

    @precondition(lambda self: not self.stopped and self.inactive)
    @rule()
    def activate(self) -> None:
        self.command.active = True
        self.inactive = False
        self._tick()

    @precondition(lambda self: not self.stopped)
    @rule()
    def repair(self) -> None:
        """Ports back, amplifiers answering, errors cleared (~/clear_faults); a side that was cut
        off is reached again once its poller reconnected (within its reconnect period)."""
        for sim in self.sims.values():
            sim.clear_faults()
            sim.reopen_port()
        self.command.request_clear(list(SIDES))
        for side in self.link_fault_at:
            self.reconnecting_until[side] = self.clock.now + RECONNECT_S + 2 * POLL_S
        for side in self.hung_at:  # its turn comes again; it sends on its next cycle
            self.reconnecting_until[side] = max(
                self.reconnecting_until.get(side, 0.0), self.clock.now + 2 * POLL_S
            )
        self.hung_at.clear()
        self.link_fault_at.clear()
        self.error_at.clear()
        self._tick()
        # as des_driver's ~/clear_faults: a side its request did not reach is not cleared later (an
        # error word raised meanwhile would otherwise be cleared behind the caller's back)
        self.command.withdraw_clear_requests()

    @precondition(lambda self: not self.stopped and self.steps >= SIGNAL_AFTER)
    @rule()
    def signal(self) -> None:
        """What des_driver does on any signal that ends it (stop_motors: shutting down, then each
        poller's stop, which ends its thread with zero speed, disable, close)."""
        self.command.shutting_down = True
        for poller in self.pollers.values():
            poller.request_stop()
            poller._shutdown()  # what the stopped thread runs last
        self.stopped = True
        for side in self._reachable():  # rule 4
            sim = self.sims[side]
            assert sim.speed_setpoint_rpm == 0 and not sim.enabled, f'after a signal: {side} still driven'

    @precondition(lambda self: self.stopped)
    @rule()
    def stays_stopped(self) -> None:
        """After the stop path nothing is sent again: what the amplifiers hold stays zero."""
        for side in self._reachable():
            assert self.sims[side].speed_setpoint_rpm == 0 and not self.sims[side].enabled

    @invariant()
    def set_points_are_bounded(self) -> None:
        self.steps += 1  # an invariant runs after every step: the count SIGNAL_AFTER reads
        for side in SIDES:
            rpm = self.sims[side].speed_setpoint_rpm
            assert isinstance(rpm, int) and abs(rpm) <= GEOMETRY.motor_rpm(1.5, 2.0)['left'] + 1


DriverModel.TestCase.settings = settings(
    max_examples=EXAMPLES,
    stateful_step_count=12,
    deadline=None,
    database=None,  # every seed starts afresh: no failure replayed from an earlier run
    # DES_MODEL_SHRINK=0 (the planted-fault table): report the first failure found, unshrunk
    phases=[p for p in Phase if p != Phase.shrink or os.environ.get('DES_MODEL_SHRINK', '1') == '1'],
    suppress_health_check=[HealthCheck.too_slow],
)
test_driver_safety_rules = DriverModel.TestCase
