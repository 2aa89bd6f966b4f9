"""Chapter 2 terramechanics: terrains, soil laws, single track, single wheel (pure numpy/scipy).

The names below load on first use (PEP 562), so importing a light submodule (e.g. ``ranges`` for a
command line's argument types) does not import scipy: ``skidsteer-power --help`` starts fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.soil import (
        pressure_sinkage,
        shear_strength,
        shear_stress,
        sinkage_for_pressure,
    )
    from skidsteer_power.terramechanics.terrain import PRESETS, Terrain, load_terrain
    from skidsteer_power.terramechanics.track import TrackState, single_track
    from skidsteer_power.terramechanics.wheel import (
        WheelState,
        sinkage_at_slip,
        solve_wheel,
        solve_wheel_bracketed,
        wheel_at_slip,
        wheel_forces,
    )

_WHERE = {
    'pressure_sinkage': 'soil',
    'shear_strength': 'soil',
    'shear_stress': 'soil',
    'sinkage_for_pressure': 'soil',
    'PRESETS': 'terrain',
    'Terrain': 'terrain',
    'load_terrain': 'terrain',
    'TrackState': 'track',
    'single_track': 'track',
    'WheelState': 'wheel',
    'sinkage_at_slip': 'wheel',
    'solve_wheel': 'wheel',
    'solve_wheel_bracketed': 'wheel',
    'wheel_at_slip': 'wheel',
    'wheel_forces': 'wheel',
}

__all__ = [
    'PRESETS',
    'Terrain',
    'TrackState',
    'WheelState',
    'load_terrain',
    'pressure_sinkage',
    'shear_strength',
    'shear_stress',
    'single_track',
    'sinkage_at_slip',
    'sinkage_for_pressure',
    'solve_wheel',
    'solve_wheel_bracketed',
    'wheel_at_slip',
    'wheel_forces',
]


def __getattr__(name: str) -> object:  # the names' own types: the imports above (mypy)
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'{__name__}.{module}'), name)
    globals()[name] = value
    return value
