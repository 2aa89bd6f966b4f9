"""``power_estimator`` node: predicted and measured locomotion power, battery state, diagnostics.

A thin rclpy shell around :class:`skidsteer_power.estimator.EstimatorCore` (all physics is there).

Topics (names are defaults; remap freely)
----------------------------------------
subscribes (best-effort by default, so reliable AND best-effort publishers both match; see QoS)
    ``cmd_vel``  geometry_msgs/Twist or TwistStamped (``cmd_vel_type``, by default whichever the
                 publishers offer; stale or future stamps refused: nodes/cmd_vel_input.py):
                 linear.x = V [m/s], angular.z = yaw rate [rad/s] (REP 103, + = left)
    ``joint_states`` sensor_msgs/JointState from ``des_driver``: ``left_motor``/``right_motor``,
                 velocity = motor shaft speed [rad/s], effort = Kt * I [N m]; any other robot's
                 joints by the vehicle file's ``joints:`` section or the ``*_joints`` parameters
publishes per cmd_vel
    ``power/predicted`` sensor_msgs/JointState: ``left_motor``, ``right_motor`` (motor shaft: velocity
                 [rad/s], effort = predicted Kt * I [N m], comparable with joint_states) and
                 ``left_axle``, ``right_axle`` (axle / sprocket: velocity [rad/s], effort = torque the
                 terrain needs [N m]); stamp = the TwistStamped's, else receive time
    ``power/predicted_twist`` geometry_msgs/TwistStamped, with the figures below (``figure_period_s``):
                 the motion the model expects for the latest command (``kinematics: cmd``: FESS
                 at its wheel speed set points; linear.x = V [m/s], angular.z = yaw rate [rad/s];
                 frame base_link; stamp = that command's)
periodic, and on ``~/reset_odometry``
    ``odom/predicted`` nav_msgs/Odometry: that motion dead-reckoned (frame odom, child base_link;
                 every ``publish_period_s``; the pose restarts at the origin on ``~/reset_odometry``)
publishes per joint_states
    ``power/measured`` sensor_msgs/JointState: ``left_motor``, ``right_motor`` as measured (velocity
                 [rad/s], effort = Kt * I [N m]) after the side mapping; stamp = the joint_states'
                 (both with an empty frame_id)
figures for plots, std_msgs/Float64, the latest value every ``figure_period_s`` (20 Hz) while new
cmd_vel / joint_states come (not per message: 9 publishes per input pair cost more than the physics)
    ``power/predicted_left_w``, ``power/predicted_right_w`` (motor terminal power [W]),
    ``power/predicted_battery_w`` (both sides at the battery [W]), ``power/terrain_w``,
    ``power/internal_w`` [W], ``power/traction_margin`` [-];
    ``power/measured_left_w``, ``power/measured_right_w``, ``power/measured_battery_w`` [W]
periodic (``publish_period_s``)
    ``power/summary`` diagnostic_msgs/DiagnosticArray, one status named 'power summary' whose
    key/values are every named figure (:data:`skidsteer_power.estimator.summary.SUMMARY_FIELDS`);
    ``battery/state`` sensor_msgs/BatteryState (V, A, Ah, fraction; NaN where unknown, status from
    the current's sign); ``energy/remaining_wh`` std_msgs/Float64 [Wh]; ``energy/time_to_empty_s``
    std_msgs/Float64 [s] (inf when idle); ``energy/time_to_empty_p10_s``, ``energy/time_to_empty_p90_s``
    std_msgs/Float64 [s] (bounds, :mod:`skidsteer_power.estimator.tte_bounds`); ``power/correction``
    sensor_msgs/JointState whose names are the online correction's fields (units in the names) and
    whose positions are their values (:data:`skidsteer_power.estimator.adaptation.CORRECTION_FIELDS`);
    the terrain-change flag is in ``diagnostics`` (``terrain_changes``, ``terrain_changed_at_s``, a
    warning for 10 s); ``diagnostics`` diagnostic_msgs/DiagnosticArray (energy
    source, stale inputs, rejected-input counts, implausible-power counts (WARN), traction warning,
    malformed-message counts ``malformed_<topic>`` (WARN for 10 s after one: a cmd_vel or joint_states
    whose bytes do not decode is dropped, counted and logged at most every ``warn_period_s``,
    :mod:`skidsteer_power.nodes.malformed`)) every ``diagnostics_period_s``.
path energy (:mod:`skidsteer_power.nodes.path_hook`)
    ``plan`` nav_msgs/Path in; ``energy/path_required_wh``, ``energy/path_margin_wh`` std_msgs/Float64
    [Wh] out, and a ``path energy`` diagnostic that WARNs while the margin is negative.
service
    ``~/reset_energy`` std_srvs/Trigger: the battery was swapped for a full one; state of charge back
    to full, energy tallies to 0 J, state file rewritten.
    ``~/reset_odometry`` std_srvs/Trigger: ``odom/predicted`` restarts at the origin, heading 0.

QoS
---
Subscriptions are best-effort by default (``input_reliability``): a best-effort reader matches both
reliable and best-effort writers, a reliable reader only reliable ones (sensor-data QoS drivers would
be dropped). ``output_qos: sensor_data`` makes the per-message outputs best-effort, depth 5.
Every publisher and subscription accepts ``qos_overrides.<topic>.<publisher|subscription>.<policy>``
parameters (depth, durability, history, reliability), e.g. ``qos_overrides./joint_states.subscription
.reliability: reliable`` where every joint_states writer is reliable and no loss is acceptable.

The energy state is saved atomically to ``state_file`` every ``save_period_s`` (0.5 s: what a SIGKILL
or power cut can lose; written by a thread, skipped while nothing changed) and on shutdown, and
restored on start; an unusable file is moved aside to ``<file>.corrupt-<UTC time>`` with one
warning. ``terrain`` can be set at run time: the new map is loaded (or built) in a worker thread and
swapped in when ready; the old map serves until then.

CPU (issue 18): ``main`` spins with :class:`skidsteer_power.nodes.spin.LeanExecutor` (the wait set
is kept between waits); publishers carry no QoS-event handlers (:class:`~skidsteer_power.nodes.spin
.QuietNode`); cmd_vel and joint_states are taken raw and decoded by rosbags, and power/predicted and
power/measured are kept serialized, only stamp and numbers patched (:mod:`skidsteer_power.nodes.wire`);
the figure topics come from a timer; a backlog of cmd_vel or joint_states is taken in batches
(:class:`~skidsteer_power.nodes.spin.Batched`). ``benchmarks/bench_estimator.py`` measures latency,
loss and CPU per message, and the floor under them (the same node shell with no estimator).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from skidsteer_power.drive.prediction_modes import prediction_mode
from skidsteer_power.errors import ConfigError, InputError, SkidsteerError
from skidsteer_power.estimator import factory
from skidsteer_power.estimator.adaptation import CORRECTION_FIELDS, AdaptationSettings, correction_values
from skidsteer_power.estimator.core import EstimatorCore, EstimatorSettings, RejectedInput
from skidsteer_power.estimator.factory import BatteryMessageFields
from skidsteer_power.estimator.inputs import InputLimits, JointMap
from skidsteer_power.estimator.odometry import PredictedOdometry
from skidsteer_power.estimator.persistence import StateWriter, load_or_quarantine
from skidsteer_power.estimator.prediction import Prediction, Predictor
from skidsteer_power.estimator.state_lock import StateLock
from skidsteer_power.estimator.summary import (
    COMMAND_FIGURES,
    MEASUREMENT_FIGURES,
    SUMMARY_STATUS_NAME,
    measurement_figures,
    prediction_figures,
    summary_key_values,
)
from skidsteer_power.nodes import cmd_vel_input
from skidsteer_power.nodes.cmd_vel_input import CmdVelInput
from skidsteer_power.nodes.malformed import MalformedInputs
from skidsteer_power.nodes.measured_power_feed import vehicle_limits, vendor_feed
from skidsteer_power.nodes.param_spec import ParamSpec, declare, read_parameters
from skidsteer_power.nodes.parameters import PowerEstimatorParameters
from skidsteer_power.nodes.path_hook import PARAMETERS as PATH_PARAMETERS
from skidsteer_power.nodes.path_hook import PathEnergyHook, PathInputs
from skidsteer_power.nodes.spin import Batched, LeanExecutor, QuietNode, spin_node
from skidsteer_power.nodes.wire import PackedJointState, decoder
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from typing import Unpack

    from builtin_interfaces.msg import Time
    from rclpy.parameter import Parameter
    from rclpy.publisher import Publisher
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as DecodedTwist
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TwistStamped as DecodedTwistStamped
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__JointState as DecodedJointState

    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.nodes.ros_types import NodeKwargs, RosMessage, TimeLike

NODE_NAME = 'power_estimator'

PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec('vehicle', 'test_robot_track', 'vehicle name in config/vehicles/ or a YAML file'),
    ParamSpec('terrain', 'dry_sand', 'terrain preset or YAML file; may be changed at run time (swaps maps)'),
    ParamSpec(
        'kinematics',
        'cmd',
        "how a command is predicted: 'cmd' (at its wheel speed set points; 'setpoint' still accepted) or "
        "'twist' (as the motion)",
    ),
    ParamSpec(
        'map_cache_dir',
        '',
        'directory of cached maps ("" = $SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power)',
    ),
    ParamSpec(
        'state_file',
        '',
        'energy state file ("" = ~/.local/state/skidsteer_power/energy_[<namespace>_]<vehicle>.json); '
        'one live process per file (a lock)',
    ),
    ParamSpec('persist', True, 'save the energy state and restore it on start'),
    ParamSpec(
        'initial_soc', -1.0, 'state of charge at start when nothing is restored [-]; < 0 = full', (-1.0, 1.0)
    ),
    ParamSpec(
        'cmd_vel_stamped', False, 'deprecated: cmd_vel_type:=twist_stamped (true = that, with a warning)'
    ),
    *cmd_vel_input.PARAMETERS,
    ParamSpec('cmd_timeout_s', 0.5, 'cmd_vel older than this is stale [s]', (0.01, 60.0)),
    ParamSpec('joint_timeout_s', 0.5, 'joint_states older than this is stale [s]', (0.01, 60.0)),
    ParamSpec(
        'traction_warning_margin', 0.1, 'warn when the traction margin is at or below this [-]', (0.0, 1.0)
    ),
    ParamSpec(
        'power_filter_s', 5.0, 'time constant of the power filter behind time to empty [s]', (0.0, 3600.0)
    ),
    ParamSpec(
        'warn_period_s', 2.0, 'least time between two warnings about rejected inputs [s]', (0.01, 3600.0)
    ),
    ParamSpec('max_speed_m_s', 5.0, 'cmd_vel |linear.x| above this is rejected [m/s]', (0.001, 100.0)),
    ParamSpec(
        'max_yaw_rate_rad_s', 10.0, 'cmd_vel |angular.z| above this is rejected [rad/s]', (0.001, 100.0)
    ),
    ParamSpec(
        'drive_max_speed_m_s',
        0.0,
        "the drive's |V| limit the predictions follow [m/s]; 0 = the vehicle file's (run: the des_driver's)",
        (0.0, 100.0),
    ),
    ParamSpec(
        'drive_max_yaw_rate_rad_s',
        0.0,
        "the drive's |yaw rate| limit the predictions follow [rad/s]; 0 = the vehicle file's",
        (0.0, 100.0),
    ),
    ParamSpec(
        'drive_max_wheel_rad_s',
        0.0,
        "the drive's wheel (axle) speed ceiling the predictions follow [rad/s]; 0 = the vehicle file's",
        (0.0, 10000.0),
    ),
    ParamSpec(
        'max_motor_speed_rad_s',
        1200.0,
        'joint_states |velocity| above this is rejected [rad/s]',
        (1.0, 10000.0),
    ),
    ParamSpec(
        'max_motor_torque_Nm', 5.0, 'joint_states |effort| above this is rejected [N m]', (0.001, 1000.0)
    ),
    ParamSpec('publish_period_s', 0.2, 'period of battery and energy topics [s]', (0.001, 3600.0)),
    ParamSpec(
        'figure_period_s',
        0.05,
        'least period of the Float64 figure topics (latest value) [s]',
        (0.001, 3600.0),
    ),
    ParamSpec('diagnostics_period_s', 1.0, 'period of diagnostics [s]', (0.01, 3600.0)),
    ParamSpec(
        'save_period_s',
        0.5,
        'period of energy-state saves [s]: the most energy a SIGKILL or power cut loses (in a thread)',
        (0.1, 86400.0),
    ),
    ParamSpec('qos_depth', 100, 'queue depth of the subscriptions and the per-message outputs', (1, 100000)),
    ParamSpec(
        'input_reliability',
        'best_effort',
        'cmd_vel / joint_states subscriptions: best_effort (matches reliable and best-effort '
        'publishers) or reliable (matches reliable publishers only)',
    ),
    ParamSpec(
        'output_qos', 'reliable', 'per-message outputs: reliable, or sensor_data (best effort, depth 5)'
    ),
    ParamSpec('left_joints', '', 'comma-separated joint names of the left side ("" = vehicle file)'),
    ParamSpec('right_joints', '', 'comma-separated joint names of the right side ("" = vehicle file)'),
    ParamSpec('effort_is', '', 'joint_states effort is "torque" [N m] or "current" [A] ("" = vehicle file)'),
    ParamSpec('joints_at', '', 'joint values are at the "motor" shaft or the "wheel" ("" = vehicle file)'),
    ParamSpec(
        'joint_gear_ratio',
        0.0,
        'motor turns per wheel turn of the joints [-] (0 = vehicle file)',
        (0.0, 1000.0),
    ),
    ParamSpec(
        'joint_torque_constant_Nm_A',
        0.0,
        'motor torque constant for a current effort [N m/A] (0 = vehicle file)',
        (0.0, 100.0),
    ),
    ParamSpec('adaptation', True, 'adapt a per-side torque scale and offset online, detect terrain changes'),
    ParamSpec(
        'adaptation_memory_s',
        10.0,
        'memory (forgetting time constant) of the online adaptation [s]',
        (0.1, 86400.0),
    ),
    ParamSpec(
        'adaptation_terrain_memory_s',
        60.0,
        'memory of the terrain scale that carries over between commands (path energy) [s]',
        (0.1, 86400.0),
    ),
    *PATH_PARAMETERS,
)

RUN_TIME_PARAMETERS = ('terrain',)
"""The parameters a set changes at run time; every other one is read at start only: its descriptor
says ``read_only`` and ROS refuses a later set."""
PARAMETERS = tuple(
    spec if spec.name in RUN_TIME_PARAMETERS else dataclasses.replace(spec, read_only=True)
    for spec in PARAMETERS
)
PARAMETER_NAMES = frozenset(spec.name for spec in PARAMETERS)

INPUT_RELIABILITY = {'best_effort': ReliabilityPolicy.BEST_EFFORT, 'reliable': ReliabilityPolicy.RELIABLE}
OUTPUT_QOS = ('reliable', 'sensor_data')


BATTERY_STATUS = {
    'charging': BatteryState.POWER_SUPPLY_STATUS_CHARGING,
    'discharging': BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
    'not_charging': BatteryState.POWER_SUPPLY_STATUS_NOT_CHARGING,
}
BATTERY_TECHNOLOGY = {
    'lipo': BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO,
    'li-ion': BatteryState.POWER_SUPPLY_TECHNOLOGY_LION,
    'lion': BatteryState.POWER_SUPPLY_TECHNOLOGY_LION,
    'life': BatteryState.POWER_SUPPLY_TECHNOLOGY_LIFE,
    'lifepo4': BatteryState.POWER_SUPPLY_TECHNOLOGY_LIFE,
    'nimh': BatteryState.POWER_SUPPLY_TECHNOLOGY_NIMH,
}


def battery_state_message(fields: BatteryMessageFields) -> BatteryState:
    """A BatteryState from :func:`skidsteer_power.estimator.factory.battery_message_fields` (its
    ``dict[str, ...]`` of message fields by name, of mixed types: ``status`` and ``chemistry`` are
    strings, the rest numbers)."""
    values = dict(fields)
    status = values.pop('status')
    chemistry = values.pop('chemistry').lower()
    msg = BatteryState(**values)
    msg.power_supply_status = BATTERY_STATUS[status]
    msg.power_supply_health = BatteryState.POWER_SUPPLY_HEALTH_UNKNOWN
    unknown = BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN
    msg.power_supply_technology = BATTERY_TECHNOLOGY.get(chemistry, unknown)
    return msg


class PowerEstimator(QuietNode):
    """Predicts per-side power from cmd_vel, measures it from joint_states, tracks the battery."""

    def __init__(self, predictor: Predictor | None = None, **node_kwargs: Unpack[NodeKwargs]) -> None:
        """``predictor`` replaces the map built from the parameters (tests, replays); ``node_kwargs``
        go to :class:`rclpy.node.Node` (context, parameter_overrides ...)."""
        super().__init__(NODE_NAME, **node_kwargs)
        declare(self, PARAMETERS)  # a value out of its range: one ConfigError
        p = read_parameters(self, PARAMETERS, PowerEstimatorParameters)
        self._lock = threading.Lock()
        self._terrain_worker: threading.Thread | None = None
        self.pending_terrain = ''
        self._traction_warned = False
        self._figures_due = [False, False]  # a new prediction / measurement since the figures' tick
        self._figure_timer_idle = False  # cancelled after a tick with nothing new (no idle wake-ups)
        settings = self._settings(p)
        self.vehicle = load_vehicle(p.vehicle)
        settings = dataclasses.replace(settings, joint_map=self._joint_map(p))
        settings = dataclasses.replace(settings, limits=vehicle_limits(settings.limits, self.vehicle, p))
        self.terrain_name = p.terrain
        try:
            self.kinematics, note = prediction_mode(p.kinematics, 'kinematics', factory.KINEMATICS)
        except InputError as err:  # a parameter: a configuration error, as the factory's
            raise ConfigError(str(err)) from err
        if note:
            self.get_logger().warning(note)
        self.controller = factory.drive_controller(
            self.vehicle,
            max_speed_m_s=p.drive_max_speed_m_s,
            max_yaw_rate_rad_s=p.drive_max_yaw_rate_rad_s,
            max_wheel_rad_s=p.drive_max_wheel_rad_s,
        )
        self.odometry = PredictedOdometry()
        self._predicted_twist_stamp: TimeLike | None = None
        if predictor is None:
            predictor = self._make_predictor(p.terrain, p.map_cache_dir)
        adaptation = AdaptationSettings(
            enabled=p.adaptation,
            memory_s=p.adaptation_memory_s,
            terrain_memory_s=p.adaptation_terrain_memory_s,
        )
        self.core = EstimatorCore(
            predictor,
            factory.battery_for(self.vehicle),
            Powertrain.for_vehicle(self.vehicle),
            settings,
            adaptation,
        )
        self.state_file = None
        if p.persist:
            self.state_file = factory.state_path(p.state_file, self.vehicle, self.get_namespace())
            self._state_lock = StateLock.take(self.state_file)  # one live process per file
        self._restore(p.initial_soc)
        self._make_interfaces(p)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    # --- set-up -------------------------------------------------------------------------------
    @staticmethod
    def _settings(p: PowerEstimatorParameters) -> EstimatorSettings:
        if p.input_reliability not in INPUT_RELIABILITY:
            reliability = p.input_reliability
            raise ConfigError(f'input_reliability must be best_effort or reliable, got {reliability!r}')
        if p.output_qos not in OUTPUT_QOS:
            raise ConfigError(f'output_qos must be reliable or sensor_data, got {p.output_qos!r}')
        limits = InputLimits(
            p.max_speed_m_s, p.max_yaw_rate_rad_s, p.max_motor_speed_rad_s, p.max_motor_torque_Nm
        )
        return EstimatorSettings(
            cmd_timeout_s=p.cmd_timeout_s,
            joint_timeout_s=p.joint_timeout_s,
            traction_warning_margin=p.traction_warning_margin,
            power_filter_s=p.power_filter_s,
            warn_period_s=p.warn_period_s,
            limits=limits,
        )

    def _joint_map(self, p: PowerEstimatorParameters) -> JointMap:
        return factory.joint_map_for(
            self.vehicle,
            left=p.left_joints,
            right=p.right_joints,
            effort_is=p.effort_is,
            location=p.joints_at,
            gear_ratio=p.joint_gear_ratio or None,
            torque_constant_Nm_A=p.joint_torque_constant_Nm_A or None,
        )

    def _make_predictor(self, terrain: str, cache_dir: str) -> Predictor:
        started = time.monotonic()
        predictor, built, path = factory.map_predictor(
            self.vehicle, terrain, cache_dir or None, self.kinematics, self.controller
        )
        if built:
            self.get_logger().info(
                f'built the power map for {self.vehicle.name} on {terrain} '
                f'in {time.monotonic() - started:.1f} s '
                f'and cached it at {path}'
            )
        else:
            self.get_logger().info(f'loaded the power map {path}')
        return predictor

    def _restore(self, initial_soc: float) -> None:
        state = None
        if self.state_file is not None:
            state, warning = load_or_quarantine(self.state_file, self._accept_state)
            if warning:
                self.get_logger().warning(warning)
            elif state is not None:
                self.get_logger().info(
                    f'restored energy state from {self.state_file}: '
                    f'{self.core.battery.remaining_wh:.2f} Wh left'
                )
        if state is None and initial_soc >= 0:
            self.core.energy.battery = factory.battery_for(self.vehicle, soc=initial_soc)

    def _accept_state(self, state: JsonObject) -> None:
        if state.get('vehicle') != self.vehicle.name:
            raise ConfigError(f'it holds the state of vehicle {state.get("vehicle")!r}')
        self.core.restore(state)

    def _make_interfaces(self, p: PowerEstimatorParameters) -> None:
        depth = p.qos_depth
        overrides = QoSOverridingOptions.with_default_policies()
        qos_in = QoSProfile(depth=depth, reliability=INPUT_RELIABILITY[p.input_reliability])
        qos_out = qos_profile_sensor_data if p.output_qos == 'sensor_data' else QoSProfile(depth=depth)

        self.malformed = MalformedInputs(self.get_logger().warning, p.warn_period_s)

        def sub(msg_type: type, topic: str, callback: Callable[[RosMessage], None]) -> None:
            # raw bytes in, decoded by rosbags (nodes/wire.py); a malformed one is dropped and counted
            decode = self.malformed.guard(topic, decoder(msg_type))

            def take(data: bytes) -> None:
                msg = decode(data)
                if msg is not None:
                    callback(msg)

            batched = Batched(take)  # a backlog in batches (spin.py)
            batched.subscription = self.create_subscription(
                msg_type, topic, batched, qos_in, qos_overriding_options=overrides, raw=True
            )

        def pub(msg_type: type, topic: str, qos: QoSProfile | int = 10) -> Publisher:
            return self.create_publisher(msg_type, topic, qos, qos_overriding_options=overrides)

        self.cmd_input = CmdVelInput(
            self,
            cmd_vel_input.cmd_vel_mode(self, p.cmd_vel_type, 'cmd_vel_stamped', p.cmd_vel_stamped),
            self._on_cmd_vel,
            qos_in,
            timeout_s=p.cmd_timeout_s,
            tolerance_s=p.cmd_vel_stamp_tolerance_s,
            # raw bytes in, decoded by rosbags (nodes/wire.py); a malformed one is dropped and counted
            decode=lambda msg_type: self.malformed.guard('cmd_vel', decoder(msg_type)),
            make_callback=Batched,  # a backlog in batches (spin.py)
            qos_overriding_options=overrides,
        )
        sub(JointState, 'joint_states', self._on_joint_states)
        joint_map = self.core.settings.joint_map
        self.side_currents = vendor_feed(self, joint_map, qos_in)  # nodes/measured_power_feed.py
        self.pub_predicted = pub(JointState, 'power/predicted', qos_out)
        self.pub_measured = pub(JointState, 'power/measured', qos_out)
        self.pub_command_figures = [pub(Float64, topic, qos_out) for topic, _ in COMMAND_FIGURES]
        self.pub_measurement_figures = [pub(Float64, topic, qos_out) for topic, _ in MEASUREMENT_FIGURES]
        self.pub_summary = pub(DiagnosticArray, 'power/summary')
        self.pub_battery = pub(BatteryState, 'battery/state')
        self.pub_remaining = pub(Float64, 'energy/remaining_wh')
        self.pub_tte = pub(Float64, 'energy/time_to_empty_s')
        self.pub_tte_p10 = pub(Float64, 'energy/time_to_empty_p10_s')
        self.pub_tte_p90 = pub(Float64, 'energy/time_to_empty_p90_s')
        self.pub_correction = pub(JointState, 'power/correction')
        self.pub_diag = pub(DiagnosticArray, 'diagnostics')
        self.pub_predicted_twist = pub(TwistStamped, 'power/predicted_twist', qos_out)
        self.pub_predicted_odom = pub(Odometry, 'odom/predicted', qos_out)
        self.create_service(Trigger, '~/reset_energy', self._on_reset_energy)
        self.create_service(Trigger, '~/reset_odometry', self._on_reset_odometry)
        self.create_timer(p.publish_period_s, self._on_publish_timer)
        self._figure_timer = self.create_timer(p.figure_period_s, self._publish_figures)
        self.create_timer(p.diagnostics_period_s, self._publish_diagnostics)
        self._writer: StateWriter | None = None
        if self.state_file is not None:
            self._writer = StateWriter(self.state_file, self.get_logger().error)
            self.create_timer(p.save_period_s, self._save_soon)
        # serialized once; each message patches its stamp and numbers (nodes/wire.py)
        axles = ['left_motor', 'right_motor', 'left_axle', 'right_axle']
        self._predicted_wire = PackedJointState(axles, ('velocity', 'effort'))
        self._measured_wire = PackedJointState(['left_motor', 'right_motor'], ('velocity', 'effort'))
        self.path_energy = PathEnergyHook(self, p, qos_in)

    # --- inputs -------------------------------------------------------------------------------
    def now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_cmd_vel(self, msg: DecodedTwist | DecodedTwistStamped) -> None:
        """A decoded (rosbags) geometry_msgs/Twist or TwistStamped (a refused stamp is dropped)."""
        received = self.get_clock().now()
        now = received.nanoseconds * 1e-9
        twist = self.cmd_input.accept(msg, now)
        if twist is None:
            return
        try:
            with self._lock:
                prediction = self.core.on_command(twist.linear.x, twist.angular.z, now)
        except RejectedInput as err:
            self._warn_rejected(err)
            return
        header = getattr(msg, 'header', None)  # TwistStamped; a zero stamp counts as none
        stamp = header.stamp if header is not None else None
        if stamp is None or not (stamp.sec or stamp.nanosec):
            stamp = received.to_msg()
        self._publish_predicted(prediction, stamp.sec, stamp.nanosec)
        self._publish_predicted_motion(prediction, now, stamp)
        self._figure_due(0)
        self._log_traction_change()

    def _log_traction_change(self) -> None:
        warning = self.core.traction_warning()
        prediction, command = self.core.prediction, self.core.command
        if warning and not self._traction_warned and prediction is not None and command is not None:
            self.get_logger().warning(
                f'traction margin {prediction.traction_margin:.2f} at V {command[0]:.2f} m/s, '
                f'yaw rate {command[1]:.2f} rad/s: the robot may get stuck (chapter 7.3.4)'
            )
        self._traction_warned = warning

    def _on_joint_states(self, msg: DecodedJointState) -> None:
        """A decoded (rosbags) sensor_msgs/JointState: number sequences are numpy arrays."""
        now = self.now_s()
        velocity, effort, position = msg.velocity.tolist(), msg.effort.tolist(), msg.position.tolist()
        names = msg.name
        feed = self.side_currents  # effort from a vendor topic (nodes/side_current_feed.py)
        if feed is not None:
            names, position, velocity, effort = feed.joint_values(names, position, velocity, now)
        try:
            with self._lock:
                comparison = self.core.on_joint_state(names, velocity, effort, now, position)
        except RejectedInput as err:
            self._warn_rejected(err)
            return
        if comparison is None:  # speed from positions: waits for a second sample
            return
        stamp = msg.header.stamp
        measured = comparison.measured
        self.pub_measured.publish(
            self._measured_wire.pack(stamp.sec, stamp.nanosec, measured.omega_rad_s, measured.torque_Nm)
        )
        self._figure_due(1)

    def _warn_rejected(self, err: RejectedInput) -> None:
        if err.warn:
            counts = self.core.rejects.counts
            self.get_logger().warning(f'rejected {err} (rejected so far: {dict(counts)})')

    def path_inputs(self) -> PathInputs:
        """What the path energy needs, read together under the node's lock (nodes/path_hook.py)."""
        with self._lock:
            core = self.core
            return PathInputs(
                core.predictor,
                core.command,
                float(core.battery.remaining_wh),
                core.adaptation.terrain_scale(),
            )

    # --- outputs ------------------------------------------------------------------------------
    def _publish_predicted(self, prediction: Prediction, sec: int, nanosec: int) -> None:
        velocity = (*prediction.motor_omega_rad_s, *prediction.axle_omega_rad_s)
        effort = (*prediction.motor_torque_Nm, *prediction.terrain_torque_Nm)
        self.pub_predicted.publish(self._predicted_wire.pack(sec, nanosec, velocity, effort))

    def _publish_predicted_motion(self, prediction: Prediction, now: float, stamp: TimeLike) -> None:
        """The dead reckoning of ``odom/predicted`` takes this command's predicted motion at once;
        ``power/predicted_twist`` goes out with the figures (``figure_period_s``, the newest
        command's stamp), as a message per command would cost the 1 kHz budget of issue 18."""
        with self._lock:
            self.odometry.set_twist(prediction.achieved_speed_m_s, prediction.achieved_yaw_rate_rad_s, now)
        self._predicted_twist_stamp = stamp

    def _publish_predicted_twist(self, prediction: Prediction) -> None:
        speed, yaw_rate = prediction.achieved_speed_m_s, prediction.achieved_yaw_rate_rad_s
        twist = TwistStamped()
        twist.header.stamp, twist.header.frame_id = self._predicted_twist_stamp, 'base_link'
        twist.twist.linear.x, twist.twist.angular.z = float(speed), float(yaw_rate)
        self.pub_predicted_twist.publish(twist)

    def _publish_odometry(self, stamp: Time) -> None:
        with self._lock:
            odo = dataclasses.replace(self.odometry)
        msg = Odometry()
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp, 'odom', 'base_link'
        msg.pose.pose.position.x, msg.pose.pose.position.y = odo.x_m, odo.y_m
        q = msg.pose.pose.orientation
        q.x, q.y, q.z, q.w = odo.quaternion()
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = odo.speed_m_s, odo.yaw_rate_rad_s
        self.pub_predicted_odom.publish(msg)

    def _on_reset_odometry(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/reset_odometry``: ``odom/predicted`` starts again at the origin, heading 0."""
        with self._lock:
            self.odometry.reset(self.now_s())
        self._publish_odometry(self.get_clock().now().to_msg())
        response.success, response.message = True, 'predicted odometry reset to the origin'
        return response

    def _figure_due(self, which: int) -> None:
        """A new prediction (0) or measurement (1) for the figure timer; restarts it if idle."""
        self._figures_due[which] = True
        if self._figure_timer_idle:
            self._figure_timer_idle = False
            self._figure_timer.reset()

    def _publish_figures(self) -> None:
        """The Float64 figure topics, from a timer (``figure_period_s``): the latest prediction's
        and measurement's, each only if a new one came since the last tick. They are for plots; per
        message they cost 9 publishes per cmd_vel + joint_states pair. A tick with nothing new
        cancels the timer until the next input, so an idle node does not wake up 20 times a second."""
        command_due, measurement_due = self._figures_due
        if not (command_due or measurement_due):
            self._figure_timer.cancel()
            self._figure_timer_idle = True
            return
        self._figures_due[:] = [False, False]
        with self._lock:
            prediction, comparison = self.core.prediction, self.core.comparison
        figures: list[tuple[Publisher, float]] = []
        if command_due:
            figures += zip(self.pub_command_figures, prediction_figures(prediction), strict=True)
            if prediction is not None and self._predicted_twist_stamp is not None:
                self._publish_predicted_twist(prediction)
        if measurement_due:
            figures += zip(self.pub_measurement_figures, measurement_figures(comparison), strict=True)
        for publisher, value in figures:
            publisher.publish(Float64(data=value))

    def _on_publish_timer(self) -> None:
        now = self.now_s()
        with self._lock:
            if not self.core.cmd_fresh.is_fresh(now):  # no command in force: the robot stands
                self.odometry.set_twist(0.0, 0.0, now)
            else:
                self.odometry.advance(now)
            expired = self.core.expired_commands
            self.core.tick(now)
            standing = self.core.prediction if self.core.expired_commands != expired else None
            fields = factory.battery_message_fields(self.core.battery, self.core.energy.power_W(now))
            remaining = float(self.core.battery.remaining_wh)
            tte = float(self.core.time_to_empty_s)
            pairs = summary_key_values(self.core, now)
            bounds = (self.core.time_to_empty_p10_s, self.core.time_to_empty_p90_s)
            correction = JointState(
                name=list(CORRECTION_FIELDS), position=correction_values(self.core.adaptation)
            )
        stamp = self.get_clock().now().to_msg()
        if standing is not None:  # the command went stale: the figures show standing still at once
            self._predicted_twist_stamp = stamp  # (power/predicted stays one message per cmd_vel)
            self._figure_due(0)
        battery = battery_state_message(fields)
        battery.header.stamp = stamp
        self.pub_battery.publish(battery)
        status = DiagnosticStatus(name=SUMMARY_STATUS_NAME, hardware_id=self.vehicle.name)
        status.values = [KeyValue(key=k, value=v) for k, v in pairs]
        summary = DiagnosticArray(status=[status])
        summary.header.stamp = stamp
        self.pub_summary.publish(summary)
        self.pub_remaining.publish(Float64(data=remaining))
        self.pub_tte.publish(Float64(data=tte))
        self.pub_tte_p10.publish(Float64(data=float(bounds[0])))
        self.pub_tte_p90.publish(Float64(data=float(bounds[1])))
        correction.header.stamp = battery.header.stamp
        self.pub_correction.publish(correction)
        self._publish_odometry(stamp)
        self.path_energy.publish()  # the battery changed: the path margin too

    def _on_reset_energy(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/reset_energy``: a full battery is in; tallies restart; the state file is rewritten."""
        with self._lock:
            self.core.reset_energy(factory.battery_for(self.vehicle, soc=1.0), self.now_s())
            remaining = self.core.battery.remaining_wh
        self.save()
        response.success = True
        response.message = f'battery reset to full: {remaining:.2f} Wh' + (
            f'; saved to {self.state_file}' if self.state_file is not None else ' (persist is off)'
        )
        self.get_logger().info(response.message)
        return response

    def _publish_diagnostics(self) -> None:
        now = self.now_s()
        with self._lock:
            level, message, values = self.core.diagnostics(now)
        malformed, counts = self.malformed.diagnostics()
        values.update(counts)
        if malformed:
            level = max(level, 1)  # WARN
            message = malformed if message.startswith('ok') else f'{message}; {malformed}'
        values['terrain'] = self.terrain_name
        values['vehicle'] = self.vehicle.name
        values.update(self.cmd_input.diagnostics())
        if self.pending_terrain:
            values['pending_terrain'] = self.pending_terrain
        status = DiagnosticStatus(level=bytes([level]), name=f'{self.get_name()}: energy', message=message)
        status.hardware_id = self.vehicle.name
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        path_status = self.path_energy.diagnostic_status()
        if path_status is not None:
            array.status.append(path_status)
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)

    # --- persistence --------------------------------------------------------------------------
    def _state(self) -> JsonObject:
        with self._lock:
            self.core.tick(self.now_s())
            state = self.core.state_dict()
        state['vehicle'] = self.vehicle.name
        return state

    def _save_soon(self) -> None:
        """The save timer: the state goes to the writer thread (the executor never waits on disk)."""
        if self._writer is not None:
            self._writer.submit(self._state())

    def save(self) -> None:
        """Write the energy state now (atomic); a failure is logged, never fatal."""
        if self._writer is not None:
            self._writer.write_now(self._state())

    # --- run-time terrain change --------------------------------------------------------------
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name == 'terrain':
                try:
                    factory.check_terrain(param.value)
                except SkidsteerError as err:
                    return SetParametersResult(successful=False, reason=str(err))
                if self._terrain_worker is not None and self._terrain_worker.is_alive():
                    return SetParametersResult(successful=False, reason='a terrain change is in progress')
                self._start_terrain_change(param.value)
        return SetParametersResult(successful=True)

    def _start_terrain_change(self, terrain: str) -> None:
        self.pending_terrain = terrain
        cache_dir = self.get_parameter('map_cache_dir').value
        self._terrain_worker = threading.Thread(
            target=self._change_terrain, args=(terrain, cache_dir), name='terrain-change', daemon=True
        )
        self._terrain_worker.start()

    def _change_terrain(self, terrain: str, cache_dir: str) -> None:
        try:
            predictor = self._make_predictor(terrain, cache_dir)
        except SkidsteerError as err:
            self.get_logger().error(f'terrain change to {terrain} failed, keeping {self.terrain_name}: {err}')
            self.pending_terrain = ''
            return
        with self._lock:
            self.core.set_predictor(predictor, self.now_s())
            self.terrain_name = terrain
        self.pending_terrain = ''
        self.get_logger().info(f'terrain changed to {terrain}')

    def wait_for_terrain_change(self, timeout_s: float | None = None) -> bool:
        """Block until a pending terrain change finished (for callers and tests); True if none pending."""
        worker = self._terrain_worker
        if worker is not None:
            worker.join(timeout_s)
            return not worker.is_alive()
        return True

    def destroy_node(self) -> None:
        hook = getattr(self, 'path_energy', None)  # absent when the node failed before making it
        if hook is not None:
            hook.close()
        writer = getattr(self, '_writer', None)
        if writer is not None:
            writer.close(self._state())
        lock = getattr(self, '_state_lock', None)
        if lock is not None:
            lock.release()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(PowerEstimator, NODE_NAME, args, executor=LeanExecutor)


if __name__ == '__main__':
    main()
