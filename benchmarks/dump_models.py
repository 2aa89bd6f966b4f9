"""Dump every solver's outputs on a fixed grid, for a before / after comparison of a refactor.

    python -m benchmarks.dump_models OUT.npz            # write the dump
    python -m benchmarks.dump_models --compare A.npz B.npz  # which arrays differ, and by how much

Not a benchmark (no ``bench_`` prefix: ``benchmarks.run`` skips it). Every model name of
:data:`skidsteer_power.models.MODELS` on a (V, R) grid for every shipped vehicle on every soil preset
(the rigid-ground terrain files for FESS only), FESS's one-point path
(:meth:`FessSolver.solve_point`), the set-point solve, the direct command prediction and a small
set-point map's queries. A point a model cannot solve is stored as its error message's hash (so a
change of which points fail shows too). Issue 38: "model outputs ... bit-identical before and after".
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path
from typing import Any

import numpy as np

from skidsteer_power.errors import SkidsteerError
from skidsteer_power.models import MODELS, RIGID_GROUND_MODELS, solve
from skidsteer_power.terramechanics.terrain import PRESETS, load_terrain
from skidsteer_power.vehicle import load_vehicle

VEHICLES = (
    'chapter3_track', 'chapter4_4wheel', 'test_robot_track', 'test_robot_4wheel', 'test_robot_6wheel',
    'packbot_track', 'packbot_4wheel', 'packbot_6wheel', 'husky_a200', 'jackal', 'leo_rover',
)  # fmt: skip
RIGID = ('asphalt', 'concrete', 'flooring', 'grass', 'ice')
SPEEDS = np.array([0.05, 0.3, 0.8])  # [m/s]
RADII = np.array([np.inf, 8.0, 1.5, -0.6, 0.3])  # [m]
COMMANDS = np.array([[0.0, 0.0], [0.4, 0.0], [-0.3, 0.2], [0.5, 0.8], [0.1, -1.5], [0.0, 1.0]])  # (V, w)
SETPOINT_NODES = (5, 5)


def _error(err: Exception) -> np.ndarray:
    digest = hashlib.sha256(f'{type(err).__name__}: {err}'.encode()).digest()[:8]
    return np.frombuffer(digest, dtype=np.float64).copy()


def _state(out: dict[str, np.ndarray], key: str, fn: Any) -> None:
    try:
        state = fn()
    except (SkidsteerError, ValueError, ArithmeticError) as err:
        out[key + '/error'] = _error(err)
        return
    for name, value in vars(state).items():
        if isinstance(value, np.ndarray):
            out[f'{key}/{name}'] = value
        elif name == 'reason':
            out[f'{key}/reason'] = np.array([hash_text(r) for r in value])
        elif name == 'extra':
            for k, v in value.items():
                if k != 'solve_time_s':
                    out[f'{key}/extra/{k}'] = np.asarray(v)


def hash_text(text: str) -> float:
    """A reason string as a float (its hash), so it lives in one npz array."""
    return float(np.frombuffer(hashlib.sha256(text.encode()).digest()[:8], dtype=np.float64)[0])


def dump() -> dict[str, np.ndarray]:
    from skidsteer_power.maps.setpoint_map import SetpointMap
    from skidsteer_power.models.fess import FessSolver
    from skidsteer_power.models.predict import CommandPredictor

    v, r = np.meshgrid(SPEEDS, RADII, indexing='ij')
    out: dict[str, np.ndarray] = {}
    terrains = [load_terrain(t) for t in (*PRESETS, *RIGID)]
    for vname in VEHICLES:
        veh = load_vehicle(vname)
        for ter in terrains:
            tag = f'{vname}/{ter.name}'
            print(tag, file=sys.stderr, flush=True)
            for model in MODELS:
                if ter.is_rigid and model not in RIGID_GROUND_MODELS:
                    continue
                if model == 'fast' and not veh.is_tracked:
                    continue
                _state(out, f'{tag}/{model}', lambda m=model, a=veh, b=ter: solve(a, b, v, r, m))
            solver = FessSolver(veh, ter)
            rows = []
            for cv, cw in COMMANDS:
                try:
                    p = solver.solve_point(cv, cw)
                    rows.append([p.s0, *p.omega, *p.torque, float(p.converged), float(p.iterations)])
                except (SkidsteerError, ValueError, ArithmeticError) as err:
                    rows.append([*_error(err), *([np.nan] * 6)])
            out[f'{tag}/point'] = np.array(rows)
            try:
                pred = CommandPredictor(veh, ter)
            except (SkidsteerError, ValueError) as err:
                out[f'{tag}/predict/error'] = _error(err)
                continue
            sp, _ = pred.setpoints(COMMANDS[:, 0], COMMANDS[:, 1])
            _state(out, f'{tag}/setpoint', lambda p=pred, s=sp: p.solver.solve(s))
            _state(out, f'{tag}/predict', lambda p=pred: p.predict(COMMANDS[:, 0], COMMANDS[:, 1]))
            try:
                smap = SetpointMap.build(veh, ter, SETPOINT_NODES, pred)
            except (SkidsteerError, ValueError) as err:
                out[f'{tag}/map/error'] = _error(err)
                continue
            out[f'{tag}/map/values'] = smap.grid.values
            out[f'{tag}/map/checked'] = smap.checked
            queries = []
            for cv, cw in COMMANDS:
                q = smap.query(cv, cw)
                queries.append([
                    *(getattr(q, f) for f in q.__dataclass_fields__ if f not in ('reason', 'motors')),
                    hash_text(q.reason),
                ])  # fmt: skip
            out[f'{tag}/map/query'] = np.array(queries, dtype=float)
    return out


def compare(a_path: Path, b_path: Path) -> int:
    """Print every array that differs between two dumps (largest abs and relative difference)."""
    a, b = np.load(a_path), np.load(b_path)
    keys = sorted(set(a.files) | set(b.files))
    differ = 0
    for key in keys:
        if key not in a.files or key not in b.files:
            print(f'{key}: only in {"after" if key in b.files else "before"}')
            differ += 1
            continue
        x, y = a[key], b[key]
        if x.shape != y.shape:
            print(f'{key}: shape {x.shape} -> {y.shape}')
            differ += 1
            continue
        same = (x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == 'f' else x == y
        if np.all(same):
            continue
        differ += 1
        with np.errstate(invalid='ignore', divide='ignore'):
            d = np.abs(x.astype(float) - y.astype(float))
            rel = d / np.maximum(np.abs(x.astype(float)), 1e-300)
        count = int(np.sum(~same))
        print(f'{key}: {count} of {x.size} differ, max |d| {np.nanmax(d):.3g}, rel {np.nanmax(rel):.3g}')
    print(f'{len(keys)} arrays, {differ} differ')
    return 1 if differ else 0


def main(argv: list[str]) -> int:
    if argv[:1] == ['--compare'] and len(argv) == 3:
        return compare(Path(argv[1]), Path(argv[2]))
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    data: dict[str, Any] = dump()
    np.savez(argv[0], **data)
    return 0


if __name__ == '__main__':
    raise SystemExit(main(sys.argv[1:]))
