"""Finding and reading powertrain and battery presets (``config/powertrains``, ``config/batteries``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, SupportsFloat, SupportsIndex

import yaml

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject


def load_preset(kind: str, name_or_path: str) -> JsonObject:
    """Read a preset by name (a file in ``config/<kind>/``, found by :mod:`skidsteer_power.resources`)
    or by YAML path; ConfigError if absent (listing the shipped presets) or bad."""
    path = resources.find(kind, name_or_path)
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'{path}: cannot read ({str(err).splitlines()[0]})') from err
    if not isinstance(data, Mapping):
        raise ConfigError(f'{path}: expected a mapping of settings')
    return dict(data)


def merged(kind: str, config: Mapping[str, object] | None) -> JsonObject:
    """``config`` with its ``preset`` (if any) expanded underneath: explicit keys override the preset."""
    config = dict(config or {})
    preset = config.pop('preset', None)
    if preset is None:
        return config
    base = load_preset(kind, str(preset))
    base.update(config)
    return base


def to_float(value: object) -> float:
    """``float(value)`` of a config value: TypeError unless it is a number, a string or bytes (what
    ``float`` takes), ValueError for text that is no number."""
    if not isinstance(value, SupportsFloat | SupportsIndex | str | bytes | bytearray):
        raise TypeError(f'float() argument must be a string or a real number, not {type(value).__name__!r}')
    return float(value)
