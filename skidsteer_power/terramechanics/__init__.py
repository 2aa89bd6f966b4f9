"""Chapter 2 terramechanics: terrains, soil laws, single track, single wheel (pure numpy/scipy)."""

from __future__ import annotations

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
