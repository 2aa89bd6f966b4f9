"""Compare benchmark (issue 27): FESS against the models a user would fit, on twin bags of 3 terrains.

For each truth terrain (two presets and :data:`HIDDEN`, a sand that is no preset: bench_calibration's
truth), the digital twin (``skidsteer_power.twin``: its own dynamics and contact, never FESS or the
maps) drives the test robot with four and separate command sets:

* training: the Table 7.3 sets (V 0.1 m/s at yaw rates 0-0.2 rad/s, 0.2 m/s at 0-0.35 rad/s, 4 s each);
* same range: other commands inside that envelope (V 0.12-0.18 m/s, yaw rates 0-0.3 rad/s);
* extrapolation: faster and tighter (V 0.3-0.4 m/s, yaw rates up to 0.5 rad/s);
* transfer: the same-range commands with a 10 kg payload, no new data (the physics models get the
  vehicle's new mass; the fitted baselines keep their coefficients).

FESS is given the truth terrain for the presets and the nearest preset for the hidden one (what a
user would pick), calibrated on the training bag, and corrected online as power_estimator does
(:mod:`skidsteer_power.apps.compare`). Goal (issue 27): FESS calibrated + online no worse than
the best baseline on the same range, and at most a third of its |energy error| (or within 5 %) on
extrapolation and transfer. Nothing here is tuned toward the goal; the table is what it is.
``python -m benchmarks.run compare`` (a few minutes on 2 cores: 12 twin runs, 3 calibrations).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.bench_calibration import TRUTH as HIDDEN
from benchmarks.bench_calibration import nearest_preset
from benchmarks.harness import Report
from skidsteer_power.apps.compare import CompareOptions, compare, table
from skidsteer_power.commands import Segment
from skidsteer_power.real_robot import table_7_3_segments
from skidsteer_power.terramechanics.terrain import PRESETS, Terrain
from skidsteer_power.twin import Twin, run_commands, write_bag
from skidsteer_power.vehicle import load_vehicle

VEHICLE = 'test_robot_4wheel'
PAYLOAD_KG = 10.0
HOLD_S, PAUSE_S = 4.0, 1.0


def _held(pairs: list[tuple[float, float]]) -> list[Segment]:
    commands = [Segment(0.0, 0.0, 2.0)]
    for speed, yaw in pairs:
        commands += [Segment(speed, yaw, HOLD_S), Segment(0.0, 0.0, PAUSE_S)]
    return commands


COMMANDS = {
    'train': [Segment(0.0, 0.0, 2.0), *table_7_3_segments(HOLD_S, PAUSE_S)],
    'same_range': _held(
        [(0.15, 0.0), (0.15, 0.05), (0.15, 0.12), (0.15, 0.25), (0.18, 0.3), (0.12, 0.03), (0.12, 0.18)]
    ),
    'extrapolation': _held([(0.3, 0.0), (0.3, 0.2), (0.3, 0.45), (0.4, 0.1), (0.4, 0.5)]),
}


def _bag(path: Path, terrain: Terrain, commands: list[Segment], payload_kg: float = 0.0) -> Path:
    vehicle = load_vehicle(VEHICLE)
    if payload_kg:
        vehicle = dataclasses.replace(vehicle, mass_kg=vehicle.mass_kg + payload_kg)
    write_bag(run_commands(Twin(vehicle, terrain, seed=0), commands), path)
    return path


def _given_terrain(terrain: Terrain) -> str:
    """The hidden truth is only the twin's: FESS gets the nearest preset (as a user would)."""
    return terrain.name if terrain.name in PRESETS else nearest_preset(terrain)


def _one_terrain(report: Report, truth: Terrain, folder: Path) -> dict[str, Any]:
    began = time.perf_counter()
    bags = {name: _bag(folder / f'{name}.mcap', truth, commands) for name, commands in COMMANDS.items()}
    transfer = _bag(folder / 'payload.mcap', truth, COMMANDS['same_range'], PAYLOAD_KG)
    given = _given_terrain(truth)
    options = CompareOptions(
        vehicle=VEHICLE,
        terrain=given,
        train=(str(bags['train']),),
        holdout=(str(bags['same_range']), str(bags['extrapolation'])),
        transfer=(str(transfer),),
        transfer_payload_kg=PAYLOAD_KG,
        work_dir=folder / 'work',
    )
    result = compare(options)
    print(f'-- truth {truth.name}, FESS given {given} ({time.perf_counter() - began:.0f} s)')
    print(table(result))
    for entry in result['holdout']:
        report.figure(
            f'{truth.name}: {Path(entry["bag"]).stem} classified {entry["split"]}',
            entry['outside_envelope_share'] * 100,
            '% outside',
            note=f'max |V| {entry["max_speed_m_s"]:.2f} m/s, '
            f'max |yaw| {entry["max_yaw_rate_rad_s"]:.2f} rad/s',
        )
    calibration = result['calibration']
    if 'error' in calibration:
        report.figure(f'{truth.name}: calibration failed', 1, '', note=calibration['error'])
    elif calibration['at_bound']:
        report.figure(f'{truth.name}: calibrated parameters at a bound', len(calibration['at_bound']), '',
                      note=', '.join(calibration['at_bound']))  # fmt: skip
    for split, g in result['goal'].items():
        report.figure(
            f'{truth.name} {split}: |E| FESS calibrated + online',
            g['fess_calibrated_online_abs_energy_error_pct'],
            '%',
            goal=f'<= {g["limit_pct"]:.1f} % (best baseline {g["best_baseline"]} '
            f'{g["best_baseline_abs_energy_error_pct"]:.1f} %)',
            met=g['met'],
        )
    return result


def run(report: Report) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for truth in (PRESETS['sand_bin'], PRESETS['clay'], HIDDEN):
            folder = Path(tmp) / truth.name
            folder.mkdir()
            _one_terrain(report, truth, folder)


if __name__ == '__main__':
    run(Report(section='compare'))
