"""The on-board node suite without ROS launch: ``power_estimator`` + ``des_driver`` in one process.

Each node spins in its own thread with its own :class:`rclpy.executors.SingleThreadedExecutor`: one
shared MultiThreadedExecutor spent most of the process's time building wait sets and, sharing the GIL
with the serial threads, let joint_states fall from 50 Hz to 1-5 Hz (measured with ``run
--simulate``; des_driver alone in its own process kept 49 Hz).

With ``simulate=True`` the amplifiers are :class:`SimulatedPair` on pseudo-terminals, driven through
the robot's own pyserial code path, and each simulated motor is loaded by the digital twin
(``skidsteer_power.twin``, never the estimator's FESS map): the twin's body and terrain contact on
its own ("truth") terrain and patches advance in real time with the two motors' speeds
(``twin/live.py``), and each motor feels its side's axle torque through the 12:1 reduction plus the
side's internal resistance of Table 7.1 (eqs. 7.1-7.4). A small ``terrain_sim`` node publishes the
twin's ``odom`` (encoder dead reckoning) and ``ground_truth/odom`` at 20 Hz.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from skidsteer_power.estimator import factory
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.stop_signals import StopFlag
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from typing import TypedDict, Unpack

    from rclpy.context import Context

    from skidsteer_power.des.simulator import SimulatedPair
    from skidsteer_power.nodes.param_spec import ParamValue
    from skidsteer_power.nodes.ros_types import NodeKwargs
    from skidsteer_power.twin.live import TwinCoupling
    from skidsteer_power.vehicle import Vehicle

    class _Placement(TypedDict):
        """Where each node of the suite lives: its context and namespace (of :class:`NodeKwargs`)."""

        context: Context | None
        namespace: str


SMOOTHING_RAD_S = 1.0
"""Motor speed over which the Coulomb terms change sign (tanh), so the explicit motor model does not
chatter at standstill [rad/s]."""


class TerrainSim(Node):
    """Publishes the twin's odom (encoder dead reckoning) and ground_truth/odom at 20 Hz."""

    def __init__(self, coupling: TwinCoupling, **kwargs: Unpack[NodeKwargs]) -> None:
        from nav_msgs.msg import Odometry

        super().__init__('terrain_sim', **kwargs)
        self.coupling = coupling
        self._odom = self.create_publisher(Odometry, 'odom', 10)
        self._truth = self.create_publisher(Odometry, 'ground_truth/odom', 10)
        self._message = Odometry
        self.create_timer(0.05, self._publish)

    def _publish(self) -> None:
        pose, twist, odom = self.coupling.snapshot()
        stamp = self.get_clock().now().to_msg()
        for publisher, (x, y, yaw, vx, vy, wz) in (
            (self._odom, (odom[0], odom[1], odom[2], odom[3], 0.0, odom[4])),
            (self._truth, (*pose, *twist)),
        ):
            msg = self._message()
            msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp, 'odom', 'base_link'
            msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
            msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
            msg.twist.twist.linear.x, msg.twist.twist.linear.y = float(vx), float(vy)
            msg.twist.twist.angular.z = float(wz)
            publisher.publish(msg)


def driver_joint_params(vehicle: Vehicle) -> dict[str, ParamValue]:
    """The estimator's joint mapping for des_driver's joint_states (``left_motor``/``right_motor``:
    motor shaft, effort = K_t I [N m], the vehicle's powertrain reduction), whatever joints the
    vehicle file's ``joints:`` names for its own stack (a ros2_control robot's wheel joints): in
    this suite the joint_states come from des_driver (issue 37 item 3)."""
    gear_ratio = float(Powertrain.for_vehicle(vehicle).gear_ratio)
    return {
        'left_joints': 'left_motor',
        'right_joints': 'right_motor',
        'joints_at': 'motor',
        'effort_is': 'torque',
        'joint_gear_ratio': gear_ratio,
    }


@dataclass
class SuiteOptions:
    """What the suite runs. Paths/names as the nodes' parameters; ``estimator_params`` and
    ``driver_params`` are extra parameter overrides by name."""

    vehicle: str = 'test_robot_track'
    terrain: str = 'dry_sand'
    sim_terrain: str = ''  # ground truth of the simulation ('' = terrain)
    patches: str = ''  # YAML file of polygons with other truth terrains (twin/terrain_field.py)
    simulate: bool = False
    map_cache_dir: str = ''
    state_file: str = ''
    left_port: str = '/dev/ttyUSB0'
    right_port: str = '/dev/ttyUSB1'
    namespace: str = ''
    estimator_params: dict[str, ParamValue] = field(default_factory=dict)
    driver_params: dict[str, ParamValue] = field(default_factory=dict)


class Suite:
    """Creates, spins (in a background thread or the caller's) and tears down the node suite."""

    def __init__(
        self, options: SuiteOptions, context: Context | None = None, stop: StopFlag | None = None
    ) -> None:
        from skidsteer_power.nodes.des_driver import DesDriver
        from skidsteer_power.nodes.power_estimator import PowerEstimator

        self.options = options
        self.context = context
        self.stop = stop if stop is not None else StopFlag()
        self.failure = ''  # why a thread of the process died (then ``stop`` is set), else ''
        self._previous_excepthook: Callable[[threading.ExceptHookArgs], None] | None = None
        self.vehicle = load_vehicle(options.vehicle)
        self.sim: SimulatedPair | None = None
        self.nodes: list[Node] = []
        self._executors: list[SingleThreadedExecutor] = []
        self._threads: list[threading.Thread] = []
        try:
            left_port, right_port = options.left_port, options.right_port
            if options.simulate:
                left_port, right_port = self._start_simulation()
            kwargs: _Placement = {'context': context, 'namespace': options.namespace}
            self.estimator = PowerEstimator(parameter_overrides=self._estimator_params(), **kwargs)
            self.nodes.append(self.estimator)
            self.driver = DesDriver(parameter_overrides=self._driver_params(left_port, right_port), **kwargs)
            self.nodes.append(self.driver)
        except BaseException:
            self.shutdown()
            raise

    def _estimator_params(self) -> list[Parameter]:
        o = self.options
        values: dict[str, ParamValue] = {
            'vehicle': o.vehicle,
            'terrain': o.terrain,
            'map_cache_dir': o.map_cache_dir,
        }
        values['state_file'] = o.state_file
        values.update(self._driver_limits())
        values.update(driver_joint_params(self.vehicle))
        values.update(o.estimator_params)
        return [Parameter(k, value=v) for k, v in values.items()]

    def _driver_limits(self) -> dict[str, float]:
        """The des_driver's own limits (its parameters or their defaults) as the estimator's
        ``drive_*`` parameters: the estimator predicts the set points the driver really commands."""
        from skidsteer_power.des.command import limits_for
        from skidsteer_power.drive.controller import controller_for_vehicle
        from skidsteer_power.nodes import des_driver
        from skidsteer_power.powertrain import Powertrain
        from skidsteer_power.powertrain.motor import RPM

        given = self.options.driver_params
        defaults = {spec.name: spec.default for spec in des_driver.PARAMETERS}

        def value(name: str) -> float:
            return float(given.get(name, defaults[name]))

        powertrain = Powertrain.for_vehicle(self.vehicle)
        limit_names = ('max_speed_m_s', 'max_yaw_rate_rad_s', 'max_accel_m_s2', 'max_yaw_accel_rad_s2')
        given_limits = {name: value(name) for name in limit_names}  # defaults 0: the vehicle's
        limits = limits_for(controller_for_vehicle(self.vehicle, powertrain), given_limits)  # as the driver
        return {
            'drive_max_speed_m_s': limits.max_speed_m_s,
            'drive_max_yaw_rate_rad_s': limits.max_yaw_rate_rad_s,
            'drive_max_wheel_rad_s': value('max_motor_rpm') * RPM / powertrain.gear_ratio,
        }

    def _driver_params(self, left_port: str, right_port: str) -> list[Parameter]:
        values: dict[str, ParamValue] = {
            'left_port': left_port,
            'right_port': right_port,
            'vehicle': self.options.vehicle,
        }
        values.update(self.options.driver_params)
        return [Parameter(k, value=v) for k, v in values.items()]

    def _start_simulation(self) -> tuple[str, str]:
        from skidsteer_power.des.simulator import SimulatedPair
        from skidsteer_power.terramechanics import load_terrain
        from skidsteer_power.twin import Twin, load_patches
        from skidsteer_power.twin.live import TwinCoupling, TwinLoad, configure_amplifier

        o = self.options
        patches = load_patches(o.patches) if o.patches else None
        twin = Twin(self.vehicle, load_terrain(o.sim_terrain or o.terrain), patches=patches)
        coupling = TwinCoupling(twin)
        self.sim = SimulatedPair(motor=twin.powertrain.motor)  # the vehicle's motor, as the driver's
        polarity = {'left': int(o.driver_params.get('left_polarity', 1))}
        polarity['right'] = int(o.driver_params.get('right_polarity', -1))
        for side, amp in (('left', self.sim.left), ('right', self.sim.right)):
            configure_amplifier(amp.model, twin)  # the body's inertia lives in the twin only
            amp.set_load(TwinLoad(coupling, side, polarity[side]))
        self.sim.start()
        sim_node = TerrainSim(coupling, context=self.context, namespace=o.namespace)
        self.nodes.append(sim_node)
        return self.sim.left.port, self.sim.right.port

    def add_node(self, node: Node) -> None:
        """Add a node (before :meth:`start`); it gets its own executor and thread."""
        self.nodes.append(node)

    def start(self) -> Suite:
        """Spin every node in a background thread of its own (for tests and the CLI's status loop)."""
        from skidsteer_power.nodes.des_driver import bring_up

        bring_up(self.driver)  # managed node: configure + activate (ConfigError if it fails)
        self._previous_excepthook, threading.excepthook = threading.excepthook, self._thread_died
        for node in self.nodes:
            executor = SingleThreadedExecutor(context=self.context)
            executor.add_node(node)
            thread = threading.Thread(target=executor.spin, name=f'spin-{node.get_name()}', daemon=True)
            self._executors.append(executor)
            self._threads.append(thread)
            thread.start()
        return self

    def _thread_died(self, args: threading.ExceptHookArgs) -> None:
        """Any thread of the process ending with an exception (a node's spin thread when a callback
        raises, a simulated amplifier) stops the whole suite: ``failure`` says which and why, and
        ``stop`` is set. The traceback is printed as before (the previous hook)."""
        if self._previous_excepthook is not None:
            self._previous_excepthook(args)
        name = args.thread.name if args.thread is not None else 'a thread'
        self.failure = self.failure or f'{name} died: {args.exc_type.__name__}: {args.exc_value}'
        self.stop.set(self.failure)

    def shutdown(self) -> None:
        """Save the energy state, stop the motors, destroy the nodes, stop the simulated amplifiers."""
        from skidsteer_power.nodes.des_driver import bring_down

        if self._previous_excepthook is not None:
            threading.excepthook, self._previous_excepthook = self._previous_excepthook, None
        if getattr(self, 'driver', None) is not None:
            bring_down(self.driver)  # managed node: deactivate (zero, disable) + cleanup (close)
            if self.driver.unsafe_stop:  # never exit 0 with a motor possibly enabled (issue 34)
                self.failure = self.failure or f'motors not confirmed stopped: {self.driver.unsafe_stop}'
        for executor in self._executors:
            executor.shutdown(timeout_sec=2.0)
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._executors.clear()
        self._threads.clear()
        for node in reversed(self.nodes):
            node.destroy_node()
        self.nodes.clear()
        if self.sim is not None:
            self.sim.stop()
            self.sim = None


def state_file_for(options: SuiteOptions) -> Path:
    """The energy-state file the suite's estimator uses."""
    vehicle = load_vehicle(options.vehicle)
    return factory.state_path(options.state_file, vehicle, options.namespace)
