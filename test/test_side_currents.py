"""Motor currents from vendor status topics (issue 29): the Husky A200's husky_msgs/HuskyStatus on
``status`` and Clearpath's clearpath_platform_msgs/Power on ``platform/mcu/status/power``, mapped to
side currents by config/vehicles/husky_a200.yaml's drivetrain section.

Real MCAP bags written here from the public message definitions (test/msg/, sources in its
README.md): the messages are typed by the bag's own stored definitions; validate and calibrate read
them; a power_estimator node subscribes when the message package is installed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_nodes_estimator import Rig

from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io.reader import build_typestore, load_msg_definitions
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.calibration.segments import SegmentOptions, read_recording
from skidsteer_power.errors import ConfigError
from skidsteer_power.estimator import MapPredictor, factory
from skidsteer_power.estimator.inputs import InputLimits, JointMap, JointReader
from skidsteer_power.maps import PowerMap
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.validation.validate import ValidateOptions, validate
from skidsteer_power.vehicle import load_vehicle

MSG_DIR = Path(__file__).resolve().parent / 'msg'
# the Husky with its pre-issue-35 side_currents mapping (config/vehicles/husky_a200.yaml now declares
# measured_power: test_measured_power.py)
VEHICLE = str(Path(__file__).resolve().parent / 'vehicles' / 'husky_a200_side_currents.yaml')
TERRAIN = 'dry_sand'
HUSKY = 'husky_msgs/msg/HuskyStatus'
POWER = 'clearpath_platform_msgs/msg/Power'
SPEED_M_S = 0.5
WHEEL_RADIUS_M = 0.1651  # husky_a200.yaml
CURRENT_A = (2.0, 3.0)  # left, right
JOINTS = (
    'front_left_wheel_joint',
    'rear_left_wheel_joint',
    'front_right_wheel_joint',
    'rear_right_wheel_joint',
)
START_NS = 1_700_000_000 * 10**9


def write_husky_bag(
    path: Path, vendor: str | None, status_s: float = 10.0, duration_s: float = 10.0, definition: bool = True
) -> None:
    """cmd_vel 0.5 m/s straight at 20 Hz; joint_states (4 wheels, position and velocity, no effort, as
    the Husky's ros2_control exports them) at 50 Hz; the vendor topic at 10 Hz for ``status_s``, its
    definition stored in the bag unless ``definition`` is False (as some recorders leave it)."""
    store = build_typestore(extra=load_msg_definitions([MSG_DIR]))
    types = store.types
    omega = SPEED_M_S / WHEEL_RADIUS_M
    with BagWriter(path) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        vendor_conn = None
        if vendor is not None:
            topic = '/status' if vendor == HUSKY else '/platform/mcu/status/power'
            msgdef = (store.generate_msgdef(vendor, ros_version=2)[0], store.hash_rihs01(vendor))
            if not definition:
                msgdef = ('', msgdef[1])
            vendor_conn = writer.add_topic(topic, vendor, msgdef=msgdef)
        vec = types['geometry_msgs/msg/Vector3']
        for k in range(int(duration_s * 100)):
            t_ns = START_NS + k * 10_000_000
            stamp = types['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            header = types['std_msgs/msg/Header'](stamp=stamp, frame_id='')
            if k % 5 == 0:
                twist = types['geometry_msgs/msg/Twist'](vec(SPEED_M_S, 0.0, 0.0), vec(0.0, 0.0, 0.0))
                writer.write(cmd, t_ns, store.serialize_cdr(twist, 'geometry_msgs/msg/Twist'))
            if k % 2 == 0:
                msg = types['sensor_msgs/msg/JointState'](
                    header=header,
                    name=list(JOINTS),
                    position=np.full(4, omega * k * 0.01),
                    velocity=np.full(4, omega),
                    effort=np.zeros(0),
                )
                writer.write(js, t_ns + 1000, store.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))
            if vendor_conn is not None and vendor is not None and k % 10 == 0 and k * 0.01 < status_s:
                writer.write(
                    vendor_conn, t_ns + 500, store.serialize_cdr(_vendor_msg(types, vendor, header), vendor)
                )


def _vendor_msg(types: dict[str, Any], vendor: str, header: object) -> object:
    if vendor == HUSKY:
        fields = {f: 0.0 for f in (
            'ros_control_loop_freq', 'mcu_and_user_port_current', 'battery_voltage', 'left_driver_voltage',
            'right_driver_voltage', 'left_driver_temp', 'right_driver_temp', 'left_motor_temp',
            'right_motor_temp', 'charge_estimate')}  # fmt: skip
        flags = dict.fromkeys(
            ('timeout', 'lockout', 'e_stop', 'ros_pause', 'no_battery', 'current_limit'), False
        )
        return types[HUSKY](
            header=header, uptime=0, left_driver_current=CURRENT_A[0], right_driver_current=CURRENT_A[1],
            capacity_estimate=0, **fields, **flags,
        )  # fmt: skip
    return types[POWER](
        header=header, shore_power_connected=0, battery_connected=1, power_12v_user_nominal=1,
        charging_complete=0, measured_voltages=np.array([26.0, 26.0, 26.0], np.float32),
        measured_currents=np.array([0.5, *CURRENT_A], np.float32),  # [MCU, LEFT_DRIVER, RIGHT_DRIVER]
    )  # fmt: skip


@pytest.fixture(scope='module')
def predictor() -> MapPredictor:
    vehicle = load_vehicle(VEHICLE)
    power_map = PowerMap.build(vehicle, factory.check_terrain(TERRAIN), shape=(6, 9))
    return MapPredictor(power_map, Powertrain.for_vehicle(vehicle), description='coarse test map')


def expected_side(current_A: float) -> tuple[float, float]:
    """(motor torque [N m], terminal power [W]) by hand: T = Kt I, w_m = G v / r_wheel,
    P = T w_m + R I^2 with the husky file's ASSUMED powertrain (EC-45: Kt 0.114 N m/A, R 0.710 ohm
    phase to phase; 12:1, chapter 7.1)."""
    pt = Powertrain.for_vehicle(load_vehicle(VEHICLE))
    kt, r = pt.motor.torque_constant_Nm_A, pt.motor.terminal_resistance_ohm
    assert (kt, r, pt.gear_ratio) == pytest.approx((0.114, 0.710, 12.0), rel=0.01)
    omega_m = pt.gear_ratio * SPEED_M_S / WHEEL_RADIUS_M
    return kt * current_A, kt * current_A * omega_m + r * current_A**2


@pytest.mark.parametrize('vendor', [HUSKY, POWER])
def test_validate_measures_power_from_the_vendor_currents(
    tmp_path: Path, predictor: MapPredictor, vendor: str
) -> None:
    path = tmp_path / 'husky.mcap'
    write_husky_bag(path, vendor, status_s=5.0)
    options = ValidateOptions(vehicle=VEHICLE, terrain=TERRAIN, report_dir=tmp_path / 'report', plots=False)
    with open_bag(path) as bag:
        assert bag.undecodable_topics == []  # typed from the bag's own stored definitions
        summary = validate(bag, options, predictor).as_json()
    assert summary['has_motor_data'] and 'motor currents from' in summary['motor_currents_from']
    assert summary['rejected']['joint_states'] == 0
    series = np.genfromtxt(summary['report']['timeseries_csv'], delimiter=',', names=True)
    for side, current in zip(('left', 'right'), CURRENT_A, strict=True):
        torque, power = expected_side(current)
        measured_torque = series[f'measured_torque_{side}_Nm']
        finite = np.isfinite(measured_torque)
        assert np.allclose(measured_torque[finite], torque, rtol=1e-5)
        assert np.allclose(series[f'measured_power_{side}_W'][finite], power, rtol=1e-5)
    # status for 5 s, then stale after 1.5 s more: rows after 6.5 s are no data, not bad input
    t = series['t_s'][np.isfinite(series['measured_torque_left_Nm'])]
    assert 6.0 < t.max() <= 6.6
    # the last status at 4.90 s (+0.5 us); joint_states every 20 ms (+1 us) older than 1.5 s after
    # it: 6.40 s to 9.98 s, (9.98 - 6.40) / 0.02 + 1 = 180 messages without fresh currents
    assert summary['joint_states_no_data'] == 180


def test_validate_without_the_vendor_topic_says_so(tmp_path: Path, predictor: MapPredictor) -> None:
    path = tmp_path / 'husky.mcap'
    write_husky_bag(path, None)
    options = ValidateOptions(vehicle=VEHICLE, terrain=TERRAIN, report_dir=tmp_path / 'report', plots=False)
    with open_bag(path) as bag:
        summary = validate(bag, options, predictor).as_json()
    assert not summary['has_motor_data'] and 'no side-current topic' in summary['motor_data_note']
    assert math.isnan(summary['metrics']['energy_measured_J'] or math.nan)


def test_calibrate_reads_the_vendor_currents(tmp_path: Path) -> None:
    path = tmp_path / 'husky.mcap'
    write_husky_bag(path, HUSKY)
    pt = Powertrain.for_vehicle(load_vehicle(VEHICLE))
    joint_map = factory.joint_map_for(load_vehicle(VEHICLE))
    reader = JointReader(joint_map, pt.gear_ratio, pt.motor.torque_constant_Nm_A, InputLimits())
    recording = read_recording(path, SegmentOptions(), reader)
    assert recording.js_t.size > 400
    expected = [expected_side(i)[0] for i in CURRENT_A]
    assert np.allclose(recording.torque, expected, rtol=1e-5)


def test_side_currents_config_errors() -> None:
    with pytest.raises(ConfigError, match='effort_is: current'):
        JointMap.from_config({'side_currents': [{'topic': 's', 'type': HUSKY, 'left': 'a', 'right': 'b'}]})
    with pytest.raises(ConfigError, match="'name' or 'name\\[index\\]'"):
        JointMap.from_config(
            {
                'effort_is': 'current',
                'side_currents': [{'topic': 's', 'type': HUSKY, 'left': 'a[x]', 'right': 'b'}],
            }
        )


@pytest.mark.ros
@pytest.mark.parametrize('installed', [True, False])
def test_power_estimator_node_takes_effort_from_a_current_topic(
    rig_factory: Callable[..., Rig], tmp_path: Path, installed: bool
) -> None:
    """Real rclpy and DDS. husky_msgs and clearpath_platform_msgs are not installed here, so the node
    is given the husky file with its side_currents pointed at std_msgs/Float64MultiArray
    (``data[0]``, ``data[1]``: a message type that is installed; any robot can publish it) and the
    Husky's joint_states. Not installed (the husky file as shipped): every joint_states is no data,
    none is rejected."""
    import yaml
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from test_estimator_core import FixedPowerPredictor

    from skidsteer_power.resources import find

    config = yaml.safe_load(find('vehicles', VEHICLE).read_text())
    if installed:
        config['joints']['side_currents'] = [
            {
                'topic': 'currents',
                'type': 'std_msgs/msg/Float64MultiArray',
                'left': 'data[0]',
                'right': 'data[1]',
            }
        ]
    vehicle = tmp_path / 'husky.yaml'
    vehicle.write_text(yaml.safe_dump(config))
    rig = rig_factory(FixedPowerPredictor(80.0), vehicle=str(vehicle), diagnostics_period_s=0.05)
    currents = rig.probe.create_publisher(Float64MultiArray, 'currents', 10)
    omega = SPEED_M_S / WHEEL_RADIUS_M
    joint_state = JointState(name=list(JOINTS), position=[0.0] * 4, velocity=[omega] * 4)
    core = rig.node.core
    if installed:
        rig.spin_until(lambda: currents.get_subscription_count() > 0)

        def measured() -> bool:
            currents.publish(Float64MultiArray(data=list(CURRENT_A)))
            rig.pub_joint.publish(joint_state)
            return core.comparison is not None

        rig.spin_until(measured)
        expected = [expected_side(i)[0] for i in CURRENT_A]
        assert core.comparison is not None
        assert core.comparison.measured.torque_Nm == pytest.approx(expected, rel=1e-6)
    else:
        for _ in range(5):
            rig.pub_joint.publish(joint_state)
        rig.spin_until(lambda: core.no_data_count >= 5)
        assert core.comparison is None
    assert core.rejects.counts['joint_states'] == 0


def test_a_bag_without_the_definition_needs_msg(tmp_path: Path, predictor: MapPredictor) -> None:
    path = tmp_path / 'husky.mcap'
    write_husky_bag(path, HUSKY, definition=False)
    options = ValidateOptions(vehicle=VEHICLE, terrain=TERRAIN, report_dir=tmp_path / 'report', plots=False)
    with open_bag(path) as bag:
        summary = validate(bag, options, predictor).as_json()
    assert not summary['has_motor_data'] and '--msg' in summary['motor_data_note']
    extra = load_msg_definitions([MSG_DIR])
    with open_bag(path, extra_types=extra) as bag:
        summary = validate(bag, options, predictor).as_json()
    assert summary['has_motor_data'] and summary['motor_currents_from'].startswith(
        'motor currents from status'
    )
    pt = Powertrain.for_vehicle(load_vehicle(VEHICLE))
    joint_map = factory.joint_map_for(load_vehicle(VEHICLE))
    reader = JointReader(joint_map, pt.gear_ratio, pt.motor.torque_constant_Nm_A, InputLimits())
    recording = read_recording(path, SegmentOptions(extra_types=extra), reader)
    assert np.allclose(recording.torque, [expected_side(i)[0] for i in CURRENT_A], rtol=1e-5)
