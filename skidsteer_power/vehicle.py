"""Vehicle descriptions: a frozen dataclass, a validating YAML loader and a stable fingerprint.

A vehicle file in ``config/vehicles/`` holds the fields of :class:`Vehicle` and of its running gear
(:class:`TrackGear` or :class:`WheelGear`) as flat keys (SI units, names carry the unit)::

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
    joints: {preset: test_robot}       # joint_states mapping (skidsteer_power.estimator.inputs.JointMap;
                                       #   'drivetrain:' before, still read)
    max_speed_m_s: 1.5           # optional: the command envelope the maps cover (defaults below)
    max_yaw_rate_rad_s: 2.0      #   and the drive controller's velocity limits
    drive_controller: {...}      # optional: skidsteer_power.drive (docs/DRIVE.md)

In Python the running gear is one field, ``Vehicle.gear: TrackGear | WheelGear``; code that needs
the fields of one kind narrows it (``isinstance``, ``match``, or :meth:`Vehicle.tracks` /
:meth:`Vehicle.wheels`, which raise InputError for the other kind).

Every problem raises :class:`~skidsteer_power.errors.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Literal

import yaml

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.terramechanics import ranges
from skidsteer_power.terramechanics.ranges import Range

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

GRAVITY_M_S2 = 9.81  # [m/s^2], the value used throughout the dissertation

RunningGear = Literal['track', 'wheel']
RUNNING_GEARS: tuple[RunningGear, ...] = ('track', 'wheel')
WHEEL_COUNTS = (4, 6)
DEFAULT_MAX_SPEED_M_S = 1.5  # the dissertation's largest simulated speed (section 3.5) [m/s]
DEFAULT_MAX_YAW_RATE_RAD_S = 2.0  # a spin in place of the test robots at full motor speed or less [rad/s]
DEFAULT_TRACK_LONGITUDINAL_SHEAR_RATIO = 1.0  # Wong's inextensible belt (eqs. 3.12-3.15) [-]


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


def _check_positive(name: str, value: object) -> None:
    """``value`` of field ``name`` is a finite number > 0 in its physical range (:func:`_field_ranges`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f'{name} must be a number, not {value!r}')
    if not math.isfinite(value) or value <= 0:
        raise ConfigError(f'{name} must be a finite number > 0, not {value!r}')
    limits = _field_ranges()[name]
    if not limits.contains(value):
        raise ConfigError(f'{name} = {value:g} is outside its range {limits.text}')


@dataclass(frozen=True)
class TrackGear:
    """One track on each side (SI units). Validated on construction.

    Attributes
    ----------
    track_length_m : contact length l of each track [m]
    track_width_m : width b of each track [m]
    sprocket_radius_m : sprocket radius r [m]
    track_longitudinal_shear_ratio : K_x / K [-] (default 1: Wong's inextensible belt, eqs.
        3.12-3.15): FESS's track shears the soil along the track as if the shear deformation
        modulus K were K_x, across it as K (a compliant belt in series with the soil;
        docs/PREDICTION_FIT.md). Only FESS reads it
    """

    track_length_m: float
    track_width_m: float
    sprocket_radius_m: float
    track_longitudinal_shear_ratio: float = DEFAULT_TRACK_LONGITUDINAL_SHEAR_RATIO

    running_gear: ClassVar[RunningGear] = 'track'

    def __post_init__(self) -> None:
        for f in fields(self):
            _check_positive(f.name, getattr(self, f.name))

    @property
    def drive_radius_m(self) -> float:
        """Sprocket radius r [m]."""
        return self.sprocket_radius_m

    @property
    def contact_width_m(self) -> float:
        """Track width b [m]."""
        return self.track_width_m


@dataclass(frozen=True)
class WheelGear:
    """Two or three rigid wheels on each side, on equally spaced axles (SI units). Validated on construction.

    Attributes
    ----------
    n_wheels : total number of wheels, 4 or 6
    wheel_radius_m, wheel_width_m : wheel radius r and width b [m]
    wheelbase_m : front axle to rear axle wb [m]; a 6-wheel vehicle's middle axle is midway
    """

    n_wheels: int
    wheel_radius_m: float
    wheel_width_m: float
    wheelbase_m: float

    running_gear: ClassVar[RunningGear] = 'wheel'

    def __post_init__(self) -> None:
        if self.n_wheels not in WHEEL_COUNTS or isinstance(self.n_wheels, bool):
            raise ConfigError(f'n_wheels must be 4 or 6, not {self.n_wheels!r}')
        for name in ('wheel_radius_m', 'wheel_width_m', 'wheelbase_m'):
            _check_positive(name, getattr(self, name))
        spacing = float(self.wheelbase_m) / (self.wheels_per_side - 1)
        if spacing <= 2.0 * float(self.wheel_radius_m):
            raise ConfigError(f'wheelbase_m ({self.wheelbase_m}) is too short: the wheels overlap')

    @property
    def drive_radius_m(self) -> float:
        """Wheel radius r [m]."""
        return self.wheel_radius_m

    @property
    def contact_width_m(self) -> float:
        """Wheel width b [m]."""
        return self.wheel_width_m

    @property
    def wheels_per_side(self) -> int:
        """Wheels on each side (2 or 3)."""
        return int(self.n_wheels) // 2

    def axle_positions_m(self) -> tuple[float, ...]:
        """Longitudinal positions of the axles of one side, front first, from the centre [m]."""
        half = 0.5 * float(self.wheelbase_m)
        return (half, -half) if self.wheels_per_side == 2 else (half, 0.0, -half)


TRACK_FIELDS = tuple(f.name for f in fields(TrackGear))
WHEEL_FIELDS = tuple(f.name for f in fields(WheelGear))


@dataclass(frozen=True)
class Vehicle:
    """A skid-steered vehicle (SI units). Validated on construction.

    Attributes
    ----------
    name : identifier (file stem for shipped vehicles)
    gear : the running gear, :class:`TrackGear` or :class:`WheelGear`
    mass_kg : total mass m [kg]
    cg_height_m : height h of the centre of gravity [m] (load transfer, eq. 3.1)
    tread_m : tread B, centre-to-centre distance of the two sides [m]
    yaw_inertia_kg_m2 : yaw moment of inertia about the CG [kg m^2] (optional; the dynamic twin uses
        it, the steady models do not; default :attr:`yaw_inertia`)
    powertrain : powertrain description, interpreted by ``skidsteer_power.powertrain`` (may be empty)
    source : where the numbers come from; flags assumed values
    joints : how its joint_states map to the sides (joint names, units), interpreted by
        :class:`skidsteer_power.estimator.inputs.JointMap` (empty: the test robot's left_motor/right_motor)
    max_speed_m_s : largest |forward speed| the vehicle is commanded [m/s] (default 1.5); the power
        maps cover it, commands beyond it are flagged ``clamped``
    max_yaw_rate_rad_s : largest |yaw rate| the vehicle is commanded [rad/s] (default 2.0), likewise
        (both are the drive controller's velocity limits)
    drive_controller : the robot's drive controller below the velocity limits (accelerations, wheel
        speed ceiling, multipliers, current limit), interpreted by
        :func:`skidsteer_power.drive.controller_for_vehicle` (empty: the DES driver's set-point limit)
    measured_power : what the robot publishes as its measured power (topics of per-side or total
        current and voltage, docs/POWERTRAINS.md), interpreted by
        :func:`skidsteer_power.estimator.measured.parse_measured_power` (empty: joint_states effort)
    """

    name: str
    gear: TrackGear | WheelGear
    mass_kg: float
    cg_height_m: float
    tread_m: float
    yaw_inertia_kg_m2: float | None = None
    powertrain: JsonObject = field(default_factory=dict, hash=False)
    source: str = ''
    joints: JsonObject = field(default_factory=dict, hash=False)
    max_speed_m_s: float = DEFAULT_MAX_SPEED_M_S
    max_yaw_rate_rad_s: float = DEFAULT_MAX_YAW_RATE_RAD_S
    drive_controller: JsonObject = field(default_factory=dict, hash=False)
    measured_power: JsonObject | list[object] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f'vehicle name must be a non-empty string, not {self.name!r}')
        try:
            _validate(self)
        except ConfigError as err:
            raise _fail(self.name, str(err)) from None

    @property
    def running_gear(self) -> RunningGear:
        """'track' or 'wheel' (the ``running_gear`` key of the vehicle file)."""
        return self.gear.running_gear

    @property
    def is_tracked(self) -> bool:
        return isinstance(self.gear, TrackGear)

    @property
    def weight_N(self) -> float:
        """Weight W = m g [N]."""
        return self.mass_kg * GRAVITY_M_S2

    @property
    def drive_radius_m(self) -> float:
        """Sprocket radius (tracks) or wheel radius (wheels) r [m]."""
        return self.gear.drive_radius_m

    @property
    def contact_width_m(self) -> float:
        """Track or wheel width b [m]."""
        return self.gear.contact_width_m

    @property
    def wheels_per_side(self) -> int:
        """Wheels on each side (2 or 3); 0 for a tracked vehicle."""
        return self.gear.wheels_per_side if isinstance(self.gear, WheelGear) else 0

    def axle_positions_m(self) -> tuple[float, ...]:
        """Longitudinal positions of one side's axles, front first, from the centre [m]; () for tracks."""
        return self.gear.axle_positions_m() if isinstance(self.gear, WheelGear) else ()

    @property
    def yaw_inertia(self) -> float:
        """Yaw moment of inertia I_z [kg m^2]: ``yaw_inertia_kg_m2`` if given, else ASSUMED a uniform
        box m (L^2 + W^2) / 12 of the overall footprint, L = contact length (tracks) or wheelbase
        (wheels) + 2 r, W = tread + b (the dissertation gives no inertia)."""
        if self.yaw_inertia_kg_m2 is not None:
            return float(self.yaw_inertia_kg_m2)
        gear = self.gear
        span = gear.track_length_m if isinstance(gear, TrackGear) else gear.wheelbase_m
        length = float(span) + 2.0 * self.drive_radius_m
        width = self.tread_m + self.contact_width_m
        return self.mass_kg * (length**2 + width**2) / 12.0

    def tracks(self) -> TrackGear:
        """The running gear of a tracked vehicle; InputError if it runs on wheels."""
        if isinstance(self.gear, TrackGear):
            return self.gear
        raise InputError(f'this needs a tracked vehicle; {self.name!r} has wheels')

    def wheels(self) -> WheelGear:
        """The running gear of a wheeled vehicle; InputError if it runs on tracks."""
        if isinstance(self.gear, WheelGear):
            return self.gear
        raise InputError(f'this needs a wheeled vehicle; {self.name!r} has tracks')

    def as_dict(self) -> JsonObject:
        """The flat fields of a vehicle file (:data:`FIELD_NAMES`; None: a field of the other running
        gear). :func:`vehicle_from_dict` builds the same vehicle from it."""
        flat: JsonObject = dict.fromkeys(FIELD_NAMES)
        flat.update({f.name: getattr(self, f.name) for f in fields(self) if f.name != 'gear'})
        flat.update({f.name: getattr(self.gear, f.name) for f in fields(self.gear)})
        flat['running_gear'] = self.running_gear
        return flat


FIELD_NAMES: tuple[str, ...] = (
    'name',
    'running_gear',
    *(f.name for f in fields(Vehicle) if f.name not in ('name', 'gear')),
    *TRACK_FIELDS,
    *WHEEL_FIELDS,
)
"""The keys of a vehicle file."""


def _fail(vehicle_name: str, message: str) -> ConfigError:
    return ConfigError(f'vehicle {vehicle_name!r}: {message}')


def _validate(vehicle: Vehicle) -> None:
    """The vehicle's own fields and how they fit its running gear (ConfigError without the name)."""
    if not isinstance(vehicle.gear, (TrackGear, WheelGear)):
        raise ConfigError(f'gear must be a TrackGear or a WheelGear, not {type(vehicle.gear).__name__}')
    for name in ('mass_kg', 'cg_height_m', 'tread_m', 'max_speed_m_s', 'max_yaw_rate_rad_s'):
        _check_positive(name, getattr(vehicle, name))
    if vehicle.tread_m <= vehicle.contact_width_m:
        raise ConfigError(
            f'tread_m ({vehicle.tread_m}) must exceed the track/wheel width ({vehicle.contact_width_m})'
        )
    if vehicle.yaw_inertia_kg_m2 is not None:
        _check_positive('yaw_inertia_kg_m2', vehicle.yaw_inertia_kg_m2)
    if not isinstance(vehicle.powertrain, dict):
        raise ConfigError(f'powertrain must be a mapping, not {type(vehicle.powertrain).__name__}')
    if not isinstance(vehicle.joints, dict):
        raise ConfigError(f'joints must be a mapping, not {type(vehicle.joints).__name__}')
    if not isinstance(vehicle.drive_controller, dict):
        raise ConfigError(
            f'drive_controller must be a mapping, not {type(vehicle.drive_controller).__name__}'
        )
    if not isinstance(vehicle.measured_power, dict | list):
        raise ConfigError(
            f'measured_power must be a mapping or a list, not {type(vehicle.measured_power).__name__}'
        )
    if not isinstance(vehicle.source, str):
        raise ConfigError('source must be a string')


def _gear_from_fields(values: JsonObject) -> TrackGear | WheelGear:
    """The running gear named by ``values['running_gear']``, from (and removing) the gear keys of a
    vehicle file's mapping; an absent or null key is missing."""
    kind = values.pop('running_gear')
    if kind not in RUNNING_GEARS:
        raise ConfigError(f'running_gear must be one of {RUNNING_GEARS}, not {kind!r}')
    given = {k: values.pop(k) for k in (*TRACK_FIELDS, *WHEEL_FIELDS) if k in values}
    given = {k: v for k, v in given.items() if v is not None}
    if kind == 'wheel' and given.get('track_longitudinal_shear_ratio') == 1.0:
        del given['track_longitudinal_shear_ratio']  # the neutral value says nothing about wheels
    gear_class: type[TrackGear] | type[WheelGear] = TrackGear if kind == 'track' else WheelGear
    own = TRACK_FIELDS if kind == 'track' else WHEEL_FIELDS
    for name in given:
        if name not in own:
            raise ConfigError(f'{name} does not apply to running_gear {kind!r}')
    for f in fields(gear_class):
        if f.name not in given and f.default is MISSING:
            raise ConfigError(f'{f.name} is required for running_gear {kind!r}')
    return gear_class(**given)


RENAMED_SECTIONS = {'drivetrain': 'joints'}
"""Vehicle-file sections of earlier rounds -> their names (issue 38: "drivetrain" was the joint
mapping here and the powertrain's parts elsewhere)."""


def _renamed_sections(data: JsonObject, origin: str) -> JsonObject:
    """``data`` with each earlier section name (:data:`RENAMED_SECTIONS`) read as its name, with a
    FutureWarning saying so; ConfigError where a file gives both."""
    out = dict(data)
    for old, new in RENAMED_SECTIONS.items():
        if old not in out:
            continue
        if new in out:
            raise ConfigError(f'{origin}: give {new!r} only ({old!r} is its earlier name)')
        out[new] = out.pop(old)
        note = f"{origin}: '{old}:' is now spelled '{new}:' (the old name still works)"
        warnings.warn(note, FutureWarning, stacklevel=3)
    return out


def vehicle_from_dict(data: object, *, origin: str = '<dict>') -> Vehicle:
    """Build a validated :class:`Vehicle` from a mapping of the flat file keys (e.g. parsed YAML);
    ``origin`` names the source."""
    if not isinstance(data, dict):
        raise ConfigError(
            f'{origin}: a vehicle file must hold a mapping of fields, not {type(data).__name__}'
        )
    data = _renamed_sections(data, origin)
    unknown = sorted(set(data) - set(FIELD_NAMES))
    if unknown:
        raise ConfigError(
            f'{origin}: unknown field(s) {", ".join(map(str, unknown))}; known: {", ".join(FIELD_NAMES)}'
        )
    for required in ('name', 'running_gear', 'mass_kg', 'cg_height_m', 'tread_m'):
        if required not in data:
            raise ConfigError(f'{origin}: missing field {required!r}')
    values = dict(data)
    for section in ('powertrain', 'joints', 'drive_controller', 'measured_power'):
        if values.get(section) is None:
            values[section] = {}
    name = str(values.pop('name'))
    try:
        try:
            gear = _gear_from_fields(values)
        except ConfigError as err:
            raise _fail(name, str(err)) from None
        return Vehicle(name=name, gear=gear, **values)
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
    'joints',
    'measured_power',
    'yaw_inertia_kg_m2',
    'max_speed_m_s',
    'max_yaw_rate_rad_s',
    'drive_controller',
)


def vehicle_fingerprint(vehicle: Vehicle) -> str:
    """Stable hex digest of the vehicle's physical parameters and powertrain (not name, source or
    the joint_states mapping, which changes no model result).

    Two vehicles with the same fingerprint give the same model results, so maps can be cached by it.
    The digest is of the flat file fields (:meth:`Vehicle.as_dict`), so it does not depend on how
    the Python class groups them.
    """
    payload = {
        name: value
        for name, value in vehicle.as_dict().items()
        # no steady-state physics: the envelope (maps key on it separately: maps.power_map.cache_path),
        # the inertia (the steady models ignore it), the joint_states mapping and the drive controller
        # (it makes the set points; a map's nodes are solved at given set points or twists)
        if name not in _NOT_FINGERPRINTED
    }
    if payload['track_longitudinal_shear_ratio'] in (None, DEFAULT_TRACK_LONGITUDINAL_SHEAR_RATIO):
        del payload['track_longitudinal_shear_ratio']  # the default: fingerprints from before it stay
    for key, value in payload.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            payload[key] = repr(float(value))  # 4 and 4.0 hash alike
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]
