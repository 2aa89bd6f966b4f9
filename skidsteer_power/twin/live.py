"""The twin as the live load of the simulated DES 70/10 amplifiers (``run --simulate``).

Each simulated amplifier (``des/simulator.SimulatedDes``) integrates its own motor and asks its
load for the torque at the motor shaft, ``load(omega_rad_s, t_s)``, from its own thread every
0.5 ms. :class:`TwinCoupling` keeps the latest speed of both motors and advances the twin's body
and terrain contact (``Twin.step_with_motor_speeds``) in wall-clock time whenever a step is due;
each side's :class:`TwinLoad` returns the twin's axle torque of that side over the gear ratio plus
the side's internal resistance (eqs. 7.1-7.4, Table 7.1), in the amplifier's sense of rotation.

Where the inertia lives (one place each, as in the offline twin): the simulated amplifier's motor
model (:func:`configure_amplifier`) carries the rotor and the side's drivetrain (track belt and
sprockets, or wheels) reflected through the reduction, i.e. the twin's ``Twin.J``; the body's mass
and yaw inertia live only in the twin's rigid body and reach each motor through the soil (the axle
torque). The amplifier's PI gains stay those designed on the rotor + half the body (as the offline
twin's and the real DES's: the tuning does not change because the simulation is split differently).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from skidsteer_power.des.simulator import MotorModel
from skidsteer_power.twin.model import Twin
from skidsteer_power.twin.motor_dynamics import FRICTION_SMOOTHING_RAD_S

MAX_CATCH_UP_STEPS = 50
"""At most this many twin steps per load call; a stalled process does not replay the backlog."""


class TwinCoupling:
    """Advances ``twin`` in real time with the motor speeds the amplifiers report (thread-safe)."""

    def __init__(self, twin: Twin) -> None:
        self.twin = twin
        self.omega_m = np.zeros(2)  # latest motor speeds, robot sense [rad/s]
        self.axle_Nm = np.zeros(2)
        self._t0: float | None = None
        self._side_t = [math.nan, math.nan]  # each amplifier's latest time [s] (own clock)
        self._lock = threading.Lock()
        # encoder dead reckoning (what odom publishes): x, y [m], yaw [rad], V [m/s], yaw rate [rad/s]
        self.odom = np.zeros(5)

    def update(self, side: int, omega_m: float, t_s: float) -> float:
        """Record side ``side``'s motor speed [rad/s] at time ``t_s`` [s]; return its axle torque [N m]."""
        with self._lock:
            self.omega_m[side] = omega_m
            self._side_t[side] = t_s
            now = min(self._side_t)  # both amplifiers have reported up to here (NaN until both have)
            if math.isnan(now):
                return float(self.axle_Nm[side])
            if self._t0 is None:
                self._t0 = now - self.twin.t
            due = int((now - self._t0 - self.twin.t) / self.twin.dt)
            for _ in range(min(max(due, 0), MAX_CATCH_UP_STEPS)):
                self.axle_Nm = self.twin.step_with_motor_speeds(self.omega_m.copy())
                self._dead_reckon()
            if due > MAX_CATCH_UP_STEPS:
                self._t0 = now - self.twin.t  # drop the backlog
            return float(self.axle_Nm[side])

    def _dead_reckon(self) -> None:
        twin = self.twin
        side = self.omega_m * twin.r / twin.G
        speed, yaw_rate = side.mean(), (side[1] - side[0]) / twin.vehicle.tread_m
        x, y, yaw = self.odom[:3]
        self.odom[:] = (
            x + twin.dt * speed * math.cos(yaw),
            y + twin.dt * speed * math.sin(yaw),
            yaw + twin.dt * yaw_rate,
            speed,
            yaw_rate,
        )

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(true pose x, y, yaw; true hull twist v_x, v_y, yaw rate; odom x, y, yaw, V, yaw rate)."""
        with self._lock:
            return self.twin.pose.copy(), self.twin.vel.copy(), self.odom.copy()


def configure_amplifier(model: MotorModel, twin: Twin) -> None:
    """Make a simulated amplifier's motor model (``des/simulator.MotorModel``) the twin's drivetrain:
    inertia rotor + drivetrain [kg m^2] (``Twin.J``, no body mass: the twin's body has it), the
    twin's PI gains kp [A s/rad] and ki [A/rad] and its bus voltage [V] as the supply. Call before
    the amplifier runs."""
    model.inertia_kg_m2 = twin.J
    model.kp_A_s = twin.kp
    model.ki_A = twin.ki
    model.supply_voltage_V = twin.bus_voltage_V


class TwinLoad:
    """Load torque [N m] at one simulated motor shaft for ``SimulatedDes.set_load``.

    T_load(w_m) = T_axle / G + b w_m + c tanh(w_m / w_s), robot sense, mapped into the amplifier's
    sense by ``polarity`` (+1/-1, as the driver's parameter); T_axle from the twin.
    """

    def __init__(self, coupling: TwinCoupling, side: str, polarity: int) -> None:
        self.coupling = coupling
        self.index = 0 if side == 'left' else 1
        pt = coupling.twin.powertrain
        self.gear_ratio = pt.gear_ratio
        self.resistance = pt.resistance(side).total
        self.polarity = polarity

    def robot_sense(self, omega_m: float, t_s: float) -> float:
        """Load [N m] at motor speed ``omega_m`` [rad/s], both in the robot's forward-positive sense."""
        axle = self.coupling.update(self.index, omega_m, t_s)
        r = self.resistance
        internal = r.viscous_Nm_s * omega_m + r.coulomb_Nm * math.tanh(omega_m / FRICTION_SMOOTHING_RAD_S)
        return axle / self.gear_ratio + internal

    def holding_torque_Nm(self) -> float:
        """The side's internal resistance at 1 rad/s [N m] (positive): what holds an unpowered motor
        at rest (``MotorModel.holding_torque``), without stepping the twin at a speed the motor does
        not turn at (every call of :meth:`__call__` is a motor speed the twin moves with)."""
        r = self.resistance
        return r.viscous_Nm_s + r.coulomb_Nm * math.tanh(1.0 / FRICTION_SMOOTHING_RAD_S)

    def slope_Nm_s(self, omega_rad_s: float) -> float:
        """d(internal resistance)/d(omega) [N m s/rad] at motor speed ``omega_rad_s`` [rad/s] (the
        same in either sense): b + c (1 - tanh^2(w / w_s)) / w_s, which ``MotorModel.step`` takes
        implicitly (its explicit step is unstable on the twin's rotor inertia near zero speed)."""
        r = self.resistance
        th = math.tanh(omega_rad_s / FRICTION_SMOOTHING_RAD_S)
        return r.viscous_Nm_s + r.coulomb_Nm * (1.0 - th * th) / FRICTION_SMOOTHING_RAD_S

    def __call__(self, omega_rad_s: float, t_s: float) -> float:
        return self.polarity * self.robot_sense(self.polarity * omega_rad_s, t_s)
