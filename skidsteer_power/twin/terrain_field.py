"""The twin's own ("truth") terrain: a base terrain plus optional polygon patches of other terrains.

Patch file (YAML), coordinates in the world (odom) frame [m], later patches win where they overlap::

    patches:
      - terrain: dry_sand                       # a preset name or a terrain YAML file
        polygon: [[1.0, -1.0], [3.0, -1.0], [3.0, 1.0], [1.0, 1.0]]
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from matplotlib.path import Path as PolygonPath

from skidsteer_power.errors import ConfigError
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain


@dataclass(frozen=True)
class Patch:
    """A region of the floor (polygon vertices [m], world frame) with another terrain."""

    terrain: Terrain
    polygon: np.ndarray  # (k, 2) [m]

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where the points (x, y) [m] lie inside the polygon."""
        points = np.column_stack([np.ravel(x), np.ravel(y)])
        return PolygonPath(self.polygon).contains_points(points).reshape(np.shape(x))


class TerrainField:
    """Terrain index at any world point: 0 = ``base``, i = ``patches[i - 1]``."""

    def __init__(self, base: Terrain, patches: Sequence[Patch] = ()) -> None:
        self.base = base
        self.patches = tuple(patches)
        self.terrains: tuple[Terrain, ...] = (base, *(p.terrain for p in self.patches))

    @property
    def uniform(self) -> bool:
        return not self.patches

    def index_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Terrain index [-] at world points (x, y) [m] (same shape as x)."""
        index = np.zeros(np.shape(x), dtype=int)
        for i, patch in enumerate(self.patches, start=1):
            index[patch.contains(x, y)] = i
        return index


def load_patches(path: str | os.PathLike[str]) -> list[Patch]:
    """Read a patch file (see the module doc); ConfigError naming the file and the entry."""
    file = Path(path)
    try:
        data = yaml.safe_load(file.read_text(encoding='utf-8'))
    except FileNotFoundError:
        raise ConfigError(f'patch file not found: {file}') from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ConfigError(f'cannot read patch file {file}: {err}'.replace('\n', ' ')) from err
    entries = data.get('patches') if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise ConfigError(f'{file}: expected a mapping with a list "patches"')
    patches = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict) or 'terrain' not in entry or 'polygon' not in entry:
            raise ConfigError(f'{file}: patch {i} needs "terrain" and "polygon"')
        try:
            polygon = np.asarray(entry['polygon'], dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(f'{file}: patch {i}: polygon must be a list of [x, y] pairs') from None
        if (
            polygon.ndim != 2
            or polygon.shape[1] != 2
            or polygon.shape[0] < 3
            or not np.all(np.isfinite(polygon))
        ):
            raise ConfigError(f'{file}: patch {i}: polygon needs >= 3 finite [x, y] vertices')
        terrain = str(entry['terrain'])
        if not os.path.isabs(terrain) and (file.parent / terrain).is_file():
            terrain = str(file.parent / terrain)
        patches.append(Patch(load_terrain(terrain), polygon))
    return patches
