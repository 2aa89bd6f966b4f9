"""Experiment design for calibration: which holds to drive next (``calibrate --suggest``, issue 27).

The fit's information about the free parameters (search coordinates z: ln of the moduli, n and phi
[deg] themselves) is the Gauss-Newton Fisher information F = J^T J / s^2 of the residual Jacobian J
[N m per z unit] at the optimum, and the 95 % interval of parameter k is z_k +- t sqrt((F^-1)_kk)
(fit.py). One more steady segment held at (V [m/s], yaw rate [rad/s]) adds its two torque rows j
(left, right motor torque derivatives, by forward differences of FESS at the fitted terrain, solved
as the fit was: at that command's wheel speed set points, or with ``fit_at`` 'motion' at that
motion): F' = F + j^T j / s^2. The widest interval is the one widest relative to its parameter
(for a log parameter the z interval is already relative). Holds are chosen greedily from a grid
over the vehicle's command envelope, each the one that most shrinks that parameter's variance given
the ones chosen before (D_s-optimal for one parameter, sequential design); 2 to :data:`MAX_HOLDS`
of them, stopping after 2 once a hold shrinks the interval by less than :data:`MIN_GAIN`.
A parameter at a bound or held fixed is not in the design (it has no interval to shrink).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from skidsteer_power.calibration.fit import PARAMS, CalibrationResult, Model, _from_z

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.vehicle import Vehicle

MAX_HOLDS = 4
MIN_GAIN = 0.05  # a further hold must shrink the widest interval by at least this fraction
STEP_Z = 1e-3  # forward-difference step in z
GRID = 7  # candidate values per axis


def candidate_grid(vehicle: Vehicle, max_speed_m_s: float = 1.0, max_yaw_rad_s: float = 1.0) -> np.ndarray:
    """(C, 2) candidate holds (V [m/s], yaw rate [rad/s]) inside the vehicle's command envelope."""
    speeds = np.linspace(0.05, min(vehicle.max_speed_m_s, max_speed_m_s), GRID)
    yaws = np.linspace(0.0, min(vehicle.max_yaw_rate_rad_s, max_yaw_rad_s), GRID)
    return np.array([(v, w) for v in speeds for w in yaws])


def relative_width(result: CalibrationResult, name: str) -> float:
    """Width of ``name``'s 95 % interval relative to its value [-] (inf without an interval)."""
    ci = result.ci95.get(name)
    value = result.values[name]
    return (ci[1] - ci[0]) / abs(value) if ci is not None and value != 0 else math.inf


def suggest_holds(
    vehicle: Vehicle, result: CalibrationResult, candidates: np.ndarray | None = None
) -> JsonObject:
    """The holds that most shrink the widest interval of ``result`` (module doc)."""
    free = [n for n in result.names if n not in result.at_bound and result.ci95.get(n) is not None]
    if not free or result.jacobian_z.size == 0:
        return {'widest_parameter': None, 'holds': [], 'note': 'no fitted parameter with an interval'}
    widest = max(free, key=lambda n: relative_width(result, n))
    columns = [result.names.index(n) for n in free]
    jac = result.jacobian_z[:, columns]
    s2 = max(result.residual_variance, 1e-12)
    info = jac.T @ jac / s2
    candidates = candidate_grid(vehicle) if candidates is None else np.asarray(candidates, dtype=float)
    rows, ok = _candidate_rows(vehicle, result, free, candidates)
    w = free.index(widest)
    dof = max(1, jac.shape[0] - len(free))
    t = float(stats.t.ppf(0.975, dof))
    z = float(result.z[result.names.index(widest)])

    def interval(matrix: np.ndarray) -> list[float]:
        sigma = math.sqrt(max(float(np.linalg.pinv(matrix)[w, w]), 0.0))
        return [_from_z(widest, z - t * sigma), _from_z(widest, z + t * sigma)]

    chosen: list[dict[str, float | list[float]]] = []
    used = np.zeros(len(candidates), bool)
    current = info
    variance = float(np.linalg.pinv(current)[w, w])
    while len(chosen) < MAX_HOLDS:
        best, best_var = -1, variance
        for c in np.flatnonzero(ok & ~used):
            trial = float(np.linalg.pinv(current + rows[c].T @ rows[c] / s2)[w, w])
            if trial < best_var:
                best, best_var = int(c), trial
        if best < 0 or (len(chosen) >= 2 and 1 - math.sqrt(best_var / variance) < MIN_GAIN):
            break
        used[best] = True
        current = current + rows[best].T @ rows[best] / s2
        variance = best_var
        chosen.append(
            {
                'speed_m_s': float(candidates[best, 0]),
                'yaw_rate_rad_s': float(candidates[best, 1]),
                f'{widest}_ci95_after': interval(current),
            }
        )
    return {
        'widest_parameter': widest,
        'unit': PARAMS[widest].unit,
        'ci95_now': list(result.ci95[widest] or []),
        'holds': chosen,
        'candidates': int(ok.sum()),
    }


def _candidate_rows(
    vehicle: Vehicle, result: CalibrationResult, free: list[str], candidates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(C, 2, p) motor-torque derivatives [N m per z unit] at each candidate, and which solved."""
    model = Model(
        vehicle, result.terrain, result.powertrain, candidates[:, 0], candidates[:, 1], result.fit_at
    )
    base, _, ok = model.predict({})
    rows = np.zeros((len(candidates), 2, len(free)))
    for k, name in enumerate(free):
        z = float(result.z[result.names.index(name)])
        torque, _, ok_k = model.predict({name: _from_z(name, z + STEP_Z)})
        rows[:, :, k] = (torque - base) / STEP_Z
        ok &= ok_k
    ok &= np.all(np.isfinite(rows), axis=(1, 2))
    return rows, ok
