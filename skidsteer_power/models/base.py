"""The one result type every skid-steering model returns (DESIGN.md, "one solver interface").

Sign conventions (ROS REP 103): x forward, y left, z up. A positive turning radius R is a left
(counter-clockwise) turn, yaw rate = V / R > 0, so the *outer* side is the right side; R < 0 is the
mirror image (outer = left). R = +inf is straight running (outer = right by convention, both sides
equal). Every field is a numpy array broadcast over the operating points.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np


@dataclass
class SteadyState:
    """Steady-state skid-steering solution over a batch of operating points (SI units).

    Attributes
    ----------
    speed_m_s : forward speed V of the vehicle centre [m/s]
    turn_radius_m : signed turning radius R [m] (+ left, - right, inf straight)
    s0_m : longitudinal offset of the turning centre ahead of the CG [m]
    omega_outer_rad_s, omega_inner_rad_s : sprocket / axle angular speed of each side [rad/s]
    torque_outer_Nm, torque_inner_Nm : total sprocket / axle torque of each side [N m]
        (a wheeled side's torque is the sum over its wheels)
    power_outer_W, power_inner_W : mechanical power torque * omega of each side [W]
        (negative = the side is braking / regenerating)
    slip_outer, slip_inner : longitudinal slip of each side [-] (1 - V_side / (r omega))
    thrust_outer_N, thrust_inner_N : longitudinal thrust of each side [N]
    sinkage_m : largest sinkage of any running gear element [m]
    traction_margin : 1 - required thrust / available thrust (largest side); <= 0 means the
        terrain cannot give what the manoeuvre needs (the robot is about to get stuck) [-]
    converged : bool per operating point
    """

    speed_m_s: np.ndarray
    turn_radius_m: np.ndarray
    s0_m: np.ndarray
    omega_outer_rad_s: np.ndarray
    omega_inner_rad_s: np.ndarray
    torque_outer_Nm: np.ndarray
    torque_inner_Nm: np.ndarray
    power_outer_W: np.ndarray
    power_inner_W: np.ndarray
    slip_outer: np.ndarray
    slip_inner: np.ndarray
    thrust_outer_N: np.ndarray
    thrust_inner_N: np.ndarray
    sinkage_m: np.ndarray
    traction_margin: np.ndarray
    converged: np.ndarray
    model: str = ''
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def unsolved(cls, speed: np.ndarray, turn_radius: np.ndarray, model: str) -> SteadyState:
        """Every point not converged (NaN results): a batch the model could not even set up."""
        shape = np.shape(speed)

        def nan() -> np.ndarray:
            return np.full(shape, np.nan)

        return cls(
            speed_m_s=np.asarray(speed, dtype=float),
            turn_radius_m=np.asarray(turn_radius, dtype=float),
            s0_m=nan(),
            omega_outer_rad_s=nan(),
            omega_inner_rad_s=nan(),
            torque_outer_Nm=nan(),
            torque_inner_Nm=nan(),
            power_outer_W=nan(),
            power_inner_W=nan(),
            slip_outer=nan(),
            slip_inner=nan(),
            thrust_outer_N=nan(),
            thrust_inner_N=nan(),
            sinkage_m=nan(),
            traction_margin=nan(),
            converged=np.zeros(shape, dtype=bool),
            model=model,
        )

    @property
    def yaw_rate_rad_s(self) -> np.ndarray:
        """Yaw rate V / R [rad/s] (0 for straight running)."""
        yaw_rate: np.ndarray = np.asarray(self.speed_m_s) / np.asarray(self.turn_radius_m)
        return yaw_rate

    @property
    def outer_is_left(self) -> np.ndarray:
        """True where the outer side is the left side (right turns, R < 0)."""
        return np.asarray(self.turn_radius_m) < 0

    def side(self, quantity: str, side: str) -> np.ndarray:
        """Return ``quantity`` ('omega', 'torque', 'power', 'slip', 'thrust') for 'left' or 'right'."""
        suffix = {'omega': '_rad_s', 'torque': '_Nm', 'power': '_W', 'slip': '', 'thrust': '_N'}[quantity]
        outer = np.asarray(getattr(self, f'{quantity}_outer{suffix}'))
        inner = np.asarray(getattr(self, f'{quantity}_inner{suffix}'))
        left_is_outer = self.outer_is_left
        if side == 'left':
            return np.where(left_is_outer, outer, inner)
        if side == 'right':
            return np.where(left_is_outer, inner, outer)
        raise ValueError(f"side must be 'left' or 'right', not {side!r}")

    @property
    def total_power_W(self) -> np.ndarray:
        total: np.ndarray = np.asarray(self.power_outer_W) + np.asarray(self.power_inner_W)
        return total

    def as_dict(self) -> dict[str, np.ndarray]:
        """All array fields (and ``extra``) by name, for JSON output or npz storage."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ('model', 'extra')}
        out.update(self.extra)
        return out
