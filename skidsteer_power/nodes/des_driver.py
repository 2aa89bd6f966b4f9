"""``des_driver``: two DES 70/10 amplifiers (one per side) as a managed (lifecycle) ROS 2 node.

Invariant: **no path leaves a motor turning without a fresh, valid command.** Every path that
could (bad input, a silent or lost amplifier, an exception in a poller or a callback, a lifecycle
transition, a signal, the end of the process) ends in zero speed, and where the amplifier can still
be reached, its power stage disabled. ``test/test_des_invariant.py`` checks it with random input.

Lifecycle (rclpy.lifecycle; ``~/change_state``, ``~/get_state`` as usual):

- configure: read the parameters and the vehicle file, open both ports and read the amplifiers
  (fails if a port cannot be opened or an amplifier does not answer within ``configure_timeout_s``);
  joint_states and diagnostics are published from here on, the power stages stay disabled.
- activate: enable the power stages; cmd_vel is accepted from now (older commands never count).
- deactivate: zero speed, then disable, on both sides before the transition returns.
- cleanup / shutdown / error: zero, disable, close the ports.

``autostart:=true`` configures and activates at start, for use without a lifecycle manager.

Subscribes ``cmd_vel`` (geometry_msgs/Twist or TwistStamped: ``cmd_vel_type``, by default whichever
the publishers offer; a stale or future stamp is refused: :mod:`skidsteer_power.nodes.cmd_vel_input`;
m/s and rad/s, REP 103), best effort by default so that reliable and best-effort publishers both match
(:func:`cmd_vel_qos`; ``qos_overrides./cmd_vel.subscription.<policy>`` parameters are honoured).
Every number is checked where it enters: a message with any non-finite field is rejected and
counted; V and yaw rate are clamped to ``max_speed_m_s`` / ``max_yaw_rate_rad_s`` (a throttled
warning, counted) and their changes to ``max_accel_m_s2`` / ``max_yaw_accel_rad_s2``; the
motor set points never exceed ``max_motor_rpm`` (itself at most the vehicle's motor's max. speed,
EC-45: 10 000 rpm).
Service ``~/clear_faults`` (std_srvs/Trigger): clear latched amplifier errors, re-enable; the answer
says whether every side came back.
Publishes ``joint_states`` (sensor_msgs/JointState, joints ``left_motor`` and ``right_motor``:
position [rad], velocity [rad/s] at the motor shaft, effort = Kt * current [N m]; forward motion of
the robot is positive on both sides, the per-side ``polarity`` maps to the amplifier's sense; a
side with no fresh data reads NaN in all three fields: "no data", which power_estimator skips)
and ``diagnostics`` (diagnostic_msgs/DiagnosticArray, one status per amplifier: connection, power
stage, status and error words, raw current [mA] and speed [rpm], link counters, poller faults;
one for the command: lifecycle state, why the motors hold zero, rejected / clamped counts).

Safety: no valid cmd_vel for ``cmd_timeout_s`` -> zero speed; an amplifier error -> both motors
stopped, reported, cleared only by ``~/clear_faults``; a failed exchange or a lost port on one side
-> that side reported ERROR and, with ``stop_both_on_link_loss`` (default), the other side stopped
too, until the link is back (the port is reopened until it returns); an exception in a poller
thread -> that amplifier zeroed and disabled, ERROR in diagnostics, the poller restarted after a
back-off; an exception in a callback -> both amplifiers zeroed and disabled, then the error
propagates; every signal that would end the process (SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1,
...: :mod:`skidsteer_power.stop_signals`), destroy and interpreter exit -> zero speed, then
disable (a stop that could not be confirmed at an amplifier: one error line and exit code 1, never
0); Ctrl-Z (SIGTSTP), SIGTTIN, SIGTTOU -> zero and disable, then the process stops; after SIGCONT
the power stages come back on and only a fresh cmd_vel drives; an amplifier that resets itself
(power stage off, set point 0) -> both sides stopped, latched and reported until ``~/clear_faults``.
A stop never waits for the next poll: the pollers wake when the command goes stale and on every
stop condition, and zero before a read exchange that would end after the command went stale, so the
watchdog's zero does not depend on ``poll_rate_hz`` (0.1 Hz included) or on a slow link; every
exchange is bounded in time and retries (issue 34). All serial I/O runs in one thread per amplifier
(:mod:`skidsteer_power.des.poller`), never in the executor. The ends no handler sees (SIGKILL,
SIGSTOP, SIGSEGV, ...) are the guardian's: a process started at configure that owns the ports and
stops both amplifiers when this one dies or freezes (``guardian``, ``guardian_timeout_s``;
:mod:`skidsteer_power.nodes.driver_guardian`).

Geometry (tread, drive radius, gear ratio) and the motor (the published effort K_t I, the largest
set point) come from the vehicle file named by ``vehicle`` and its powertrain.

On the robot: each transaction takes four turn-arounds ('O' handshakes), so a USB-RS232 adapter's
read latency dominates. FTDI adapters default to a 16 ms latency timer, which could cap the poll
rate at a few Hz (the stop still reaches both amplifiers within 0.6 s of the last command:
benchmarks/bench_des.py, issue-34 cases); set it to 1 ms
(``/sys/bus/usb-serial/devices/ttyUSB0/latency_timer``) to reach the 50 Hz default
(benchmarks/bench_des.py: about 57 Hz per side at 38400 baud on a pty with the wire's byte time
emulated, 0.86 of the line's byte-time limit).
"""

from __future__ import annotations

import functools
import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import rclpy
import rclpy.utilities
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from skidsteer_power.des.command import CommandLimits, DriveGeometry, limits_for
from skidsteer_power.des.kinematics import DES_MAX_SPEED_1PP_RPM, RPM, set_point_limit_rpm
from skidsteer_power.des.poller import AmplifierPoller, AmplifierSample, DriveCommand
from skidsteer_power.des.protocol import BAUD_CODES, DesConfig, StatusVariables
from skidsteer_power.des.transport import LinkTiming
from skidsteer_power.drive.controller import controller_for_vehicle
from skidsteer_power.errors import ConfigError, SkidsteerError
from skidsteer_power.nodes import cmd_vel_input
from skidsteer_power.nodes.cmd_vel_input import CmdVelInput
from skidsteer_power.nodes.driver_guardian import GUARDIAN_PARAMETERS, DriverGuardian
from skidsteer_power.nodes.param_spec import ParamSpec, declare, read_parameters
from skidsteer_power.nodes.parameters import DesDriverParameters
from skidsteer_power.nodes.rclpy_compat import refuse_invalid_transitions
from skidsteer_power.nodes.spin import spin_node
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.powertrain.power_flow import SIDES
from skidsteer_power.stop_signals import PauseHook, on_pause, remove_pause_hook
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from typing import TypeVar, TypeVarTuple, Unpack

    from geometry_msgs.msg import Twist, TwistStamped
    from lifecycle_msgs.srv import ChangeState
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.parameter import Parameter
    from rclpy.subscription import Subscription

    from skidsteer_power.nodes.ros_types import LifecycleNodeKwargs

    _Args = TypeVarTuple('_Args')
    _Result = TypeVar('_Result')

NODE_NAME = 'des_driver'


@dataclass(frozen=True)
class DriverSetup:
    """What the driver derives from its parameters and vehicle file at configure (kept apart from the
    parameters, which are only what was set): the powertrain, the drive geometry, the command limits
    [SI], the encoder resolution [counts/turn] (the parameter, or the motor's when it is 0) and the
    cmd_vel message type."""

    powertrain: Powertrain
    geometry: DriveGeometry
    limits: CommandLimits
    encoder_resolution: int
    cmd_vel_mode: str


_WARN_PERIOD_S = 5.0


def cmd_vel_qos() -> QoSProfile:
    """cmd_vel's QoS: a best-effort reader matches reliable and best-effort writers (many teleop
    and joystick nodes publish best effort); a lost command is what the watchdog is for.
    ``qos_overrides./cmd_vel.subscription.reliability: reliable`` (or any other policy) overrides
    it. A new profile each call: rclpy writes the overrides into the profile it is given."""
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        'vehicle',
        'test_robot_track',
        'vehicle name or YAML file: tread, drive radius, powertrain (gear ratio, motor: effort = K_t I)',
    ),
    ParamSpec('left_port', '/dev/ttyUSB0', 'serial port (path or pyserial URL) of the left amplifier'),
    ParamSpec('right_port', '/dev/ttyUSB1', 'serial port (path or pyserial URL) of the right amplifier'),
    ParamSpec(
        'baud',
        38400,
        'link speed [bit/s]: 9600, 14400, 19200, 38400, 57600 or 115200',
        (9600, 115200),
        choices=tuple(BAUD_CODES),
    ),
    ParamSpec(
        'left_polarity', 1, 'amplifier sense of forward motion, left side: +1 or -1', (-1, 1), choices=(1, -1)
    ),
    ParamSpec(
        'right_polarity',
        -1,
        'amplifier sense of forward motion, right side (mirrored motor): +1 or -1',
        (-1, 1),
        choices=(1, -1),
    ),
    ParamSpec(
        'encoder_resolution',
        0,
        "encoder lines per motor turn [-]; 0 = the vehicle's motor's (EC-45: 2048, ch. 7.1.2)",
        (0, 65535),
    ),
    ParamSpec(
        'max_motor_rpm',
        4000.0,
        "largest motor set point [rpm] (EC-45: 4010 rpm no-load at 48 V); at most the vehicle's motor's"
        ' max. speed (EC-45: 10 000 rpm) and the DES 70/10 max. 25 000 rpm / pole pairs',
        (1.0, DES_MAX_SPEED_1PP_RPM),
    ),
    ParamSpec(
        'max_speed_m_s',
        0.0,
        "|V| commands beyond are clamped [m/s]; 0 = the vehicle file's max_speed_m_s (docs/DRIVE.md)",
        (0.0, 10.0),
    ),
    ParamSpec(
        'max_yaw_rate_rad_s',
        0.0,
        "|yaw rate| commands beyond are clamped [rad/s]; 0 = the vehicle file's max_yaw_rate_rad_s",
        (0.0, 20.0),
    ),
    ParamSpec(
        'max_accel_m_s2',
        0.0,
        "largest change of the commanded V [m/s^2]; 0 = the vehicle's drive controller's, else 1.0",
        (0.0, 100.0),
    ),
    ParamSpec(
        'max_yaw_accel_rad_s2',
        0.0,
        "largest change of the commanded yaw rate [rad/s^2]; 0 = the vehicle's drive controller's, else 4.0",
        (0.0, 1000.0),
    ),
    ParamSpec('cmd_timeout_s', 0.5, 'zero speed when no valid cmd_vel for this long [s]', (0.01, 60.0)),
    ParamSpec('stop_both_on_link_loss', True, 'a failed or lost link on one side stops the other side too'),
    ParamSpec('poll_rate_hz', 50.0, 'amplifier poll and joint_states rate [Hz]', (0.1, 1000.0)),
    ParamSpec('status_every', 5, 'read the status word every N polls [-]', (1, 1000)),
    ParamSpec(
        'reconnect_period_s',
        0.5,
        'retry period for a lost port; first poller restart back-off [s]',
        (0.01, 60.0),
    ),
    ParamSpec(
        'ack_timeout_s', 0.05, 'wait for each acknowledge / reply from an amplifier [s]', (0.001, 10.0)
    ),
    ParamSpec(
        'configure_timeout_s', 5.0, 'configure fails unless both amplifiers answer within [s]', (0.1, 60.0)
    ),
    ParamSpec('diagnostics_rate_hz', 2.0, 'diagnostics rate [Hz]', (0.01, 100.0)),
    ParamSpec(
        'current_source',
        'status_variable',
        "currents from 'status_variable' (130, documented) or 'is_must' (op 0x29, UNCONFIRMED)",
        choices=('status_variable', 'is_must'),
    ),
    ParamSpec(
        'encoder_counter_variable',
        143,
        'status variable of the 16-bit encoder counter (UNCONFIRMED)',
        (128, 255),
    ),
    ParamSpec(
        'twist_stamped', False, 'deprecated: cmd_vel_type:=twist_stamped (true = that, with a warning)'
    ),
    *cmd_vel_input.PARAMETERS,
    ParamSpec('frame_id', '', 'header.frame_id of joint_states'),
    ParamSpec('autostart', False, 'configure and activate at start (no lifecycle manager needed)'),
)
"""Every parameter of the node, declared and read from this one table."""

PARAMETERS += GUARDIAN_PARAMETERS  # issue 34: the guardian process (nodes/driver_guardian.py)


def _fail_safe(
    callback: Callable[[DesDriver, Unpack[_Args]], _Result],
) -> Callable[[DesDriver, Unpack[_Args]], _Result]:
    """An exception in a callback zeroes and disables both amplifiers before it propagates."""

    @functools.wraps(callback)
    def wrapper(self: DesDriver, *args: Unpack[_Args]) -> _Result:
        try:
            return callback(self, *args)
        except RCLError:
            self.emergency_stop(f'RCLError in {callback.__name__}')
            if self.context.ok():
                raise
            # SIGINT / SIGTERM invalidated the context under a running callback: a shutdown, no bug.
            raise ExternalShutdownException from None
        except BaseException:
            self.emergency_stop(f'exception in {callback.__name__}')
            raise

    return wrapper


def _traceback_logged(
    transition: Callable[[DesDriver, LifecycleState], TransitionCallbackReturn],
) -> Callable[[DesDriver, LifecycleState], TransitionCallbackReturn]:
    """rclpy turns an exception in a transition callback into ERROR without a word: log it first."""

    @functools.wraps(transition)
    def wrapper(self: DesDriver, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            return transition(self, state)
        except Exception:
            self.get_logger().error(f'{transition.__name__} raised (a bug):\n{traceback.format_exc()}')
            raise

    return wrapper


def _given_limits(p: DesDriverParameters) -> dict[str, float]:
    """The command limits the parameters give (0: the vehicle's; :func:`limits_for`)."""
    return {
        'max_speed_m_s': p.max_speed_m_s,
        'max_yaw_rate_rad_s': p.max_yaw_rate_rad_s,
        'max_accel_m_s2': p.max_accel_m_s2,
        'max_yaw_accel_rad_s2': p.max_yaw_accel_rad_s2,
    }


class DesDriver(LifecycleNode):
    """Two DES amplifiers behind ``cmd_vel`` / ``joint_states`` / ``diagnostics`` (managed node)."""

    if TYPE_CHECKING:  # rclpy 7 leaves these unannotated; their types

        def get_logger(self) -> RcutilsLogger: ...
        def trigger_configure(self) -> TransitionCallbackReturn: ...
        def trigger_activate(self) -> TransitionCallbackReturn: ...
        def trigger_deactivate(self) -> TransitionCallbackReturn: ...
        def trigger_cleanup(self) -> TransitionCallbackReturn: ...

    def __init__(self, **kwargs: Unpack[LifecycleNodeKwargs]) -> None:
        super().__init__(NODE_NAME, **kwargs)
        declare(self, PARAMETERS)  # a value out of its range: one ConfigError
        self.params, self.setup = self._read_parameters()  # a bad value is one clear error at once
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.command: DriveCommand | None = None
        self.pollers: dict[str, AmplifierPoller] = {}
        self.guardian = DriverGuardian(self)
        self.configure_error = ''
        self.counts = {'received': 0, 'rejected_non_finite': 0, 'clamped': 0, 'ignored_inactive': 0}
        self._published = {side: 0 for side in SIDES}
        self._runtime: list[Timer | Subscription] = []  # subscription and timers of the configured state
        self._pause_hook: PauseHook | None = None
        self.unsafe_stop = ''  # set when a stop could not be confirmed at an amplifier (exit 1)
        self.cmd_input: CmdVelInput | None = None  # cmd_vel of the configured state
        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        self.create_service(Trigger, '~/clear_faults', self._on_clear_faults)

    # -- parameters -----------------------------------------------------------------------------

    def _read_parameters(self) -> tuple[DesDriverParameters, DriverSetup]:
        """The parameters (their choices checked again: a set while unconfigured is only range-checked
        by ROS) and what follows from them and the vehicle file."""
        p = read_parameters(self, PARAMETERS, DesDriverParameters)
        if p.left_port == p.right_port:
            raise ConfigError(f'left_port and right_port are the same: {p.left_port}')
        vehicle = load_vehicle(p.vehicle)
        powertrain = Powertrain.for_vehicle(vehicle)
        motor_max_rpm = set_point_limit_rpm(powertrain.motor)
        if p.max_motor_rpm > motor_max_rpm:
            raise ConfigError(
                f"max_motor_rpm {p.max_motor_rpm} is above the motor's max. speed {motor_max_rpm:.0f} rpm"
            )
        geometry = DriveGeometry(
            tread_m=float(vehicle.tread_m),
            drive_radius_m=float(vehicle.drive_radius_m),
            gear_ratio=float(powertrain.gear_ratio),
            polarity={'left': p.left_polarity, 'right': p.right_polarity},
            max_rpm=p.max_motor_rpm,
        )
        return p, DriverSetup(
            powertrain=powertrain,
            geometry=geometry,
            limits=limits_for(controller_for_vehicle(vehicle, powertrain), _given_limits(p)),
            encoder_resolution=p.encoder_resolution or powertrain.motor.encoder_counts_per_turn,
            cmd_vel_mode=cmd_vel_input.cmd_vel_mode(self, p.cmd_vel_type, 'twist_stamped', p.twist_stamped),
        )

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        if self.state_label == 'unconfigured' or all(p.name.startswith('qos_overrides.') for p in params):
            return SetParametersResult(successful=True)  # QoS overrides: declared (read-only) at configure
        return SetParametersResult(
            successful=False, reason='des_driver parameters take effect at configure: clean up first'
        )

    @property
    def state_label(self) -> str:
        """The lifecycle state: 'unconfigured', 'inactive', 'active', 'finalized', ..."""
        return str(self._state_machine.current_state[1])  # (id, label) in rclpy's state machine

    # -- lifecycle ------------------------------------------------------------------------------

    @_traceback_logged
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.params, self.setup = self._read_parameters()
            p, setup = self.params, self.setup
            self._start_pollers(self.guardian.start(p))  # the guardian's proxy ports, if on
            self._wait_connected(p.configure_timeout_s)
        except SkidsteerError as err:
            self.configure_error = str(err)
            self.get_logger().error(f'configure failed: {err}')
            self._teardown()
            return TransitionCallbackReturn.FAILURE
        except Exception:
            self._teardown()
            raise
        self.cmd_input = CmdVelInput(
            self,
            setup.cmd_vel_mode,
            self._on_cmd_vel,
            cmd_vel_qos(),
            timeout_s=p.cmd_timeout_s,
            tolerance_s=p.cmd_vel_stamp_tolerance_s,
            qos_overriding_options=QoSOverridingOptions.with_default_policies(),
        )
        self._runtime = [
            self.create_timer(1.0 / p.poll_rate_hz, self._publish_joint_states),
            self.create_timer(1.0 / p.diagnostics_rate_hz, self._publish_diagnostics),
        ]
        self.configure_error = ''
        return TransitionCallbackReturn.SUCCESS

    @_traceback_logged
    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.command is not None
        if refusal := self.guardian.refusal():
            self.get_logger().error(f'activate refused: {refusal}')
            return TransitionCallbackReturn.FAILURE
        self.command.active = True
        if not self._wait_applied():
            self.get_logger().warn('activated, but a side is not connected: motors stay at zero')
        return super().on_activate(state)

    @_traceback_logged
    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.command is not None
        self.command.active = False
        if not self._wait_applied():
            self.get_logger().warn('deactivated; a side not connected could not be disabled')
        return super().on_deactivate(state)

    @_traceback_logged
    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    @_traceback_logged
    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    @_traceback_logged
    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f'transition from {state.label} failed: motors zeroed, ports closed')
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def _start_pollers(self, p: DesDriverParameters) -> None:
        self.command = DriveCommand(
            p.cmd_timeout_s,
            max_rpm=p.max_motor_rpm,
            motor=self.setup.powertrain.motor,
            geometry=self.setup.geometry,
            limits=self.setup.limits,
            stop_both_on_link_loss=p.stop_both_on_link_loss,
            active=False,
            stall_timeout_s=max(1.0, 5.0 / p.poll_rate_hz),  # no good cycle for this long: down
        )
        config = DesConfig(
            baudrate=p.baud,
            current_source=p.current_source,
            status_variables=StatusVariables(encoder_counter=p.encoder_counter_variable),
        )
        timing = LinkTiming(
            ack_timeout_s=p.ack_timeout_s,
            reply_timeout_s=p.ack_timeout_s,
            exchange_timeout_s=max(0.25, 3.0 * p.ack_timeout_s),
        )
        self.pollers = {
            side: AmplifierPoller(
                side,
                p.left_port if side == 'left' else p.right_port,
                self.command,
                config=config,
                timing=timing,
                poll_period_s=1.0 / p.poll_rate_hz,
                status_every=p.status_every,
                reconnect_period_s=p.reconnect_period_s,
                encoder_resolution=self.setup.encoder_resolution,
                log_error=self.get_logger().error,
            )
            for side in SIDES
        }
        for poller in self.pollers.values():
            poller.start()
        # Ctrl-Z (SIGTSTP), SIGTTIN, SIGTTOU: zero and disable before the process stops (issue 34)
        self._pause_hook = on_pause(self._pause_for_stop, self.command.resume)
        # (the guardian's heartbeat, issue 34 item 6, is started here too: see docs/RELIABILITY.md)

    def _pause_for_stop(self, signal_name: str) -> None:
        """The process is about to stop: zero, disable, and wait (bounded) until both sides did."""
        command = self.command
        if command is None:
            return
        command.pause(signal_name)
        for poller in self.pollers.values():
            poller.wait_applied(command.generation, 0.5)

    def _wait_connected(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.sample.sequence > 0 for p in self.pollers.values()):
                return
            time.sleep(0.01)
        problems = [f'{s}: {p.sample.message}' for s, p in self.pollers.items() if p.sample.sequence == 0]
        raise ConfigError(f'DES amplifiers not ready after {timeout_s:g} s ({"; ".join(problems)})')

    def _wait_applied(self, timeout_s: float = 3.0) -> bool:
        """Wait until every poller has run a cycle with the command's current state."""
        assert self.command is not None
        generation = self.command.generation
        return all(p.wait_applied(generation, timeout_s) for p in self.pollers.values())

    def _stop_pollers(self) -> None:
        """Zero speed on both sides, then disable both, then close the ports (idempotent)."""
        if self._pause_hook is not None:
            remove_pause_hook(self._pause_hook)
            self._pause_hook = None
        if self.command is not None:
            self.command.shutting_down = True
        for poller in self.pollers.values():
            poller.request_stop()
        for poller in self.pollers.values():
            poller.stop()
            if poller.unsafe_stop:
                self.unsafe_stop = '; '.join(filter(None, (self.unsafe_stop, poller.unsafe_stop)))
                self.get_logger().error(f'stop not confirmed: {poller.unsafe_stop}')

    def _teardown(self) -> None:
        self._stop_pollers()
        self.guardian.close()
        for entity in self._runtime:
            if isinstance(entity, Timer):
                self.destroy_timer(entity)
            else:
                self.destroy_subscription(entity)
        self._runtime = []
        if self.cmd_input is not None:
            self.cmd_input.close()
            self.cmd_input = None
        self.pollers = {}
        self.command = None

    def emergency_stop(self, reason: str) -> None:
        """Zero and disable both amplifiers now (from any thread); the node stays up, inactive."""
        self.get_logger().error(f'{reason}: zeroing and disabling both amplifiers')
        command = self.command
        if command is not None:
            command.active = False
            for poller in self.pollers.values():
                poller.wait_applied(command.generation, 1.0)

    # -- callbacks ------------------------------------------------------------------------------

    @_fail_safe
    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        self.counts['received'] += 1
        command, cmd_input = self.command, self.cmd_input
        if command is None or not command.active or cmd_input is None:
            self.counts['ignored_inactive'] += 1
            return
        twist = cmd_input.accept(msg, self.get_clock().now().nanoseconds * 1e-9)
        if twist is None:  # a stale or future stamp: refused (warned, counted)
            return
        values = (
            twist.linear.x,
            twist.linear.y,
            twist.linear.z,
            twist.angular.x,
            twist.angular.y,
            twist.angular.z,
        )
        if not all(math.isfinite(v) for v in values):
            self.counts['rejected_non_finite'] += 1
            self.get_logger().warn(
                f'rejected cmd_vel with a non-finite value {values} '
                f'({self.counts["rejected_non_finite"]} so far)',
                throttle_duration_sec=_WARN_PERIOD_S,
            )
            return
        checked = command.set_twist(twist.linear.x, twist.angular.z)
        if checked.clamped:
            self.counts['clamped'] += 1
            self.get_logger().warn(
                f'cmd_vel ({twist.linear.x:g} m/s, {twist.angular.z:g} rad/s) clamped to '
                f'({checked.linear_m_s:g} m/s, {checked.yaw_rate_rad_s:g} rad/s) '
                f'({self.counts["clamped"]} so far)',
                throttle_duration_sec=_WARN_PERIOD_S,
            )

    @_fail_safe
    def _on_clear_faults(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        command = self.command
        if command is None:
            response.success, response.message = False, f'not configured ({self.state_label})'
            return response
        self.get_logger().info('clearing amplifier errors on request')
        command.request_clear(list(SIDES))
        reached = self._wait_applied()
        command.withdraw_clear_requests()  # an unreachable side is not cleared behind the caller's back
        latched = {s: p.sample.errors.describe() for s, p in self.pollers.items() if p.sample.fault_latched}
        response.success = reached and not latched
        if latched:
            response.message = 'still latched: ' + ', '.join(f'{s} ({e})' for s, e in latched.items())
        elif not reached:
            response.message = 'a side is not connected: ' + command.stop_reason()
        else:
            response.message = 'cleared' if command.active else 'cleared (inactive: power stages stay off)'
        return response

    @_fail_safe
    def _publish_joint_states(self) -> None:
        samples = {side: poller.sample for side, poller in self.pollers.items()}
        if len(samples) != len(SIDES) or all(samples[s].sequence == self._published[s] for s in SIDES):
            return
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.params.frame_id
        msg.name = [f'{side}_motor' for side in SIDES]
        for side in SIDES:
            self._published[side] = samples[side].sequence
            position, velocity, effort = self._joint_values(side, samples[side])
            msg.position.append(position)
            msg.velocity.append(velocity)
            msg.effort.append(effort)
        self.joint_pub.publish(msg)

    def _joint_values(self, side: str, sample: AmplifierSample) -> tuple[float, float, float]:
        """(position [rad], velocity [rad/s], effort [N m]) at the motor shaft, forward positive."""
        stale_after_s = max(0.2, 5.0 / self.params.poll_rate_hz)
        age_s = self.pollers[side].clock() - sample.stamp  # the clock that stamped it
        if not sample.connected or not sample.sequence or age_s > stale_after_s:
            return math.nan, math.nan, math.nan
        sign = self.setup.geometry.polarity[side]
        counts_per_rev = (
            self.setup.encoder_resolution * self.pollers[side].amp.config.quadrature_counts_per_count
        )
        position = sign * sample.position_counts / counts_per_rev * 2.0 * math.pi
        velocity = sign * sample.velocity_rpm * RPM
        effort = sign * self.setup.powertrain.motor.torque_constant_Nm_A * sample.current_ma / 1000.0
        return position, velocity, effort

    @_fail_safe
    def _publish_diagnostics(self) -> None:
        command = self.command
        if command is None:
            return
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        stop_reason = command.stop_reason()
        for side, poller in self.pollers.items():
            msg.status.append(self._side_status(side, poller, poller.sample, command, stop_reason))
        msg.status.append(self._command_status(command, stop_reason))
        self.diag_pub.publish(msg)

    def _side_status(
        self,
        side: str,
        poller: AmplifierPoller,
        sample: AmplifierSample,
        command: DriveCommand,
        stop_reason: str,
    ) -> DiagnosticStatus:
        halted = command.halted_by
        fault_recent = sample.poller_fault_recent(poller.clock())
        if sample.fault_latched or not sample.connected or fault_recent:
            level = DiagnosticStatus.ERROR
        elif halted or command.links_down or sample.message != 'ok':
            level = DiagnosticStatus.WARN
        else:
            level = DiagnosticStatus.OK
        message = sample.message
        if sample.connected and fault_recent:
            message = f'restarted after a poller fault: {sample.last_poller_fault}'
        elif halted and not sample.fault_latched:
            message = f'stopped: fault on {", ".join(sorted(halted))} side'
        elif level == DiagnosticStatus.WARN and sample.message == 'ok':
            message = f'stopped: {stop_reason}'
        elif level == DiagnosticStatus.OK and stop_reason == 'inactive':
            message = 'ok (inactive: power stage disabled)'
        elif level == DiagnosticStatus.OK and command.timed_out():
            message = 'ok (no cmd_vel: watchdog holds zero speed)'
        values = {
            'port': poller.amp.port,
            'connected': str(sample.connected),
            'enabled': str(sample.enabled),
            'fault_latched': str(sample.fault_latched),
            'status_word': f'0x{int(sample.status):04X}',
            'status': sample.status.describe(),
            'error_word': f'0x{int(sample.errors):04X}',
            'errors': sample.errors.describe(),
            'current_mA': str(sample.current_ma),
            'velocity_rpm': str(sample.velocity_rpm),
            'velocity_setpoint_rpm': str(sample.setpoint_rpm),
            'poll_rate_hz': f'{sample.poll_rate_hz:.1f}',
            'watchdog_zero': str(command.timed_out()),
            'poller_faults': str(sample.poller_faults),
            'last_poller_fault': sample.last_poller_fault,
            **{f'link_{k}': str(v) for k, v in sample.link.items()},
        }
        return DiagnosticStatus(
            level=level,
            name=f'{NODE_NAME}: {side} amplifier',
            message=message,
            hardware_id=poller.amp.port,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )

    def _command_status(self, command: DriveCommand, stop_reason: str) -> DiagnosticStatus:
        rejected = self.counts['rejected_non_finite']
        level = DiagnosticStatus.WARN if rejected or command.nonfinite_setpoints else DiagnosticStatus.OK
        limits = self.setup.limits
        values = {
            'lifecycle_state': self.state_label,
            'stop_reason': stop_reason or 'none (driving on a fresh command)',
            'cmd_vel_received': str(self.counts['received']),
            'cmd_vel_rejected_non_finite': str(rejected),
            'cmd_vel_clamped': str(self.counts['clamped']),
            'cmd_vel_ignored_inactive': str(self.counts['ignored_inactive']),
            'setpoints_non_finite': str(command.nonfinite_setpoints),
            'max_speed_m_s': f'{limits.max_speed_m_s:g}',
            'max_yaw_rate_rad_s': f'{limits.max_yaw_rate_rad_s:g}',
            'max_motor_rpm': f'{command.max_rpm:g}',
            'guardian': self.guardian.status(),
            **(self.cmd_input.diagnostics() if self.cmd_input is not None else {}),
        }
        message = f'{self.state_label}; ' + (f'zero speed: {stop_reason}' if stop_reason else 'driving')
        if rejected:
            message += f'; {rejected} non-finite cmd_vel rejected'
        return DiagnosticStatus(
            level=level,
            name=f'{NODE_NAME}: command',
            message=message,
            hardware_id='cmd_vel',
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )

    # -- shutdown -------------------------------------------------------------------------------

    def stop_motors(self) -> None:
        """Zero speed on both sides, then disable both, then close the ports (idempotent)."""
        self._stop_pollers()

    def destroy_node(self) -> None:
        self._teardown()
        LifecycleNode.destroy_node(self)  # its one base (spelled out: rclpy leaves it unannotated)


def _log_refused(node: LifecycleNode, request: ChangeState.Request, err: Exception) -> None:
    node.get_logger().warn(f'refused lifecycle transition {request.transition}: {err}')


# rclpy's change_state handler raises (and ends the spin) on a transition the current state does not
# have; answer success: false instead (stock rclpy's behaviour where its internals differ)
refuse_invalid_transitions(DesDriver, (RCLError,), _log_refused)


def bring_up(node: DesDriver) -> None:
    """Configure and activate (as a lifecycle manager would); ConfigError if either fails."""
    if node.state_label == 'unconfigured' and node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError(f'des_driver: configure failed: {node.configure_error or "see the log"}')
    if node.state_label == 'inactive' and node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError('des_driver: activate failed: see the log')


def bring_down(node: DesDriver) -> None:
    """Deactivate (zero, disable) and clean up (close the ports), from whatever state it is in."""
    if node.state_label == 'active':
        node.trigger_deactivate()
    if node.state_label == 'inactive':
        node.trigger_cleanup()
    node.stop_motors()  # in any other state too (idempotent)


def make_driver(**kwargs: Unpack[LifecycleNodeKwargs]) -> DesDriver:
    """A :class:`DesDriver`; with ``autostart`` configured and activated (ConfigError if that fails).

    A SIGINT / SIGTERM during start-up (rclpy then invalidates the context under the node) is an
    external shutdown, not an error.
    """
    context = kwargs.get('context')
    try:
        node = DesDriver(**kwargs)
    except RCLError:
        if rclpy.utilities.ok(context=context):
            raise
        raise ExternalShutdownException from None
    if node.params.autostart:
        try:
            bring_up(node)
        except RCLError:
            node.destroy_node()
            if rclpy.utilities.ok(context=context):
                raise
            raise ExternalShutdownException from None
        except BaseException:
            node.destroy_node()
            raise
    return node


def main(args: list[str] | None = None) -> None:
    spin_node(make_driver, NODE_NAME, args)


if __name__ == '__main__':
    main()
