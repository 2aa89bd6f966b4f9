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

Rigid ground (asphalt, concrete, flooring, ice: no sinkage, Coulomb friction; issue 35)::

    name: asphalt
    contact: rigid         # soil (default) | rigid
    mu_longitudinal: 0.65  # friction coefficient along the wheel / track [-]
    mu_lateral: 0.65       # friction coefficient across it [-]
    rolling_resistance: 0.015  # rolling resistance coefficient f_r [-]: F = f_r x load
    K: 0.003               # slip modulus [m]: friction mobilised as mu p (1 - exp(-j/K)) (eq. 2.3)

A rigid terrain carries no Bekker or Mohr-Coulomb fields (they are an error in its file); inside,
its soil fields hold the rigid limit (n = 1, kc = 0, c = 0, kphi = :data:`RIGID_KPHI`, phi =
atan(mu_longitudinal)) so that code written for a soil reads a consistent, sinkage-free ground.
The contact FESS builds for it is in :mod:`skidsteer_power.models.rigid_contact`.
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
from typing import TYPE_CHECKING, TypedDict, cast

import yaml

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError
from skidsteer_power.numeric import Real
from skidsteer_power.terramechanics.ranges import RIGID_FIELD_RANGES

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

# Table 2.4 (Wong and Reece, dry sand): the only wheel coefficients the dissertation gives. Chapter 2
# uses them for all three soils, and so do the presets here.
TABLE_2_4 = {'a0': 0.24, 'a1': 0.32, 'b0': -0.45, 'b1': 0.0}

CONTACT_SOIL = 'soil'
CONTACT_RIGID = 'rigid'
CONTACTS = (CONTACT_SOIL, CONTACT_RIGID)
RIGID_KPHI = 1e12
"""kphi [N/m^(n+2)] that stands for rigid ground in a rigid terrain's soil fields (n = 1): a 1 MPa
contact pressure sinks 1 um. Never used by the rigid contact itself (its sinkage is 0)."""
RIGID_FIELDS = ('mu_longitudinal', 'mu_lateral', 'rolling_resistance', 'K')
"""The fields of a rigid terrain file (all required), SI units; ranges in
:data:`skidsteer_power.terramechanics.ranges.RIGID_FIELD_RANGES`."""


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
    contact: str = 'soil'
    mu_lateral: float | None = None
    rolling_resistance: float | None = None

    def __post_init__(self) -> None:
        _validate(self)

    @property
    def is_rigid(self) -> bool:
        """True for rigid ground (Coulomb friction, no sinkage), False for a deformable soil."""
        return self.contact == CONTACT_RIGID

    @property
    def mu_longitudinal(self) -> float:
        """Friction coefficient along the running gear [-]: tan(phi) (eq. 2.2 with c = 0)."""
        return math.tan(self.phi)

    @property
    def phi_deg(self) -> float:
        """Internal friction angle [deg]."""
        return math.degrees(self.phi)

    def k_eq(self, b: Real) -> Real:
        """Equivalent pressure-sinkage modulus kc/b + kphi [N/m^(n+2)] for contact width b [m]
        (eq. 2.1); a float or an array (:mod:`skidsteer_power.numeric`)."""
        return self.kc / b + self.kphi


class TerrainNumbers(TypedDict, total=False):
    """The numeric fields of a :class:`Terrain` (SI), as a mapping handed to its constructor or to
    ``dataclasses.replace`` (a file's soil fields, a study's sampled parameters)."""

    n: float
    kc: float
    kphi: float
    c: float
    phi: float
    K: float
    Kr: float | None
    Kw: float | None
    a0: float
    a1: float
    b0: float
    b1: float
    mu_lateral: float | None
    rolling_resistance: float | None


def _bad(name: str, field: str, why: str) -> ConfigError:
    return ConfigError(f'terrain {name!r}: field {field!r} {why}')


def _validate(t: Terrain) -> None:
    if t.contact not in CONTACTS:
        raise _bad(t.name, 'contact', f"must be 'soil' or 'rigid', got {t.contact!r}")
    if t.is_rigid:
        _validate_rigid(t)
    elif t.mu_lateral is not None or t.rolling_resistance is not None:
        raise _bad(t.name, 'mu_lateral', "and rolling_resistance belong to 'contact: rigid' ground")
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


def _validate_rigid(t: Terrain) -> None:
    values = {'mu_longitudinal': t.mu_longitudinal, 'mu_lateral': t.mu_lateral}
    values.update(rolling_resistance=t.rolling_resistance, K=t.K)
    for field, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise _bad(t.name, field, f'must be a finite number, got {value!r}')
        limits = RIGID_FIELD_RANGES[field]
        if not limits.contains(float(value)):
            raise _bad(t.name, field, f'= {value:g} is outside its range {limits.text}')
    if t.shear_type != 'A':
        raise _bad(t.name, 'shear_type', "must be 'A' for rigid ground (friction mobilised as 1 - exp(-j/K))")


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
_TEXT_KEYS = ('name', 'shear_type', 'source', 'description', 'contact')
# provenance and uncertainty written by `skidsteer-power calibrate` (skidsteer_power/calibration/io.py)
_SKIPPED_KEYS = ('calibration',)


def terrain_from_mapping(data: Mapping[str, object], default_name: str = 'terrain') -> Terrain:
    """Build a :class:`Terrain` from table units (see module doc); ConfigError names a bad field."""
    if not isinstance(data, Mapping):
        raise ConfigError(
            f'terrain {default_name!r}: expected a mapping of fields, got {type(data).__name__}'
        )
    name = str(data.get('name', default_name))
    contact = str(data.get('contact', CONTACT_SOIL))
    if contact == CONTACT_RIGID:
        return _rigid_from_mapping(data, name)
    if contact != CONTACT_SOIL:
        raise _bad(name, 'contact', f"must be 'soil' or 'rigid', got {contact!r}")
    fields: dict[str, float] = {}
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
    return Terrain(name=name, shear_type=shear_type, **cast('TerrainNumbers', fields))  # _UNIT_KEYS' fields


def _rigid_from_mapping(data: Mapping[str, object], name: str) -> Terrain:
    """A rigid terrain from its file fields (:data:`RIGID_FIELDS`, SI); soil fields are an error."""
    values: dict[str, float] = {}
    for key, value in data.items():
        if key in _TEXT_KEYS or key in _SKIPPED_KEYS:
            continue
        if key not in RIGID_FIELDS:
            raise _bad(name, str(key), 'is not a field of rigid ground (contact: rigid)')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _bad(name, str(key), f'must be a number, got {value!r}')
        values[str(key)] = float(value)
    for field in RIGID_FIELDS:
        if field not in values:
            raise _bad(name, field, 'is missing')
    shear_type = str(data.get('shear_type', 'A')).upper()
    return rigid_terrain(name, shear_type=shear_type, **values)


def rigid_terrain(
    name: str,
    *,
    mu_longitudinal: float,
    mu_lateral: float,
    rolling_resistance: float,
    K: float,
    shear_type: str = 'A',
) -> Terrain:
    """Rigid ground (SI): friction coefficients along and across the running gear [-], rolling
    resistance coefficient [-], slip modulus K [m]; soil fields at the rigid limit (module doc)."""
    mu = RIGID_FIELD_RANGES['mu_longitudinal']
    if isinstance(mu_longitudinal, bool) or not mu.contains(float(mu_longitudinal)):
        raise _bad(name, 'mu_longitudinal', f'= {mu_longitudinal!r} is outside its range {mu.text}')
    return Terrain(
        name=name,
        n=1.0,
        kc=0.0,
        kphi=RIGID_KPHI,
        c=0.0,
        phi=math.atan(float(mu_longitudinal)),
        K=K,
        shear_type=shear_type,
        contact=CONTACT_RIGID,
        mu_lateral=mu_lateral,
        rolling_resistance=rolling_resistance,
    )


def terrain_fields(terrain: Terrain) -> JsonObject:
    """The fields a terrain file of ``terrain`` holds, SI units (phi as ``phi_deg`` [deg]): the soil
    fields of a soil, ``contact`` and :data:`RIGID_FIELDS` of rigid ground."""
    if terrain.is_rigid:
        assert terrain.mu_lateral is not None and terrain.rolling_resistance is not None  # validated
        return {
            'contact': CONTACT_RIGID,
            'mu_longitudinal': terrain.mu_longitudinal,
            'mu_lateral': float(terrain.mu_lateral),
            'rolling_resistance': float(terrain.rolling_resistance),
            'K': float(terrain.K),
        }
    fields: JsonObject = {'contact': CONTACT_SOIL}
    for key in ('n', 'kc', 'kphi', 'c'):
        fields[key] = float(getattr(terrain, key))
    fields['phi_deg'] = terrain.phi_deg
    fields['K'] = float(terrain.K)
    fields['shear_type'] = terrain.shear_type
    for key in ('Kr', 'Kw'):
        if getattr(terrain, key) is not None:
            fields[key] = float(getattr(terrain, key))
    for key in ('a0', 'a1', 'b0', 'b1'):
        fields[key] = float(getattr(terrain, key))
    return fields


# Table units, exactly as printed. Tables 2.1-2.3 (dry sand, sandy loam, clay; K from Table 2.3 and
# the text under Figure 2.10), Table 7.2 (sand bin), Table 8.2 (sandy soil), Table 8.3 (LETE sand).
_PRESET_TABLES: dict[str, dict[str, float]] = {
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
    # a soil's digest is over its soil fields only, as before rigid ground existed (cached maps
    # keep their keys); rigid ground adds its own fields
    rigid_only = ('contact', 'mu_lateral', 'rolling_resistance')
    payload = {
        k: (repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
        for k, v in dataclasses.asdict(terrain).items()
        if k != 'name' and (terrain.is_rigid or k not in rigid_only)
    }
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]
