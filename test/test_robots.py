"""Any skid-steer robot: joint mapping, vehicle files, held cmd_vel, map coverage, real bag (issue 16).

Bags are written here with the project's MCAP writer (:class:`skidsteer_power.bag_io.writer.BagWriter`)
from real rosbags message objects; predictions come from a real (coarse) FESS power map.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from conftest import REQUIRE_SHARED_ENV, shared_path
from numpy.typing import ArrayLike
from rclpy.context import Context
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator import EstimatorCore, EstimatorSettings, MapPredictor, factory
from skidsteer_power.estimator.core import LEVEL_WARN
from skidsteer_power.estimator.inputs import InputLimits, JointMap, JointReader
from skidsteer_power.estimator.prediction import Predictor
from skidsteer_power.maps import PowerMap
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.validation.cmd_timing import command_timing
from skidsteer_power.validation.validate import ValidateOptions, validate
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from rosbags.typesys.store import Msg  # the typestore's message protocol (declared for type checkers)

NS = 1_000_000_000
START_NS = 1_700_000_000 * NS
STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types
TERRAIN = 'sand_bin'
FOUR_WHEEL_JOINTS = ('front_left_wheel_joint', 'rear_left_wheel_joint')  # ros2_control_4wheel preset


@pytest.fixture(scope='module')
def track() -> MapPredictor:
    """The test robot's FESS map (coarse grid: fast), covering |V| <= 1.5 m/s, |yaw| <= 2 rad/s."""
    return _predictor('test_robot_track')


@pytest.fixture(scope='module')
def four_wheel() -> MapPredictor:
    return _predictor('test_robot_4wheel')


def _predictor(name: str) -> MapPredictor:
    vehicle = load_vehicle(name)
    power_map = PowerMap.build(vehicle, factory.check_terrain(TERRAIN), shape=(6, 21))
    return MapPredictor(power_map, Powertrain.for_vehicle(vehicle), description=f'coarse {name} map')


def _twist(v: float, w: float) -> bytes:
    vec = T['geometry_msgs/msg/Vector3']
    return STORE.serialize_cdr(
        T['geometry_msgs/msg/Twist'](vec(v, 0.0, 0.0), vec(0.0, 0.0, w)), 'geometry_msgs/msg/Twist'
    )


def _header(t_s: float) -> Msg:
    sec, nsec = divmod(START_NS + round(t_s * NS), NS)
    return T['std_msgs/msg/Header'](T['builtin_interfaces/msg/Time'](sec, nsec), '')


def _odom(t_s: float, x: float, y: float, yaw: float) -> bytes:
    pose = T['geometry_msgs/msg/Pose'](
        T['geometry_msgs/msg/Point'](x, y, 0.0),
        T['geometry_msgs/msg/Quaternion'](0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
    )
    vec = T['geometry_msgs/msg/Vector3']
    twist = T['geometry_msgs/msg/Twist'](vec(0.0, 0.0, 0.0), vec(0.0, 0.0, 0.0))
    msg = T['nav_msgs/msg/Odometry'](
        _header(t_s),
        'base_link',
        T['geometry_msgs/msg/PoseWithCovariance'](pose, np.zeros(36)),
        T['geometry_msgs/msg/TwistWithCovariance'](twist, np.zeros(36)),
    )
    return STORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry')


def _joint_state(
    t_s: float, names: Sequence[str], position: ArrayLike, velocity: ArrayLike, effort: ArrayLike
) -> bytes:
    msg = T['sensor_msgs/msg/JointState'](
        _header(t_s),
        list(names),
        np.asarray(position, float),
        np.asarray(velocity, float),
        np.asarray(effort, float),
    )
    return STORE.serialize_cdr(msg, 'sensor_msgs/msg/JointState')


def _write(
    path: Path,
    commands: Sequence[tuple[float, float, float]],
    odom: Sequence[tuple[float, float, float, float]] = (),
    joints: Sequence[tuple[float, Sequence[str], ArrayLike, ArrayLike, ArrayLike]] = (),
) -> Path:
    """A bag of (t, V, yaw) commands, (t, x, y, yaw) odometry and (t, names, pos, vel, effort) joints."""
    with BagWriter(path) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        od = writer.add_topic('/odom', 'nav_msgs/msg/Odometry') if odom else None
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState') if joints else None
        events = [(t, 0, _twist(v, w)) for t, v, w in commands]
        events += [(row[0], 1, _odom(*row)) for row in odom]
        events += [(row[0], 2, _joint_state(*row)) for row in joints]
        for t, kind, data in sorted(events, key=lambda e: (e[0], e[1])):
            connection = (cmd, od, js)[kind]
            assert connection is not None  # a kind of event exists only where its topic was added
            writer.write(connection, START_NS + round(t * NS), data)
    return path


def _validate(
    path: Path, tmp_path: Path, predictor: Predictor, vehicle: str = 'test_robot_track', **options: Any
) -> dict[str, Any]:
    options.setdefault('plots', False)
    opts = ValidateOptions(vehicle=vehicle, terrain=TERRAIN, report_dir=tmp_path / 'report', **options)
    with open_bag(path) as bag:
        return validate(bag, opts, predictor).as_json()


# --- the shared folder helper -------------------------------------------------------------------
def test_missing_shared_folder_skips_on_a_clone_and_fails_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(REQUIRE_SHARED_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match='no-such-folder is missing'):
        shared_path('no-such-folder')
    monkeypatch.setenv(REQUIRE_SHARED_ENV, '1')
    with pytest.raises(pytest.fail.Exception, match='SKIDSTEER_REQUIRE_SHARED=1 requires it'):
        shared_path('no-such-folder')


# --- joint mapping --------------------------------------------------------------------------------
LIMITS = InputLimits()


def test_four_wheel_joints_at_the_wheel_in_newton_metres_become_motor_equivalent_values() -> None:
    """Hand calculation: side torque = sum of wheel torques, side speed = mean wheel speed, referred
    to the motor of a 12:1 powertrain: T_m = T_side / 12, w_m = 12 w_side."""
    joint_map = JointMap.from_config({'preset': 'ros2_control_4wheel'})
    reader = JointReader(joint_map, 12.0, 0.114, LIMITS)
    names = [
        'rear_right_wheel_joint',
        'front_left_wheel_joint',
        'front_right_wheel_joint',
        'rear_left_wheel_joint',
    ]
    velocity = [2.2, 1.0, 1.8, 1.2]  # rad/s at each wheel
    effort = [4.0, 3.0, 5.0, 6.0]  # N m at each wheel
    read = reader.read(names, [], velocity, effort, 0.0)
    assert read is not None
    omega, torque = read
    assert omega == pytest.approx((12 * (1.0 + 1.2) / 2, 12 * (1.8 + 2.2) / 2), rel=1e-12)
    assert torque == pytest.approx(((3.0 + 6.0) / 12, (5.0 + 4.0) / 12), rel=1e-12)


def test_current_effort_at_the_motor_uses_the_torque_constant_and_inverted_joints_flip() -> None:
    joint_map = JointMap(
        left=('l',), right=('r',), effort_is='current', torque_constant_Nm_A=0.05, inverted=('r',)
    )
    reader = JointReader(joint_map, 12.0, 0.114, LIMITS)
    read = reader.read(['l', 'r'], [], [100.0, -100.0], [2.0, -3.0], 0.0)
    assert read is not None
    omega, torque = read
    assert omega == (100.0, 100.0)
    assert torque == pytest.approx((0.05 * 2.0, 0.05 * 3.0), rel=1e-12)  # T = Kt I


def test_speed_from_positions_when_no_velocity_is_published() -> None:
    joint_map = JointMap(left=('l',), right=('r',), location='wheel', interfaces=('position', 'effort'))
    reader = JointReader(joint_map, 10.0, 0.114, LIMITS)
    assert reader.read(['l', 'r'], [0.0, 0.0], [], [1.0, 1.0], 0.0) is None  # needs two samples
    read = reader.read(['l', 'r'], [0.5, 1.0], [], [1.0, 1.0], 0.5)
    assert read is not None
    omega, _ = read
    assert omega == pytest.approx((10 * 1.0, 10 * 2.0))  # (0.5 rad / 0.5 s) x 10, (1 / 0.5) x 10


def test_joint_mapping_errors_are_clear() -> None:
    with pytest.raises(ConfigError, match='listed twice'):
        JointMap(left=('a',), right=('a',))
    with pytest.raises(
        ConfigError, match="effort_is must be one of \\('torque', 'current', 'battery_power'\\)"
    ):
        JointMap(effort_is='amps')
    with pytest.raises(ConfigError, match='unknown key'):
        JointMap.from_config({'left': ['a'], 'right': ['b'], 'wheels': 4})
    with pytest.raises(ConfigError, match=r'no_such_drivetrain.*shipped: ros2_control_4wheel, test_robot'):
        JointMap.from_config({'preset': 'no_such_drivetrain'})
    reader = JointReader(JointMap.from_config({'preset': 'ros2_control_4wheel'}), 12.0, 0.114, LIMITS)
    with pytest.raises(InputError, match='lacks rear_left_wheel_joint'):
        reader.read(['front_left_wheel_joint'], [], [1.0], [1.0], 0.0)


@pytest.mark.parametrize(
    ('name', 'mass', 'tread', 'radius', 'wheelbase'),
    [
        # husky_description: 46.034 kg base + 4 x 2.637 kg wheels; track 0.5708, r 0.1651, wb 0.512
        ('husky_a200', 46.034 + 4 * 2.637, 0.5708, 0.1651, 0.512),
        # jackal_description: 16.523 kg chassis + 4 x 0.477 kg wheels; track 0.37559, r 0.098, wb 0.262
        ('jackal', 16.523 + 4 * 0.477, 0.37559, 0.098, 0.262),
        # Leo Rover specification 6.5 kg, tyre ~130 mm; leo_description wheel_separation 0.358, 2 x 0.15256
        ('leo_rover', 6.5, 0.358, 0.065, 2 * 0.15256),
    ],
)
def test_public_robot_files_hold_their_published_dimensions(
    name: str, mass: float, tread: float, radius: float, wheelbase: float
) -> None:
    vehicle = load_vehicle(name)
    assert vehicle.mass_kg == pytest.approx(mass, abs=0.006)
    assert (vehicle.tread_m, vehicle.wheels().wheel_radius_m) == (tread, radius)
    assert vehicle.wheels().wheelbase_m == pytest.approx(wheelbase, abs=5e-4)
    assert 'ASSUMED' in vehicle.source and 'github' in vehicle.source.lower()
    assert len(factory.joint_map_for(vehicle).joints) == 4


def test_diagnostics_warn_while_a_command_is_outside_the_map(track: MapPredictor) -> None:
    vehicle = load_vehicle('test_robot_track')
    core = EstimatorCore(
        track, factory.battery_for(vehicle), Powertrain.for_vehicle(vehicle), EstimatorSettings()
    )
    core.on_command(0.2, 0.0, 0.0)
    level, message, values = core.diagnostics(0.1)
    assert values['command_outside_map'] == 'false' and 'outside' not in message
    core.on_command(3.0, 0.0, 0.2)  # the map covers |V| <= 1.5 m/s: clamped to its edge
    level, message, values = core.diagnostics(0.3)
    assert level == LEVEL_WARN and 'command outside the power map' in message
    assert values['command_outside_map'] == 'true' and values['commands_outside_map'] == '1'


@pytest.mark.ros
def test_estimator_node_takes_the_vehicle_files_mapping_and_parameter_overrides(
    ros_context: Context, track: MapPredictor
) -> None:
    from rclpy.parameter import Parameter

    from skidsteer_power.estimator.core import RejectedInput
    from skidsteer_power.nodes.power_estimator import PowerEstimator

    overrides = {
        'left_joints': 'fl, rl',
        'right_joints': 'fr,rr',
        'effort_is': 'current',
        'joint_gear_ratio': 20.0,
    }
    node = PowerEstimator(
        predictor=track,
        context=ros_context,
        parameter_overrides=[
            Parameter('vehicle', value='husky_a200'),
            Parameter('terrain', value=TERRAIN),
            Parameter('persist', value=False),
            *(Parameter(k, value=v) for k, v in overrides.items()),
        ],
    )
    try:
        joint_map = node.core.settings.joint_map
        assert (joint_map.left, joint_map.right) == (('fl', 'rl'), ('fr', 'rr'))
        assert (joint_map.effort_is, joint_map.gear_ratio, joint_map.location) == ('current', 20.0, 'wheel')
        # husky_a200.yaml: no effort in joint_states; the effort is the measured power of its status
        # topics (measured_power, test_measured_power.py), so joint_states alone carry no effort
        assert joint_map.interfaces == ('position', 'velocity', 'effort')
        assert [sorted(s.topics()) for s in joint_map.measured_power] == [
            ['status'], ['platform/mcu/status/power'],
            ['left_drive/status/battery_current', 'right_drive/status/battery_current'],
        ]  # fmt: skip
        with pytest.raises(RejectedInput, match='no effort'):
            node.core.on_joint_state(['fl', 'rl', 'fr', 'rr'], [1.0] * 4, [], 0.0, [0.0] * 4)
    finally:
        node.destroy_node()


# --- command semantics ----------------------------------------------------------------------------
# On change: three commands at irregular times, each different from the one before (no repeats).
ON_CHANGE = [(0.0, 0.2, 0.0), (1.3, 0.2, 0.3), (2.0, 0.0, 0.0)]


def test_on_change_commands_are_held_until_the_next_one(tmp_path: Path, track: MapPredictor) -> None:
    bag = _write(tmp_path / 'on_change.mcap', [*ON_CHANGE, (5.0, 0.0, 0.0)])
    summary = _validate(bag, tmp_path, track)
    assert summary['cmd_vel_mode'] == 'on_change' and summary['cmd_hold_s'] == math.inf
    # Hand calculation of the held energy: (0.2, 0) for 1.3 s, (0.2, 0.3) for 0.7 s, rest (0 W) after.
    p1, p2 = track.predict(0.2, 0.0), track.predict(0.2, 0.3)
    rest = track.predict(0.0, 0.0)
    assert sum(rest.electrical_W) == 0.0
    held = sum(p1.electrical_W) * 1.3 + sum(p2.electrical_W) * 0.7
    assert summary['metrics']['energy_predicted_J'] == pytest.approx(held, rel=1e-9)
    # The old 0.5 s staleness would have counted only (0.5 + 0.5) s of driving.
    assert (
        summary['metrics']['energy_predicted_J'] > 1.5 * (sum(p1.electrical_W) + sum(p2.electrical_W)) * 0.5
    )
    report = (tmp_path / 'report' / 'report.md').read_text()
    assert 'only when they change' in report and 'until the next command' in report


def test_on_change_hold_ends_where_odometry_shows_the_robot_at_rest(
    tmp_path: Path, track: MapPredictor
) -> None:
    """The robot drives at 0.2 m/s for 1.5 s, then stands (its driver timed out) although the next
    command comes only at 3.0 s: the hold ends at 1.5 s, the first odometry interval at rest."""
    odom = [(k / 10, 0.2 * min(k / 10, 1.5), 0.0, 0.0) for k in range(31)]
    bag = _write(tmp_path / 'rest.mcap', [(0.0, 0.2, 0.0), (3.0, 0.0, 0.0)], odom=odom)
    summary = _validate(bag, tmp_path, track, cmd_hold_s=None)
    p = track.predict(0.2, 0.0)
    assert summary['metrics']['energy_predicted_J'] == pytest.approx(sum(p.electrical_W) * 1.5, rel=1e-9)


def test_stream_detection_and_a_given_hold(tmp_path: Path, track: MapPredictor) -> None:
    commands = [(k / 20, 0.2, 0.0) for k in range(40)]  # 20 Hz, all repeats
    timing = command_timing(np.array([c[0] for c in commands]), np.array([c[1:] for c in commands]))
    assert timing.mode == 'stream' and timing.period_s == pytest.approx(0.05)
    assert timing.hold_s == pytest.approx(0.5)  # floor: the estimator's staleness beats 3 periods
    bag = _write(tmp_path / 'gap.mcap', [*commands, (4.0, 0.2, 0.0), (4.05, 0.0, 0.0)])
    summary = _validate(bag, tmp_path, track, cmd_hold_s=0.2)
    assert summary['cmd_hold_s'] == 0.2 and summary['cmd_hold_inferred'] is False
    # 39 x 0.05 s, the last stream command held 0.2 s (the 2.05 s gap), 4.0 -> 4.05: 2.2 s in all.
    p = track.predict(0.2, 0.0)
    assert summary['metrics']['energy_predicted_J'] == pytest.approx(sum(p.electrical_W) * 2.2, rel=1e-9)


def test_mirrored_spins_in_place_predict_mirrored_sides(tmp_path: Path, track: MapPredictor) -> None:
    """Spinning left then right at the same rate: each side's axle torque (what the terrain needs) in
    one equals the other side's in the other (REP 103 mirror). Terminal power is not compared: the
    two drivetrains' internal resistances differ (Table 7.1, left and right)."""
    commands = [(k / 10, 0.0, 1.0) for k in range(30)] + [(3 + k / 10, 0.0, -1.0) for k in range(31)]
    bag = _write(tmp_path / 'spin.mcap', commands)
    _validate(bag, tmp_path, track)
    table = np.genfromtxt(tmp_path / 'report' / 'timeseries.csv', delimiter=',', names=True)
    left_turn, right_turn = table['yaw_rate_cmd_rad_s'] > 0, table['yaw_rate_cmd_rad_s'] < 0
    assert left_turn.sum() == 30 and right_turn.sum() == 31
    for a, b in (('left', 'right'), ('right', 'left')):
        mirrored = table[f'predicted_axle_torque_{b}_Nm'][right_turn][0]
        assert table[f'predicted_axle_torque_{a}_Nm'][left_turn] == pytest.approx(mirrored, rel=1e-12)
        assert mirrored != 0


def test_out_of_map_share_of_time_and_energy_is_reported(tmp_path: Path, track: MapPredictor) -> None:
    commands = [(k / 10, 0.2, 0.0) for k in range(20)] + [(2 + k / 10, 3.0, 0.0) for k in range(20)]
    bag = _write(tmp_path / 'fast.mcap', commands)
    summary = _validate(bag, tmp_path, track)
    # Hand calculation: 40 commands 0.1 s apart, the last held until the bag ends with it (0 s):
    # inside 2.0 s, outside (V = 3 m/s > the map's 1.5 m/s) 1.9 s.
    assert summary['clamped_time_fraction'] == pytest.approx(1.9 / 3.9, rel=1e-9)
    inside, outside = sum(track.predict(0.2, 0.0).electrical_W), sum(track.predict(3.0, 0.0).electrical_W)
    assert summary['clamped_energy_fraction'] == pytest.approx(outside * 1.9 / (inside * 2.0 + outside * 1.9))
    saved = json.loads((tmp_path / 'report' / 'summary.json').read_text())
    assert saved['clamped_time_fraction'] == pytest.approx(summary['clamped_time_fraction'])
    assert '48.7 % of the time' in (tmp_path / 'report' / 'report.md').read_text()


def test_four_wheel_ros2_control_joint_states_are_validated_with_measured_power(
    tmp_path: Path, four_wheel: MapPredictor
) -> None:
    """joint_states like joint_state_broadcaster's: four wheel joints, effort in N m at the wheel.
    Each wheel reports half its side's predicted wheel torque (12 x motor torque) at the side's
    wheel speed, so measured equals predicted: torque and power errors 0, energy error 0 %."""
    names = (
        'front_left_wheel_joint',
        'rear_left_wheel_joint',
        'front_right_wheel_joint',
        'rear_right_wheel_joint',
    )
    commands, joints = [], []
    for k in range(40):
        t = k / 20
        v, w = (0.2, 0.0) if t < 1.0 else (0.2, 0.2)
        commands.append((t, v, w))
        p = four_wheel.predict(v, w)
        wheel_w = [p.motor_omega_rad_s[0] / 12] * 2 + [p.motor_omega_rad_s[1] / 12] * 2
        wheel_t = [12 * p.motor_torque_Nm[0] / 2] * 2 + [12 * p.motor_torque_Nm[1] / 2] * 2
        joints.append((t + 0.001, names, np.zeros(4), wheel_w, wheel_t))
    vehicle = tmp_path / 'four.yaml'
    text = (
        Path(__file__).resolve().parents[1] / 'config' / 'vehicles' / 'test_robot_4wheel.yaml'
    ).read_text()
    vehicle.write_text(text.replace('{preset: test_robot}      #', '{preset: ros2_control_4wheel}      #'))
    bag = _write(tmp_path / 'ros2_control.mcap', commands, joints=joints)
    summary = _validate(bag, tmp_path, four_wheel, vehicle=str(vehicle))
    assert summary['has_motor_data'] is True and summary['joints']['at'] == 'wheel'
    assert summary['joints']['left'] == list(names[:2])
    m = summary['metrics']
    assert m['samples_compared'] == 40 and summary['rejected']['joint_states'] == 0
    assert m['torque_left']['mae_Nm'] < 1e-9 and m['power_right']['mae_W'] < 1e-6
    assert abs(m['energy_error_pct']) < 1e-6 and m['energy_measured_J'] > 0


# --- message types --------------------------------------------------------------------------------
def test_markers_and_tf_are_read_and_markers_can_be_replayed(tmp_path: Path, track: MapPredictor) -> None:
    """visualization_msgs is installed (requirements.txt), so replay can publish /person_marker;
    validate reads /tf from the bag's definitions, with or without tf2_msgs built (make tf2-msgs);
    a type that is not installed is an InputError naming it."""
    from rclpy.serialization import serialize_message
    from visualization_msgs.msg import Marker

    from skidsteer_power.bag_io._ros import message_class

    marker = Marker(ns='person', id=7, type=Marker.CYLINDER)
    transform = T['geometry_msgs/msg/TransformStamped'](
        _header(0.0),
        'base_link',
        T['geometry_msgs/msg/Transform'](
            T['geometry_msgs/msg/Vector3'](1.0, 2.0, 0.0),
            T['geometry_msgs/msg/Quaternion'](0.0, 0.0, 0.0, 1.0),
        ),
    )
    tf = STORE.serialize_cdr(T['tf2_msgs/msg/TFMessage']([transform]), 'tf2_msgs/msg/TFMessage')
    path = tmp_path / 'types.mcap'
    with BagWriter(path) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        person = writer.add_topic('/person_marker', 'visualization_msgs/msg/Marker')
        tf_topic = writer.add_topic('/tf', 'tf2_msgs/msg/TFMessage')
        for k in range(5):
            stamp = START_NS + k * NS // 10
            writer.write(cmd, stamp, _twist(0.2, 0.0))
            writer.write(person, stamp + 1, serialize_message(marker))
            writer.write(tf_topic, stamp + 2, tf)
    summary = _validate(path, tmp_path, track)
    assert summary['undecodable_topics'] == []
    with open_bag(path) as bag:
        markers = [bag.deserialize(m) for m in bag.messages(['/person_marker'])]
        frames = [bag.deserialize(m).transforms[0].child_frame_id for m in bag.messages(['/tf'])]
    assert (markers[0].ns, markers[0].id) == ('person', 7) and frames == ['base_link'] * 5
    assert message_class('visualization_msgs/msg/Marker') is Marker
    with pytest.raises(InputError, match='no_such_msgs/msg/Status is not installed'):
        message_class('no_such_msgs/msg/Status')


# --- the real bag ---------------------------------------------------------------------------------
def test_real_bag_report_reads_the_commands_and_shows_only_what_exists(
    tmp_path: Path, track: MapPredictor, neato_bag: Path
) -> None:
    with open_bag(neato_bag, warn_unknown=False) as bag:
        summary = validate(
            bag, ValidateOptions('test_robot_track', TERRAIN, tmp_path / 'report', plots=True), track
        ).as_json()
    # Keyboard teleop: a held key repeats every ~0.03 s (a stream), after a ~0.5 s auto-repeat delay.
    assert summary['cmd_vel_mode'] == 'stream' and summary['cmd_period_s'] == pytest.approx(0.03, abs=0.002)
    assert 0.5 < summary['cmd_hold_s'] < 0.6
    report = (tmp_path / 'report' / 'report.md').read_text()
    assert 'needs 2 points' not in report and 'got 0' not in report
    assert 'Predicted vs measured' not in report  # no motor data in this recording
    assert 'predicted 0 J' not in report and 'from predicted power' in report
    assert all(seg['points'] >= 2 for seg in summary['segments'])
    assert (tmp_path / 'report' / 'trace.png').stat().st_size > 0
