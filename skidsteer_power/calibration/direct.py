"""Checking the estimator directly against the twin: a map stand-in answering each query with a FESS
solve (no map to build), and feeding a twin trace to an estimator core.

For checks of a calibrated terrain or of the online adaptation on a few commands, where building a
16 x 101 map first would cost more than the solves: ``MapPredictor(DirectFessMap(vehicle, terrain),
powertrain)`` is an estimator predictor. Each query is one point (a few ms, wheels ~100 ms); the
predictor's cache answers repeated commands.
"""

from __future__ import annotations

import math
import types
from typing import TYPE_CHECKING, Any, Protocol

from skidsteer_power.models.fess import FessSolver

if TYPE_CHECKING:
    import numpy as np

    from skidsteer_power.estimator.core import EstimatorCore
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle


class DirectFessMap:
    """``query(V [m/s], yaw rate [rad/s])`` with the fields MapPredictor reads, from FESS (ch. 6)."""

    def __init__(self, vehicle: Vehicle, terrain: Terrain) -> None:
        self.solver = FessSolver(vehicle, terrain)

    def query(self, speed_m_s: float, yaw_rate_rad_s: float) -> Any:  # Any: stands in for a MapQuery
        """A namespace with the :class:`~skidsteer_power.maps.power_map.MapQuery` fields MapPredictor
        reads (not a MapQuery: no power, sinkage or offset), so the class fits
        :class:`~skidsteer_power.seams.PowerMapLike`."""
        sol = self.solver.solve_twist(speed_m_s, yaw_rate_rad_s)
        return types.SimpleNamespace(
            omega_left_rad_s=sol.omega[0, 0],
            omega_right_rad_s=sol.omega[0, 1],
            torque_left_Nm=sol.torque[0, 0],
            torque_right_Nm=sol.torque[0, 1],
            traction_margin=sol.traction_margin[0],
            clamped=False,  # a direct solve covers any command: no map envelope
            limited=not bool(sol.converged[0]),  # no steady state: a physics limit (maps.MapQuery)
        )


class TraceLike(Protocol):
    """What :func:`feed_trace` reads of a twin trace (:class:`skidsteer_power.twin.TwinTrace`): per
    sample the time [s], the command (V [m/s], yaw rate [rad/s]) and the joints' speed [rad/s] and
    effort [N m]."""

    @property
    def t(self) -> np.ndarray: ...

    @property
    def cmd(self) -> np.ndarray: ...

    @property
    def joint_velocity_rad_s(self) -> np.ndarray: ...

    @property
    def joint_effort_Nm(self) -> np.ndarray: ...


def feed_trace(
    core: EstimatorCore, trace: TraceLike, *, tick_period_s: float = 0.2, after_s: float = -math.inf
) -> list[float]:
    """Feed a twin trace (``skidsteer_power.twin.TwinTrace``) to an ``EstimatorCore`` as the node
    would: per sample the command, then joint_states; ``tick`` whenever a multiple of
    ``tick_period_s`` [s] is passed (the node's publish timer, default 0.2 s).

    Samples at or before ``after_s`` [s] are skipped: a trace of a run continued with another
    ``run_commands`` call starts with a sample at the previous trace's last time, whose current
    average is still empty; pass that time. Returns the times [s] at which a terrain change was
    flagged.
    """
    names = ('left_motor', 'right_motor')
    flags = []
    previous = after_s
    for i in range(trace.t.size):
        now = float(trace.t[i])
        if now <= after_s:
            continue
        core.on_command(float(trace.cmd[i, 0]), float(trace.cmd[i, 1]), now)
        before = core.adaptation.terrain_changes
        core.on_joint_state(names, trace.joint_velocity_rad_s[i], trace.joint_effort_Nm[i], now)
        if core.adaptation.terrain_changes > before:
            flags.append(now)
        if not math.isfinite(previous) or math.floor(now / tick_period_s) > math.floor(
            previous / tick_period_s
        ):
            core.tick(now)
        previous = now
    return flags
