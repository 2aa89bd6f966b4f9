"""The design study of ch. 8.3 over the Table 8.4 grid: 3 configurations x 3^5 parameter levels = 729.

Each candidate drives straight at 0.2 m/s and turns at R = 2 m, 0.2 m/s; its power is the total of
terrain and internal power (the test robot's internal resistance, ch. 8.3: "assumed to stay unchanged
with robot parameters (but of course they change with the configurations)"), its mobility the maximum
drawbar pull over the weight (see :mod:`skidsteer_power.missions.mobility`).

Table 8.4 does not give the CG height: we use the chapter 8 Packbot's 0.08 m (Table 8.1) for all.

Best design per configuration (the criterion is ours; Table 8.5 is not used to choose it): the
study's own axes are mobility (max drawbar pull / weight, X) and power (Y) (Figures 8.16-8.18), so a
good design sits low and to the right. ``merit`` (default) maximizes their ratio,
(F_dp,max / W) / P_mean [1/W], with P_mean the mean power of the two manoeuvres: mobility and power
weigh equally, and a heavier vehicle gains nothing by pulling more in absolute terms. ``power`` picks
the lowest mean power, ``mobility`` the largest drawbar pull ratio. Only candidates that converge in
both manoeuvres and have a positive drawbar pull are eligible.

Candidates run in parallel processes (concurrent.futures.ProcessPoolExecutor), each process solving
one contiguous part of the grid; the result order is the grid order, so the study is deterministic.
The parts are contiguous because FESS prepares a single-wheel table per (wheel, load) once per process
(about 3 ms, one batched Newton over 25 loads; cached): the 9 candidates that differ only in length
and tread share it. The split balances an estimated cost per candidate, measured on this machine.
"""

from __future__ import annotations

import importlib
import itertools
import os
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING, TypeAlias

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.missions.energy import state_powers
from skidsteer_power.missions.mobility import max_drawbar_pull
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.powertrain.perturbed import apply_powertrain
from skidsteer_power.powertrain.power_flow import SIDES
from skidsteer_power.vehicle import GRAVITY_M_S2, TrackGear, Vehicle, WheelGear

if TYPE_CHECKING:
    from collections.abc import Mapping

    from skidsteer_power.distributed.engine import Engine
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.terramechanics.terrain import Terrain

    ChunkJob: TypeAlias = (
        tuple[list[JsonObject], Terrain, str]
        | tuple[list[JsonObject], Terrain, str, Mapping[str, float] | None]
    )
    """A task of :func:`evaluate_chunk`: (candidates (:func:`grid` rows), terrain, model[, powertrain
    sample (:func:`skidsteer_power.powertrain.perturbed.apply_powertrain`)])."""

CONFIGURATIONS = ('track', '4-wheel', '6-wheel')  # Table 8.4
MASSES_KG = (10.0, 20.0, 30.0)
WIDTHS_M = (0.05, 0.125, 0.2)
RADII_M = (0.08, 0.1, 0.12)
LENGTHS_M = (0.5, 0.7, 0.9)  # track length / wheel base
TREADS_M = (0.3, 0.4, 0.5)
CG_HEIGHT_M = 0.08  # ASSUMED: Table 8.1's Packbot value (Table 8.4 gives none)
SPEED_M_S = 0.2  # ch. 8.3
TURN_RADIUS_M = 2.0  # ch. 8.3
CRITERIA = ('merit', 'power', 'mobility')


def grid() -> list[JsonObject]:
    """The 729 Table 8.4 candidates in a fixed order (configuration, mass, width, radius, length, tread)."""
    rows = itertools.product(CONFIGURATIONS, MASSES_KG, WIDTHS_M, RADII_M, LENGTHS_M, TREADS_M)
    keys = ('configuration', 'mass_kg', 'width_m', 'radius_m', 'length_or_wheelbase_m', 'tread_m')
    return [dict(zip(keys, row, strict=True)) | {'index': k} for k, row in enumerate(rows)]


def candidate_vehicle(c: JsonObject) -> Vehicle:
    """The :class:`~skidsteer_power.vehicle.Vehicle` of one grid row, with the test robot's powertrain."""
    gear: TrackGear | WheelGear
    if c['configuration'] == 'track':
        gear = TrackGear(
            track_length_m=c['length_or_wheelbase_m'],
            track_width_m=c['width_m'],
            sprocket_radius_m=c['radius_m'],
        )
    else:
        gear = WheelGear(
            n_wheels=int(c['configuration'][0]),
            wheel_radius_m=c['radius_m'],
            wheel_width_m=c['width_m'],
            wheelbase_m=c['length_or_wheelbase_m'],
        )
    return Vehicle(
        name=f'design-{c["index"]:03d}-{c["configuration"]}',
        gear=gear,
        mass_kg=c['mass_kg'],
        cg_height_m=CG_HEIGHT_M,
        tread_m=c['tread_m'],
        powertrain={'preset': 'test_robot'},
        source='Table 8.4 design study grid; CG height assumed (Table 8.1)',
    )


def evaluate_chunk(job: ChunkJob) -> list[JsonObject]:
    """Solve (candidates, terrain, model[, powertrain sample]) (see skidsteer_power.studies)."""
    from skidsteer_power.models import solve

    candidates, terrain, model, *sample = job
    powertrains = {g: Powertrain.default_test_robot(g) for g in ('track', 'wheel')}
    if sample and sample[0]:
        powertrains = {g: apply_powertrain(pt, sample[0]) for g, pt in powertrains.items()}
    out = []
    for c in candidates:
        vehicle = candidate_vehicle(c)
        state = solve(
            vehicle,
            terrain,
            SPEED_M_S,
            np.array([np.inf, TURN_RADIUS_M]),
            model=model,
            raise_on_failure=False,
        )
        pt = powertrains[vehicle.running_gear]
        axle = {f'{q}_{side}': state.side(q, side) for q in ('torque', 'omega') for side in SIDES}
        powers = state_powers(pt, axle)
        power, internal = powers['mechanical_W'], powers['internal_W']
        converged = bool(np.all(state.converged))
        out.append(
            c
            | {
                'converged': converged,
                'power_straight_W': float(power[0]) if converged else None,
                'power_turning_W': float(power[1]) if converged else None,
                'internal_straight_W': float(internal[0]) if converged else None,
                'internal_turning_W': float(internal[1]) if converged else None,
                'sinkage_m': float(np.max(state.sinkage_m)) if converged else None,
            }
        )
    return out


def design_study(
    terrain: Terrain,
    *,
    model: str = 'fess',
    criterion: str = 'merit',
    workers: int | None = None,
    engine: Engine | None = None,
    configurations: tuple[str, ...] = CONFIGURATIONS,
) -> JsonObject:
    """Evaluate the Table 8.4 grid on ``terrain``; returns candidates, best per configuration, criterion.

    ``engine`` (a :class:`skidsteer_power.distributed.engine.Engine`) runs the parts on Dask instead;
    ``configurations`` limits the grid to some of :data:`CONFIGURATIONS`.
    """
    if criterion not in CRITERIA:
        raise InputError(f'criterion must be one of {", ".join(CRITERIA)}, not {criterion!r}')
    rows = [c for c in grid() if c['configuration'] in configurations]
    workers = workers or min(2, os.cpu_count() or 1)
    _preload(model)
    parts = balanced_parts(rows, workers)
    jobs = [(part, terrain, model) for part in parts]
    if engine is not None:
        done = engine.map(evaluate_chunk, jobs, label='design study', heavy=True)
    elif workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            done = list(pool.map(evaluate_chunk, jobs))
    else:
        done = [evaluate_chunk(job) for job in jobs]
    evaluated = score(sorted(itertools.chain.from_iterable(done), key=lambda c: c['index']), terrain)
    best = best_per_configuration(evaluated, criterion)
    return {
        'terrain': terrain.name,
        'model': model,
        'speed_m_s': SPEED_M_S,
        'turn_radius_m': TURN_RADIUS_M,
        'criterion': criterion,
        'criterion_text': CRITERION_TEXT[criterion],
        'n_candidates': len(evaluated),
        'n_converged': sum(c['converged'] for c in evaluated),
        'best': {k: v for k, v in best.items() if v is not None and k in configurations},
        'candidates': evaluated,
    }


def score(evaluated: list[JsonObject], terrain: Terrain) -> list[JsonObject]:
    """Add max drawbar pull [N], its ratio to the weight [-] and the merit [1/W] to solved candidates."""
    dp = max_drawbar_pull([candidate_vehicle(c) for c in evaluated], terrain)
    for c, pull in zip(evaluated, dp, strict=True):
        weight = c['mass_kg'] * GRAVITY_M_S2
        c['max_drawbar_pull_N'] = float(pull)
        c['drawbar_pull_ratio'] = float(pull / weight)
        c['merit'] = _merit(c)
    return evaluated


def best_per_configuration(evaluated: list[JsonObject], criterion: str) -> dict[str, JsonObject | None]:
    """Configuration -> its best scored candidate by ``criterion`` (None if none is eligible)."""
    return {
        config: _best([c for c in evaluated if c['configuration'] == config], criterion)
        for config in CONFIGURATIONS
    }


def _preload(model: str) -> None:
    """Import the model before forking, so every worker runs the same code and skips the import."""
    from skidsteer_power.models import MODELS

    if model not in MODELS:
        raise InputError(f'unknown model {model!r}; choose one of {", ".join(MODELS)}')
    importlib.import_module(MODELS[model])


_TRACK_COST, _WHEEL_COST, _WHEEL_TABLE_COST = 1.6, 2.5, 3.0  # ms, measured (see module doc)


def balanced_parts(rows: list[JsonObject], parts: int) -> list[list[JsonObject]]:
    """Split the grid into ``parts`` contiguous pieces of about equal estimated cost."""
    cost = np.array([_TRACK_COST if c['configuration'] == 'track' else _WHEEL_COST for c in rows])
    first_of_group = np.array([k % (len(LENGTHS_M) * len(TREADS_M)) == 0 for k in range(len(rows))])
    cost = cost + np.where(first_of_group & (cost == _WHEEL_COST), _WHEEL_TABLE_COST, 0.0)
    cumulative = np.cumsum(cost)
    cuts = np.searchsorted(cumulative, cumulative[-1] * np.arange(1, parts) / parts)
    bounds = [0, *cuts.tolist(), len(rows)]
    return [rows[a:b] for a, b in itertools.pairwise(bounds) if b > a]


CRITERION_TEXT = {
    'merit': 'max (max drawbar pull / weight) / mean power of the straight and R = 2 m manoeuvres [1/W]',
    'power': 'min mean power of the straight and R = 2 m manoeuvres',
    'mobility': 'max (max drawbar pull / weight)',
}


def _merit(c: JsonObject) -> float | None:
    if not c['converged']:
        return None
    mean_power = 0.5 * (c['power_straight_W'] + c['power_turning_W'])
    return c['drawbar_pull_ratio'] / mean_power if mean_power > 0 else None


def _best(rows: list[JsonObject], criterion: str) -> JsonObject | None:
    eligible = [c for c in rows if c['converged'] and c['max_drawbar_pull_N'] > 0 and c['merit'] is not None]
    if not eligible:
        return None
    if criterion == 'merit':
        return max(eligible, key=lambda c: (c['merit'], -c['index']))
    if criterion == 'power':
        return min(eligible, key=lambda c: (c['power_straight_W'] + c['power_turning_W'], c['index']))
    return max(eligible, key=lambda c: (c['drawbar_pull_ratio'], -c['index']))
