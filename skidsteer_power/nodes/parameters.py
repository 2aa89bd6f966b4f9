"""The nodes' parameters as frozen, typed objects: one dataclass per node, a field per parameter (name,
type, default, description as in the node's PARAMETERS spec), filled by
:func:`skidsteer_power.nodes.param_spec.read_parameters` after each value's type, range and choices
are checked. Rendered from the specs by ``python -m skidsteer_power.nodes.param_files`` (``--check``
in CI): edit the spec, not this file.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DesDriverParameters:
    """The parameters of the des_driver node (its PARAMETERS)."""

    vehicle: str = 'test_robot_track'
    """vehicle name or YAML file: tread, drive radius, powertrain (gear ratio, motor: effort = K_t I)"""
    left_port: str = '/dev/ttyUSB0'
    """serial port (path or pyserial URL) of the left amplifier"""
    right_port: str = '/dev/ttyUSB1'
    """serial port (path or pyserial URL) of the right amplifier"""
    baud: int = 38400
    """link speed [bit/s]: 9600, 14400, 19200, 38400, 57600 or 115200; range 9600 .. 115200; one of 9600,
    14400, 19200, 38400, 57600, 115200
    """
    left_polarity: int = 1
    """amplifier sense of forward motion, left side: +1 or -1; range -1 .. 1; one of 1, -1"""
    right_polarity: int = -1
    """amplifier sense of forward motion, right side (mirrored motor): +1 or -1; range -1 .. 1; one of 1,
    -1
    """
    encoder_resolution: int = 0
    """encoder lines per motor turn [-]; 0 = the vehicle's motor's (EC-45: 2048, ch. 7.1.2); range
    0 .. 65535
    """
    max_motor_rpm: float = 4000.0
    """largest motor set point [rpm] (EC-45: 4010 rpm no-load at 48 V); at most the vehicle's motor's max.
    speed (EC-45: 10 000 rpm) and the DES 70/10 max. 25 000 rpm / pole pairs; range 1 .. 25000
    """
    max_speed_m_s: float = 0.0
    """|V| commands beyond are clamped [m/s]; 0 = the vehicle file's max_speed_m_s (docs/DRIVE.md); range
    0 .. 10
    """
    max_yaw_rate_rad_s: float = 0.0
    """|yaw rate| commands beyond are clamped [rad/s]; 0 = the vehicle file's max_yaw_rate_rad_s; range
    0 .. 20
    """
    max_accel_m_s2: float = 0.0
    """largest change of the commanded V [m/s^2]; 0 = the vehicle's drive controller's, else 1.0; range
    0 .. 100
    """
    max_yaw_accel_rad_s2: float = 0.0
    """largest change of the commanded yaw rate [rad/s^2]; 0 = the vehicle's drive controller's, else 4.0;
    range 0 .. 1000
    """
    cmd_timeout_s: float = 0.5
    """zero speed when no valid cmd_vel for this long [s]; range 0.01 .. 60"""
    stop_both_on_link_loss: bool = True
    """a failed or lost link on one side stops the other side too"""
    poll_rate_hz: float = 50.0
    """amplifier poll and joint_states rate [Hz]; range 0.1 .. 1000"""
    status_every: int = 5
    """read the status word every N polls [-]; range 1 .. 1000"""
    reconnect_period_s: float = 0.5
    """retry period for a lost port; first poller restart back-off [s]; range 0.01 .. 60"""
    ack_timeout_s: float = 0.05
    """wait for each acknowledge / reply from an amplifier [s]; range 0.001 .. 10"""
    configure_timeout_s: float = 5.0
    """configure fails unless both amplifiers answer within [s]; range 0.1 .. 60"""
    diagnostics_rate_hz: float = 2.0
    """diagnostics rate [Hz]; range 0.01 .. 100"""
    current_source: str = 'status_variable'
    """currents from 'status_variable' (130, documented) or 'is_must' (op 0x29, UNCONFIRMED); one of
    'status_variable', 'is_must'
    """
    encoder_counter_variable: int = 143
    """status variable of the 16-bit encoder counter (UNCONFIRMED); range 128 .. 255"""
    twist_stamped: bool = False
    """deprecated: cmd_vel_type:=twist_stamped (true = that, with a warning)"""
    cmd_vel_type: str = 'auto'
    """cmd_vel message type: 'auto' (follow the publishers on the graph), 'twist' (geometry_msgs/Twist) or
    'twist_stamped' (geometry_msgs/TwistStamped)
    """
    cmd_vel_stamp_tolerance_s: float = 0.2
    """a TwistStamped stamped more than this after the node clock is refused [s]; range 0 .. 60"""
    frame_id: str = ''
    """header.frame_id of joint_states"""
    autostart: bool = False
    """configure and activate at start (no lifecycle manager needed)"""
    guardian: bool = True
    """run the guardian process that owns the ports and stops both amplifiers when the driver dies or
    freezes (SIGKILL, SIGSTOP, SIGSEGV, ...); false: no guardian, the driver opens the ports itself
    """
    guardian_timeout_s: float = 0.3
    """the guardian stops both amplifiers after no heartbeat from the driver for this long [s]; range
    0.05 .. 5
    """
    guardian_feed: str = 'none'
    """modem-control line of both amplifier ports that the guardian toggles every 50 ms as the feed of a
    hardware watchdog on the enable input, while a fresh command is in force on healthy links: none, dtr
    or rts (docs/RELIABILITY.md, the hardware line of defence)
    """


@dataclass(frozen=True)
class PowerEstimatorParameters:
    """The parameters of the power_estimator node (its PARAMETERS)."""

    vehicle: str = 'test_robot_track'
    """vehicle name in config/vehicles/ or a YAML file; read only"""
    terrain: str = 'dry_sand'
    """terrain preset or YAML file; may be changed at run time (swaps maps)"""
    kinematics: str = 'cmd'
    """how a command is predicted: 'cmd' (at its wheel speed set points; 'setpoint' still accepted) or
    'twist' (as the motion); read only
    """
    map_cache_dir: str = ''
    """directory of cached maps ('' = $SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power); read only"""
    state_file: str = ''
    """energy state file ('' = ~/.local/state/skidsteer_power/energy_[<namespace>_]<vehicle>.json); one
    live process per file (a lock); read only
    """
    persist: bool = True
    """save the energy state and restore it on start; read only"""
    initial_soc: float = -1.0
    """state of charge at start when nothing is restored [-]; < 0 = full; range -1 .. 1; read only"""
    cmd_vel_stamped: bool = False
    """deprecated: cmd_vel_type:=twist_stamped (true = that, with a warning); read only"""
    cmd_vel_type: str = 'auto'
    """cmd_vel message type: 'auto' (follow the publishers on the graph), 'twist' (geometry_msgs/Twist) or
    'twist_stamped' (geometry_msgs/TwistStamped); read only
    """
    cmd_vel_stamp_tolerance_s: float = 0.2
    """a TwistStamped stamped more than this after the node clock is refused [s]; range 0 .. 60; read only"""
    cmd_timeout_s: float = 0.5
    """cmd_vel older than this is stale [s]; range 0.01 .. 60; read only"""
    joint_timeout_s: float = 0.5
    """joint_states older than this is stale [s]; range 0.01 .. 60; read only"""
    traction_warning_margin: float = 0.1
    """warn when the traction margin is at or below this [-]; range 0 .. 1; read only"""
    power_filter_s: float = 5.0
    """time constant of the power filter behind time to empty [s]; range 0 .. 3600; read only"""
    warn_period_s: float = 2.0
    """least time between two warnings about rejected inputs [s]; range 0.01 .. 3600; read only"""
    max_speed_m_s: float = 5.0
    """cmd_vel |linear.x| above this is rejected [m/s]; range 0.001 .. 100; read only"""
    max_yaw_rate_rad_s: float = 10.0
    """cmd_vel |angular.z| above this is rejected [rad/s]; range 0.001 .. 100; read only"""
    drive_max_speed_m_s: float = 0.0
    """the drive's |V| limit the predictions follow [m/s]; 0 = the vehicle file's (run: the des_driver's);
    range 0 .. 100; read only
    """
    drive_max_yaw_rate_rad_s: float = 0.0
    """the drive's |yaw rate| limit the predictions follow [rad/s]; 0 = the vehicle file's; range 0 .. 100;
    read only
    """
    drive_max_wheel_rad_s: float = 0.0
    """the drive's wheel (axle) speed ceiling the predictions follow [rad/s]; 0 = the vehicle file's; range
    0 .. 10000; read only
    """
    max_motor_speed_rad_s: float = 1200.0
    """joint_states |velocity| above this is rejected [rad/s]; range 1 .. 10000; read only"""
    max_motor_torque_Nm: float = 5.0
    """joint_states |effort| above this is rejected [N m]; range 0.001 .. 1000; read only"""
    publish_period_s: float = 0.2
    """period of battery and energy topics [s]; range 0.001 .. 3600; read only"""
    figure_period_s: float = 0.05
    """least period of the Float64 figure topics (latest value) [s]; range 0.001 .. 3600; read only"""
    diagnostics_period_s: float = 1.0
    """period of diagnostics [s]; range 0.01 .. 3600; read only"""
    save_period_s: float = 0.5
    """period of energy-state saves [s]: the most energy a SIGKILL or power cut loses (in a thread); range
    0.1 .. 86400; read only
    """
    qos_depth: int = 100
    """queue depth of the subscriptions and the per-message outputs; range 1 .. 100000; read only"""
    input_reliability: str = 'best_effort'
    """cmd_vel / joint_states subscriptions: best_effort (matches reliable and best-effort publishers) or
    reliable (matches reliable publishers only); read only
    """
    output_qos: str = 'reliable'
    """per-message outputs: reliable, or sensor_data (best effort, depth 5); read only"""
    left_joints: str = ''
    """comma-separated joint names of the left side ('' = vehicle file); read only"""
    right_joints: str = ''
    """comma-separated joint names of the right side ('' = vehicle file); read only"""
    effort_is: str = ''
    """joint_states effort is 'torque' [N m] or 'current' [A] ('' = vehicle file); read only"""
    joints_at: str = ''
    """joint values are at the 'motor' shaft or the 'wheel' ('' = vehicle file); read only"""
    joint_gear_ratio: float = 0.0
    """motor turns per wheel turn of the joints [-] (0 = vehicle file); range 0 .. 1000; read only"""
    joint_torque_constant_Nm_A: float = 0.0
    """motor torque constant for a current effort [N m/A] (0 = vehicle file); range 0 .. 100; read only"""
    adaptation: bool = True
    """adapt a per-side torque scale and offset online, detect terrain changes; read only"""
    adaptation_memory_s: float = 10.0
    """memory (forgetting time constant) of the online adaptation [s]; range 0.1 .. 86400; read only"""
    adaptation_terrain_memory_s: float = 60.0
    """memory of the terrain scale that carries over between commands (path energy) [s]; range
    0.1 .. 86400; read only
    """
    path_speed_m_s: float = 0.0
    """speed to drive the planned path at [m/s]; 0 = the last commanded speed; range 0 .. 10; read only"""
    path_reserve_wh: float = 0.0
    """energy kept in reserve in energy/path_margin_wh [Wh]; range 0 .. 1e+06; read only"""
