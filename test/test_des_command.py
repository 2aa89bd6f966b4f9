"""Command checks, slew limiting and DriveCommand's stop conditions (pure, no ROS, no port)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from des_harness import Clock
from hypothesis import given
from hypothesis import strategies as st

from skidsteer_power.des.command import CommandLimits, DriveGeometry, SlewLimiter, limit_twist
from skidsteer_power.des.kinematics import set_point_limit_rpm, twist_to_motor_rpm
from skidsteer_power.des.poller import DriveCommand
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.powertrain import EC45, Powertrain
from skidsteer_power.vehicle import load_vehicle

LIMITS = CommandLimits(
    max_speed_m_s=1.5, max_yaw_rate_rad_s=2.0, max_accel_m_s2=1.0, max_yaw_accel_rad_s2=4.0
)
# test_robot_track.yaml: tread 0.426 m, sprocket 0.1 m; 12:1 (ch. 7.1.1); right motor mirrored.
GEOMETRY = DriveGeometry(
    tread_m=0.426, drive_radius_m=0.1, gear_ratio=12.0, polarity={'left': 1, 'right': -1}, max_rpm=4000.0
)
# Largest set point the limits allow: |V| + |w| B / 2 = 1.5 + 2.0 * 0.213 = 1.926 m/s at a side ->
# 1.926 / 0.1 * 12 = 231.1 rad/s = 2207 rpm (below max_rpm 4000).
LIMIT_RPM = (1.5 + 2.0 * 0.426 / 2) / 0.1 * 12 * 60 / (2 * math.pi)

any_float = st.floats(allow_nan=True, allow_infinity=True)


def test_non_finite_twist_is_rejected() -> None:
    for v, w in ((math.nan, 0.0), (0.0, math.inf), (-math.inf, 1.0)):
        with pytest.raises(InputError, match='non-finite'):
            limit_twist(v, w, LIMITS)


def test_finite_twist_is_clamped_per_axis() -> None:
    checked = limit_twist(1e308, -1e9, LIMITS)
    assert (checked.linear_m_s, checked.yaw_rate_rad_s, checked.clamped) == (1.5, -2.0, True)
    checked = limit_twist(0.2, 0.1, LIMITS)
    assert (checked.linear_m_s, checked.yaw_rate_rad_s, checked.clamped) == (0.2, 0.1, False)


def test_limits_must_be_positive_and_finite() -> None:
    with pytest.raises(ConfigError, match='max_speed_m_s'):
        CommandLimits(max_speed_m_s=math.inf)
    with pytest.raises(ConfigError, match='max_accel_m_s2'):
        CommandLimits(max_accel_m_s2=0.0)


def test_kinematics_refuses_non_finite_and_overflowing_twists() -> None:
    kw = {'tread_m': 0.426, 'drive_radius_m': 0.1, 'gear_ratio': 12.0, 'max_rpm': 4000.0}
    with pytest.raises(InputError):
        twist_to_motor_rpm(math.nan, 0.0, **kw)
    with pytest.raises(InputError, match='overflows'):
        twist_to_motor_rpm(1e308, 0.0, **kw)  # 1e308 * 120 / RPM is inf: never a NaN set point


def test_slew_limiter_ramps_at_the_limits() -> None:
    slew = SlewLimiter(LIMITS)
    slew.reset(0.0)
    # 0.05 s at 1 m/s^2 and 4 rad/s^2: 0.05 m/s and 0.2 rad/s.
    assert slew.step(1.0, 1.0, 0.05) == pytest.approx((0.05, 0.2))
    assert slew.step(1.0, 1.0, 10.0) == pytest.approx((0.15, 0.6))  # a stall counts as 0.1 s at most
    assert slew.step(0.1, 0.6, 10.05) == pytest.approx((0.1, 0.6))  # slowing down: also ramped, reached


@given(v=any_float, w=any_float)
def test_every_set_point_is_a_bounded_integer(v: float, w: float) -> None:
    clock = Clock()
    command = DriveCommand(1.0, geometry=GEOMETRY, limits=LIMITS, max_rpm=4000.0, clock=clock)
    for side in ('left', 'right'):
        command.link_up(side)
    try:
        command.set_twist(v, w)
    except InputError:
        assert not (math.isfinite(v) and math.isfinite(w))
    clock.now += 0.001
    for _ in range(3):
        for side in ('left', 'right'):
            rpm = command.wanted_rpm(side)
            assert isinstance(rpm, int) and abs(rpm) <= LIMIT_RPM + 1


def test_drive_command_stop_conditions() -> None:
    clock = Clock()
    command = DriveCommand(0.2, geometry=GEOMETRY, limits=LIMITS, active=False, clock=clock)
    command.set_twist(0.2, 0.0)
    assert command.wanted_rpm('left') == 0 and command.stop_reason() == 'inactive'
    command.active = True  # activation forgets any earlier command
    assert command.stop_reason().startswith('link down')  # no poller has connected yet
    command.link_up('left')
    command.link_up('right')
    assert command.stop_reason() == 'no fresh command'
    command.set_twist(0.2, 0.0)
    command.wanted_rpm('left')  # the pollers ask every cycle; the ramp starts at the first call
    clock.now += 0.05
    assert command.wanted_rpm('left') > 0 and command.wanted_rpm('right') < 0
    command.link_down('right', 'port lost')
    assert command.wanted_rpm('left') == 0  # stop_both_on_link_loss (default)
    command.link_up('right')
    command.halt('left')
    assert command.wanted_rpm('right') == 0 and 'fault on left' in command.stop_reason()
    command.cleared('left')
    clock.now += 0.25
    assert command.wanted_rpm('left') == 0 and command.timed_out()  # watchdog


def test_opting_out_of_stop_both_keeps_the_other_side() -> None:
    clock = Clock()
    command = DriveCommand(1.0, geometry=GEOMETRY, limits=LIMITS, stop_both_on_link_loss=False, clock=clock)
    command.link_up('left')
    command.set_twist(0.2, 0.0)
    command.wanted_rpm('left')
    clock.now += 0.05
    assert command.wanted_rpm('left') > 0 and command.wanted_rpm('right') == 0  # right never connected


def test_rpm_targets_are_capped_at_the_motor_limit() -> None:
    command = DriveCommand(1.0, max_rpm=1e9)  # the default: the test robot's motor, the EC-45
    assert command.max_rpm == command.motor_limit_rpm == pytest.approx(10000.0)  # Appendix B line 23
    command.link_up('left')
    command.link_up('right')
    command.set({'left': 1e12, 'right': math.nan})
    assert command.wanted_rpm('left') == 10000
    assert command.wanted_rpm('right') == 0 and command.nonfinite_setpoints == 1


def test_the_vehicles_motor_sets_the_set_point_limit(strong_motor_vehicle: Path) -> None:
    """A vehicle whose motor allows 5000 rpm (the fixture) caps the set points there, not at the
    EC-45's 10 000 rpm; a requested max_rpm below the motor's limit stays."""
    motor = Powertrain.for_vehicle(load_vehicle(str(strong_motor_vehicle))).motor
    command = DriveCommand(1.0, max_rpm=1e9, motor=motor)
    assert command.max_rpm == pytest.approx(5000.0)
    command.link_up('left')
    command.link_up('right')
    command.set({'left': 7000.0, 'right': -7000.0})
    assert (command.wanted_rpm('left'), command.wanted_rpm('right')) == (5000, -5000)
    assert DriveCommand(1.0, max_rpm=4000.0, motor=motor).max_rpm == 4000.0


def test_the_amplifier_caps_a_fast_motor() -> None:
    """The DES 70/10 runs at most 25 000 rpm with one pole pair (Appendix A), 25 000 / p with p:
    a 2-pole-pair motor allowed 20 000 rpm gets 12 500 rpm, a 1-pole-pair one 20 000 rpm."""
    fast = dataclasses.replace(EC45, max_speed_rad_s=20000 * 2 * math.pi / 60)
    assert set_point_limit_rpm(fast) == pytest.approx(12500.0)
    assert set_point_limit_rpm(dataclasses.replace(fast, pole_pairs=1)) == pytest.approx(20000.0)


def test_a_stalled_poller_counts_as_a_lost_link() -> None:
    clock = Clock()
    command = DriveCommand(10.0, geometry=GEOMETRY, limits=LIMITS, stall_timeout_s=0.1, clock=clock)
    command.link_up('left')
    command.link_up('right')
    command.set_twist(0.2, 0.0)
    command.wanted_rpm('left')
    clock.now += 0.05
    assert command.wanted_rpm('left') > 0
    clock.now += 0.1  # the right poller has not reported a good cycle since: hung or dead
    command.link_up('left')
    assert command.wanted_rpm('left') == 0 and 'right (poller stalled' in command.stop_reason()
    command.link_up('right')
    assert command.stop_reason() == ''


def test_the_driver_limits_default_to_the_vehicle_files_controller() -> None:
    # Issue 36: des_driver's max_speed_m_s / max_yaw_rate_rad_s / max_accel_* at 0 (their defaults)
    # are the vehicle's drive controller's. husky_a200.yaml: max_speed_m_s 1.0, max_yaw_rate_rad_s 2.0,
    # drive_controller max_accel_m_s2 3.0, max_yaw_accel_rad_s2 6.0 (husky_control control.yaml).
    from skidsteer_power.des.command import FALLBACK_ACCEL, limits_for
    from skidsteer_power.drive import controller_for_vehicle

    husky = controller_for_vehicle(load_vehicle('husky_a200'))
    assert limits_for(husky, {}) == CommandLimits(1.0, 2.0, 3.0, 6.0)
    given = {'max_speed_m_s': 0.5, 'max_yaw_rate_rad_s': 0.0, 'max_accel_m_s2': 0.2}
    assert limits_for(husky, given) == CommandLimits(0.5, 2.0, 0.2, 6.0)  # a value > 0 is the user's
    # the test robot's file declares no acceleration limit (inf): the driver still slews, at the
    # 1.0 m/s^2 / 4.0 rad/s^2 it always had, and its velocity limits are the file's defaults 1.5 / 2.0
    robot = controller_for_vehicle(load_vehicle('test_robot_track'))
    assert math.isinf(robot.max_accel_m_s2)
    assert limits_for(robot, {}) == CommandLimits(1.5, 2.0, *FALLBACK_ACCEL) == LIMITS
