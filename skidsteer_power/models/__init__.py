"""Skid-steering models behind one interface.

``solve(vehicle, terrain, speed, turn_radius, model='fess', **options) -> SteadyState``

Each model module exposes ``solve(vehicle, terrain, speed, turn_radius, **options)`` taking
broadcastable arrays of forward speed V [m/s] and signed turning radius R [m] (inf = straight) and
returning :class:`~skidsteer_power.models.base.SteadyState`. Modules are imported lazily so a model
that needs heavy set-up costs nothing until it is used.
"""

from __future__ import annotations

import importlib
import inspect
from typing import TYPE_CHECKING

from skidsteer_power.errors import InputError
from skidsteer_power.models.base import SteadyState

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy.typing as npt

    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

MODELS: dict[str, str] = {
    'steeds': 'skidsteer_power.models.steeds',  # chapter 3.2, closed form
    'icr': 'skidsteer_power.models.icr',  # chapter 3.4
    'wong': 'skidsteer_power.models.wong',  # chapter 3.3 (tracks) and chapter 4 (wheels)
    'fast': 'skidsteer_power.models.fast',  # chapter 5
    'fess': 'skidsteer_power.models.fess',  # chapter 6
}

RIGID_GROUND_MODELS = ('fess',)
"""The models that solve rigid ground (``contact: rigid`` terrains, :mod:`~skidsteer_power.models.
rigid_contact`); the others are written for a deformable soil (Bekker sinkage, compaction)."""

__all__ = ['MODELS', 'RIGID_GROUND_MODELS', 'SteadyState', 'solve']


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: npt.ArrayLike,
    turn_radius: npt.ArrayLike,
    model: str = 'fess',
    **options: object,
) -> SteadyState:
    """Solve the steady state of ``vehicle`` on ``terrain`` with the named ``model``."""
    try:
        module_name = MODELS[model]
    except KeyError:
        raise InputError(f'unknown model {model!r}; choose one of {", ".join(MODELS)}') from None
    if terrain.is_rigid and model not in RIGID_GROUND_MODELS:
        raise InputError(
            f'model {model!r} describes a deformable soil; terrain {terrain.name!r} is rigid ground '
            f'(contact: rigid): use model {" or ".join(RIGID_GROUND_MODELS)}'
        )
    solve_model: Callable[..., SteadyState] = importlib.import_module(module_name).solve
    if model == 'wong':  # wong.solve forwards its options to the track or the wheel solver
        solve_model = importlib.import_module(module_name).solver_for(vehicle)
    try:  # an unknown option is the caller's error, named here, never silently ignored
        inspect.signature(solve_model).bind(vehicle, terrain, speed, turn_radius, **options)
    except TypeError as err:
        raise InputError(f'model {model!r}: {err}') from None
    return solve_model(vehicle, terrain, speed, turn_radius, **options)
