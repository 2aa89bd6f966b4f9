"""Real powertrains, the effective powertrain, measured power from what robots publish, limits from
the vehicle's own motor and the CSV import (issue 35).

Bags are real MCAP files written by the project's BagWriter; the BorealTC test reads the real logs in
``../shared/realdata/borealtc-husky`` (conftest.shared_path: skipped on a user's clone, fails in CI).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import shared_path
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.cli.import_csv import PRESETS, Columns, import_csv
from skidsteer_power.errors import ConfigError
from skidsteer_power.estimator import MapPredictor, factory
from skidsteer_power.estimator.inputs import InputLimits
from skidsteer_power.estimator.measured import parse_measured_power
from skidsteer_power.maps import PowerMap
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.validation.validate import ValidateOptions, console_warnings, reading_warnings, validate
from skidsteer_power.vehicle import load_vehicle

HUSKY, TERRAIN = 'husky_a200', 'sandy_loam'
JOINTS = (
    'front_left_wheel_joint',
    'rear_left_wheel_joint',
    'front_right_wheel_joint',
    'rear_right_wheel_joint',
)
START_NS = 1_700_000_000 * 10**9
STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types


@pytest.fixture(scope='module')
def predictor() -> MapPredictor:
    vehicle = load_vehicle(HUSKY)
    power_map = PowerMap.build(vehicle, factory.check_terrain(TERRAIN), shape=(6, 9))
    return MapPredictor(power_map, Powertrain.for_vehicle(vehicle), description='coarse test map')


@pytest.mark.parametrize('preset', ['test_robot', 'husky_a200', 'jackal', 'leo_rover', 'effective'])
def test_the_parts_of_a_prediction_add_up_to_the_battery_power(preset: str) -> None:
    pt = Powertrain.from_config({'preset': preset, 'idle_power_W': 10.0}, 'wheel')
    axle_torque, axle_omega = np.array([0.0, 5.0, 20.0, -8.0]), np.array([0.0, 3.0, -4.0, 6.0])
    m = pt.motor_side('left', axle_torque, axle_omega)
    parts = m.terrain_power_W + m.internal_power_W + m.copper_loss_W + m.amplifier_loss_W + m.idle_power_W
    np.testing.assert_allclose(parts, m.electrical_power_W, rtol=1e-12, atol=1e-9)
    assert np.all(np.asarray(m.copper_loss_W) >= 0) and np.all(np.asarray(m.amplifier_loss_W) >= -1e-12)
    np.testing.assert_allclose(m.idle_power_W, 5.0)  # half of both sides' 10 W
    # a standstill draws the idle power only (no torque, no speed)
    assert float(np.asarray(m.electrical_power_W)[0]) == pytest.approx(5.0)


def test_an_effective_powertrain_starts_neutral_and_says_so() -> None:
    """Neutral: battery power = axle power T w by hand (no loss, efficiency 1, no idle)."""
    pt = Powertrain.from_config({'preset': 'effective', 'bus_voltage_V': 48.0}, 'wheel')
    assert pt.is_effective and pt.nominal_bus_voltage_V() == 48.0 and pt.gear_ratio == 1.0
    assert math.isinf(pt.current_limit_A)
    m = pt.motor_side('right', 3.0, 2.0)
    assert m.electrical_power_W == pytest.approx(6.0) and m.copper_loss_W == 0.0
    # a copper-loss coefficient k: 6 W + k T^2 = 6 + 0.5 x 9 = 10.5 W; idle 4 W: +2 W per side
    fitted = Powertrain.from_config(
        {'preset': 'effective', 'copper_loss_W_per_Nm2': 0.5, 'idle_power_W': 4.0}, 'wheel'
    )
    assert fitted.motor_side('right', 3.0, 2.0).electrical_power_W == pytest.approx(12.5)
    # the inverse used for battery-side measurements gives the torque back
    assert fitted.torque_from_terminal(fitted.terminal_from_bus(12.5), 2.0) == pytest.approx(3.0)
    assert not Powertrain.from_config({'preset': 'husky_a200'}, 'wheel').is_effective
    with pytest.raises(ConfigError, match='unknown key'):
        Powertrain.from_config({'preset': 'effective', 'idle_W': 3.0}, 'wheel')


def test_limits_come_from_the_vehicles_own_motor_and_driver() -> None:
    # EC-45 + DES 70/10 (Appendix A, B): 0.114 N m/A x 30 A x 1.5 = 5.13 N m; 10000 rpm x 1.15
    test_robot = InputLimits.for_powertrain(Powertrain.default_test_robot())
    assert test_robot.max_motor_torque_Nm == pytest.approx(5.13)
    assert test_robot.max_motor_speed_rad_s == pytest.approx(10000 * 2 * math.pi / 60 * 1.15)
    # the Husky's (config/powertrains/husky_a200.yaml): 0.0458 x 60 A x 1.5 = 4.122 N m; 24 V x 60 A x 1.5
    husky = InputLimits.for_powertrain(Powertrain.from_config({'preset': 'husky_a200'}, 'wheel'))
    assert husky.max_motor_torque_Nm == pytest.approx(4.122)
    assert husky.max_side_power_W == pytest.approx(2160.0)


def test_measured_power_config_errors_are_one_clear_line() -> None:
    current = {'topic': 'a', 'type': 'std_msgs/msg/Float64', 'field': 'data'}
    with pytest.raises(ConfigError, match='current_is must be one of'):
        parse_measured_power(
            {'left': {'current': current, 'current_is': 'bus'}, 'right': {'current': current}}
        )
    with pytest.raises(ConfigError, match='give left and right, or total'):
        parse_measured_power({'left': {'current': current}})
    with pytest.raises(ConfigError, match='a motor current has a side'):
        parse_measured_power({'total': {'current': current, 'current_is': 'motor'}})
    (battery,) = parse_measured_power(
        {'total': {'topic': 'battery/state', 'type': 'sensor_msgs/msg/BatteryState'}}
    )
    assert battery.total is not None and battery.total.current.scale == -1.0  # negative while discharging


def write_bag(path: Path, currents: list[tuple[float, float]] | None, battery: bool = False) -> None:
    """10 s, 20 Hz: cmd_vel 0.5 m/s straight, the Husky's joint_states (velocity only) and one
    Float64 battery-side current per side (``currents``, cycled) or a BatteryState (24.5 V, -8 A)."""
    omega = 0.5 / 0.1651
    with BagWriter(path) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        sides = (
            [
                writer.add_topic(f'/{s}_drive/status/battery_current', 'std_msgs/msg/Float64')
                for s in ('left', 'right')
            ]
            if currents
            else []
        )
        state = writer.add_topic('/battery/state', 'sensor_msgs/msg/BatteryState') if battery else None
        vec = T['geometry_msgs/msg/Vector3']
        for k in range(200):
            t_ns = START_NS + k * 50_000_000
            stamp = T['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            header = T['std_msgs/msg/Header'](stamp=stamp, frame_id='')
            twist = T['geometry_msgs/msg/Twist'](vec(0.5, 0.0, 0.0), vec(0.0, 0.0, 0.0))
            writer.write(cmd, t_ns, STORE.serialize_cdr(twist, 'geometry_msgs/msg/Twist'))
            if currents:
                for side, value in zip(sides, currents[k % len(currents)], strict=True):
                    msg = T['std_msgs/msg/Float64'](data=value)
                    writer.write(side, t_ns + 100, STORE.serialize_cdr(msg, 'std_msgs/msg/Float64'))
            if state is not None:
                msg = T['sensor_msgs/msg/BatteryState'](
                    header=header,
                    voltage=24.5,
                    temperature=math.nan,
                    current=-8.0,
                    charge=math.nan,
                    capacity=math.nan,
                    design_capacity=math.nan,
                    percentage=math.nan,
                    power_supply_status=2,
                    power_supply_health=0,
                    power_supply_technology=0,
                    present=True,
                    cell_voltage=np.zeros(0, np.float32),
                    cell_temperature=np.zeros(0, np.float32),
                    location='',
                    serial_number='',
                )
                writer.write(state, t_ns + 100, STORE.serialize_cdr(msg, 'sensor_msgs/msg/BatteryState'))
            msg = T['sensor_msgs/msg/JointState'](
                header=header,
                name=list(JOINTS),
                position=np.full(4, omega * k * 0.05),
                velocity=np.full(4, omega),
                effort=np.zeros(0),
            )
            writer.write(js, t_ns + 1000, STORE.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def test_one_float64_battery_current_per_side_is_v_times_i(tmp_path: Path, predictor: MapPredictor) -> None:
    """A driver's battery-side current that a reversing driver reports negative (signed: false: a
    magnitude) is 24 V x |I| of drawn power (the Husky's bus, no voltage topic), per side."""
    path = tmp_path / 'husky.mcap'
    write_bag(path, [(-5.0, 7.0)])
    options = ValidateOptions(vehicle=HUSKY, terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False)
    with open_bag(path) as bag:
        result = validate(bag, options, predictor)
        summary = result.as_json()
    assert summary['power_compared'] == 'battery' and 'V x I' in summary['motor_currents_from']
    assert summary['rejected']['joint_states'] == 0
    series = np.genfromtxt(summary['report']['timeseries_csv'], delimiter=',', names=True)
    moving = np.isfinite(series['measured_power_left_W'])
    np.testing.assert_allclose(series['measured_power_left_W'][moving], 24.0 * 5.0)  # |-5 A| x 24 V
    np.testing.assert_allclose(series['measured_power_right_W'][moving], 24.0 * 7.0)
    # energy: 288 W over the compared rows, each held 0.05 s (the next reading)
    metrics = summary['metrics']
    held = metrics['samples_compared'] * 0.05
    assert metrics['energy_measured_J'] == pytest.approx(288.0 * held, rel=0.02)
    # compared with the predicted BATTERY-side power, not the motor terminal power
    assert series['predicted_power_left_W'][moving][5] == pytest.approx(
        series['predicted_battery_W'][moving][5] - series['predicted_power_right_W'][moving][5]
    )
    assert console_warnings(result) == []


def _battery_state_husky(tmp_path: Path) -> tuple[Path, Path]:
    """(the Husky's file with a whole-robot BatteryState as its measured power, a bag of it)."""
    import yaml

    from skidsteer_power.resources import find

    config = yaml.safe_load(find('vehicles', HUSKY).read_text())
    config['measured_power'] = {'total': {'topic': 'battery/state', 'type': 'sensor_msgs/msg/BatteryState'}}
    vehicle = tmp_path / 'husky_battery_state.yaml'
    vehicle.write_text(yaml.safe_dump(config))
    path = tmp_path / 'husky.mcap'
    write_bag(path, None, battery=True)
    return vehicle, path


def test_a_whole_robot_battery_state_is_measured_power(tmp_path: Path, predictor: MapPredictor) -> None:
    """sensor_msgs/BatteryState: current -8 A (discharging, the message's sign) at 24.5 V = 196 W, half
    per side."""
    vehicle, path = _battery_state_husky(tmp_path)
    options = ValidateOptions(vehicle=str(vehicle), terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False)
    with open_bag(path) as bag:
        result = validate(bag, options, predictor)
        summary = result.as_json()
    series = np.genfromtxt(summary['report']['timeseries_csv'], delimiter=',', names=True)
    finite = np.isfinite(series['measured_battery_W'])
    np.testing.assert_allclose(series['measured_battery_W'][finite], 196.0)


def test_a_bag_without_the_declared_topics_is_told_so_once(tmp_path: Path, predictor: MapPredictor) -> None:
    path = tmp_path / 'husky.mcap'
    write_bag(path, None)
    options = ValidateOptions(vehicle=HUSKY, terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False)
    with open_bag(path) as bag:
        result = validate(bag, options, predictor)
        summary = result.as_json()
    assert not summary['has_motor_data']
    warnings = console_warnings(result)
    assert len(warnings) == 1 and 'lacks the measured_power topics' in warnings[0]
    assert 'left_drive/status/battery_current' in warnings[0]


def test_dropped_readings_are_counted_and_explained_on_the_console(
    tmp_path: Path, predictor: MapPredictor
) -> None:
    """Every other reading at 100 A (2400 W per side, beyond the Husky driver's 24 V x 60 A x 1.5 =
    2160 W) is dropped: half the readings, a loud warning with the reason."""
    path = tmp_path / 'husky.mcap'
    write_bag(path, [(5.0, 5.0), (100.0, 5.0)])
    options = ValidateOptions(vehicle=HUSKY, terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False)
    with open_bag(path) as bag:
        result = validate(bag, options, predictor)
        summary = result.as_json()
    assert summary['rejected']['joint_states'] == 100
    (line,) = console_warnings(result)
    assert line.startswith('WARNING: A THIRD OR MORE') and '100 of 200' in line
    assert 'battery power = # W exceeds the plausible limit # W' in line


def test_the_online_correction_is_scored_battery_side_against_v_times_i(
    tmp_path: Path, predictor: MapPredictor
) -> None:
    """With a battery-side measurement (V x I) the online rows are battery-side too: each side's
    corrected power is its predicted battery power plus the change the correction makes through
    the amplifier, so the sides add up to the corrected battery power (``online_battery_W``, what
    the node integrates). They were terminal powers: compare's online rows on a BorealTC import then
    read -57 % where the corrected battery energy was -24 % (a terminal power lacks the amplifier
    and idle terms the measured V x I holds)."""
    path = tmp_path / 'husky.mcap'
    write_bag(path, [(-5.0, 7.0)])
    options = ValidateOptions(vehicle=HUSKY, terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False)
    with open_bag(path) as bag:
        summary = validate(bag, options, predictor).as_json()
    assert summary['power_compared'] == 'battery'
    c = np.genfromtxt(summary['report']['timeseries_csv'], delimiter=',', names=True)
    rows = np.isfinite(c['online_battery_W'])
    corrected = c['online_torque_left_Nm'] != c['predicted_torque_left_Nm']
    assert corrected[rows].any()  # the correction acted (24 V x 5 A is not what the map predicts)
    sides = c['online_power_left_W'] + c['online_power_right_W']
    # the report's CSV holds 6 decimals
    np.testing.assert_allclose(sides[rows], c['online_battery_W'][rows], rtol=1e-6, atol=1e-4)
    uncorrected = rows & ~corrected
    np.testing.assert_allclose(
        c['online_power_left_W'][uncorrected], c['predicted_power_left_W'][uncorrected], atol=1e-4
    )


def test_import_a_borealtc_run_and_validate_it(tmp_path: Path, predictor: MapPredictor) -> None:
    """BorealTC ASPHALT run 00 (338 rows at 6.5 Hz, 5186 IMU rows) as a bag: the measured energy is
    24 V x (|curL| + |curR|) x the hold of each reading (until the next, at most the 0.5 s joint
    timeout), by hand from the CSV."""
    run = shared_path('realdata', 'borealtc-husky', 'ASPHALT')
    out = tmp_path / 'a00.mcap'
    result = import_csv(
        run / 'pro_00.csv', out, HUSKY, Columns(**PRESETS['borealtc']), imu=run / 'imu_00.csv'
    )
    assert result['messages']['/joint_states'] == 338 and result['messages']['/imu/data'] == 5186
    csv = np.genfromtxt(run / 'pro_00.csv', delimiter=',', names=True)
    with open_bag(out) as bag:
        validated = validate(
            bag,
            ValidateOptions(vehicle=HUSKY, terrain=TERRAIN, report_dir=tmp_path / 'r', plots=False),
            predictor,
        )
        summary = validated.as_json()
    hold = np.minimum(np.diff(csv['time'], append=csv['time'][-1]), 0.5)
    by_hand = float(np.sum(24.0 * (csv['curL'] + csv['curR']) * hold))
    assert summary['metrics']['energy_measured_J'] == pytest.approx(by_hand, rel=0.02)
    assert summary['metrics']['energy_measured_J'] > 0 and console_warnings(validated) == []
    # the set points are the recorded wheel speeds: V = (v_l + v_r) / 2 of row 10
    with open_bag(out) as bag:
        from skidsteer_power.bag_io.decode import decode_twists

        _, cmd = decode_twists(bag, '/cmd_vel', bag.start_ns)
    assert cmd[10, 0] == pytest.approx((csv['velL'][10] + csv['velR'][10]) / 2)
    # and the Husky's own drive controller (wheel separation x 1.875) turns every command back into
    # the recorded wheel speeds: an import with the bare tread gave a yaw rate 1.875 x too large
    from skidsteer_power.drive import controller_for_vehicle
    from skidsteer_power.vehicle import load_vehicle

    recorded = np.column_stack([csv['velL'], csv['velR']]) / 0.1651  # husky_a200.yaml wheel radius
    setpoint = controller_for_vehicle(load_vehicle(HUSKY)).apply(cmd[:, 0], cmd[:, 1]).setpoint
    assert np.allclose(setpoint, recorded, atol=1e-9)


@pytest.mark.ros
def test_power_estimator_node_measures_v_times_i_from_one_float64_per_side(rig_factory: Any) -> None:
    """Real rclpy and DDS, the shipped husky file: one std_msgs/Float64 battery-side current per side
    (its third measured_power alternative; husky_msgs is not installed here, so the node takes the
    first whose messages are). A reversing driver's -5 A is a magnitude: 24 V x 5 A = 120 W drawn on
    the left, 24 V x 7 A = 168 W on the right."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64
    from test_estimator_core import FixedPowerPredictor

    rig = rig_factory(FixedPowerPredictor(80.0), vehicle=HUSKY, diagnostics_period_s=0.05)
    left = rig.probe.create_publisher(Float64, 'left_drive/status/battery_current', 10)
    right = rig.probe.create_publisher(Float64, 'right_drive/status/battery_current', 10)
    omega = 0.5 / 0.1651
    joint_state = JointState(name=list(JOINTS), position=[0.0] * 4, velocity=[-omega] * 4)
    core = rig.node.core
    rig.spin_until(lambda: left.get_subscription_count() > 0 and right.get_subscription_count() > 0)

    def measured() -> bool:
        left.publish(Float64(data=-5.0))
        right.publish(Float64(data=7.0))
        rig.pub_joint.publish(joint_state)
        return core.comparison is not None

    rig.spin_until(measured)
    assert core.comparison is not None
    assert core.comparison.measured.bus_W == pytest.approx((120.0, 168.0))
    assert core.comparison.measured.battery_side
    assert core.rejects.counts['joint_states'] == 0
    # the vehicle's own limits, not the test robot's fixed 5 N m (config/powertrains/husky_a200.yaml)
    assert core.settings.limits.max_motor_torque_Nm == pytest.approx(4.122)


def _calibration_segments(bag: Path, vehicle: str) -> list[Any]:
    """The steady segments calibrate cuts from ``bag`` with ``vehicle``'s own reader (as calibrate_bags)."""
    from skidsteer_power.calibration.segments import SegmentOptions, find_segments, read_recording
    from skidsteer_power.estimator.inputs import JointReader

    veh = load_vehicle(vehicle)
    pt = Powertrain.for_vehicle(veh)
    limits = InputLimits.for_powertrain(pt)
    reader = JointReader(factory.joint_map_for(veh), pt.gear_ratio, pt.motor.torque_constant_Nm_A, limits)
    segments, _ = find_segments(read_recording(bag, SegmentOptions(), reader), SegmentOptions(), pt.motor)
    return segments


def test_calibration_fits_a_battery_side_power_in_watts_and_knows_a_total(tmp_path: Path) -> None:
    """calibrate compares the measured V x I [W] with the predicted battery-side power, so a segment
    keeps it in watts: 24 V x |-5 A| = 120 W and 24 V x 7 A = 168 W per side (the Float64 currents of
    :func:`write_bag`, the Husky's 24 V bus). It once stored the motor torque of the powertrain's
    inverse there (N m compared with W: +4135 % energy error on a twin bag). A whole-robot
    BatteryState (24.5 V x 8 A = 196 W) is split half per side and flagged as a total: only the sum
    is measured, and the fit compares the sum (fit.battery_error)."""
    from skidsteer_power.calibration.fit import battery_error

    per_side = tmp_path / 'per_side.mcap'
    write_bag(per_side, [(-5.0, 7.0)])
    (segment,) = _calibration_segments(per_side, HUSKY)
    assert segment.battery_W == pytest.approx((120.0, 168.0)) and not segment.battery_total
    vehicle, total = _battery_state_husky(tmp_path)
    (segment,) = _calibration_segments(total, str(vehicle))
    assert segment.battery_W == pytest.approx((98.0, 98.0)) and segment.battery_total
    # the sum's error, once: predicted 150 + 60 W against the measured 196 W is +14 W, whatever the split
    error = battery_error(np.array([[150.0, 60.0]]), np.array([segment.battery_W]), np.array([True]))
    np.testing.assert_allclose(error, [[14.0, 0.0]])


def test_a_negative_measured_energy_is_a_console_warning() -> None:
    """The issue's silently wrong number: a battery-side current read as a motor current (K_t I w < 0
    while reversing) gave 'measured 641.5 J' with no word; a negative measured energy is now said."""
    (line,) = reading_warnings(read=10, dropped=0, reasons={}, note=None, measured_J=-641.5)
    assert 'measured energy is negative (-641.5 J)' in line and 'current_is: battery' in line
