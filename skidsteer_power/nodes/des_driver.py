"""``des_driver``: two DES 70/10 amplifiers (one per side) as a ROS 2 node.

Subscribes ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped with ``twist_stamped:=true``; m/s and
rad/s, REP 103) and ``~/clear_faults`` (std_msgs/Empty: clear latched amplifier errors).
Publishes ``joint_states`` (sensor_msgs/JointState, joints ``left_motor`` and ``right_motor``:
position [rad], velocity [rad/s] at the motor shaft, effort = Kt * current [N m]; forward motion of
the robot is positive on both sides, the per-side ``polarity`` maps to the amplifier's sense; a
side with no fresh data reads NaN) and ``diagnostics`` (diagnostic_msgs/DiagnosticArray, one status
per amplifier: connection, status and error words, raw current [mA] and speed [rpm], link
counters).

Safety: no cmd_vel for ``cmd_vel_timeout_s`` -> zero speed; an amplifier error -> both motors
stopped, reported, cleared only by ``~/clear_faults``; a lost port -> reopened until it returns;
SIGINT/SIGTERM -> zero speed, then disable. All serial I/O runs in one thread per amplifier
(:mod:`skidsteer_power.des.poller`), never in the executor.

On the robot: each transaction takes four turn-arounds ('O' handshakes), so a USB-RS232 adapter's
read latency dominates. FTDI adapters default to a 16 ms latency timer, which could cap the poll
rate at a few Hz; set it to 1 ms (``/sys/bus/usb-serial/devices/ttyUSB0/latency_timer``) to reach
the 50 Hz default (benchmarks/bench_des.py: about 57 Hz per side at 38400 baud on a pty with the
wire's byte time emulated, 0.86 of the line's byte-time limit).
"""

from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist, TwistStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from skidsteer_power.des.kinematics import RPM, twist_to_motor_rpm
from skidsteer_power.des.poller import AmplifierPoller, AmplifierSample, DriveCommand
from skidsteer_power.des.protocol import BAUD_CODES, DesConfig, StatusVariables
from skidsteer_power.des.transport import LinkTiming
from skidsteer_power.errors import ConfigError
from skidsteer_power.nodes.spin import spin_node
from skidsteer_power.powertrain.motor import EC45, GEAR_RATIO

NODE_NAME = 'des_driver'
SIDES = ('left', 'right')


def _float_range(low: float, high: float) -> list[FloatingPointRange]:
    return [FloatingPointRange(from_value=low, to_value=high, step=0.0)]


class DesDriver(Node):
    """Two DES amplifiers behind ``cmd_vel`` / ``joint_states`` / ``diagnostics``."""

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        p = self._read_parameters()
        self.params = p
        self.command = DriveCommand(p['cmd_vel_timeout_s'])
        config = DesConfig(
            baudrate=p['baud'],
            current_source=p['current_source'],
            status_variables=StatusVariables(encoder_counter=p['encoder_counter_variable']),
        )
        timing = LinkTiming(ack_timeout_s=p['ack_timeout_s'], reply_timeout_s=p['ack_timeout_s'])
        self.pollers = {
            side: AmplifierPoller(
                side,
                p[f'{side}_port'],
                self.command,
                config=config,
                timing=timing,
                poll_period_s=1.0 / p['poll_rate_hz'],
                status_every=p['status_every'],
                reconnect_period_s=p['reconnect_period_s'],
                encoder_resolution=p['encoder_resolution'],
            )
            for side in SIDES
        }
        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        msg_type = TwistStamped if p['twist_stamped'] else Twist
        self.create_subscription(msg_type, 'cmd_vel', self._on_cmd_vel, 10)
        self.create_subscription(Empty, '~/clear_faults', self._on_clear_faults, 10)
        self._published = {side: 0 for side in SIDES}
        self.create_timer(1.0 / p['poll_rate_hz'], self._publish_joint_states)
        self.create_timer(1.0 / p['diagnostics_rate_hz'], self._publish_diagnostics)
        for poller in self.pollers.values():
            poller.start()

    # -- parameters -----------------------------------------------------------------------------

    def _declare_parameters(self) -> None:
        def declare(name: str, default: object, description: str, **ranges: object) -> None:
            self.declare_parameter(
                name, default, ParameterDescriptor(description=description, read_only=True, **ranges)
            )

        declare('left_port', '/dev/ttyUSB0', 'serial port (path or pyserial URL) of the left amplifier')
        declare('right_port', '/dev/ttyUSB1', 'serial port (path or pyserial URL) of the right amplifier')
        declare('baud', 38400, 'link speed [bit/s]: 9600, 14400, 19200, 38400, 57600 or 115200')
        declare('left_polarity', 1, 'amplifier sense of forward motion, left side: +1 or -1')
        declare(
            'right_polarity', -1, 'amplifier sense of forward motion, right side (mirrored motor): +1 or -1'
        )
        declare(
            'gear_ratio',
            GEAR_RATIO,
            'motor-to-axle reduction [-] (ch. 7.1.1: 12)',
            floating_point_range=_float_range(0.01, 1000.0),
        )
        declare(
            'encoder_resolution',
            EC45.encoder_counts_per_turn,
            'encoder lines per motor turn [-] (ch. 7.1.2: 2048)',
            integer_range=[IntegerRange(from_value=1, to_value=65535, step=1)],
        )
        declare(
            'tread_m',
            0.426,
            'effective tread for skid-steer kinematics [m] (test_robot_track.yaml, ASSUMED)',
            floating_point_range=_float_range(0.01, 10.0),
        )
        declare(
            'drive_radius_m',
            0.1,
            'sprocket / wheel radius [m] (test_robot_track.yaml, ASSUMED)',
            floating_point_range=_float_range(0.001, 10.0),
        )
        declare(
            'max_motor_rpm',
            4000.0,
            'motor speed limit of the set points [rpm] (EC-45 no-load speed 4010 rpm at 48 V)',
            floating_point_range=_float_range(1.0, 10000.0),
        )
        declare(
            'poll_rate_hz',
            50.0,
            'amplifier poll and joint_states rate [Hz]',
            floating_point_range=_float_range(0.1, 1000.0),
        )
        declare(
            'status_every',
            5,
            'read the status word every N polls [-]',
            integer_range=[IntegerRange(from_value=1, to_value=1000, step=1)],
        )
        declare(
            'cmd_vel_timeout_s',
            0.5,
            'zero speed when no cmd_vel for this long [s]',
            floating_point_range=_float_range(0.01, 60.0),
        )
        declare(
            'reconnect_period_s',
            0.5,
            'retry period for a lost port [s]',
            floating_point_range=_float_range(0.01, 60.0),
        )
        declare(
            'ack_timeout_s',
            0.05,
            'wait for each acknowledge / reply from an amplifier [s]',
            floating_point_range=_float_range(0.001, 10.0),
        )
        declare(
            'diagnostics_rate_hz',
            2.0,
            'diagnostics rate [Hz]',
            floating_point_range=_float_range(0.01, 100.0),
        )
        declare(
            'current_source',
            'status_variable',
            "how currents are read: 'status_variable' (130, documented) or 'is_must' (op 0x29, UNCONFIRMED)",
        )
        declare(
            'encoder_counter_variable',
            143,
            'status variable of the 16-bit encoder counter (a source is off by one from 135 on: UNCONFIRMED)',
            integer_range=[IntegerRange(from_value=128, to_value=255, step=1)],
        )
        declare('twist_stamped', False, 'cmd_vel is geometry_msgs/TwistStamped instead of Twist')
        declare('frame_id', '', 'header.frame_id of joint_states')

    def _read_parameters(self) -> dict:
        names = [
            'left_port', 'right_port', 'baud', 'left_polarity', 'right_polarity', 'gear_ratio',
            'encoder_resolution', 'tread_m', 'drive_radius_m', 'max_motor_rpm', 'poll_rate_hz',
            'status_every', 'cmd_vel_timeout_s', 'reconnect_period_s', 'ack_timeout_s',
            'diagnostics_rate_hz', 'twist_stamped', 'frame_id', 'current_source', 'encoder_counter_variable',
        ]  # fmt: skip
        p = {name: self.get_parameter(name).value for name in names}
        if p['baud'] not in BAUD_CODES:
            raise ConfigError(f'baud must be one of {sorted(BAUD_CODES)}, not {p["baud"]}')
        for side in SIDES:
            if p[f'{side}_polarity'] not in (1, -1):
                raise ConfigError(f'{side}_polarity must be +1 or -1, not {p[f"{side}_polarity"]}')
        if p['current_source'] not in ('status_variable', 'is_must'):
            raise ConfigError(
                f"current_source must be 'status_variable' or 'is_must', not {p['current_source']!r}"
            )
        if p['left_port'] == p['right_port']:
            raise ConfigError(f'left_port and right_port are the same: {p["left_port"]}')
        return p

    # -- callbacks ------------------------------------------------------------------------------

    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        p = self.params
        values = (twist.linear.x, twist.angular.z)
        if not all(math.isfinite(v) for v in values):
            self.get_logger().warn(f'ignoring non-finite cmd_vel {values}', throttle_duration_sec=5.0)
            return
        left, right = twist_to_motor_rpm(
            *values,
            tread_m=p['tread_m'],
            drive_radius_m=p['drive_radius_m'],
            gear_ratio=p['gear_ratio'],
            max_rpm=p['max_motor_rpm'],
        )
        self.command.set({'left': left * p['left_polarity'], 'right': right * p['right_polarity']})

    def _on_clear_faults(self, msg: Empty) -> None:
        self.get_logger().info('clearing amplifier errors on request')
        self.command.request_clear(list(SIDES))

    def _publish_joint_states(self) -> None:
        samples = {side: poller.sample for side, poller in self.pollers.items()}
        if all(samples[s].sequence == self._published[s] for s in SIDES):
            return
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.params['frame_id']
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
        stale_after_s = max(0.2, 5.0 / self.params['poll_rate_hz'])
        if not sample.connected or not sample.sequence or time.monotonic() - sample.stamp > stale_after_s:
            return math.nan, math.nan, math.nan
        sign = self.params[f'{side}_polarity']
        counts_per_rev = (
            self.params['encoder_resolution'] * self.pollers[side].amp.config.quadrature_counts_per_count
        )
        position = sign * sample.position_counts / counts_per_rev * 2.0 * math.pi
        velocity = sign * sample.velocity_rpm * RPM
        effort = sign * EC45.torque_constant_Nm_A * sample.current_ma / 1000.0
        return position, velocity, effort

    def _publish_diagnostics(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        halted = self.command.halted_by
        for side, poller in self.pollers.items():
            msg.status.append(self._side_status(side, poller, poller.sample, halted))
        self.diag_pub.publish(msg)

    def _side_status(
        self, side: str, poller: AmplifierPoller, sample: AmplifierSample, halted: set[str]
    ) -> DiagnosticStatus:
        if sample.fault_latched or not sample.connected:
            level = DiagnosticStatus.ERROR
        elif halted or sample.message != 'ok':
            level = DiagnosticStatus.WARN
        else:
            level = DiagnosticStatus.OK
        message = sample.message
        if halted and not sample.fault_latched:
            message = f'stopped: fault on {", ".join(sorted(halted))} side'
        elif level == DiagnosticStatus.OK and self.command.timed_out():
            message = 'ok (no cmd_vel: watchdog holds zero speed)'
        values = {
            'port': poller.amp.port,
            'connected': str(sample.connected),
            'fault_latched': str(sample.fault_latched),
            'status_word': f'0x{int(sample.status):04X}',
            'status': sample.status.describe(),
            'error_word': f'0x{int(sample.errors):04X}',
            'errors': sample.errors.describe(),
            'current_mA': str(sample.current_ma),
            'velocity_rpm': str(sample.velocity_rpm),
            'velocity_setpoint_rpm': str(sample.setpoint_rpm),
            'poll_rate_hz': f'{sample.poll_rate_hz:.1f}',
            'watchdog_zero': str(self.command.timed_out()),
            **{f'link_{k}': str(v) for k, v in sample.link.items()},
        }
        return DiagnosticStatus(
            level=level,
            name=f'{NODE_NAME}: {side} amplifier',
            message=message,
            hardware_id=poller.amp.port,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )

    # -- shutdown -------------------------------------------------------------------------------

    def stop_motors(self) -> None:
        """Zero speed on both sides, then disable both, then close the ports (idempotent)."""
        self.command.shutting_down = True
        for poller in self.pollers.values():
            poller.request_stop()
        for poller in self.pollers.values():
            poller.stop()

    def destroy_node(self) -> None:
        self.stop_motors()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(DesDriver, NODE_NAME, args)


if __name__ == '__main__':
    main()
