"""Sensitivity of a mission to the soil parameters (ch. 8.2): each of n, k_c, k_phi, c, phi, K changed
by +-1 %, and all of them at once, for each vehicle; relative changes of energy, mobility (max drawbar
pull / weight) and max sinkage. Cases run in parallel processes (concurrent.futures)."""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from skidsteer_power.missions.energy import run_mission
from skidsteer_power.missions.routes import Route

SOIL_PARAMETERS = ('n', 'kc', 'kphi', 'c', 'phi', 'K')
METRICS = ('energy_J', 'drawbar_pull_ratio', 'max_sinkage_m')


def perturbed(terrain: Any, parameters: tuple[str, ...], factor: float) -> Any:
    """``terrain`` with each named parameter multiplied by ``factor`` [-]."""
    changes = {p: getattr(terrain, p) * factor for p in parameters}
    return dataclasses.replace(terrain, name=f'{terrain.name}*', **changes)


def cases(delta: float) -> dict[str, tuple[tuple[str, ...], float]]:
    """Case label -> (parameters changed, factor): 'baseline', '<p>+', '<p>-', 'all+', 'all-'."""
    out: dict[str, tuple[tuple[str, ...], float]] = {'baseline': ((), 1.0)}
    for p in SOIL_PARAMETERS:
        out[f'{p}+'] = ((p,), 1.0 + delta)
        out[f'{p}-'] = ((p,), 1.0 - delta)
    out['all+'] = (SOIL_PARAMETERS, 1.0 + delta)
    out['all-'] = (SOIL_PARAMETERS, 1.0 - delta)
    return out


def _metrics(job: tuple[Any, Any, Route, str, str]) -> dict[str, float]:
    vehicle, terrain, route, source, model = job
    summary = run_mission(vehicle, terrain, route, source=source, model=model).summary()
    return {m: float(summary[m]) for m in METRICS}


def sensitivity(
    vehicles: list[Any],
    terrain: Any,
    route: Route,
    *,
    delta: float = 0.01,
    source: str = 'map',
    model: str = 'fess',
    workers: int | None = None,
) -> dict[str, Any]:
    """Run every case for every vehicle; returns baseline values and per-case changes in percent."""
    labels = cases(delta)
    jobs = [
        (v, perturbed(terrain, params, factor), route, source, model)
        for v in vehicles
        for params, factor in labels.values()
    ]
    workers = workers or min(len(jobs), os.cpu_count() or 1)
    if workers > 1:
        # loaded before forking, so every worker runs the same code and skips the import
        import skidsteer_power.maps
        import skidsteer_power.models.fess  # noqa: F401

        with ProcessPoolExecutor(max_workers=workers) as pool:
            values = list(pool.map(_metrics, jobs))
    else:
        values = [_metrics(job) for job in jobs]
    results: dict[str, Any] = {}
    per_vehicle = len(labels)
    for k, vehicle in enumerate(vehicles):
        chunk = dict(zip(labels, values[k * per_vehicle : (k + 1) * per_vehicle], strict=True))
        base = chunk.pop('baseline')
        results[vehicle.name] = {
            'baseline': base,
            'changes_percent': {
                label: {m: 100.0 * (vals[m] - base[m]) / base[m] if base[m] else 0.0 for m in METRICS}
                for label, vals in chunk.items()
            },
        }
    return {
        'terrain': terrain.name,
        'route': route.name,
        'synthetic_route': route.synthetic,
        'delta': delta,
        'parameters': list(SOIL_PARAMETERS),
        'model': model,
        'source': source,
        'results': results,
    }
