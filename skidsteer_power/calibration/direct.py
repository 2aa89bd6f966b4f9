"""A stand-in for a power map that answers every query with a direct FESS solve (no map to build).

For checks of a calibrated terrain or of the online adaptation on a few commands, where building a
16 x 101 map first would cost more than the solves: ``MapPredictor(DirectFessMap(vehicle, terrain),
powertrain)`` is an estimator predictor. Each query is one point (a few ms, wheels ~100 ms); the
predictor's cache answers repeated commands.
"""

from __future__ import annotations

import types
from typing import Any

from skidsteer_power.models.fess import FessSolver


class DirectFessMap:
    """``query(V [m/s], yaw rate [rad/s])`` with the fields MapPredictor reads, from FESS (ch. 6)."""

    def __init__(self, vehicle: Any, terrain: Any) -> None:
        self.solver = FessSolver(vehicle, terrain)

    def query(self, speed_m_s: float, yaw_rate_rad_s: float) -> Any:
        sol = self.solver.solve_twist(speed_m_s, yaw_rate_rad_s)
        return types.SimpleNamespace(
            omega_left_rad_s=sol.omega[0, 0],
            omega_right_rad_s=sol.omega[0, 1],
            torque_left_Nm=sol.torque[0, 0],
            torque_right_Nm=sol.torque[0, 1],
            traction_margin=sol.traction_margin[0],
            clamped=not bool(sol.converged[0]),
        )
