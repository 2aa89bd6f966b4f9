"""``skidsteer-power fit-internal FILE.csv|BAG``: least-squares fit of eq. (7.1) to no-load runs (ch. 7.2).

JSON keys: torque_constant_Nm_A; fits: {side: {stage: {viscous_Nm_s, coulomb_Nm, viscous_A_s,
coulomb_A, rms_residual_Nm, n_samples}}}; components: {side: {component: {viscous_Nm_s, coulomb_Nm,
viscous_A_s, coulomb_A}}} when the samples name assembly stages (eqs. 7.3, 7.4: differences of fits).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, nonnegative_float
from skidsteer_power.errors import InputError
from skidsteer_power.jsonout import JsonObject
from skidsteer_power.powertrain.internal import COMPONENTS, InternalFit, components_from_stages, fit_internal
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.powertrain.samples import read_bag, read_csv
from skidsteer_power.vehicle import load_vehicle


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'fit-internal',
        help='fit internal-resistance coefficients b, c (eq. 7.1) to no-load speed/current runs',
        description='Least-squares fit of K_t i = b omega + c sign(omega) (eq. 7.1) per side and assembly '
        'stage, from a CSV (speed + current columns, optional side and stage) or a bag (joint_states).',
    )
    parser.add_argument('source', help='CSV file, or a rosbag2 bag (MCAP file/directory, sqlite3)')
    parser.add_argument('--topic', default='/joint_states', help='JointState topic in a bag')
    parser.add_argument(
        '--stage', default='all', choices=('all', *COMPONENTS), help='assembly stage of a bag'
    )
    parser.add_argument(
        '--min-speed', type=nonnegative_float, default=1.0, help='drop samples slower than this [rad/s]'
    )
    parser.add_argument(
        '--vehicle',
        default='test_robot_track',
        help='vehicle name or YAML file; its motor K_t turns a CSV current into torque (%(default)s)',
    )
    add_json_flag(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = Path(args.source)
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    kt = Powertrain.for_vehicle(load_vehicle(args.vehicle)).motor.torque_constant_Nm_A
    if path.is_file() and path.suffix.lower() == '.csv':
        samples = read_csv(path, kt)
    else:
        samples = read_bag(path, args.topic, args.stage)
    fits: dict[str, dict[str, dict[str, float]]] = {}  # side -> stage -> coefficients, rms, n
    stage_fits: dict[str, dict[str, InternalFit]] = {}
    for (side, stage), (omega, torque) in sorted(samples.arrays().items()):
        keep = np.abs(omega) >= args.min_speed
        try:
            fit = fit_internal(omega[keep], torque[keep])
        except InputError as err:
            raise InputError(f'{side}/{stage}: {err}') from None
        fits.setdefault(side, {})[stage] = {
            **fit.as_dict(),
            **_as_current(fit.viscous_Nm_s, fit.coulomb_Nm, kt),
        }
        if stage != 'all':
            stage_fits.setdefault(side, {})[stage] = fit
    payload: JsonObject = {'torque_constant_Nm_A': kt, 'fits': fits}
    if stage_fits:
        payload['components'] = {
            side: {
                name: {
                    'viscous_Nm_s': r.viscous_Nm_s,
                    'coulomb_Nm': r.coulomb_Nm,
                    **_as_current(r.viscous_Nm_s, r.coulomb_Nm, kt),
                }
                for name, r in components_from_stages(stages).items()
            }
            for side, stages in stage_fits.items()
        }
    if args.json:
        emit(payload, True)
    else:
        for side, stages in fits.items():
            for stage, row in stages.items():
                coefficients = f'b = {row["viscous_Nm_s"]:.4g} N m s/rad   c = {row["coulomb_Nm"]:.4g} N m'
                quality = f'(rms {row["rms_residual_Nm"]:.2g} N m, n = {row["n_samples"]})'
                print(f'{side:<6} {stage:<13} {coefficients}   {quality}')
    return 0


def _as_current(viscous: float, coulomb: float, kt: float) -> dict[str, float]:
    """The same coefficients as Table 7.1 lists them: motor current per rad/s [A s] and [A]."""
    return {'viscous_A_s': viscous / kt, 'coulomb_A': coulomb / kt}
