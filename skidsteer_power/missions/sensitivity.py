"""Sensitivity of a mission to the soil parameters (ch. 8.2): each of n, k_c, k_phi, c, phi, K changed
by +-1 %, and all of them at once, for each vehicle; relative changes of energy, mobility (max drawbar
pull / weight) and max sinkage. Cases run in parallel processes (concurrent.futures).

Every case is a converged DIRECT solve of the route's states (``source='direct'``): a map's
interpolation error (largest near the traction limit) is of the order of a 1 % change and would
show up as noise. The derivative is the central difference (f(+h) - f(-h)) / 2h, in percent of the
baseline per percent of the parameter. A case is flagged ``non_smooth`` (and its derivative not
reported as a number) when the one-sided changes f(+h) - f(0) and f(0) - f(-h) disagree in sign
with the central derivative (e.g. both signs lowering the energy: the response is not smooth there,
typically at the traction limit), and ``failed`` when a solve did not converge.
"""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING

from skidsteer_power.errors import ConvergenceError
from skidsteer_power.missions.energy import run_mission
from skidsteer_power.missions.routes import Route

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

SOIL_PARAMETERS = ('n', 'kc', 'kphi', 'c', 'phi', 'K')
METRICS = ('energy_J', 'drawbar_pull_ratio', 'max_sinkage_m')


def perturbed(terrain: Terrain, parameters: tuple[str, ...], factor: float) -> Terrain:
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


def _metrics(job: tuple[Vehicle, Terrain, Route, str, str]) -> dict[str, float] | None:
    """The case's metrics; None when a solve did not converge."""
    vehicle, terrain, route, source, model = job
    try:
        summary = run_mission(vehicle, terrain, route, source=source, model=model).summary()
    except ConvergenceError:
        return None
    return {m: float(summary[m]) for m in METRICS}


SMOOTH_TOLERANCE = 1e-9  # relative changes below this count as zero (no sign)


def derivatives(
    base: dict[str, float], plus: dict[str, float] | None, minus: dict[str, float] | None, delta: float
) -> dict[str, dict[str, float | str | None]]:
    """Central-difference derivatives [% per %] of each metric and whether each is smooth.

    Returns {metric: {'derivative': value or None, 'status': 'ok' | 'non_smooth' | 'failed'}}.
    """
    out: dict[str, dict[str, float | str | None]] = {}
    for m in METRICS:
        if plus is None or minus is None or not base[m]:
            out[m] = {'derivative': None, 'status': 'failed'}
            continue
        up, down = (plus[m] - base[m]) / abs(base[m]), (base[m] - minus[m]) / abs(base[m])
        central = (up + down) / (2.0 * delta)  # (f(+h) - f(-h)) / 2h, relative to f(0)
        sign = 0 if abs(central * delta) < SMOOTH_TOLERANCE else (1 if central > 0 else -1)
        sides = [0 if abs(x) < SMOOTH_TOLERANCE else (1 if x > 0 else -1) for x in (up, down)]
        smooth = all(side == sign for side in sides)
        out[m] = {'derivative': central if smooth else None, 'status': 'ok' if smooth else 'non_smooth'}
    return out


def sensitivity(
    vehicles: list[Vehicle],
    terrain: Terrain,
    route: Route,
    *,
    delta: float = 0.01,
    source: str = 'direct',
    model: str = 'fess',
    workers: int | None = None,
) -> JsonObject:
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
    results: JsonObject = {}
    per_vehicle = len(labels)
    for k, vehicle in enumerate(vehicles):
        chunk = dict(zip(labels, values[k * per_vehicle : (k + 1) * per_vehicle], strict=True))
        base = chunk.pop('baseline')
        if base is None:
            results[vehicle.name] = {
                'baseline': None,
                'failed': True,
                'changes_percent': {},
                'derivatives': {},
            }
            continue
        results[vehicle.name] = {
            'baseline': base,
            'changes_percent': {
                label: (
                    None
                    if vals is None
                    else {m: 100.0 * (vals[m] - base[m]) / base[m] if base[m] else 0.0 for m in METRICS}
                )
                for label, vals in chunk.items()
            },
            'derivatives': {
                group: derivatives(base, chunk[f'{group}+'], chunk[f'{group}-'], delta)
                for group in (*SOIL_PARAMETERS, 'all')
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
