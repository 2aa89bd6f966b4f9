"""FESS results as the models' common :class:`~skidsteer_power.models.base.SteadyState`: left / right
sides of a :class:`~skidsteer_power.models.fess.TwistSolution` turned into outer / inner (split out of
``fess.py``, which holds the residual and the solver)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.models.base import SteadyState

if TYPE_CHECKING:
    from skidsteer_power.models.fess import TwistSolution

LEFT, RIGHT = 0, 1  # side indices of a TwistSolution's (n, 2) arrays (fess.py imports them)


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
