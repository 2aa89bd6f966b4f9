"""Build the estimator's parts from names: vehicle, terrain, map, powertrain, battery, state path.

Pure (no ROS): the node, the suite and tests share these, so a parameter means the same everywhere.
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

from skidsteer_power.drive.prediction_modes import CMD, TWIST, prediction_mode
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator.inputs import JointMap
from skidsteer_power.estimator.prediction import MapPredictor, SetpointPredictor
from skidsteer_power.powertrain import Battery, Powertrain
from skidsteer_power.seams import BatteryModel
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain
from skidsteer_power.vehicle import Vehicle

if TYPE_CHECKING:
    from skidsteer_power.drive.controller import DriveController
    from skidsteer_power.maps.power_map import PowerMap

SECONDS_PER_HOUR = 3600.0


def check_terrain(name_or_path: str) -> Terrain:
    """The terrain preset or YAML file; ConfigError if unknown or non-physical."""
    return load_terrain(name_or_path)


def state_path(configured: str, vehicle: Vehicle, namespace: str = '') -> Path:
    """The energy-state file: ``configured`` if set, else
    $XDG_STATE_HOME/skidsteer_power/energy_<vehicle>.json in the root namespace and
    energy_<namespace>_<vehicle>.json in another (``/robot1/sub`` -> ``robot1.sub``): one robot, one
    battery, one file (issue 37 item 8)."""
    if configured:
        return Path(configured).expanduser()
    base = os.environ.get('XDG_STATE_HOME') or Path.home() / '.local' / 'state'
    ns = '.'.join(part for part in namespace.split('/') if part)
    name = f'energy_{ns}_{vehicle.name}.json' if ns else f'energy_{vehicle.name}.json'
    return Path(base) / 'skidsteer_power' / name


def joint_map_for(vehicle: Vehicle, **overrides: object) -> JointMap:
    """The vehicle's joint_states mapping (its ``joints:`` and ``measured_power:`` sections), with
    non-empty ``overrides`` (node parameters, CLI options: left, right, effort_is, location,
    gear_ratio ...) applied."""
    measured = getattr(vehicle, 'measured_power', None)
    bus = Powertrain.for_vehicle(vehicle).nominal_bus_voltage_V() if measured else None
    return JointMap.from_config(vehicle.joints or None, measured, bus).with_overrides(**overrides)


def battery_for(vehicle: Vehicle, soc: float = 1.0) -> Battery:
    """The vehicle's battery (its powertrain's ``battery`` preset), at state of charge ``soc`` [-]."""
    return Battery.from_config(Powertrain.for_vehicle(vehicle).battery, soc)


KINEMATICS = (CMD, TWIST)
"""How a command is predicted (:mod:`skidsteer_power.drive.prediction_modes`): 'cmd' (default: at
the command's wheel speed set points, the motion FESS finds for them; issue 25) or 'twist' (the
command taken as the motion itself)."""


def drive_controller(vehicle: Vehicle, **limits: float) -> DriveController:
    """The vehicle file's drive controller (:func:`skidsteer_power.drive.controller_for_vehicle`) with
    the given limits (``max_speed_m_s`` [m/s], ``max_yaw_rate_rad_s`` [rad/s], ``max_wheel_rad_s``
    [rad/s] ...) in place of its own; a limit of 0 keeps the file's. The estimator predicts through
    the limits the robot's driver applies (the des_driver's parameters, ``skidsteer-power run``)."""
    from skidsteer_power.drive.controller import controller_for_vehicle

    ctrl = controller_for_vehicle(vehicle, Powertrain.for_vehicle(vehicle))
    given = {name: float(value) for name, value in limits.items() if value}
    return ctrl.with_values(**given) if given else ctrl


def map_predictor(
    vehicle: Vehicle,
    terrain_name: str,
    cache_dir: str | os.PathLike[str] | None = None,
    kinematics: str = CMD,
    controller: DriveController | None = None,
) -> tuple[MapPredictor | SetpointPredictor, bool, str]:
    """A predictor for ``vehicle`` on the named terrain from its cached map, loaded from
    ``cache_dir`` (default: $SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power) or built there
    (FESS) if missing: the set-point map (:class:`SetpointPredictor`) for ``kinematics='cmd'``,
    the (V, yaw rate) power map (:class:`MapPredictor`) for ``'twist'``. ``controller``: the drive
    controller the set points follow (default: the vehicle file's, :mod:`skidsteer_power.drive`).

    Returns (predictor, built, description of the map).
    """
    try:
        kinematics, note = prediction_mode(kinematics, 'kinematics', KINEMATICS)
    except InputError as err:
        raise ConfigError(str(err)) from err
    if note:  # an earlier spelling (a saved parameter file): it works, and its owner learns the name
        warnings.warn(note, FutureWarning, stacklevel=2)
    terrain = check_terrain(terrain_name)
    if kinematics == CMD:
        from skidsteer_power.maps import setpoint_map

        smap, built = setpoint_map.load_or_build(
            vehicle, terrain, cache_dir=cache_dir or None, controller=controller
        )
        where = setpoint_map.cache_path(vehicle, terrain, cache_dir=cache_dir or None)
        description = f'{vehicle.name} on {terrain.name}, set points ({where})'

        def motion_map() -> PowerMap:  # path energy starts from a motion: the (V, yaw rate) map
            from skidsteer_power.maps import load_or_build

            return load_or_build(vehicle, terrain, cache_dir or None)[0]

        predictor = SetpointPredictor(
            smap, Powertrain.for_vehicle(vehicle), description=description, motion_map=motion_map
        )
        return predictor, built, str(where)
    from skidsteer_power.maps import cache_path, load_or_build
    from skidsteer_power.models.predict import max_axle_speed

    power_map, built = load_or_build(vehicle, terrain, cache_dir or None)
    where = cache_path(vehicle, terrain, cache_dir or None)
    description = f'{vehicle.name} on {terrain.name} ({where})'
    powertrain = Powertrain.for_vehicle(vehicle)
    ctrl = controller or drive_controller(vehicle)
    path_scale = functools.partial(ctrl.path_scale, ceiling_rad_s=max_axle_speed(powertrain))
    twist = MapPredictor(power_map, powertrain, description=description, path_scale=path_scale)
    return twist, built, str(where)


CURRENT_DEADBAND_A = 1e-3
"""|current| [A] below which the battery is neither charging nor discharging."""

BatteryMessageFields: TypeAlias = dict[str, Any]  # Any: a field's value type depends on its name
"""sensor_msgs/BatteryState field name -> value, as :func:`battery_message_fields` gives them: floats,
the per-cell lists, ``present`` (bool), ``status`` and ``chemistry`` (str). A plain dict, not a
TypedDict: the node's ``battery_state_message`` (nodes/power_estimator.py) is typed to take a plain
dict, and pops ``status`` and ``chemistry`` off a copy before building the message from the rest."""


def battery_message_fields(battery: BatteryModel, power_W: float) -> BatteryMessageFields:
    """sensor_msgs/BatteryState fields for the battery under ``power_W`` [W] (battery side).

    The message's conventions: ``current`` [A] negative while discharging; voltage [V]; charge,
    capacity, design_capacity [Ah]; percentage 0..1; NaN where nothing is measured (temperature,
    per-cell voltages and temperatures, one NaN per cell in series); ``status`` is 'charging',
    'discharging' or 'not_charging' from the current's sign (the node maps it to the message's
    constants); ``chemistry`` is the battery file's.
    """
    state = battery.state
    config = battery.config
    capacity_Ah = config.capacity_C / SECONDS_PER_HOUR
    current = battery.current_for_power(power_W) if power_W != 0 else 0.0
    if current > CURRENT_DEADBAND_A:
        status = 'discharging'
    elif current < -CURRENT_DEADBAND_A:
        status = 'charging'
    else:
        status = 'not_charging'
    cells = [math.nan] * int(config.cells_in_series)
    return {
        'voltage': float(config.ocv(state.soc) - config.resistance_ohm * current),
        'current': float(-current),
        'charge': float(state.charge_C / SECONDS_PER_HOUR),
        'capacity': float(capacity_Ah),
        'design_capacity': float(capacity_Ah),
        'percentage': float(state.soc),
        'temperature': math.nan,
        'cell_voltage': cells,
        'cell_temperature': list(cells),
        'present': True,
        'status': status,
        'chemistry': config.chemistry,
    }
