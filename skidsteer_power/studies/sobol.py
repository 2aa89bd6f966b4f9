"""Variance-based (Sobol) sensitivity of a mission to uncertain terrain and powertrain parameters.

Complements the one-at-a-time table of :mod:`skidsteer_power.missions.sensitivity` (ch. 8.2, +-1 %
around one point): here every parameter varies over its whole spread at once
(:mod:`skidsteer_power.studies.uncertainty`: normal, defaults or ``--uncertainty FILE.yaml``), and
each metric's variance is split into first-order indices S1 (the share explained by one parameter
alone) and total indices ST (its share including every interaction), with bootstrap 95 % confidence
half-widths. Saltelli's sampling and the Jansen/Saltelli estimators are SALib's
(``SALib.sample.sobol``, ``SALib.analyze.sobol``, without second-order terms): N base samples give
N (D + 2) mission runs for D parameters, run as tasks on the study's Dask engine.

Reading: sum(S1) close to 1 means the metric is nearly additive in the parameters; ST - S1 is what
a parameter contributes only through interactions; a parameter with ST ~ 0 can be fixed anywhere
in its spread. Parameters with a zero spread are left out (they have no variance to explain).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.missions.routes import Route
from skidsteer_power.studies.uncertainty import (
    ParameterSpread,
    apply_powertrain,
    apply_terrain,
    clip,
    nominal_values,
)

if TYPE_CHECKING:
    from skidsteer_power.distributed.engine import Engine
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

METRICS = ('energy_J', 'drawbar_pull_ratio', 'max_sinkage_m')


def _task(job: tuple[Vehicle, Terrain, Route, Powertrain, str, str]) -> tuple[float, ...]:
    from skidsteer_power.missions.energy import run_mission

    vehicle, terrain, route, powertrain, source, model = job
    summary = run_mission(
        vehicle, terrain, route, source=source, model=model, powertrain=powertrain
    ).summary()
    return tuple(float(summary[m]) for m in METRICS)


def sobol_indices(
    engine: Engine,
    vehicles: list[Vehicle],
    terrain: Terrain,
    route: Route,
    spread: ParameterSpread,
    *,
    samples: int = 64,
    seed: int = 0,
    source: str = 'map',
    model: str = 'fess',
) -> JsonObject:
    """S1, ST and their 95 % confidence half-widths per vehicle, metric and parameter (module doc).

    ``samples`` is SALib's N (ideally a power of 2); the mission runs N (D + 2) times per vehicle.
    """
    from SALib.analyze import sobol as analyze
    from SALib.sample import sobol as sample

    from skidsteer_power.errors import InputError
    from skidsteer_power.powertrain import Powertrain

    if samples < 2:
        raise InputError(f'Sobol indices need --samples >= 2 (a power of 2, e.g. 64), not {samples}')
    sigma = spread.sigma
    names = [n for n in spread.names if sigma[n] > 0]
    if not names:
        raise InputError(f'{spread.source}: every parameter has a zero spread')
    out: JsonObject = {}
    runs = 0
    for vehicle in vehicles:
        powertrain = Powertrain.for_vehicle(vehicle)
        nominal = nominal_values(names, terrain, powertrain)
        problem = {
            'num_vars': len(names),
            'names': names,
            'bounds': [[float(m), sigma[n]] for m, n in zip(nominal, names, strict=True)],
            'dists': ['norm'] * len(names),
        }
        x = clip(names, sample.sample(problem, samples, calc_second_order=False, seed=seed))
        sets = [dict(zip(names, row.tolist(), strict=True)) for row in x]
        jobs = [
            (vehicle, apply_terrain(terrain, s), route, apply_powertrain(powertrain, s), source, model)
            for s in sets
        ]
        y = np.asarray(engine.map(_task, jobs, label=f'Sobol {vehicle.name}: {len(jobs)} missions'))
        runs += len(jobs)
        per_metric = {}
        for k, metric in enumerate(METRICS):
            res = analyze.analyze(problem, y[:, k], calc_second_order=False, seed=seed)
            per_metric[metric] = {
                name: {key: float(res[key][i]) for key in ('S1', 'S1_conf', 'ST', 'ST_conf')}
                for i, name in enumerate(names)
            }
        out[vehicle.name] = per_metric
    return {
        'method': 'sobol (SALib Saltelli sampling, no second order)',
        'base_samples': samples,
        'runs': runs,
        'seed': seed,
        'parameters': names,
        'spread': spread.source,
        'sigma_SI': {n: sigma[n] for n in names},
        'engine': engine.description,
        'indices': out,
    }
