"""What a stored map was built for, and the one check every map file passes before it is used.

A map file (the (V, w_z) power map, the set-point map) stores its identity: the vehicle and terrain
by name and fingerprint, and the model with a digest of the whole physics code. A file whose
identity is not the one asked for is a :class:`~skidsteer_power.errors.MapMismatchError`: the cache
rebuilds it, a user's ``--map FILE`` is refused; never used.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.cache import physics_digest
from skidsteer_power.errors import MapMismatchError
from skidsteer_power.terramechanics.terrain import terrain_fingerprint
from skidsteer_power.vehicle import vehicle_fingerprint

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle


def model_version(model: str = 'fess') -> str:
    """The model and a digest of the whole physics code (:func:`skidsteer_power.cache.physics_digest`);
    a stored map must match it, so a map built by older code is rebuilt, never used."""
    return f'{model}-{physics_digest()}'


def map_identity(vehicle: Vehicle, terrain: Terrain, model: str = 'fess') -> dict[str, str]:
    """The identity a map built now for ``vehicle`` on ``terrain`` with ``model`` stores."""
    return {
        'vehicle': vehicle.name,
        'vehicle_fingerprint': vehicle_fingerprint(vehicle),
        'terrain': terrain.name,
        'terrain_fingerprint': terrain_fingerprint(terrain),
        'model': model,
        'model_version': model_version(model),
    }


def check_identity(
    source: Path, meta: Mapping[str, object], vehicle: Vehicle | None, terrain: Terrain | None
) -> None:
    """MapMismatchError unless the map at ``source`` (its stored ``meta``) was built by this physics
    code and, where given, for ``vehicle`` and ``terrain``."""
    current = model_version(str(meta.get('model', 'fess')))
    if meta.get('model_version') != current:
        raise MapMismatchError(
            f'{source}: built by model version {meta.get("model_version")!r}, this package is {current!r}'
        )
    if vehicle is not None and meta.get('vehicle_fingerprint') != vehicle_fingerprint(vehicle):
        raise MapMismatchError(
            f'{source}: built for vehicle {meta.get("vehicle")!r} '
            f'({meta.get("vehicle_fingerprint")}), not {vehicle.name!r} ({vehicle_fingerprint(vehicle)})'
        )
    if terrain is not None and meta.get('terrain_fingerprint') != terrain_fingerprint(terrain):
        raise MapMismatchError(
            f'{source}: built for terrain {meta.get("terrain")!r}, not {terrain.name!r} (parameters differ)'
        )
