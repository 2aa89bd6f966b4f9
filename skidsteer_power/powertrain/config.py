"""Finding and reading powertrain and battery presets (``config/powertrains``, ``config/batteries``)."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from skidsteer_power.errors import ConfigError


def config_dirs(kind: str) -> list[Path]:
    """Folders searched for ``kind`` presets ('powertrains' | 'batteries'): source tree, then share/."""
    package_root = Path(__file__).resolve().parents[2]
    return [
        package_root / 'config' / kind,
        Path(sys.prefix) / 'share' / 'skidsteer_power' / 'config' / kind,
    ]


def load_preset(kind: str, name_or_path: str) -> dict[str, Any]:
    """Read a preset by name (a file in ``config/<kind>/``) or by YAML path; ConfigError if absent/bad."""
    candidate = Path(name_or_path)
    path = candidate if candidate.is_file() else None
    if path is None:
        for folder in config_dirs(kind):
            found = folder / f'{name_or_path}.yaml'
            if found.is_file():
                path = found
                break
    if path is None:
        raise ConfigError(f'{kind[:-1] if kind.endswith("s") else kind} preset {name_or_path!r} not found')
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'{path}: cannot read ({str(err).splitlines()[0]})') from err
    if not isinstance(data, Mapping):
        raise ConfigError(f'{path}: expected a mapping of settings')
    return dict(data)


def merged(kind: str, config: Mapping[str, Any] | None) -> dict[str, Any]:
    """``config`` with its ``preset`` (if any) expanded underneath: explicit keys override the preset."""
    config = dict(config or {})
    preset = config.pop('preset', None)
    if preset is None:
        return config
    base = load_preset(kind, str(preset))
    base.update(config)
    return base
