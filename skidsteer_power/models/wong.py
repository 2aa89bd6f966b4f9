"""Wong's skid-steering theory: tracks (chapter 3, ``wong_track``) or wheels (chapter 4, ``wong_wheel``).

``solve`` dispatches on ``vehicle.running_gear``; options (``resolution``, ``tol``, ``max_iter``,
``raise_on_failure``) pass through. See the two modules for the equations.
"""

from __future__ import annotations

from collections.abc import Callable

from numpy.typing import ArrayLike

from skidsteer_power.models import wong_track, wong_wheel
from skidsteer_power.models.base import SteadyState
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import Vehicle


def solve(
    vehicle: Vehicle, terrain: Terrain, speed: ArrayLike, turn_radius: ArrayLike, **options: object
) -> SteadyState:
    """Steady state by Wong's theory for speed V [m/s] and signed turning radius R [m] (inf straight)."""
    return solver_for(vehicle)(vehicle, terrain, speed, turn_radius, **options)


def solver_for(vehicle: Vehicle) -> Callable[..., SteadyState]:
    """Wong's track solver (chapter 3.3) for a tracked vehicle, the wheel solver (chapter 4) else."""
    return wong_track.solve if vehicle.is_tracked else wong_wheel.solve
