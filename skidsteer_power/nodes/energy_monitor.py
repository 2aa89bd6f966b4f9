"""``energy_monitor``: a terminal view for energy-aware teleoperation (chapter 7.1.3 software, redone).

Modes
-----
``free``  arrow keys drive (Up/Down: forward speed, Left/Right: yaw rate, Space: stop, q: quit); the
          keys are read from the terminal in raw mode with a zero-timeout ``select`` inside a timer,
          so the executor never blocks.
``case``  a V / yaw-rate profile (``--case-file`` CSV with duration_s,speed_m_s,yaw_rate_rad_s, or
          ``--speed/--yaw-rate/--duration``) is sent, then the robot is stopped and the monitor exits.
``view``  watch only; nothing is published.

Subscribes ``cmd_vel`` (the command shown is the one on the topic, whoever sends it),
``power/summary`` (diagnostic_msgs/DiagnosticArray, figures by name, among them the prediction
power_estimator corrects online: ``corrected_*_W``), ``joint_states``,
``battery/state``, ``energy/remaining_wh``, ``energy/time_to_empty_s`` and its ``_p10_s`` /
``_p90_s`` bounds, ``energy/path_required_wh``, ``energy/path_margin_wh`` (all best effort, so they
match any publisher); publishes ``cmd_vel`` (Twist, or TwistStamped with ``--stamped``) at
``--rate`` Hz in free and case mode. A source silent for
:data:`~skidsteer_power.ui.monitor.STALE_AFTER_S` is greyed and marked stale. Every frame shown
is appended to ``--csv`` (default ``energy_monitor_<UTC time>.csv``). The drawing is
:func:`skidsteer_power.ui.monitor.render`.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import sys
import termios
import time
import tty
from collections.abc import Callable
from typing import TYPE_CHECKING

import rclpy
import rclpy.utilities
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64

from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError, SkidsteerError
from skidsteer_power.estimator.summary import SUMMARY_STATUS_NAME, summary_from_key_values
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.ui.monitor import (
    STALE_AFTER_S,
    CaseProfile,
    CsvLog,
    FreeDrive,
    MonitorView,
    csv_row,
    decode_keys,
    load_case_csv,
    render,
)
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from typing import Unpack

    from skidsteer_power.nodes.ros_types import NodeKwargs

MODES = ('free', 'case', 'view')


class KeyReader:
    """Reads key presses from a terminal file descriptor without blocking.

    The terminal is put in cbreak mode (no line buffering, no echo) and restored by :meth:`close`.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        self._pending = b''

    def read_keys(self) -> list[str]:
        """Key names typed since the last call ([] if none); never waits."""
        data = b''
        while select.select([self.fd], [], [], 0)[0]:
            chunk = os.read(self.fd, 64)
            if not chunk:
                break
            data += chunk
        keys, self._pending = decode_keys(self._pending + data)
        return keys

    def close(self) -> None:
        termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)


class EnergyMonitor(Node):
    """Collects what the estimator and driver publish into a :class:`MonitorView`; drives in free/case mode.

    ``on_frame(view)`` is called at ``refresh_hz`` (the terminal draws there); ``keys`` is a
    :class:`KeyReader` for free mode; ``profile`` the case profile.
    """

    if TYPE_CHECKING:  # rclpy 7 leaves it unannotated; its type

        def destroy_node(self) -> None: ...

    def __init__(
        self,
        mode: str = 'view',
        *,
        profile: CaseProfile | None = None,
        keys: KeyReader | None = None,
        csv_path: str | os.PathLike[str] | None = None,
        on_frame: Callable[[MonitorView], None] | None = None,
        stamped: bool = False,
        rate_hz: float = 10.0,
        refresh_hz: float = 5.0,
        drive: FreeDrive | None = None,
        vehicle: str = 'test_robot_track',
        **node_kwargs: Unpack[NodeKwargs],
    ) -> None:
        super().__init__('energy_monitor', **node_kwargs)
        if mode not in MODES:
            raise InputError(f'mode must be one of {", ".join(MODES)}, not {mode!r}')
        if mode == 'case' and profile is None:
            raise InputError('case mode needs a profile (a case file or --speed/--yaw-rate/--duration)')
        self.view = MonitorView(mode=mode)
        self.torque_constant_Nm_A = Powertrain.for_vehicle(load_vehicle(vehicle)).motor.torque_constant_Nm_A
        """K_t of the vehicle's motor [N m/A]: the driver publishes effort = K_t I (DESIGN.md, des_driver)."""
        self.profile, self.keys, self.on_frame = profile, keys, on_frame
        self.drive = drive or FreeDrive()
        self.stamped = stamped
        self.done = False
        self._started = time.monotonic()
        self.last_heard = dict.fromkeys(('command', 'joint_states', 'summary', 'battery'), -math.inf)
        self.target = (0.0, 0.0)
        """What free/case mode sends [m/s, rad/s]; ``view.command`` is what is seen on cmd_vel."""
        self.csv = CsvLog(csv_path) if csv_path else None
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)  # matches any publisher
        cmd_type = TwistStamped if stamped else Twist
        self.create_subscription(cmd_type, 'cmd_vel', self._on_cmd_vel, qos)
        self.create_subscription(DiagnosticArray, 'power/summary', self._on_summary, qos)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, qos)
        self.create_subscription(BatteryState, 'battery/state', self._on_battery, qos)
        self.create_subscription(Float64, 'energy/remaining_wh', self._on_remaining, qos)
        self.create_subscription(Float64, 'energy/time_to_empty_s', self._on_tte, qos)
        self.create_subscription(Float64, 'energy/time_to_empty_p10_s', self._on_tte_p10, qos)
        self.create_subscription(Float64, 'energy/time_to_empty_p90_s', self._on_tte_p90, qos)
        self.create_subscription(Float64, 'energy/path_required_wh', self._on_path_required, qos)
        self.create_subscription(Float64, 'energy/path_margin_wh', self._on_path_margin, qos)
        if mode != 'view':
            self.pub_cmd = self.create_publisher(TwistStamped if stamped else Twist, 'cmd_vel', 10)
            self.create_timer(1.0 / rate_hz, self._on_drive_timer)
        if self.profile is not None:
            self.view.case_total_s = self.profile.duration_s
        self.create_timer(1.0 / refresh_hz, self._on_frame_timer)

    # --- inputs -------------------------------------------------------------------------------
    def _heard(self, source: str) -> None:
        self.last_heard[source] = time.monotonic()

    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        self.view.command = (float(twist.linear.x), float(twist.angular.z))
        self._heard('command')

    def _on_summary(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == SUMMARY_STATUS_NAME:
                self.view.summary = summary_from_key_values((kv.key, kv.value) for kv in status.values)
                self._heard('summary')

    def _on_joint_states(self, msg: JointState) -> None:
        index = {name: i for i, name in enumerate(msg.name)}
        if not all(n in index for n in ('left_motor', 'right_motor')):
            return
        left, right = index['left_motor'], index['right_motor']
        if len(msg.velocity) > max(left, right):
            self.view.motor_speed_rad_s = (msg.velocity[left], msg.velocity[right])
        if len(msg.effort) > max(left, right):
            kt = self.torque_constant_Nm_A
            self.view.motor_current_A = (msg.effort[left] / kt, msg.effort[right] / kt)
        self._heard('joint_states')

    def _on_battery(self, msg: BatteryState) -> None:
        self.view.soc, self.view.voltage_V = msg.percentage, msg.voltage
        self._heard('battery')

    def _on_remaining(self, msg: Float64) -> None:
        self.view.remaining_wh = msg.data
        self._heard('battery')

    def _on_tte(self, msg: Float64) -> None:
        self.view.time_to_empty_s = msg.data
        self._heard('battery')

    def _on_tte_p10(self, msg: Float64) -> None:
        """The time to empty that 10 % of the spread falls below [s] (estimator/tte_bounds.py)."""
        self.view.time_to_empty_p10_s = msg.data
        self._heard('battery')

    def _on_tte_p90(self, msg: Float64) -> None:
        """The time to empty that 90 % of the spread falls below [s]."""
        self.view.time_to_empty_p90_s = msg.data
        self._heard('battery')

    def _on_path_required(self, msg: Float64) -> None:
        """Energy to drive the planned path [Wh] (power_estimator's path energy)."""
        self.view.path_required_wh = msg.data

    def _on_path_margin(self, msg: Float64) -> None:
        """Energy left after the planned path and the way back [Wh] (power_estimator's path energy)."""
        self.view.path_margin_wh = msg.data

    # --- driving ------------------------------------------------------------------------------
    def _on_drive_timer(self) -> None:
        if self.keys is not None:
            for key in self.keys.read_keys():
                if key == 'quit':
                    self.done = True
                else:
                    self.target = self.drive.apply(self.target, key)
        if self.profile is not None:
            elapsed = time.monotonic() - self._started
            command = self.profile.command_at(elapsed)
            self.view.case_elapsed_s = min(elapsed, self.profile.duration_s)
            if command is None:
                self.done = True
            self.target = command or (0.0, 0.0)
        self.publish_command(*(self.target if not self.done else (0.0, 0.0)))

    def publish_command(self, speed_m_s: float, yaw_rate_rad_s: float) -> None:
        twist = Twist()
        twist.linear.x, twist.angular.z = float(speed_m_s), float(yaw_rate_rad_s)
        if self.stamped:
            msg = TwistStamped(twist=twist)
            msg.header.stamp = self.get_clock().now().to_msg()
            self.pub_cmd.publish(msg)
        else:
            self.pub_cmd.publish(twist)

    # --- display ------------------------------------------------------------------------------
    def _on_frame_timer(self) -> None:
        now = time.monotonic()
        self.view.stale = frozenset(k for k, t in self.last_heard.items() if now - t > STALE_AFTER_S)
        self.view.ready = 'joint_states' not in self.view.stale
        if self.csv is not None:
            self.csv.write([csv_row(self.view, time.monotonic() - self._started)])
        if self.on_frame is not None:
            self.on_frame(self.view)

    def close(self) -> None:
        """Stop the robot (free and case mode) and close the CSV file."""
        if self.view.mode != 'view':
            self.publish_command(0.0, 0.0)
        if self.csv is not None:
            self.csv.close()


# --- command line -------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='energy_monitor', description=__doc__.split('\n')[0])
    parser.add_argument('--mode', choices=MODES, default='view')
    parser.add_argument('--case-file', help='CSV profile: duration_s,speed_m_s,yaw_rate_rad_s')
    parser.add_argument('--speed', type=float, help='case mode: forward speed [m/s]')
    parser.add_argument('--yaw-rate', type=float, default=0.0, help='case mode: yaw rate [rad/s] (+ left)')
    parser.add_argument('--duration', type=float, default=10.0, help='case mode: duration [s]')
    parser.add_argument('--csv', help='CSV file of what was shown (default energy_monitor_<UTC>.csv)')
    parser.add_argument('--stamped', action='store_true', help='publish TwistStamped')
    parser.add_argument('--rate', type=float, default=10.0, help='cmd_vel rate [Hz]')
    parser.add_argument(
        '--vehicle',
        default='test_robot_track',
        help='vehicle name or YAML file (current = effort / its K_t)',
    )
    return parser


def profile_from_args(args: argparse.Namespace) -> CaseProfile | None:
    """The case profile named by the arguments (file, or one speed/yaw-rate step), or None."""
    if args.case_file:
        return load_case_csv(args.case_file)
    if args.speed is not None:
        return CaseProfile((Segment(args.speed, args.yaw_rate, args.duration),))
    return None


def main(args: list[str] | None = None) -> int:
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    options = build_parser().parse_args(argv)
    try:
        return _run(options, args)
    except SkidsteerError as err:
        print(f'energy_monitor: error: {err}', file=sys.stderr)
        return 2


def _run(options: argparse.Namespace, ros_args: list[str] | None) -> int:
    from rich.console import Console
    from rich.live import Live

    profile = profile_from_args(options)
    if options.mode == 'case' and profile is None:
        raise InputError('case mode needs a profile (a case file or --speed/--yaw-rate/--duration)')
    if options.mode == 'free' and not sys.stdin.isatty():
        raise InputError('free mode reads the arrow keys from a terminal; stdin is not one')
    csv_path = options.csv or time.strftime('energy_monitor_%Y%m%dT%H%M%SZ.csv', time.gmtime())
    keys = KeyReader(sys.stdin.fileno()) if options.mode == 'free' else None
    rclpy.init(args=ros_args)
    node = None
    console = Console()
    try:
        with Live(render(MonitorView(mode=options.mode)), console=console, auto_refresh=False) as live:
            node = EnergyMonitor(
                options.mode, profile=profile, keys=keys, csv_path=csv_path, stamped=options.stamped,
                rate_hz=options.rate, vehicle=options.vehicle,
                on_frame=lambda view: live.update(render(view), refresh=True),
            )  # fmt: skip
            while rclpy.utilities.ok() and not node.done:
                rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if keys is not None:
            keys.close()
        if node is not None:
            node.close()
            node.destroy_node()
            console.print(f'\nsaved what was shown to {csv_path}')
        rclpy.utilities.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
