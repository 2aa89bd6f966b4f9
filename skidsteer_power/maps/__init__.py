"""Look-up maps over (forward speed, signed yaw rate) built by FESS; .npz storage; interpolation.

See :mod:`skidsteer_power.maps.power_map` for the grid, symmetry and small-radius conventions.
"""

from __future__ import annotations

from skidsteer_power.cache import default_cache_dir
from skidsteer_power.errors import MapMismatchError
from skidsteer_power.maps.power_map import (
    FIELDS,
    QUERY_FIELDS,
    MapQuery,
    PowerMap,
    build_options,
    cache_path,
    load_or_build,
)
from skidsteer_power.terramechanics.terrain import terrain_fingerprint

__all__ = [
    'FIELDS',
    'QUERY_FIELDS',
    'MapMismatchError',
    'MapQuery',
    'PowerMap',
    'build_options',
    'cache_path',
    'default_cache_dir',
    'load_or_build',
    'terrain_fingerprint',
]
