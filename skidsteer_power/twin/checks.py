"""The figures docs/TWIN.md quotes: ``python -m skidsteer_power.twin.checks [stuck|terms]``.

stuck: the Table 7.3 grid on dry sand (ch. 7.3.4): each cell a 6 s hold from rest; ``S`` if the
twin got stuck, else the motion over the last 2 s as a fraction of the commanded one; then the
deepest sinkage plus excavation [mm].
terms: what the slip-sinkage and bulldozing terms change against ``contact='classic'`` (the steady
models' contact) on sand_bin at 0.2 m/s, straight and at 0.2 rad/s commanded.
"""

from __future__ import annotations

import sys

from skidsteer_power.commands import Segment
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin.model import Twin
from skidsteer_power.twin.sensors import run_commands
from skidsteer_power.vehicle import load_vehicle

VEHICLES = ('test_robot_4wheel', 'test_robot_6wheel', 'test_robot_track')
YAW_RATES = (0.0, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
"""Commanded yaw rates [rad/s]: Table 7.3's range and beyond."""


def stuck_grid() -> None:
    """Print the stuck grid (see the module doc)."""
    dry_sand = load_terrain('dry_sand')
    print('configuration, V | ' + ' | '.join(f'{w:g}' for w in YAW_RATES) + ' rad/s')
    for name in VEHICLES:
        vehicle = load_vehicle(name)
        for speed in (0.1, 0.2):
            cells = []
            for yaw_rate in YAW_RATES:
                trace = run_commands(Twin(vehicle, dry_sand), [Segment(speed, yaw_rate, 6.0)])
                stuck = trace.stuck(vehicle.tread_m)
                last = trace.t >= trace.t[-1] - 2.0
                wanted, actual = trace.motion(vehicle.tread_m)
                progress = actual[last].mean() / wanted[last].mean()
                mark = 'S' if stuck else f'{progress:.2f}'
                cells.append(f'{mark}, {1e3 * trace.sinkage_m.max():.0f}')
            print(f'{name}, {speed:g} m/s | ' + ' | '.join(cells), flush=True)


def terms() -> None:
    """Print the effect of the slip-sinkage and bulldozing terms (see the module doc)."""
    sand_bin = load_terrain('sand_bin')
    for name in VEHICLES:
        vehicle = load_vehicle(name)
        per_side = 1 if vehicle.is_tracked else vehicle.wheels_per_side
        for yaw_rate in (0.0, 0.2):
            row = []
            for laws in ('classic', 'extended'):
                twin = Twin(vehicle, sand_bin, contact=laws)
                trace = run_commands(twin, [Segment(0.2, yaw_rate, 7.0)])
                slip = 1.0 - twin.vel[0] / (twin.r * twin.omega_m.mean() / twin.G)
                torque = trace.axle_torque_Nm[-1] / per_side
                row.append(
                    f'slip {slip:.5g}, yaw rate {twin.vel[2]:.4f} rad/s, axle torque per wheel/track '
                    f'{torque[0]:.4f} / {torque[1]:.4f} N m'
                )
            print(f'{name}, 0.2 m/s, {yaw_rate:g} rad/s: without {row[0]} | with {row[1]}', flush=True)


def main(argv: list[str] | None = None) -> int:
    which = (argv if argv is not None else sys.argv[1:]) or ['stuck', 'terms']
    for name in which:
        {'stuck': stuck_grid, 'terms': terms}[name]()
    return 0


if __name__ == '__main__':
    sys.exit(main())
