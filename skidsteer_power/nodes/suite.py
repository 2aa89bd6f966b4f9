"""The on-board node suite without ROS launch: ``power_estimator`` + ``des_driver`` in one process.

Each node spins in its own thread with its own :class:`rclpy.executors.SingleThreadedExecutor`: one
shared MultiThreadedExecutor spent most of the process's time building wait sets and, sharing the GIL
with the serial threads, let joint_states fall from 50 Hz to 1-5 Hz (measured with ``run
--simulate``; des_driver alone in its own process kept 49 Hz).

With ``simulate=True`` the amplifiers are :class:`SimulatedPair` on pseudo-terminals, driven through
the robot's own pyserial code path, and each simulated motor is
loaded like the test robot's: the axle torque the FESS map gives for the current command on the
chosen vehicle and terrain (the "ground truth" terrain, which may differ from the estimator's), plus
the side's internal resistance of Table 7.1 (eqs. 7.1-7.4), seen at the motor through the 12:1
reduction. A small ``terrain_sim`` node follows ``cmd_vel`` for that; without cmd_vel for
``cmd_timeout_s`` the load falls to the internal resistance alone (the driver has stopped).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from geometry_msgs.msg import Twist, TwistStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from skidsteer_power.estimator import factory
from skidsteer_power.estimator.prediction import MapPredictor
from skidsteer_power.powertrain import Powertrain

SMOOTHING_RAD_S = 1.0
"""Motor speed over which the Coulomb terms change sign (tanh), so the explicit motor model does not
chatter at standstill [rad/s]."""


@dataclass
class CommandHolder:
    """The latest (V [m/s], yaw rate [rad/s]) and when it arrived (time.monotonic [s]); thread-safe."""

    timeout_s: float = 0.5
    command: tuple[float, float] = (0.0, 0.0)
    stamp_s: float = -math.inf
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def set(self, speed: float, yaw_rate: float) -> None:
        with self._lock:
            self.command, self.stamp_s = (speed, yaw_rate), time.monotonic()

    def current(self) -> tuple[float, float]:
        with self._lock:
            fresh = time.monotonic() - self.stamp_s <= self.timeout_s
            return self.command if fresh else (0.0, 0.0)


class TerrainLoad:
    """Load torque at one simulated motor shaft [N m] for ``SimulatedDes.set_load``.

    T_load(w_m) = T_axle(V, r) / G + b w_m + c tanh(w_m / w_s), in the robot's sense of the side,
    mapped into the amplifier's sense by ``polarity`` (+1/-1, as the driver's parameter). T_axle is
    the map's torque of this side for the held command; b and c the side's internal resistance.
    """

    def __init__(
        self,
        side: str,
        predictor: MapPredictor,
        powertrain: Powertrain,
        commands: CommandHolder,
        polarity: int,
    ) -> None:
        self.side = side
        self.index = 0 if side == 'left' else 1
        self.predictor = predictor
        self.gear_ratio = powertrain.gear_ratio
        self.resistance = powertrain.resistance(side).total
        self.commands = commands
        self.polarity = polarity

    def robot_sense(self, omega_m: float) -> float:
        """Load [N m] at motor speed ``omega_m`` [rad/s], both in the robot's forward-positive sense."""
        speed, yaw_rate = self.commands.current()
        axle = 0.0
        if speed != 0.0 or yaw_rate != 0.0:
            axle = self.predictor.predict(speed, yaw_rate).terrain_torque_Nm[self.index]
        r = self.resistance
        internal = r.viscous_Nm_s * omega_m + r.coulomb_Nm * math.tanh(omega_m / SMOOTHING_RAD_S)
        return axle / self.gear_ratio + internal

    def __call__(self, omega_rad_s: float, t_s: float) -> float:
        return self.polarity * self.robot_sense(self.polarity * omega_rad_s)


class TerrainSim(Node):
    """Follows cmd_vel for the simulated loads (no output)."""

    def __init__(self, commands: CommandHolder, stamped: bool = False, **kwargs: Any) -> None:
        super().__init__('terrain_sim', **kwargs)
        self.commands = commands
        self.create_subscription(TwistStamped if stamped else Twist, 'cmd_vel', self._on_cmd_vel, 10)

    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        if math.isfinite(twist.linear.x) and math.isfinite(twist.angular.z):
            self.commands.set(twist.linear.x, twist.angular.z)


@dataclass
class SuiteOptions:
    """What the suite runs. Paths/names as the nodes' parameters; ``estimator_params`` and
    ``driver_params`` are extra parameter overrides by name."""

    vehicle: str = 'test_robot_track'
    terrain: str = 'dry_sand'
    sim_terrain: str = ''  # ground truth of the simulation ('' = terrain)
    simulate: bool = False
    map_cache_dir: str = ''
    state_file: str = ''
    left_port: str = '/dev/ttyUSB0'
    right_port: str = '/dev/ttyUSB1'
    namespace: str = ''
    estimator_params: dict[str, Any] = field(default_factory=dict)
    driver_params: dict[str, Any] = field(default_factory=dict)


class Suite:
    """Creates, spins (in a background thread or the caller's) and tears down the node suite."""

    def __init__(self, options: SuiteOptions, context: Any = None) -> None:
        from skidsteer_power.nodes.des_driver import DesDriver
        from skidsteer_power.nodes.power_estimator import PowerEstimator

        self.options = options
        self.context = context
        self.vehicle = factory.load_vehicle_config(options.vehicle)
        self.sim = None
        self.nodes: list[Node] = []
        self._executors: list[SingleThreadedExecutor] = []
        self._threads: list[threading.Thread] = []
        try:
            left_port, right_port = options.left_port, options.right_port
            if options.simulate:
                left_port, right_port = self._start_simulation()
            kwargs = {'context': context, 'namespace': options.namespace}
            self.estimator = PowerEstimator(parameter_overrides=self._estimator_params(), **kwargs)
            self.nodes.append(self.estimator)
            self.driver = DesDriver(parameter_overrides=self._driver_params(left_port, right_port), **kwargs)
            self.nodes.append(self.driver)
        except BaseException:
            self.shutdown()
            raise

    def _estimator_params(self) -> list[Parameter]:
        o = self.options
        values = {'vehicle': o.vehicle, 'terrain': o.terrain, 'map_cache_dir': o.map_cache_dir}
        values['state_file'] = o.state_file
        values.update(o.estimator_params)
        return [Parameter(k, value=v) for k, v in values.items()]

    def _driver_params(self, left_port: str, right_port: str) -> list[Parameter]:
        values: dict[str, Any] = {
            'left_port': left_port,
            'right_port': right_port,
            'vehicle': self.options.vehicle,
        }
        values.update(self.options.driver_params)
        return [Parameter(k, value=v) for k, v in values.items()]

    def _start_simulation(self) -> tuple[str, str]:
        from skidsteer_power.des.simulator import SimulatedPair

        o = self.options
        predictor, _, _ = factory.map_predictor(
            self.vehicle, o.sim_terrain or o.terrain, o.map_cache_dir or None
        )
        powertrain = factory.powertrain_for(self.vehicle)
        commands = CommandHolder()
        self.sim = SimulatedPair().start()
        polarity = {'left': int(o.driver_params.get('left_polarity', 1))}
        polarity['right'] = int(o.driver_params.get('right_polarity', -1))
        for side, amp in (('left', self.sim.left), ('right', self.sim.right)):
            amp.set_load(TerrainLoad(side, predictor, powertrain, commands, polarity[side]))
        sim_node = TerrainSim(commands, context=self.context, namespace=o.namespace)
        self.nodes.append(sim_node)
        return self.sim.left.port, self.sim.right.port

    def add_node(self, node: Node) -> None:
        """Add a node (before :meth:`start`); it gets its own executor and thread."""
        self.nodes.append(node)

    def start(self) -> Suite:
        """Spin every node in a background thread of its own (for tests and the CLI's status loop)."""
        from skidsteer_power.nodes.des_driver import bring_up

        bring_up(self.driver)  # managed node: configure + activate (ConfigError if it fails)
        for node in self.nodes:
            executor = SingleThreadedExecutor(context=self.context)
            executor.add_node(node)
            thread = threading.Thread(target=executor.spin, name=f'spin-{node.get_name()}', daemon=True)
            self._executors.append(executor)
            self._threads.append(thread)
            thread.start()
        return self

    def shutdown(self) -> None:
        """Save the energy state, stop the motors, destroy the nodes, stop the simulated amplifiers."""
        from skidsteer_power.nodes.des_driver import bring_down

        if getattr(self, 'driver', None) is not None:
            bring_down(self.driver)  # managed node: deactivate (zero, disable) + cleanup (close)
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
    return factory.state_path(options.state_file, factory.load_vehicle_config(options.vehicle))
