"""Calibrated terrain and powertrain files, and reading a calibration's covariance back.

The terrain file has the format of ``config/terrains/*.yaml`` (so ``load_terrain`` reads it wherever a
terrain is accepted: solve, map, estimator, missions), with SI keys (n, kc [N/m^(n+1)], kphi
[N/m^(n+2)], c [Pa], phi_deg [deg], K [m]) and one extra top-level mapping, which ``load_terrain``
skips::

    calibration:
      parameters: [n, phi, K]          # fitted Terrain fields, in this order
      units: ['-', deg, m]             # units of values and covariance (phi in degrees, as phi_deg)
      values: [...]                    # the fitted values (= the file's fields, in these units)
      covariance: [[...], ...]         # 95 % CIs = value +- 1.96 sqrt(diag) approximately
      ci95: {n: [lo, hi], ...}
      fixed: [kphi, c, kc]             # not identifiable from the data: left at the start value
      at_bound: [phi]                  # fitted but stopped at a fit bound: no estimate, no covariance
      bags: [...]; date: ISO 8601 UTC; residual_rms_Nm: fit residual (motor torque RMS)
      start_terrain: name of T0; segments_fit, segments_holdout
      fit_at: cmd | motion             # what the segments were solved at (the commands' wheel speed
                                       # set points, as the estimator predicts, or the measured motion)
      powertrain_parameters / powertrain_covariance: when internal resistance was fitted

The covariance of a log-searched parameter is the delta-method linearization (see ``fit.py``).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import yaml

from skidsteer_power.calibration.fit import (
    BATTERY_PARAMS,
    INTERNAL_PARAMS,
    PARAMS,
    TERRAIN_PARAMS,
    TIED_INTERNAL_PARAMS,
    CalibrationResult,
    terrain_params,
)
from skidsteer_power.errors import ConfigError, SkidsteerError
from skidsteer_power.terramechanics.terrain import load_terrain

POWERTRAIN_NAMES = (*INTERNAL_PARAMS, *TIED_INTERNAL_PARAMS, *BATTERY_PARAMS)  # fitted powertrain terms

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.powertrain.motor import AmplifierConstants, MotorConstants
    from skidsteer_power.terramechanics.terrain import Terrain

    Part = TypeVar('Part', MotorConstants, AmplifierConstants)


def _block(result: CalibrationResult, names: list[str]) -> tuple[list[float], list[list[float]]]:
    index = [result.names.index(n) for n in names]
    cov = result.covariance[np.ix_(index, index)]
    return [float(result.values[n]) for n in names], [[float(v) for v in row] for row in cov]


def calibration_block(result: CalibrationResult, bags: Sequence[str], start_name: str) -> JsonObject:
    """The ``calibration:`` mapping written into the terrain file (see module doc)."""
    # a parameter at a fit bound is no estimate (fit.py): written as a plain value, listed in at_bound
    # so is one whose interval left its range (not in names) and every fit when the start was kept
    kept = bool(result.kept_start)
    terrain_names = [n for n in result.names if n in TERRAIN_PARAMS and n not in result.at_bound and not kept]
    values, cov = _block(result, terrain_names)
    block: JsonObject = {
        'parameters': terrain_names,
        'units': [PARAMS[n].unit for n in terrain_names],
        'values': values,
        'covariance': cov,
        'ci95': {n: [float(v) for v in ci] for n in terrain_names if (ci := result.ci95.get(n))},
        'fixed': [n for n in terrain_params(result.terrain) if n not in result.names],
        'at_bound': sorted(n for n in result.at_bound if n in TERRAIN_PARAMS),
        'correlations_warnings': list(result.correlations_warnings),
        'bags': [str(Path(b).resolve()) for b in bags],
        'date': _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        'residual_rms_Nm': float(result.residual_rms_Nm),
        'start_terrain': start_name,
        'segments_fit': result.segments_fit,
        'segments_holdout': result.segments_holdout,
        'fit_at': result.fit_at,
        'fit_to': result.fit_to,
        'not_identifiable': sorted(result.not_identifiable),
        'kept_start': result.kept_start or None,
    }
    internal = [
        n
        for n in result.names
        if n in POWERTRAIN_NAMES and n not in result.at_bound and not kept and n not in result.reconciled
    ]
    if internal:
        block['powertrain_parameters'] = internal
        block['powertrain_units'] = [PARAMS[n].unit for n in internal]
        block['powertrain_values'], block['powertrain_covariance'] = _block(result, internal)
    return block


def terrain_mapping(terrain: Terrain) -> JsonObject:
    """A terrain as a YAML mapping in SI keys (phi in degrees as ``phi_deg``; rigid ground: its
    friction, rolling resistance and K, :func:`terrain_fields`)."""
    if terrain.is_rigid:
        from skidsteer_power.terramechanics.terrain import terrain_fields

        return {'name': terrain.name, **terrain_fields(terrain)}
    data: JsonObject = {
        'name': terrain.name,
        'n': float(terrain.n),
        'kc': float(terrain.kc),
        'kphi': float(terrain.kphi),
        'c': float(terrain.c),
        'phi_deg': math.degrees(terrain.phi),
        'K': float(terrain.K),
        'shear_type': terrain.shear_type,
    }
    for key in ('Kr', 'Kw'):
        if getattr(terrain, key) is not None:
            data[key] = float(getattr(terrain, key))
    for key in ('a0', 'a1', 'b0', 'b1'):
        data[key] = float(getattr(terrain, key))
    return data


def write_terrain(
    path: str | Path, result: CalibrationResult, bags: Sequence[str], start_name: str, name: str
) -> Path:
    """Write the calibrated terrain YAML; returns the path. Re-reads it with ``load_terrain`` as a check."""
    out = Path(path)
    data = terrain_mapping(result.terrain)
    data['name'] = name
    data['source'] = (
        f'calibrated from {len(bags)} bag(s) starting at {start_name} (skidsteer-power calibrate)'
    )
    data['calibration'] = calibration_block(result, bags, start_name)
    header = '# Written by `skidsteer-power calibrate`: SI keys; see skidsteer_power/calibration/io.py.\n'
    out.write_text(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None), encoding='utf-8')
    load_terrain(out)
    return out


def _preset_or_fields(value: Part, presets: Mapping[str, Part]) -> str | dict[str, float | bool | str]:
    """A preset's name when ``value`` is one of ``presets``; a preset with one field changed (a fitted
    efficiency) as ``{preset: name, field: value}``; else its fields (SI units) as a mapping: a
    vehicle's own motor or amplifier is written out in full."""

    def plain(v: float | bool | str) -> float | bool | str:
        return v if isinstance(v, bool | str) else float(v)

    fields = dataclasses.asdict(value)
    for key, preset in presets.items():
        if preset == value:
            return key
    for key, preset in presets.items():  # a preset with a fitted field (the amplifier's efficiency)
        changed = {k: v for k, v in fields.items() if getattr(preset, k) != v and k != 'name'}
        if preset.name == value.name and len(changed) == 1:
            return {'preset': key, **{k: plain(v) for k, v in changed.items()}}
    return {k: plain(v) for k, v in fields.items()}


def powertrain_mapping(result: CalibrationResult, bags: Sequence[str]) -> JsonObject:
    """The calibrated powertrain as a ``config/powertrains/*.yaml`` mapping (with its calibration)."""
    pt = result.powertrain
    sides = {
        side: {
            name: {'viscous_Nm_s': float(part.viscous_Nm_s), 'coulomb_Nm': float(part.coulomb_Nm)}
            for name, part in getattr(pt, side).components.items()
        }
        for side in ('left', 'right')
    }
    # a term fitted again to every sample (reconcile.py) has no steady-window covariance: listed apart
    kept = bool(result.kept_start)
    internal = [n for n in result.names if n in POWERTRAIN_NAMES and not kept and n not in result.reconciled]
    data: JsonObject = {
        'name': f'{pt.name}_calibrated',
        'source': f'{pt.name} with the internal resistance of {len(bags)} bag(s) '
        '(skidsteer-power calibrate); '
        'each side total spread over the components in the original proportions',
        'motor': _preset_or_fields(pt.motor, _motors()),
        'amplifier': _preset_or_fields(pt.amplifier, _amplifiers()),
        'gear_ratio': float(pt.gear_ratio),
        'current_limit_A': float(pt.current_limit_A),
        'regen_efficiency': pt.regen_efficiency,
        'internal_resistance': sides,
        'battery': pt.battery,
        'bus_voltage_V': pt.bus_voltage_V,
        'idle_power_W': float(pt.idle_power_W),
    }
    # the fitted k_cu replaces the motor's R (R = k_cu K_t^2)
    if 'copper_loss_W_per_Nm2' in internal or 'copper_loss_W_per_Nm2' in result.reconciled:
        data['copper_loss_W_per_Nm2'] = float(pt.copper_loss_W_per_Nm2)
    if internal:
        values, cov = _block(result, internal)
        data['calibration'] = {
            'parameters': internal,
            'units': [PARAMS[n].unit for n in internal],
            'values': values,
            'covariance': cov,
            'bags': [str(Path(b).resolve()) for b in bags],
            'date': _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
            'residual_rms_Nm': float(result.residual_rms_Nm),
        }
    if result.reconciled:  # fitted to every sample's battery power (calibration/reconcile.py)
        record = data.setdefault('calibration', {'bags': [str(Path(b).resolve()) for b in bags]})
        record['reconciled'] = {
            'parameters': list(result.reconciled),
            'units': [PARAMS[n].unit for n in result.reconciled],
            'values': [float(v) for v in result.reconciled.values()],
            'report': result.reconciliation,
        }
    return data


def write_powertrain(path: str | Path, result: CalibrationResult, bags: Sequence[str]) -> Path:
    """Write the calibrated powertrain in the format of ``config/powertrains/*.yaml``."""
    out = Path(path)
    data = powertrain_mapping(result, bags)
    out.write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None), encoding='utf-8')
    return out


def write_vehicle(
    path: str | Path, vehicle: str, result: CalibrationResult, bags: Sequence[str], terrain_file: str
) -> Path:
    """Write ``vehicle``'s file with its identified powertrain inline (``powertrain:``); its
    ``source`` says what was calibrated from which bags and where the terrain went (a vehicle file has
    no other free-text key); re-read as a check."""
    from skidsteer_power import resources
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.vehicle import load_vehicle

    data = yaml.safe_load(resources.find('vehicles', vehicle).read_text(encoding='utf-8'))
    data['powertrain'] = powertrain_mapping(result, bags)
    if result.drive is not None:  # the drive controller's limits the recordings reached (docs/DRIVE.md)
        identified = result.drive.vehicle_entries(f'skidsteer-power calibrate from {len(bags)} bag(s)')
        drive = {**(data.get('drive_controller') or {}), **identified.pop('drive_controller', {})}
        if drive:
            sources = {**(data.get('drive_controller') or {}).get('sources', {}), **drive.get('sources', {})}
            data['drive_controller'] = {**drive, 'sources': sources}
        data.update(identified)
    data['name'] = f'{data.get("name", "vehicle")}_calibrated'
    fitted = [n for n in result.names if not result.kept_start]
    kept = f' ({result.kept_start})' if result.kept_start else ''
    data['source'] = (
        f'{str(data.get("source", "")).strip()} Calibrated by skidsteer-power calibrate '
        f'({_dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()}) from '
        f'{", ".join(str(Path(b).resolve()) for b in bags)}: fitted {", ".join(fitted) or "nothing"}{kept}; '
        f'terrain written to {Path(terrain_file).resolve()}.'
    ).strip()
    out = Path(path)
    header = (
        '# Written by `skidsteer-power calibrate --out-vehicle`; see skidsteer_power/calibration/io.py.\n'
    )
    out.write_text(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None), encoding='utf-8')
    try:
        Powertrain.for_vehicle(load_vehicle(str(out)))
    except SkidsteerError as err:  # a bug here, not the user's input: say so plainly
        raise ConfigError(f'{out}: the written vehicle does not load again ({err})') from err
    return out


def _motors() -> dict[str, MotorConstants]:
    from skidsteer_power.powertrain.power_flow import MOTORS

    return dict(MOTORS)


def _amplifiers() -> dict[str, AmplifierConstants]:
    from skidsteer_power.powertrain.power_flow import AMPLIFIERS

    return dict(AMPLIFIERS)


def read_calibration(path: str | Path) -> tuple[Terrain, list[str], np.ndarray, np.ndarray]:
    """(terrain, parameter names, values, covariance) of a calibrated terrain file, in the block's units.

    ConfigError when the file has no usable ``calibration:`` block.
    """
    terrain = load_terrain(path)
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
        block = data['calibration']
        names = [str(n) for n in block['parameters']]
        values = np.array([float(getattr(terrain, n)) / PARAMS[n].to_si for n in names])
        cov = np.array(block['covariance'], dtype=float).reshape(len(names), len(names))
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f'{path}: no usable calibration block ({err})') from err
    if not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T, rtol=1e-6, atol=0):
        raise ConfigError(f'{path}: calibration covariance must be a finite symmetric matrix')
    return terrain, names, values, cov
