"""Digital twin: a dynamic simulation of the robot on its own ("truth") terrain, independent of the
estimator's predictor (it never imports ``models.fess`` or ``maps``; test_twin.py checks).

Stable API (used by the calibration helper and the CLI)::

    from skidsteer_power.twin import Twin, run_commands, write_bag, commands_from_csv
    twin = Twin(vehicle, terrain, powertrain=None, *, patches=None, seed=0, dt=2e-3)
    twin.step(cmd_speed, cmd_yaw_rate, n_steps)        # hold (V [m/s], yaw rate [rad/s]) n steps
    trace = run_commands(twin, commands)               # commands: [Segment(speed, yaw_rate, duration)]
    write_bag(trace, 'out.mcap')                       # /cmd_vel /joint_states /odom
                                                       # /ground_truth/odom /battery/measured
    trace.summary() -> {duration_s, messages, energy_J, distance_m, max_sinkage_m, stuck}

``Segment`` is :class:`skidsteer_power.commands.Segment` (speed_m_s, yaw_rate_rad_s, duration_s);
patches come from :func:`load_patches` (YAML polygons). Physics: ``twin/model.py``; sensors:
``twin/sensors.py``; agreement with and departures from the steady models: docs/TWIN.md.
"""

from __future__ import annotations

from skidsteer_power.commands import Segment
from skidsteer_power.twin.model import Twin
from skidsteer_power.twin.sensors import (
    TwinTrace,
    commands_from_bag,
    commands_from_csv,
    commands_from_route,
    drive_until_empty,
    run_commands,
    write_bag,
)
from skidsteer_power.twin.terrain_field import Patch, TerrainField, load_patches

__all__ = [
    'Patch',
    'Segment',
    'TerrainField',
    'Twin',
    'TwinTrace',
    'commands_from_bag',
    'commands_from_csv',
    'commands_from_route',
    'drive_until_empty',
    'load_patches',
    'run_commands',
    'write_bag',
]
