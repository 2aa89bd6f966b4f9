"""Vehicle descriptions: a frozen dataclass, a validating YAML loader and a stable fingerprint.

A vehicle file in ``config/vehicles/`` holds the fields of :class:`Vehicle` as flat keys (SI units,
names carry the unit)::

    name: chapter3_track
    source: Table 3.3 of the dissertation
    running_gear: track          # 'track' | 'wheel'
    mass_kg: 30.0
    cg_height_m: 0.15
    tread_m: 0.4
    track_length_m: 0.7          # tracks only
    track_width_m: 0.07
    sprocket_radius_m: 0.1
    n_wheels: 4                  # wheels only (4 or 6, total)
    wheel_radius_m: 0.1
    wheel_width_m: 0.074
    wheelbase_m: 0.45            # front axle to rear axle
    yaw_inertia_kg_m2: 1.5       # optional; default: a uniform box (see Vehicle.yaw_inertia)
    track_longitudinal_shear_ratio: 4.0   # optional, tracks only: K_x / K in FESS (default 1)
    powertrain: {preset: test_robot}
    drivetrain: {preset: test_robot}   # joint_states mapping (skidsteer_power.estimator.inputs.JointMap)
    max_speed_m_s: 1.5           # optional: the command envelope the maps cover (defaults below)
    max_yaw_rate_rad_s: 2.0

Every problem raises :class:`~skidsteer_power.errors.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError
from skidsteer_power.terramechanics import ranges
from skidsteer_power.terramechanics.ranges import Range

GRAVITY_M_S2 = 9.81  # [m/s^2], the value used throughout the dissertation

RUNNING_GEARS = ('track', 'wheel')
WHEEL_COUNTS = (4, 6)
TRACK_FIELDS = ('track_length_m', 'track_width_m', 'sprocket_radius_m')
WHEEL_FIELDS = ('n_wheels', 'wheel_radius_m', 'wheel_width_m', 'wheelbase_m')
DEFAULT_MAX_SPEED_M_S = 1.5  # the dissertation's largest simulated speed (section 3.5) [m/s]
DEFAULT_MAX_YAW_RATE_RAD_S = 2.0  # a spin in place of the test robots at full motor speed or less [rad/s]


@dataclass(frozen=True)
class Vehicle:
    """A skid-steered vehicle (SI units). Validated on construction.

    Attributes
    ----------
    name : identifier (file stem for shipped vehicles)
    running_gear : 'track' or 'wheel'
    mass_kg : total mass m [kg]
    cg_height_m : height h of the centre of gravity [m] (load transfer, eq. 3.1)
    tread_m : tread B, centre-to-centre distance of the two sides [m]
    track_length_m : contact length l of each track [m] (tracks)
    track_width_m : width b of each track [m] (tracks)
    sprocket_radius_m : sprocket radius r [m] (tracks)
    n_wheels : total number of wheels, 4 or 6 (wheels)
    wheel_radius_m, wheel_width_m : wheel radius r and width b [m] (wheels)
    wheelbase_m : front axle to rear axle wb [m] (wheels); a 6-wheel vehicle's middle axle is midway
    yaw_inertia_kg_m2 : yaw moment of inertia about the CG [kg m^2] (optional; the dynamic twin uses
        it, the steady models do not; default :attr:`yaw_inertia`)
    powertrain : powertrain description, interpreted by ``skidsteer_power.powertrain`` (may be empty)
    drivetrain : how its joint_states map to the sides (joint names, units), interpreted by
        :class:`skidsteer_power.estimator.inputs.JointMap` (empty: the test robot's left_motor/right_motor)
    source : where the numbers come from; flags assumed values
    max_speed_m_s : largest |forward speed| the vehicle is commanded [m/s] (default 1.5); the power
        maps cover it, commands beyond it are flagged ``clamped``
    max_yaw_rate_rad_s : largest |yaw rate| the vehicle is commanded [rad/s] (default 2.0), likewise
    track_longitudinal_shear_ratio : K_x / K [-] of a track (tracks only; default 1: Wong's
        inextensible belt, eqs. 3.12-3.15): FESS's track shears the soil along the track as if the
        shear deformation modulus K were K_x, across it as K (a compliant belt in series with the
        soil; docs/PREDICTION_FIT.md). Only FESS reads it
    """

    name: str
    running_gear: str
    mass_kg: float
    cg_height_m: float
    tread_m: float
    track_length_m: float | None = None
    track_width_m: float | None = None
    sprocket_radius_m: float | None = None
    n_wheels: int | None = None
    wheel_radius_m: float | None = None
    wheel_width_m: float | None = None
    wheelbase_m: float | None = None
    yaw_inertia_kg_m2: float | None = None
    powertrain: dict[str, Any] = field(default_factory=dict, hash=False)
    source: str = ''
    drivetrain: dict[str, Any] = field(default_factory=dict, hash=False)
    max_speed_m_s: float = DEFAULT_MAX_SPEED_M_S
    max_yaw_rate_rad_s: float = DEFAULT_MAX_YAW_RATE_RAD_S
    track_longitudinal_shear_ratio: float = 1.0

    def __post_init__(self) -> None:
        _validate(self)

    @property
    def weight_N(self) -> float:
        """Weight W = m g [N]."""
        return self.mass_kg * GRAVITY_M_S2

    @property
    def drive_radius_m(self) -> float:
        """Sprocket radius (tracks) or wheel radius (wheels) r [m]."""
        radius = self.sprocket_radius_m if self.is_tracked else self.wheel_radius_m
        assert radius is not None  # guaranteed by validation
        return radius

    @property
    def yaw_inertia(self) -> float:
        """Yaw moment of inertia I_z [kg m^2]: ``yaw_inertia_kg_m2`` if given, else ASSUMED a uniform
        box m (L^2 + W^2) / 12 of the overall footprint, L = contact length (tracks) or wheelbase
        (wheels) + 2 r, W = tread + b (the dissertation gives no inertia)."""
        if self.yaw_inertia_kg_m2 is not None:
            return float(self.yaw_inertia_kg_m2)
        span = self.track_length_m if self.is_tracked else self.wheelbase_m
        length = float(span or 0.0) + 2.0 * self.drive_radius_m
        width = self.tread_m + self.contact_width_m
        return self.mass_kg * (length**2 + width**2) / 12.0

    @property
    def is_tracked(self) -> bool:
        return self.running_gear == 'track'

    @property
    def contact_width_m(self) -> float:
        """Track or wheel width b [m]."""
        width = self.track_width_m if self.is_tracked else self.wheel_width_m
        assert width is not None
        return width

    @property
    def wheels_per_side(self) -> int:
        """Wheels on each side (2 or 3); 0 for a tracked vehicle."""
        return 0 if self.is_tracked else int(self.n_wheels or 0) // 2

    def axle_positions_m(self) -> tuple[float, ...]:
        """Longitudinal positions of the axles of one side, front first, from the centre [m]."""
        if self.is_tracked:
            return ()
        half = 0.5 * float(self.wheelbase_m or 0.0)
        return (half, -half) if self.wheels_per_side == 2 else (half, 0.0, -half)


def _fail(vehicle_name: str, message: str) -> ConfigError:
    return ConfigError(f'vehicle {vehicle_name!r}: {message}')


def _field_ranges() -> dict[str, Range]:
    """The physical range of each number of a vehicle file (terramechanics.ranges states why)."""
    return {
        'mass_kg': ranges.MASS_KG,
        'cg_height_m': ranges.CG_HEIGHT_M,
        'tread_m': ranges.TREAD_M,
        'max_speed_m_s': ranges.FORWARD_SPEED_M_S,
        'max_yaw_rate_rad_s': ranges.YAW_RATE_RAD_S,
        'track_length_m': ranges.LENGTH_M,
        'track_width_m': ranges.WIDTH_M,
        'sprocket_radius_m': ranges.RADIUS_M,
        'wheel_radius_m': ranges.RADIUS_M,
        'wheel_width_m': ranges.WIDTH_M,
        'wheelbase_m': ranges.WHEELBASE_M,
        'yaw_inertia_kg_m2': ranges.YAW_INERTIA_KG_M2,
        'track_longitudinal_shear_ratio': ranges.LONGITUDINAL_SHEAR_RATIO,
    }


def _check_positive(vehicle: Vehicle, name: str) -> None:
    """``name`` is a finite number > 0 inside its physical range (:func:`_field_ranges`)."""
    value = getattr(vehicle, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(vehicle.name, f'{name} must be a number, not {value!r}')
    if not math.isfinite(value) or value <= 0:
        raise _fail(vehicle.name, f'{name} must be a finite number > 0, not {value!r}')
    limits = _field_ranges()[name]
    if not limits.contains(value):
        raise _fail(vehicle.name, f'{name} = {value:g} is outside its range {limits.text}')


def _validate(vehicle: Vehicle) -> None:
    if not isinstance(vehicle.name, str) or not vehicle.name:
        raise ConfigError(f'vehicle name must be a non-empty string, not {vehicle.name!r}')
    if vehicle.running_gear not in RUNNING_GEARS:
        raise _fail(
            vehicle.name, f'running_gear must be one of {RUNNING_GEARS}, not {vehicle.running_gear!r}'
        )
    for name in ('mass_kg', 'cg_height_m', 'tread_m', 'max_speed_m_s', 'max_yaw_rate_rad_s'):
        _check_positive(vehicle, name)
    own, other = (TRACK_FIELDS, WHEEL_FIELDS) if vehicle.is_tracked else (WHEEL_FIELDS, TRACK_FIELDS)
    for name in own:
        if getattr(vehicle, name) is None:
            raise _fail(vehicle.name, f'{name} is required for running_gear {vehicle.running_gear!r}')
    for name in other:
        if getattr(vehicle, name) is not None:
            raise _fail(vehicle.name, f'{name} does not apply to running_gear {vehicle.running_gear!r}')
    for name in own:
        if name == 'n_wheels':
            if vehicle.n_wheels not in WHEEL_COUNTS or isinstance(vehicle.n_wheels, bool):
                raise _fail(vehicle.name, f'n_wheels must be 4 or 6, not {vehicle.n_wheels!r}')
        else:
            _check_positive(vehicle, name)
    if vehicle.tread_m <= vehicle.contact_width_m:
        raise _fail(
            vehicle.name,
            f'tread_m ({vehicle.tread_m}) must exceed the track/wheel width ({vehicle.contact_width_m})',
        )
    if not vehicle.is_tracked:
        assert vehicle.wheelbase_m is not None and vehicle.wheel_radius_m is not None  # checked above
        spacing = float(vehicle.wheelbase_m) / (vehicle.wheels_per_side - 1)
        if spacing <= 2.0 * float(vehicle.wheel_radius_m):
            raise _fail(vehicle.name, f'wheelbase_m ({vehicle.wheelbase_m}) is too short: the wheels overlap')
    if vehicle.yaw_inertia_kg_m2 is not None:
        _check_positive(vehicle, 'yaw_inertia_kg_m2')
    _check_positive(vehicle, 'track_longitudinal_shear_ratio')
    if not vehicle.is_tracked and vehicle.track_longitudinal_shear_ratio != 1.0:
        raise _fail(vehicle.name, "track_longitudinal_shear_ratio does not apply to running_gear 'wheel'")
    if not isinstance(vehicle.powertrain, dict):
        raise _fail(vehicle.name, f'powertrain must be a mapping, not {type(vehicle.powertrain).__name__}')
    if not isinstance(vehicle.drivetrain, dict):
        raise _fail(vehicle.name, f'drivetrain must be a mapping, not {type(vehicle.drivetrain).__name__}')
    if not isinstance(vehicle.source, str):
        raise _fail(vehicle.name, 'source must be a string')


FIELD_NAMES = tuple(f.name for f in dataclasses.fields(Vehicle))


def vehicle_from_dict(data: Any, *, origin: str = '<dict>') -> Vehicle:
    """Build a validated :class:`Vehicle` from a mapping (e.g. parsed YAML); ``origin`` names the source."""
    if not isinstance(data, dict):
        raise ConfigError(
            f'{origin}: a vehicle file must hold a mapping of fields, not {type(data).__name__}'
        )
    unknown = sorted(set(data) - set(FIELD_NAMES))
    if unknown:
        raise ConfigError(
            f'{origin}: unknown field(s) {", ".join(map(str, unknown))}; known: {", ".join(FIELD_NAMES)}'
        )
    for required in ('name', 'running_gear', 'mass_kg', 'cg_height_m', 'tread_m'):
        if required not in data:
            raise ConfigError(f'{origin}: missing field {required!r}')
    values = dict(data)
    for section in ('powertrain', 'drivetrain'):
        if values.get(section) is None:
            values[section] = {}
    values['name'] = str(values['name'])
    try:
        return Vehicle(**values)
    except ConfigError as err:
        raise ConfigError(f'{origin}: {err}') from None


def vehicle_dirs() -> list[Path]:
    """Folders searched for vehicle names (:func:`skidsteer_power.resources.config_dirs`)."""
    return resources.config_dirs('vehicles')


def available_vehicles() -> list[str]:
    """Names of the shipped vehicle files (without .yaml)."""
    return sorted(resources.shipped('vehicles'))


def _resolve(path_or_name: str | os.PathLike[str]) -> Path:
    return resources.find('vehicles', path_or_name)


def load_vehicle(path_or_name: str | os.PathLike[str] | Vehicle) -> Vehicle:
    """Load a vehicle from a YAML file path, or a name in ``config/vehicles/`` (without .yaml).

    A :class:`Vehicle` passes through unchanged. Raises ConfigError for a missing, unreadable or
    invalid file, naming the file and the field.
    """
    if isinstance(path_or_name, Vehicle):
        return path_or_name
    path = _resolve(path_or_name)
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as err:
        raise ConfigError(f'{path}: cannot read vehicle file ({err.strerror or err})') from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f'{path}: not valid YAML ({str(err).splitlines()[0]})') from err
    return vehicle_from_dict(data, origin=str(path))


_NOT_FINGERPRINTED = (
    'name',
    'source',
    'drivetrain',
    'yaw_inertia_kg_m2',
    'max_speed_m_s',
    'max_yaw_rate_rad_s',
)


def vehicle_fingerprint(vehicle: Vehicle) -> str:
    """Stable hex digest of the vehicle's physical parameters and powertrain (not name, source or
    the joint_states mapping, which changes no model result).

    Two vehicles with the same fingerprint give the same model results, so maps can be cached by it.
    """
    payload = {
        f.name: getattr(vehicle, f.name)
        for f in dataclasses.fields(vehicle)
        # no steady-state physics: the envelope (maps key on it separately: maps.power_map.cache_path),
        # the inertia (the steady models ignore it) and the joint_states mapping
        if f.name not in _NOT_FINGERPRINTED
    }
    if vehicle.track_longitudinal_shear_ratio == 1.0:
        del payload['track_longitudinal_shear_ratio']  # the default: fingerprints from before it stay
    for key, value in payload.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            payload[key] = repr(float(value))  # 4 and 4.0 hash alike
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]
