"""The figures docs/TWIN.md quotes on the extended laws: ``python -m skidsteer_power.twin.checks``.

(The Table 7.3 grid and the Appendix D radii: ``python -m skidsteer_power.twin.motion``.)
terms: what the extended contact laws change against ``contact='classic'`` (the steady
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


def terms() -> None:
    """Print the effect of the extended contact laws (see the module doc)."""
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
    which = (argv if argv is not None else sys.argv[1:]) or ['terms']
    for name in which:
        {'terms': terms}[name]()
    return 0


if __name__ == '__main__':
    sys.exit(main())
