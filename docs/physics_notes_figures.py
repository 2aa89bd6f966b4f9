"""Regenerate the figures of docs/PHYSICS_NOTES.md from the current code (model output, not data).

    .venv/bin/python docs/physics_notes_figures.py

Prints the patrol table (Table 7.1 read four ways, three Packbots, sandy soil, 0.2 m/s, power-map
source) and the search-and-retrieve energies under the project's reading. The Table 7.1 readings
are built from config/powertrains/test_robot.yaml's own numbers: as torques (the project) or as
motor currents (x K_t), with the viscous coefficient per rad/s or per rpm (x 60 / 2 pi).
"""

from __future__ import annotations

import copy
import math

from skidsteer_power.missions import run_mission
from skidsteer_power.missions.routes import patrol, search_retrieve
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.powertrain.config import merged
from skidsteer_power.powertrain.motor import EC45
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

VEHICLES = ('packbot_track', 'packbot_4wheel', 'packbot_6wheel')
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def _reading(base: dict, current: bool, per_rpm: bool) -> dict:
    """The test robot's powertrain config with Table 7.1 read as currents and/or per rpm."""
    cfg = copy.deepcopy(base)
    for side in cfg['internal_resistance'].values():
        for name, entry in side.items():
            b, c = entry['viscous_Nm_s'], entry['coulomb_Nm']
            b = b * RPM_PER_RAD_S if per_rpm else b
            side[name] = (
                {'viscous_A_s': b, 'coulomb_A': c} if current else {'viscous_Nm_s': b, 'coulomb_Nm': c}
            )
    return cfg


def main() -> None:
    sandy = load_terrain('sandy_soil')
    route = patrol(0.2)
    readings = {
        'A, A s/rad': (True, False),
        'A, A/rpm': (True, True),
        '**N m, N m s/rad (project)**': (False, False),
        'N m, N m/rpm': (False, True),
    }
    print(f'K_t = {EC45.torque_constant_Nm_A} N m/A\n')
    print('| Table 7.1 read as | ' + ' | '.join(VEHICLES) + ' |')
    print('| --- | ' + ' | '.join('---' for _ in VEHICLES) + ' |')
    terrain_J = {}
    for label, (current, per_rpm) in readings.items():
        cells = []
        for name in VEHICLES:
            vehicle = load_vehicle(name)
            base = merged('powertrains', vehicle.powertrain or {'preset': 'test_robot'})
            powertrain = Powertrain.from_config(_reading(base, current, per_rpm), vehicle.running_gear)
            r = run_mission(vehicle, sandy, route, powertrain=powertrain)
            terrain_J[name] = r.energy_terrain_J
            cells.append(f'{r.energy_J:,.0f} J ({100 * r.energy_internal_J / r.energy_J:.0f} % int)')
        print(f'| {label} | ' + ' | '.join(cells) + ' |')
    print('\nterrain energies: ' + ', '.join(f'{n} {e:,.0f} J' for n, e in terrain_J.items()))
    sr = {name: run_mission(load_vehicle(name), sandy, search_retrieve()).energy_J for name in VEHICLES}
    print(
        'search-retrieve, sandy soil (project reading): '
        + ', '.join(f'{n} {e:,.0f} J' for n, e in sr.items())
    )


if __name__ == '__main__':
    main()
