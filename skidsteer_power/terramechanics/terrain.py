"""Terrain parameters (Bekker, Mohr-Coulomb, Janosi-Hanamoto, Wong-Reece) and their presets.

Inside the package every value is SI: N/m^(n+1), N/m^(n+2), Pa, rad, m. The dissertation's tables mix
kN and degrees; the conversion happens once, in :func:`terrain_from_mapping`, which both the presets
and YAML files go through.

YAML terrain file (see ``config/terrains/example_terrain.yaml``)::

    name: my_sand
    n: 1.1                 # sinkage exponent [-]
    kc: 900                # N/m^(n+1)     (or kc_kN in kN/m^(n+1))
    kphi: 1523400          # N/m^(n+2)     (or kphi_kN in kN/m^(n+2))
    c: 1000                # Pa            (or c_kPa in kPa)
    phi_deg: 30            # degrees
    K: 0.025               # m
    shear_type: A          # optional: A | B | C; B and C need Kw [m], C also Kr [-]
    a0: 0.24               # optional wheel coefficients (default Table 2.4)
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError
from skidsteer_power.numeric import Real

# Table 2.4 (Wong and Reece, dry sand): the only wheel coefficients the dissertation gives. Chapter 2
# uses them for all three soils, and so do the presets here.
TABLE_2_4 = {'a0': 0.24, 'a1': 0.32, 'b0': -0.45, 'b1': 0.0}


@dataclass(frozen=True)
class Terrain:
    """One soil, SI units. Validated on construction (:class:`ConfigError` naming the field).

    n : sinkage exponent [-] (eq. 2.1); kc : cohesive modulus [N/m^(n+1)]; kphi : frictional modulus
    [N/m^(n+2)]; c : cohesion [Pa] and phi : internal friction angle [rad] (eq. 2.2); K : shear
    deformation modulus [m] (eq. 2.3); shear_type 'A' | 'B' | 'C' (eqs. 2.3-2.5) with Kr [-] (type C)
    and Kw [m] (types B, C); a0, a1, b0, b1 : Wong-Reece wheel coefficients [-] (eqs. 2.20, 2.22).
    """

    name: str
    n: float
    kc: float
    kphi: float
    c: float
    phi: float
    K: float
    shear_type: str = 'A'
    Kr: float | None = None
    Kw: float | None = None
    a0: float = TABLE_2_4['a0']
    a1: float = TABLE_2_4['a1']
    b0: float = TABLE_2_4['b0']
    b1: float = TABLE_2_4['b1']

    def __post_init__(self) -> None:
        _validate(self)

    @property
    def phi_deg(self) -> float:
        """Internal friction angle [deg]."""
        return math.degrees(self.phi)

    def k_eq(self, b: Real) -> Real:
        """Equivalent pressure-sinkage modulus kc/b + kphi [N/m^(n+2)] for contact width b [m]
        (eq. 2.1); a float or an array (:mod:`skidsteer_power.numeric`)."""
        return self.kc / b + self.kphi


def _bad(name: str, field: str, why: str) -> ConfigError:
    return ConfigError(f'terrain {name!r}: field {field!r} {why}')


def _validate(t: Terrain) -> None:
    numbers = ('n', 'kc', 'kphi', 'c', 'phi', 'K', 'a0', 'a1', 'b0', 'b1')
    for field in numbers:
        value = getattr(t, field)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise _bad(t.name, field, f'must be a finite number, got {value!r}')
    if t.n <= 0:
        raise _bad(t.name, 'n', f'must be > 0, got {t.n}')
    if t.K <= 0:
        raise _bad(t.name, 'K', f'must be > 0 m, got {t.K}')
    for field in ('kc', 'kphi', 'c'):
        if getattr(t, field) < 0:
            raise _bad(t.name, field, f'must be >= 0, got {getattr(t, field)}')
    if t.kc == 0 and t.kphi == 0:
        raise _bad(t.name, 'kphi', 'and kc cannot both be 0 (no bearing capacity)')
    if not 0 < t.phi < math.pi / 2:
        raise _bad(t.name, 'phi', f'must lie in (0, 90) degrees, got {math.degrees(t.phi):.6g} degrees')
    _validate_shear_type(t)
    _validate_wheel_angles(t)


def _validate_shear_type(t: Terrain) -> None:
    if t.shear_type not in ('A', 'B', 'C'):
        raise _bad(t.name, 'shear_type', f"must be 'A', 'B' or 'C', got {t.shear_type!r}")
    if t.shear_type in ('B', 'C') and (t.Kw is None or not math.isfinite(t.Kw) or t.Kw <= 0):
        raise _bad(t.name, 'Kw', f'must be > 0 m for shear type {t.shear_type}, got {t.Kw!r}')
    if t.shear_type == 'C' and (t.Kr is None or not math.isfinite(t.Kr) or not 0 < t.Kr <= 1):
        raise _bad(t.name, 'Kr', f'must lie in (0, 1] for shear type C, got {t.Kr!r}')


def _validate_wheel_angles(t: Terrain) -> None:
    # eqs. 2.20/2.22: theta_r < theta_m <= theta_f must hold for every slip in [-1, 1]; the
    # coefficients are linear in s, so checking both ends suffices.
    for s in (-1.0, 1.0):
        m = t.a0 + t.a1 * s
        r = t.b0 + t.b1 * s
        if not m <= 1.0:
            raise _bad(t.name, 'a0/a1', f'give theta_m > theta_f at slip {s:+g} (a0 + a1 s = {m:.4g})')
        if not r < m:
            raise _bad(t.name, 'b0/b1', f'give theta_r >= theta_m at slip {s:+g} ({r:.4g} >= {m:.4g})')


# key in a mapping -> (Terrain field, factor to SI)
_UNIT_KEYS: dict[str, tuple[str, float]] = {
    'n': ('n', 1.0),
    'kc': ('kc', 1.0),
    'kc_kN': ('kc', 1e3),
    'kphi': ('kphi', 1.0),
    'kphi_kN': ('kphi', 1e3),
    'c': ('c', 1.0),
    'c_kPa': ('c', 1e3),
    'phi_deg': ('phi', math.pi / 180.0),
    'K': ('K', 1.0),
    'Kr': ('Kr', 1.0),
    'Kw': ('Kw', 1.0),
    'a0': ('a0', 1.0),
    'a1': ('a1', 1.0),
    'b0': ('b0', 1.0),
    'b1': ('b1', 1.0),
}
_REQUIRED = ('n', 'kc', 'kphi', 'c', 'phi', 'K')
_TEXT_KEYS = ('name', 'shear_type', 'source', 'description')
# provenance and uncertainty written by `skidsteer-power calibrate` (skidsteer_power/calibration/io.py)
_SKIPPED_KEYS = ('calibration',)


def terrain_from_mapping(data: Mapping[str, Any], default_name: str = 'terrain') -> Terrain:
    """Build a :class:`Terrain` from table units (see module doc); ConfigError names a bad field."""
    if not isinstance(data, Mapping):
        raise ConfigError(
            f'terrain {default_name!r}: expected a mapping of fields, got {type(data).__name__}'
        )
    name = str(data.get('name', default_name))
    fields: dict[str, Any] = {}
    for key, value in data.items():
        if key in _TEXT_KEYS or key in _SKIPPED_KEYS:
            continue
        if key not in _UNIT_KEYS:
            hint = " (give phi in degrees as 'phi_deg')" if key == 'phi' else ''
            raise _bad(name, str(key), f'is not a terrain field{hint}')
        field, factor = _UNIT_KEYS[key]
        if field in fields:
            raise _bad(name, field, 'is given twice (in two units)')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _bad(name, str(key), f'must be a number, got {value!r}')
        fields[field] = float(value) * factor
    for field in _REQUIRED:
        if field not in fields:
            raise _bad(name, field if field != 'phi' else 'phi_deg', 'is missing')
    shear_type = str(data.get('shear_type', 'A')).upper()
    return Terrain(name=name, shear_type=shear_type, **fields)


# Table units, exactly as printed. Tables 2.1-2.3 (dry sand, sandy loam, clay; K from Table 2.3 and
# the text under Figure 2.10), Table 7.2 (sand bin), Table 8.2 (sandy soil), Table 8.3 (LETE sand).
_PRESET_TABLES: dict[str, dict[str, Any]] = {
    'dry_sand': {'n': 1.1, 'kc_kN': 0.90, 'kphi_kN': 1523.4, 'c': 1000, 'phi_deg': 30, 'K': 0.025},
    'sandy_loam': {'n': 0.7, 'kc_kN': 5.3, 'kphi_kN': 1515.0, 'c': 1700, 'phi_deg': 29, 'K': 0.025},
    'clay': {'n': 0.5, 'kc_kN': 13.2, 'kphi_kN': 692.2, 'c': 4140, 'phi_deg': 13, 'K': 0.01},
    'sand_bin': {'n': 1.08, 'kc': 1000, 'kphi': 1528600, 'c': 200, 'phi_deg': 27, 'K': 0.024},
    'sandy_soil': {'n': 1.1, 'kc': 900, 'kphi': 1523400, 'c': 1000, 'phi_deg': 30, 'K': 0.025},
    'lete_sand': {'n': 0.79, 'kc': 102000, 'kphi': 5301000, 'c': 1300, 'phi_deg': 31.1, 'K': 0.005},
}

PRESET_SOURCES: dict[str, str] = {
    'dry_sand': 'Tables 2.1-2.3 (Wong [10]); wheel a0..b1 Table 2.4',
    'sandy_loam': 'Tables 2.1-2.3 (Wong [10]); wheel a0..b1 from Table 2.4 (dry sand, assumed)',
    'clay': 'Tables 2.1-2.3 (Wong [10]); wheel a0..b1 from Table 2.4 (dry sand, assumed)',
    'sand_bin': 'Table 7.2 (ShearTrac II measurement); wheel a0..b1 from Table 2.4 (assumed)',
    'sandy_soil': 'Table 8.2 ([45]); wheel a0..b1 from Table 2.4 (assumed)',
    'lete_sand': 'Table 8.3 (Wong [10]); wheel a0..b1 from Table 2.4 (assumed)',
}

PRESETS: dict[str, Terrain] = {
    name: terrain_from_mapping(table, default_name=name) for name, table in _PRESET_TABLES.items()
}


def load_terrain(name_or_path: str | os.PathLike[str]) -> Terrain:
    """A preset by name (see :data:`PRESETS`), a shipped terrain file by name (``config/terrains/``,
    found by :mod:`skidsteer_power.resources`) or a YAML terrain file; ConfigError otherwise."""
    text = os.fspath(name_or_path)
    if text in PRESETS:
        return PRESETS[text]
    try:
        path = resources.find('terrains', text, ('.yaml', '.yml'))
    except ConfigError:
        if Path(text).suffix.lower() in ('.yaml', '.yml'):
            raise ConfigError(f'terrain file not found: {text}') from None
        shipped = sorted(set(PRESETS) | set(resources.shipped('terrains', ('.yaml', '.yml'))))
        raise ConfigError(
            f'unknown terrain {text!r}: not a preset nor a YAML file (shipped: {", ".join(shipped)})'
        ) from None
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ConfigError(f'cannot read terrain file {text}: {err}'.replace('\n', ' ')) from err
    return terrain_from_mapping(data, default_name=path.stem)


def terrain_fingerprint(terrain: Terrain) -> str:
    """Stable hex digest of the terrain's physical parameters (not its name)."""
    payload = {
        k: (repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
        for k, v in dataclasses.asdict(terrain).items()
        if k != 'name'
    }
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]
