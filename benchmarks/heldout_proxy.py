"""A PROXY of issue 35's held-out check, "a robot you don't have, calibrated on half of its drive,
predicts the other half's measured V x I energy within 15 % and better than the linear fit": the
whole path a new user takes, through the real command line, on bags of a robot whose motor nobody
modelled. It is no real robot: the recordings come from the project's dynamic twin
(``skidsteer-power simulate``: its own contact laws, motor dynamics and sensor noise, never FESS or
the maps), driving a Husky A200 with the husky_a200 powertrain; the user's vehicle file knows the
Husky's geometry only, with ``powertrain: {preset: effective}`` (every loss term neutral) and the
twin's ``battery/measured`` (sensor_msgs/BatteryState, the whole robot's V x I) as ``measured_power``.

Per case: two teleop-like command files (holds of 1-8 s: straights, turns, spins, reversing,
stops, each with the twin's own accelerations), one simulated bag each; ``calibrate --fit auto
--out-vehicle --out-terrain`` on the first; ``validate`` on the second with the written vehicle
and terrain. The simplest alternative, P = a|v| + b|w| + c of the commanded (v, w), is fitted by
least squares to the first bag's validate rows and predicts the second's. Both energies integrate
validate's rows the same way (each row held until the next).
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from skidsteer_power.resources import find

VEHICLE = 'husky_a200'
GEAR_RATIO = 79.0  # the twin's joint_states are at the motor (husky_a200 powertrain, config/powertrains)
BUS_V = 24.0  # the Husky's nominal bus (config/powertrains/husky_a200.yaml)


@dataclass(frozen=True)
class Case:
    terrain: str
    seed: int
    seconds: float = 150.0


@dataclass(frozen=True)
class Outcome:
    """Energy errors of the second half, predicted / measured - 1 [%]."""

    case: Case
    start_pct: float  # the effective powertrain's neutral start, uncalibrated
    calibrated_pct: float
    linear_pct: float
    measured_J: float
    fitted: str  # what calibrate fitted


Command = tuple[float, float]


def teleop_commands(path: Path, seconds: float, seed: int, pick: Callable[[random.Random], Command]) -> Path:
    """A teleop-like command CSV (t_s, speed_m_s, yaw_rate_rad_s): holds of 1-8 s, each command
    ``pick(rng)`` [m/s, rad/s], ending at rest."""
    rng = random.Random(seed)
    rows, t = ['t_s,speed_m_s,yaw_rate_rad_s'], 0.0
    while t < seconds:
        v, w = pick(rng)
        rows.append(f'{t:.2f},{v:.3f},{w:.3f}')
        t += rng.uniform(1.0, 8.0)
    rows.append(f'{t:.2f},0,0')
    path.write_text('\n'.join(rows) + '\n')
    return path


def _energy_mix(rng: random.Random) -> Command:
    """Stops, straights, turns, spins to 1.5 rad/s and slow reversing."""
    kind = rng.random()
    if kind < 0.15:
        return 0.0, 0.0
    if kind < 0.35:
        return rng.uniform(0.2, 1.0), 0.0
    if kind < 0.7:
        return rng.uniform(0.1, 0.9), rng.uniform(-1.0, 1.0)
    if kind < 0.85:
        return 0.0, rng.choice((-1.0, 1.0)) * rng.uniform(0.3, 1.5)
    return -rng.uniform(0.1, 0.5), rng.uniform(-0.3, 0.3)


def commands(path: Path, seconds: float, seed: int) -> Path:
    """The energy proxy's command CSV (:func:`teleop_commands` of :func:`_energy_mix`)."""
    return teleop_commands(path, seconds, seed, _energy_mix)


def user_vehicle(path: Path) -> Path:
    """The Husky's geometry with an effective powertrain and the twin's battery topic."""
    config = yaml.safe_load(find('vehicles', VEHICLE).read_text(encoding='utf-8'))
    config['name'] = 'proxy_ugv'
    config['powertrain'] = {'preset': 'effective', 'bus_voltage_V': BUS_V}
    config['measured_power'] = {
        'total': {'topic': 'battery/measured', 'type': 'sensor_msgs/msg/BatteryState'}
    }
    # the twin publishes one motor joint per side at the motor shaft, velocity and position
    config['joints'] = {
        'preset': 'test_robot',
        'gear_ratio': GEAR_RATIO,
        'interfaces': ['position', 'velocity'],
    }
    config.pop('battery', None)
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def cli(*args: str) -> str:
    """``skidsteer-power ARGS`` in a subprocess; its stdout. A failure raises with its stderr."""
    done = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', *args], capture_output=True, text=True, timeout=900
    )
    if done.returncode != 0:
        raise RuntimeError(f'skidsteer-power {args[0]} exited {done.returncode}: {done.stderr.strip()}')
    return done.stdout


def simulate(folder: Path, case: Case, half: int) -> Path:
    csv = commands(folder / f'cmd{half}.csv', case.seconds, case.seed * 10 + half)
    bag = folder / f'half{half}.mcap'
    cli('simulate', '--vehicle', VEHICLE, '--terrain', case.terrain, '--commands', str(csv),
        '--seed', str(case.seed * 10 + half), '-o', str(bag), '--json')  # fmt: skip
    return bag


def validate_rows(bag: Path, vehicle: Path | str, terrain: str, report: Path) -> dict[str, np.ndarray]:
    cli('validate', str(bag), '--vehicle', str(vehicle), '--terrain', terrain, '--report', str(report),
        '--no-plots', '--json')  # fmt: skip
    data = np.genfromtxt(report / 'timeseries.csv', delimiter=',', names=True)
    return {name: np.asarray(data[name], dtype=float) for name in data.dtype.names or ()}


def energy(rows: dict[str, np.ndarray], power_W: np.ndarray) -> float:
    """Energy [J] of ``power_W`` over the rows where a battery power was measured, each row held
    until the next (the last one the median step)."""
    t = rows['t_s']
    step = np.diff(t, append=t[-1] + float(np.median(np.diff(t))))
    keep = np.isfinite(rows['measured_battery_W']) & np.isfinite(power_W)
    return float(np.sum(power_W[keep] * step[keep]))


def linear_design(rows: dict[str, np.ndarray]) -> np.ndarray:
    """P = a|v| + b|w| + c of the commanded (v, w)."""
    return np.column_stack(
        [np.abs(rows['speed_cmd_m_s']), np.abs(rows['yaw_rate_cmd_rad_s']), np.ones(rows['t_s'].size)]
    )


def run_case(case: Case, folder: Path) -> Outcome:
    folder.mkdir(parents=True, exist_ok=True)
    vehicle = user_vehicle(folder / 'proxy_ugv.yaml')
    first, second = simulate(folder, case, 1), simulate(folder, case, 2)
    out_vehicle, out_terrain = folder / 'calibrated_vehicle.yaml', folder / 'calibrated_terrain.yaml'
    report = json.loads(
        cli(
            'calibrate',
            str(first),
            '--vehicle',
            str(vehicle),
            '--terrain',
            case.terrain,
            '--fit',
            'auto',
            '--out-vehicle',
            str(out_vehicle),
            '--out-terrain',
            str(out_terrain),
            '--json',
        )
    )
    fitted = ', '.join(n for n, p in report['parameters'].items() if p.get('fitted')) or 'nothing'
    train = validate_rows(first, vehicle, case.terrain, folder / 'train')
    start = validate_rows(second, vehicle, case.terrain, folder / 'start')
    calibrated = validate_rows(second, out_vehicle, str(out_terrain), folder / 'calibrated')
    ok = np.isfinite(train['measured_battery_W'])
    coef, *_ = np.linalg.lstsq(linear_design(train)[ok], train['measured_battery_W'][ok], rcond=None)
    measured = energy(calibrated, calibrated['measured_battery_W'])

    def pct(rows: dict[str, np.ndarray], power: np.ndarray) -> float:
        return 100.0 * (energy(rows, power) / measured - 1.0)

    return Outcome(
        case,
        pct(start, start['predicted_battery_W']),
        pct(calibrated, calibrated['predicted_battery_W']),
        pct(calibrated, linear_design(calibrated) @ coef),
        measured,
        fitted,
    )
