"""FESS's result types (:class:`TwistSolution` of a batch, :class:`PointSolution` of one point) and
the batch as the models' common :class:`~skidsteer_power.models.base.SteadyState`: left / right sides
turned into outer / inner (split out of ``fess.py``, which holds the residual and the solver; this
module imports neither FESS kernel, so both can import it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skidsteer_power.models.base import SteadyState

LEFT, RIGHT = 0, 1  # side indices of a TwistSolution's (n, 2) arrays


@dataclass
class TwistSolution:
    """FESS steady state over a batch of (V, yaw rate) points, per side (left, right), SI units."""

    speed: np.ndarray  # V [m/s]
    yaw_rate: np.ndarray  # w_z [rad/s]
    s0: np.ndarray  # turning-centre offset along x, ahead of the CG [m] (negative in reverse)
    omega: np.ndarray  # (P, 2) [rad/s]
    torque: np.ndarray  # (P, 2) drive torque [N m]
    thrust: np.ndarray  # (P, 2) longitudinal shear force [N]
    lateral: np.ndarray  # (P, 2) lateral shear force [N]
    slip: np.ndarray  # (P, 2) [-] eq. 2.13
    sinkage: np.ndarray  # (P,) largest sinkage [m]
    traction_margin: np.ndarray  # (P,) [-]
    converged: np.ndarray  # (P,)
    residual: np.ndarray  # (P, 3)
    iterations: np.ndarray  # (P,) Newton steps per point

    @property
    def power(self) -> np.ndarray:
        """(P, 2) mechanical power torque * omega [W]."""
        power: np.ndarray = self.torque * self.omega
        return power

    @property
    def state(self) -> np.ndarray:
        """(P, 3) solver state (s0, omega_left, omega_right), forward-driving frame, for warm starts."""
        return np.column_stack([self.s0, self.omega])


@dataclass
class PointSolution:
    """One FESS steady state (left, right sides), SI units; see :meth:`FessSolver.solve_point`."""

    s0: float  # [m]
    omega: np.ndarray  # (2,) [rad/s]
    torque: np.ndarray  # (2,) [N m]
    converged: bool
    iterations: int

    @property
    def power(self) -> np.ndarray:
        """(2,) torque * omega [W]."""
        power: np.ndarray = self.torque * self.omega
        return power

    @property
    def state(self) -> np.ndarray:
        """(s0, omega_left, omega_right), to warm-start the next call."""
        return np.array([self.s0, *self.omega])


def to_steady_state(sol: TwistSolution, turn_radius: np.ndarray, solve_time: float) -> SteadyState:
    """Convert left/right results to the outer/inner :class:`SteadyState` (R >= 0: outer = right)."""
    outer_left = turn_radius < 0
    o = np.where(outer_left, LEFT, RIGHT)
    i = 1 - o
    rows = np.arange(len(o))

    def pick(a: np.ndarray, side: np.ndarray) -> np.ndarray:
        picked: np.ndarray = a[rows, side]
        return picked

    power = sol.power
    return SteadyState(
        speed_m_s=sol.speed,
        turn_radius_m=turn_radius,
        s0_m=sol.s0,
        omega_outer_rad_s=pick(sol.omega, o),
        omega_inner_rad_s=pick(sol.omega, i),
        torque_outer_Nm=pick(sol.torque, o),
        torque_inner_Nm=pick(sol.torque, i),
        power_outer_W=pick(power, o),
        power_inner_W=pick(power, i),
        slip_outer=pick(sol.slip, o),
        slip_inner=pick(sol.slip, i),
        thrust_outer_N=pick(sol.thrust, o),
        thrust_inner_N=pick(sol.thrust, i),
        sinkage_m=sol.sinkage,
        traction_margin=sol.traction_margin,
        converged=sol.converged,
        model='fess',
        extra={
            'lateral_outer_N': pick(sol.lateral, o),
            'lateral_inner_N': pick(sol.lateral, i),
            'solve_time_s': np.full(len(o), solve_time),
            'iterations': np.asarray(sol.iterations, dtype=float),
        },
    )


def reshape_state(state: SteadyState, shape: tuple[int, ...]) -> SteadyState:
    """``state`` with every 1-D array (and ``extra``) reshaped to ``shape`` (a batch back to the
    caller's broadcast shape)."""
    for name, value in list(vars(state).items()):
        if isinstance(value, np.ndarray) and value.ndim == 1:
            setattr(state, name, value.reshape(shape))
    state.extra = {k: v.reshape(shape) for k, v in state.extra.items()}
    return state
