"""Uncertain terrain and powertrain parameters: where the spread comes from, and samples of it.

A :class:`ParameterSpread` is a zero-mean multivariate normal over named parameters, in SI units, around
the nominal values of the study's terrain (``--terrain``) and the vehicle's powertrain. A sample is
nominal + delta, clipped to :data:`BOUNDS` (physical validity), and applied with
:func:`apply_terrain` / :func:`apply_powertrain`.

Parameters
    terrain: any numeric :class:`~skidsteer_power.terramechanics.terrain.Terrain` field (n, kc, kphi,
        c, phi, K, ...), SI (phi in rad);
    powertrain: ``internal_scale`` [-] (multiplies every internal-resistance coefficient of both sides,
        eqs. 7.1-7.4; nominal 1) and ``{left,right}_{b,c}``: the side's total viscous b [N m s/rad] and
        Coulomb c [N m] at the motor shaft (eq. 7.1; nominal: the sum of the vehicle's components;
        a sample replaces the side's components by one of these totals).

Where the spread comes from (first that applies)
    1. ``--from-calibration F.yaml``: the ``calibration:`` block of a calibrated terrain file
       (``skidsteer-power calibrate``): ``parameters`` (names as above; a file key such as ``phi_deg``
       or ``kphi_kN`` is accepted too) and ``covariance`` (list of lists, same order), in the units of
       the terrain file's own fields: for ``phi`` given in the file as ``phi_deg``, degrees^2; for
       ``kphi_kN``, kN^2...; optional ``powertrain_parameters`` / ``powertrain_covariance`` (SI).
    2. ``--uncertainty FILE.yaml``: ``terrain:`` and ``powertrain:`` mappings of parameter -> a number
       (relative standard deviation, e.g. 0.1 = 10 % of nominal) or ``{sigma: x}`` (absolute, in the
       key's unit: ``phi_deg: {sigma: 1.5}`` is 1.5 degrees). Independent parameters.
    3. neither: :data:`DEFAULT_RELATIVE_SIGMA`, independent. ASSUMED values (the dissertation gives
       no scatter; chapter 8.2 perturbs by +-1 % only): typical between-sample scatter of bevameter and
       shear-box tests on one site, n 5 %, kc 20 %, kphi 10 %, c 20 %, phi 5 %, K 20 %, and the
       drivetrain's internal resistance 10 % (a fit to Table 7.1-style no-load runs of one robot).

Sampling: scrambled Sobol points (quasi-Monte Carlo, :class:`scipy.stats.qmc.MultivariateNormalQMC`,
inverse-transform) by default, or plain pseudo-random normals (``method='random'``); both seeded, so a
study is reproducible and identical wherever its tasks run.
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
import yaml

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.powertrain.perturbed import apply_powertrain as apply_powertrain  # its home (re-export)
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.terramechanics.terrain import _UNIT_KEYS, Terrain

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.terramechanics.terrain import TerrainNumbers

DEFAULT_RELATIVE_SIGMA: dict[str, float] = {
    'n': 0.05,
    'kc': 0.20,
    'kphi': 0.10,
    'c': 0.20,
    'phi': 0.05,
    'K': 0.20,
    'internal_scale': 0.10,
}
# physical validity of a sample (SI); a draw outside is clipped to the bound
BOUNDS: dict[str, tuple[float, float]] = {
    'n': (0.05, 3.0),
    'kc': (0.0, math.inf),
    'kphi': (0.0, math.inf),
    'c': (0.0, math.inf),
    'phi': (math.radians(1.0), math.radians(89.0)),
    'K': (1e-4, math.inf),
    'Kr': (1e-3, 1.0),
    'Kw': (1e-4, math.inf),
    'internal_scale': (0.0, math.inf),
}
_SIDE_KEY = re.compile(r'^(left|right)_(b|c)$')
POWERTRAIN_NAMES = ('internal_scale',)
METHODS = ('sobol', 'random')


@dataclass(frozen=True)
class ParameterSpread:
    """Zero-mean normal deltas over ``names`` with covariance ``cov`` (SI units), and their source."""

    names: tuple[str, ...]
    cov: np.ndarray
    source: str

    def __post_init__(self) -> None:
        cov = np.asarray(self.cov, dtype=float)
        n = len(self.names)
        if cov.shape != (n, n) or not np.all(np.isfinite(cov)):
            raise ConfigError(f'{self.source}: covariance must be a finite {n} x {n} matrix')
        if not np.allclose(cov, cov.T, rtol=1e-6, atol=0.0):
            raise ConfigError(f'{self.source}: covariance is not symmetric')
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        live = sd > 0
        corr = cov[np.ix_(live, live)] / np.outer(sd[live], sd[live])  # scale-free check
        if np.any(np.diag(cov) < 0) or (corr.size and np.min(np.linalg.eigvalsh(corr)) < -1e-9):
            raise ConfigError(f'{self.source}: covariance is not positive semi-definite')
        for name in self.names:
            if not _is_terrain(name) and not _is_powertrain(name):
                raise ConfigError(f'{self.source}: {name!r} is not a terrain or powertrain parameter')

    @property
    def sigma(self) -> dict[str, float]:
        """Standard deviation per parameter (SI)."""
        return dict(zip(self.names, np.sqrt(np.diag(self.cov)).tolist(), strict=True))

    def deltas(self, n: int, seed: int, method: str = 'sobol') -> np.ndarray:
        """``n`` draws of the deltas, shape (n, len(names)), reproducible for ``seed``."""
        if method not in METHODS:
            raise InputError(f'sampling method must be one of {", ".join(METHODS)}, not {method!r}')
        if n < 1:
            raise InputError(f'number of samples must be >= 1, not {n}')
        mean = np.zeros(len(self.names))
        if method == 'random':
            return np.random.default_rng(seed).multivariate_normal(mean, self.cov, size=n, method='eigh')
        from scipy.stats import qmc

        # a zero-variance parameter makes the covariance singular: sample only the others
        active = np.flatnonzero(np.diag(self.cov) > 0)
        out = np.zeros((n, len(self.names)))
        if active.size:
            sampler = qmc.MultivariateNormalQMC(
                mean[active], self.cov[np.ix_(active, active)], rng=np.random.default_rng(seed)
            )
            with warnings.catch_warnings():  # balance properties need 2^m points; any n is fine here
                warnings.simplefilter('ignore', UserWarning)
                out[:, active] = sampler.random(n)
        return out


def nominal_values(names: Sequence[str], terrain: Terrain, powertrain: Powertrain) -> np.ndarray:
    """Nominal value of each parameter (SI) for ``terrain`` and ``powertrain``."""
    out = []
    for name in names:
        if _is_terrain(name):
            value = getattr(terrain, name)
            if value is None:
                raise ConfigError(f'terrain {terrain.name!r} has no {name} to vary')
            out.append(float(value))
        elif name == 'internal_scale':
            out.append(1.0)
        else:
            side_key = _SIDE_KEY.match(name)
            if side_key is None:
                raise ConfigError(f'{name!r} is not a terrain or powertrain parameter')
            side, coefficient = side_key.groups()
            total = powertrain.resistance(side).total
            out.append(total.viscous_Nm_s if coefficient == 'b' else total.coulomb_Nm)
    return np.asarray(out)


def clip(names: Sequence[str], values: np.ndarray) -> np.ndarray:
    """Values (..., len(names)) clipped to :data:`BOUNDS` (side coefficients to >= 0)."""
    out = np.array(values, dtype=float)
    for k, name in enumerate(names):
        lo, hi = BOUNDS.get(name, (0.0, math.inf) if _SIDE_KEY.match(name) else (-math.inf, math.inf))
        out[..., k] = np.clip(out[..., k], lo, hi)
    return out


def draw(
    spread: ParameterSpread,
    terrain: Terrain,
    powertrain: Powertrain,
    n: int,
    seed: int,
    method: str = 'sobol',
) -> list[dict[str, float]]:
    """``n`` parameter sets (name -> SI value): nominal + delta, clipped (module doc)."""
    values = clip(
        spread.names, nominal_values(spread.names, terrain, powertrain) + spread.deltas(n, seed, method)
    )
    return [dict(zip(spread.names, row.tolist(), strict=True)) for row in values]


def apply_terrain(terrain: Terrain, sample: Mapping[str, float]) -> Terrain:
    """``terrain`` with the sample's terrain parameters (SI) replaced (validated as any terrain)."""
    changes = {k: v for k, v in sample.items() if _is_terrain(k)}
    if not changes:
        return terrain
    return dataclasses.replace(terrain, name=f'{terrain.name}~', **cast('TerrainNumbers', changes))


def _is_terrain(name: str) -> bool:
    return name in {f.name for f in dataclasses.fields(Terrain)} and name not in ('name', 'shear_type')


def _is_powertrain(name: str) -> bool:
    return name in POWERTRAIN_NAMES or bool(_SIDE_KEY.match(name))


# ---------------------------------------------------------------------------------------- sources
def default_spread(terrain: Terrain, powertrain: Powertrain) -> ParameterSpread:
    """Independent :data:`DEFAULT_RELATIVE_SIGMA` around the nominal values (module doc, 3.)."""
    names = tuple(DEFAULT_RELATIVE_SIGMA)
    sigma = np.asarray([DEFAULT_RELATIVE_SIGMA[k] for k in names]) * np.abs(
        nominal_values(names, terrain, powertrain)
    )
    return ParameterSpread(names, np.diag(sigma**2), 'default sigmas (assumed; docs/STUDIES.md)')


def spread_from_yaml(path: str | Path, terrain: Terrain, powertrain: Powertrain) -> ParameterSpread:
    """``--uncertainty FILE.yaml`` (module doc, 2.)."""
    data = _read_yaml(path)
    unknown = set(data) - {'terrain', 'powertrain'}
    if unknown:
        raise ConfigError(
            f'{path}: unknown section(s) {", ".join(sorted(map(str, unknown)))} (terrain, powertrain)'
        )
    names: list[str] = []
    sigmas: list[float] = []
    for section in ('terrain', 'powertrain'):
        entries = data.get(section) or {}
        if not isinstance(entries, Mapping):
            raise ConfigError(f'{path}: {section} must map parameter names to sigmas')
        for key, spec in entries.items():
            name, factor = _field_and_factor(str(key), path)
            if name in names:
                raise ConfigError(f'{path}: {name} is given twice')
            nominal = float(nominal_values([name], terrain, powertrain)[0])
            if isinstance(spec, Mapping) and set(spec) == {'sigma'}:
                sigma = _number(spec['sigma'], f'{path}: {key}.sigma') * factor
            elif isinstance(spec, Mapping):
                raise ConfigError(f'{path}: {key}: give a relative sigma (a number) or {{sigma: x}}')
            else:
                sigma = _number(spec, f'{path}: {key}') * abs(nominal)
            if sigma < 0:
                raise ConfigError(f'{path}: {key}: sigma must be >= 0')
            names.append(name)
            sigmas.append(sigma)
    if not names:
        raise ConfigError(f'{path}: no parameters in terrain or powertrain')
    return ParameterSpread(tuple(names), np.diag(np.square(sigmas)), f'{path}')


def spread_from_calibration(path: str | Path) -> ParameterSpread:
    """``--from-calibration F.yaml`` (module doc, 1.): covariance converted to SI."""
    data = _read_yaml(path)
    block = data.get('calibration')
    if not isinstance(block, Mapping):
        raise ConfigError(f'{path}: no calibration: block (write it with skidsteer-power calibrate)')
    names: list[str] = []
    blocks: list[np.ndarray] = []
    for params_key, cov_key in (
        ('parameters', 'covariance'),
        ('powertrain_parameters', 'powertrain_covariance'),
    ):
        if params_key not in block and params_key != 'parameters':
            continue
        raw = block.get(params_key)
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f'{path}: calibration.{params_key} must be a non-empty list of names')
        cov = _matrix(block.get(cov_key), len(raw), f'{path}: calibration.{cov_key}')
        factors = []
        for key in map(str, raw):
            if params_key == 'parameters':
                name, factor = _field_and_factor(_file_key(key, data), path)
            else:
                name, factor = _field_and_factor(key, path)
            names.append(name)
            factors.append(factor)
        f = np.asarray(factors)
        blocks.append(cov * np.outer(f, f))
    n = sum(len(b) for b in blocks)
    cov = np.zeros((n, n))
    k = 0
    for b in blocks:
        cov[k : k + len(b), k : k + len(b)] = b
        k += len(b)
    if len(set(names)) != len(names):
        raise ConfigError(f'{path}: a calibration parameter is listed twice')
    return ParameterSpread(tuple(names), cov, f'calibration {path}')


def _file_key(name: str, data: Mapping[str, object]) -> str:
    """The key under which the terrain file gives field ``name`` (so its unit), else ``name``."""
    if name in data or (name in _UNIT_KEYS and _UNIT_KEYS[name][0] != name):
        return name
    for key, (field, _factor) in _UNIT_KEYS.items():
        if field == name and key in data:
            return key
    return name


def _field_and_factor(key: str, path: str | Path) -> tuple[str, float]:
    """(parameter name, factor to SI) for a terrain file key, field name or powertrain name."""
    if _is_powertrain(key):
        return key, 1.0
    if key in _UNIT_KEYS:
        field, factor = _UNIT_KEYS[key]
        if _is_terrain(field):
            return field, factor
    if key == 'phi':
        return 'phi', 1.0  # a Terrain field given by name: SI (rad)
    raise ConfigError(f'{path}: {key!r} is not a terrain or powertrain parameter')


def _matrix(value: object, n: int, where: str) -> np.ndarray:
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f'{where} must be a list of {n} lists of {n} numbers') from None
    if out.shape != (n, n):
        raise ConfigError(f'{where} must be {n} x {n}, got shape {out.shape}')
    return out


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f'{where} must be a finite number, got {value!r}')
    return float(value)


def _read_yaml(path: str | Path) -> JsonObject:
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except FileNotFoundError:
        raise ConfigError(f'file not found: {path}') from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ConfigError(f'cannot read {path}: {err}'.replace('\n', ' ')) from err
    if not isinstance(data, Mapping):
        raise ConfigError(f'{path}: expected a mapping')
    return dict(data)
