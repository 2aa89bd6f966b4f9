"""What the robot does for a command: set points, FESS at the set points, motors, amplifiers, battery.

``predict_commands(vehicle, terrain, speed_cmd, yaw_cmd)`` is the direct (solver) answer of
``skidsteer-power predict --direct`` (DESIGN.md): the command's side axle speed set points (the
vehicle's drive controller, :mod:`skidsteer_power.drive`: its velocity limits, kinematics and wheel
speed ceiling, and no motor past its no-load speed at the battery's full voltage, scaled), the body
motion FESS finds for them
(:class:`~skidsteer_power.models.setpoint.SetpointSolver`), and each side's motor current and the
battery power through the powertrain of chapter 7 (:meth:`Powertrain.motor_side`, eqs. 7.1-7.4, the
EC-45 and the DES 70/10).

No prediction draws more than the driver's current limit (the controller's ``current_limit_A``, else
the powertrain's). A side whose steady state needs more cannot hold its set point: the amplifier holds
the current at the limit and the side falls behind until the terrain asks no more torque than the
limit gives. The prediction is that motion, the drive's real one (:meth:`CommandPredictor.held_by_current`:
the over-limit sides' set points scaled down by bisection, :data:`CURRENT_BISECTIONS` solves, until
their current is the limit): ``omega`` is the wheels' speed there, below the set points, and the point
is ``limited`` with a reason. A side that needs more at any speed (Coulomb friction in the
drivetrain, eq. 7.1's c, or a spin on soft soil where the shear saturates) stalls: it stands, the
motor pushing with the limit current (:data:`REASON_STALL`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

import numpy as np

from skidsteer_power.drive.controller import DriveController, controller_for_vehicle
from skidsteer_power.drive.current import current_limited
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.models.setpoint import SetpointSolution, SetpointSolver
from skidsteer_power.powertrain.battery import Battery
from skidsteer_power.powertrain.power_flow import SIDES, Powertrain

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

REASON_CURRENT = 'current limit: a side needs more than the amplifier gives and falls behind its set point'
REASON_STALL = (
    'current limit, stalled: a side needs more than the amplifier gives at any speed; it stands with '
    'the current at the limit'
)
CURRENT_BISECTIONS = 12
"""Bisections of the over-limit sides' speed [-]: a held-back side's speed to 1/4096 of its set point."""

JSON_KEYS = (
    'speed_cmd_m_s',
    'yaw_rate_cmd_rad_s',
    'setpoint_left_rad_s',
    'setpoint_right_rad_s',
    'speed_m_s',
    'yaw_rate_rad_s',
    'turn_radius_m',
    'omega_left_rad_s',
    'omega_right_rad_s',
    'torque_left_Nm',
    'torque_right_Nm',
    'slip_left',
    'slip_right',
    'sinkage_m',
    'current_left_A',
    'current_right_A',
    'battery_power_W',
    'limited',
    'clamped',
    'reason',
)
"""The keys of ``skidsteer-power predict --json`` (DESIGN.md), in order."""
PredictRecord: TypeAlias = dict[str, float | bool | str | None]
"""One command's record (keys :data:`JSON_KEYS`): numbers, the two flags, the reason; ``predict`` makes
an undefined turn radius (at rest) None."""


@dataclass
class CommandPrediction:
    """Predictions for P commands; every array (P,) or (P, 2) (left, right), SI units.

    setpoint : side axle speed set points [rad/s]; omega : the axle speeds the wheels turn at [rad/s]
    (the set points, or below them where the current limit holds a side back); speed, yaw_rate,
    turn_radius : the motion produced [m/s, rad/s, m]; torque : axle torque [N m]; slip [-];
    sinkage [m]; current : motor current [A] (|.| <= the current limit); battery_power : both
    amplifiers' bus power [W];
    limited, clamped, reason : see the module doc; clamped: the drive controller changed the command
    (a velocity limit or the wheel speed ceiling, :class:`~skidsteer_power.drive.WheelSetpoints`).
    """

    speed_cmd: np.ndarray
    yaw_rate_cmd: np.ndarray
    setpoint: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    turn_radius: np.ndarray
    torque: np.ndarray
    slip: np.ndarray
    sinkage: np.ndarray
    current: np.ndarray
    battery_power: np.ndarray
    limited: np.ndarray
    clamped: np.ndarray
    reason: list[str]
    omega: np.ndarray | None = None  # None: the set points

    def record(self, k: int) -> PredictRecord:
        """Point ``k`` as the JSON record of ``skidsteer-power predict`` (keys :data:`JSON_KEYS`)."""
        left, right = 0, 1
        omega = self.setpoint if self.omega is None else self.omega
        values = (
            self.speed_cmd[k],
            self.yaw_rate_cmd[k],
            self.setpoint[k, left],
            self.setpoint[k, right],
            self.speed[k],
            self.yaw_rate[k],
            self.turn_radius[k],
            omega[k, left],
            omega[k, right],
            self.torque[k, left],
            self.torque[k, right],
            self.slip[k, left],
            self.slip[k, right],
            self.sinkage[k],
            self.current[k, left],
            self.current[k, right],
            self.battery_power[k],
        )
        out: PredictRecord = {key: float(v) for key, v in zip(JSON_KEYS, values, strict=False)}
        out.update(limited=bool(self.limited[k]), clamped=bool(self.clamped[k]), reason=self.reason[k])
        return out


def max_axle_speed(powertrain: Powertrain) -> float:
    """Largest axle speed [rad/s] a set point may ask for: the motor's no-load speed at the battery's
    full open-circuit voltage (Kn V_bus), at most its permissible speed, through the reduction."""
    motor = powertrain.motor
    # a battery that is not described is the test robot's (Battery.from_config); a battery described
    # wrongly is the user's ConfigError, never silently the motor's nominal voltage (issue 38)
    v_bus = float(Battery.from_config(powertrain.battery).config.ocv(1.0))
    return min(motor.speed_constant_rad_s_V * v_bus, motor.max_speed_rad_s) / powertrain.gear_ratio


class CommandPredictor:
    """Set-point predictions for one vehicle and terrain, prepared once."""

    def __init__(
        self,
        vehicle: Vehicle,
        terrain: Terrain,
        powertrain: Powertrain | None = None,
        controller: DriveController | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.powertrain = powertrain or Powertrain.for_vehicle(vehicle)
        self.controller = controller or controller_for_vehicle(vehicle, self.powertrain)
        self.solver = SetpointSolver(FessSolver(vehicle, terrain))
        self.max_axle_rad_s = max_axle_speed(self.powertrain)
        limit = self.controller.current_limit_A
        self.current_limit_A = self.powertrain.current_limit_A if limit is None else limit

    def setpoints(self, speed_cmd: ArrayLike, yaw_cmd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(set points (P, 2) [rad/s], clamped (P,)) of commands held steady, as the robot's drive
        controller makes them, at most the motors' no-load speed (:func:`max_axle_speed`)."""
        out = self.controller.apply(speed_cmd, yaw_cmd, ceiling_rad_s=self.max_axle_rad_s)
        return out.setpoint, out.clamped

    def predict(self, speed_cmd: ArrayLike, yaw_cmd: ArrayLike) -> CommandPrediction:
        """Predict P commands (V [m/s], w_z [rad/s], broadcast) in one batched solve."""
        v, w = np.broadcast_arrays(np.asarray(speed_cmd, dtype=float), np.asarray(yaw_cmd, dtype=float))
        sp, clamped = self.setpoints(v, w)
        sol = self.solver.solve(sp)
        torque, current, power, over = self.electrical(sol.torque, sp)
        omega = sp
        if np.any(over & ~sol.limited):  # the drive's real motion: the limited sides held back (module doc)
            sol, omega = self.held_by_current(sp, sol)
            torque, current, power, _ = self.electrical(sol.torque, omega)
        limited = sol.limited | over
        reason = [r or (REASON_CURRENT if o else '') for r, o in zip(sol.reason, over, strict=True)]
        return CommandPrediction(
            speed_cmd=v.ravel().copy(),
            yaw_rate_cmd=w.ravel().copy(),
            setpoint=sp,
            speed=sol.speed,
            yaw_rate=sol.yaw_rate,
            turn_radius=sol.turn_radius,
            torque=torque,
            slip=sol.slip,
            sinkage=sol.sinkage,
            current=current,
            battery_power=power,
            limited=limited,
            clamped=clamped,
            reason=reason,
            omega=omega,
        )

    def held_by_current(
        self, setpoint: np.ndarray, sol: SetpointSolution
    ) -> tuple[SetpointSolution, np.ndarray]:
        """The steady state where the current limit holds sides back: for each point with a steady
        state (not ``limited`` already) and a side over the limit, that side's (or both sides') set
        point times the largest factor in (0, 1] whose steady state needs no more than the limit
        (bisection, :data:`CURRENT_BISECTIONS` batched solves of those points). Returns (the solution
        at the wheels' speeds, those speeds (P, 2) [rad/s])."""
        high = self._over_sides(sol.torque, setpoint) & ~sol.limited[:, None]  # dug in: as it is
        idx = np.flatnonzero(high.any(axis=1))
        lo, hi = np.zeros(idx.size), np.ones(idx.size)
        scale_of = high[idx].astype(float)

        def at(factor: np.ndarray) -> np.ndarray:
            f = 1.0 - scale_of * (1.0 - factor[:, None])  # the over sides scaled, the others held
            return np.asarray(setpoint[idx] * f)

        for _ in range(CURRENT_BISECTIONS):
            mid = 0.5 * (lo + hi)
            trial = at(mid)
            over = self._over_sides(self.solver.solve(trial).torque, trial).any(axis=1)
            hi, lo = np.where(over, mid, hi), np.where(over, lo, mid)
        omega = setpoint.copy()
        omega[idx] = at(lo)
        held = self.solver.solve(omega[idx])
        for name in ('speed', 'yaw_rate', 's0', 'omega', 'torque', 'slip', 'sinkage', 'traction_margin',
                     'limited', 'iterations', 'dug_in', 'element_turn', 'contact_length'):  # fmt: skip
            getattr(sol, name)[idx] = getattr(held, name)
        for k, j in enumerate(idx):
            sol.reason[j] = held.reason[k]
        stalled = idx[lo == 0.0]  # no speed the limit can hold: the side stands, pushing at the limit
        pt = self.powertrain
        push = (
            np.sign(setpoint[stalled]) * pt.gear_ratio * pt.motor.torque_constant_Nm_A * self.current_limit_A
        )
        sol.torque[stalled] = np.where(high[stalled], push, sol.torque[stalled])
        for j in stalled:
            sol.reason[j] = REASON_STALL
        return sol, omega

    def _over_sides(self, torque: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """(P, 2) the side's steady current at axle torque [N m] and speed [rad/s] passes the limit."""
        pt = self.powertrain
        currents = [
            np.asarray(pt.motor_side(s, torque[:, k], omega[:, k]).current_A) for k, s in enumerate(SIDES)
        ]
        over: np.ndarray = np.abs(np.column_stack(currents)) > self.current_limit_A
        return over

    def electrical(
        self, torque: np.ndarray, omega: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Axle torque (P, 2) [N m] at axle speeds (P, 2) [rad/s] through the powertrain, with the
        current limit: (torque, current [A], battery power (P,) [W], over the limit (P,))."""
        torque = torque.copy()
        current = np.empty_like(torque)
        power = np.zeros(len(torque))
        over = np.zeros(len(torque), dtype=bool)
        for k, side in enumerate(SIDES):
            held, i, point, high = current_limited(
                self.powertrain, side, torque[:, k], omega[:, k], self.current_limit_A
            )
            torque[:, k], current[:, k] = held, i
            power += np.asarray(point.electrical_power_W, dtype=float)
            over |= high
        return torque, current, power, over
