"""Measured motor power from joint_states (motor shaft speed and Kt * I).

The DES driver publishes, per motor, the shaft speed omega [rad/s] and effort = Kt * I [N m]
(DESIGN.md, ROS interface). Per motor (eq. 7.1 uses the same Kt * i torque):

    current                      I     = effort / Kt                             [A]
    mechanical (air-gap) power   P_m   = Kt * I * omega                          [W]
    terminal (electrical) power  P_e   = P_m + R * I**2   (winding copper loss)  [W]
    battery-side (DC bus) power  P_bus = P_e / eta, or P_e * eta_regen if P_e < 0 [W]

The last two are :func:`skidsteer_power.powertrain.motor.terminal_power` and ``bus_power`` (DES 70/10,
4-quadrant, 7.1.2), reused here so the measured and predicted sides share one motor model. Negative
power is regenerative braking.
"""

from __future__ import annotations

from dataclasses import dataclass

from skidsteer_power.powertrain.motor import (
    DES_70_10,
    AmplifierConstants,
    MotorConstants,
    bus_power,
    motor_current,
    terminal_power,
)

Pair = tuple[float, float]


@dataclass(frozen=True)
class MeasuredPower:
    """Per-side (left, right) measured motor quantities, SI units.

    omega_rad_s : motor shaft speed [rad/s]; torque_Nm : Kt*I [N m]; current_A : I [A];
    mechanical_W : Kt*I*omega [W]; electrical_W : terminal power with R I^2 [W];
    bus_W : battery-side power through the amplifier [W].
    """

    omega_rad_s: Pair
    torque_Nm: Pair
    current_A: Pair
    mechanical_W: Pair
    electrical_W: Pair
    bus_W: Pair

    @property
    def bus_total_W(self) -> float:
        """Battery power of both sides [W]."""
        return self.bus_W[0] + self.bus_W[1]

    @property
    def electrical_total_W(self) -> float:
        return self.electrical_W[0] + self.electrical_W[1]


def measure_motor_power(
    omega_rad_s: Pair,
    torque_Nm: Pair,
    motor: MotorConstants,
    amplifier: AmplifierConstants = DES_70_10,
    regen_efficiency: float | None = None,
) -> MeasuredPower:
    """Per-side measured power from motor shaft speed [rad/s] and Kt*I [N m] (see module docstring).

    ``regen_efficiency`` is the amplifier's bus/terminal power ratio when generating (None: its
    efficiency), as in :func:`skidsteer_power.powertrain.motor.bus_power`. Computed in floats, one
    side at a time (per message: :mod:`skidsteer_power.numeric`).
    """
    wl, wr = float(omega_rad_s[0]), float(omega_rad_s[1])
    tl, tr = float(torque_Nm[0]), float(torque_Nm[1])
    electrical = terminal_power(motor, tl, wl), terminal_power(motor, tr, wr)
    return MeasuredPower(
        omega_rad_s=(wl, wr),
        torque_Nm=(tl, tr),
        current_A=(motor_current(motor, tl), motor_current(motor, tr)),
        mechanical_W=(tl * wl, tr * wr),
        electrical_W=electrical,
        bus_W=(
            bus_power(electrical[0], amplifier, regen_efficiency),
            bus_power(electrical[1], amplifier, regen_efficiency),
        ),
    )
