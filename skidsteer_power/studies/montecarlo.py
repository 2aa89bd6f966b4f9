"""Missions and the design study under uncertain terrain and powertrain (issue 19; ch. 8.2's scatter).

Every sample is a full model run with its own terrain and powertrain (:mod:`.uncertainty`): for a
mission, the FESS power map of the sampled terrain is built in memory (0.1 s for a track, 1-2 s for
wheels; nothing is cached, so a thousand samples leave no thousand maps behind) and the route goes
through :func:`skidsteer_power.missions.energy.run_mission`; for the design study, the 729 Table 8.4
candidates are solved directly, as in :func:`skidsteer_power.missions.design.design_study`. Samples are
drawn on the caller's side before any task starts, so the result of a seed does not depend on where
or in what order the tasks ran (:class:`skidsteer_power.distributed.engine.Engine`).

Percentiles are numpy's linear-interpolation percentiles of the samples (p05, p50, p95).
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from skidsteer_power.missions.routes import Route
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.studies.uncertainty import ParameterSpread, apply_powertrain, apply_terrain, draw

if TYPE_CHECKING:
    from skidsteer_power.distributed.engine import Engine
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

PERCENTILES = (5, 50, 95)
MISSION_KEYS = ('energy_J', 'energy_battery_J', 'energy_terrain_J', 'energy_internal_J')


def percentiles(values: ArrayLike, prefix: str) -> dict[str, float]:
    """``{prefix_p05, prefix_p50, prefix_p95}`` of the finite values (nan if none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return {f'{prefix}_p{p:02d}': float(np.percentile(v, p)) if v.size else float('nan') for p in PERCENTILES}


# ----------------------------------------------------------------------------------------- mission
def _mission_task(job: tuple[Vehicle, Terrain, Route, Powertrain, str, str]) -> dict[str, float]:
    from skidsteer_power.missions.energy import run_mission

    vehicle, terrain, route, powertrain, source, model = job
    result = run_mission(vehicle, terrain, route, source=source, model=model, powertrain=powertrain)
    summary = result.summary()
    return {k: float(summary[k]) for k in (*MISSION_KEYS, 'clamped_segments', 'limited_segments')}


def mission_uncertainty(
    engine: Engine,
    vehicle: Vehicle,
    terrain: Terrain,
    route: Route,
    powertrain: Powertrain,
    spread: ParameterSpread,
    *,
    samples: int,
    seed: int = 0,
    method: str = 'sobol',
    source: str = 'map',
    model: str = 'fess',
) -> JsonObject:
    """Energy percentiles of ``route`` over ``samples`` draws of ``spread`` (module doc).

    Returns energy_J_p05/p50/p95 (terrain + internal, the mission's ``energy_J``),
    energy_battery_J_p05/p50/p95 and an ``uncertainty`` block (samples, seed, method, source of the
    spread, sigmas, samples with a map query flagged clamped or limited).
    """
    sets = draw(spread, terrain, powertrain, samples, seed, method)
    jobs = [
        (vehicle, apply_terrain(terrain, s), route, apply_powertrain(powertrain, s), source, model)
        for s in sets
    ]
    results = engine.map(_mission_task, jobs, label=f'mission x {samples} samples')
    out: JsonObject = {}
    for key in ('energy_J', 'energy_battery_J'):
        out |= percentiles([r[key] for r in results], key)
    out['uncertainty'] = {
        'samples': samples,
        'seed': seed,
        'method': method,
        'spread': spread.source,
        'sigma_SI': spread.sigma,
        'samples_clamped': int(sum(r['clamped_segments'] > 0 for r in results)),
        'samples_limited': int(sum(r['limited_segments'] > 0 for r in results)),
        'energy_J_mean': float(np.mean([r['energy_J'] for r in results])),
        'energy_J_std': float(np.std([r['energy_J'] for r in results], ddof=1)) if samples > 1 else 0.0,
        'engine': engine.description,
    }
    return out


# ------------------------------------------------------------------------------------ design study
def _design_task(
    job: tuple[int, list[JsonObject], Terrain, str, dict[str, float]],
) -> list[tuple[int, float | None, bool]]:
    """(candidate index, merit, usable) of one sample's design-grid chunk."""
    from skidsteer_power.missions.design import evaluate_chunk, score

    _sample, rows, terrain, model, pt_sample = job
    scored = score(evaluate_chunk((rows, terrain, model, pt_sample)), terrain)
    return [
        (c['index'], c['merit'], c['converged'] and c['max_drawbar_pull_N'] > 0 and c['merit'] is not None)
        for c in scored
    ]


def design_uncertainty(
    engine: Engine,
    terrain: Terrain,
    spread: ParameterSpread,
    *,
    samples: int,
    seed: int = 0,
    method: str = 'sobol',
    model: str = 'fess',
    rows: list[JsonObject] | None = None,
    parts_per_sample: int = 3,
) -> JsonObject:
    """The design study repeated over ``samples`` draws (criterion: merit).

    Returns per configuration the probability that each candidate is the best (those best at least
    once, most likely first) and, per candidate index, merit_p05/p50/p95 and p_best. ``rows`` limits
    the grid (default: all 729 of Table 8.4); each sample is split into ``parts_per_sample`` tasks.
    """
    from skidsteer_power.errors import InputError
    from skidsteer_power.missions.design import balanced_parts, grid

    sides = [n for n in spread.names if n.startswith(('left_', 'right_'))]
    if sides:
        raise InputError(
            f'the design study varies the powertrain by internal_scale only, not {", ".join(sides)}'
        )
    rows = grid() if rows is None else rows
    nominal_pt = Powertrain.default_test_robot('track')
    sets = draw(spread, terrain, nominal_pt, samples, seed, method)
    parts = balanced_parts(rows, parts_per_sample)
    pt_names = [n for n in spread.names if not hasattr(terrain, n)]
    jobs = [
        (k, part, apply_terrain(terrain, s), model, {n: s[n] for n in pt_names})
        for k, s in enumerate(sets)
        for part in parts
    ]
    done = engine.map(_design_task, jobs, label=f'design study x {samples} samples', heavy=True)
    by_row = {r['index']: r for r in rows}
    merit: dict[int, list[float]] = {r['index']: [] for r in rows}
    wins: dict[str, Counter[int]] = {}
    per_sample = len(parts)
    for k in range(samples):
        flat = [t for chunk in done[k * per_sample : (k + 1) * per_sample] for t in chunk]
        best: dict[str, tuple[float | None, int]] = {}  # m is None only where not eligible
        for index, m, eligible in flat:
            merit[index].append(m if m is not None else np.nan)
            config = by_row[index]['configuration']
            if eligible and (config not in best or (m, -index) > (best[config][0], -best[config][1])):
                best[config] = (m, index)
        for config, (_m, index) in best.items():
            wins.setdefault(config, Counter())[index] += 1
    stats = {
        index: percentiles(values, 'merit')
        | {'p_best': wins.get(by_row[index]['configuration'], Counter())[index] / samples}
        for index, values in merit.items()
    }
    best_probability = {
        config: [
            {k: by_row[i][k] for k in by_row[i] if k != 'index'} | {'index': i} | stats[i]
            for i, _n in counter.most_common()
        ]
        for config, counter in wins.items()
    }
    return {
        'best_probability': best_probability,
        'candidate_stats': stats,
        'uncertainty': {
            'samples': samples,
            'seed': seed,
            'method': method,
            'spread': spread.source,
            'sigma_SI': spread.sigma,
            'criterion': 'merit',
            'engine': engine.description,
            'tasks': len(jobs),
        },
    }
