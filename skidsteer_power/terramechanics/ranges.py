"""Physical ranges of the inputs the terramechanics and skid-steer models accept, and validity checks
of their results.

The models hold for a small skid-steered robot (the dissertation's vehicles weigh 20-60 kg, run at up
to 1.5 m/s, chapter 3.5) on soil described by plate-sinkage parameters. The ranges below are wide
around that, so that every physically meaningful question is accepted, and they stop at values where
the equations overflow or lose their meaning (a 1e-300 m wide track, a 1e300 N load, a wheel at
1e308 m/s). A value outside its range is an :class:`~skidsteer_power.errors.InputError` naming the
range; each CLI option shows its range in ``--help``
(:mod:`skidsteer_power.argtypes`, outside the hashed physics code).

Results: a sinkage deeper than the wheel radius (wheel) or the track's height (track) means the hub
or the belly would plough the soil, which none of eqs. 2.6-2.34 describe: :func:`check_sinkage`
makes that an error.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from skidsteer_power.errors import InputError


@dataclass(frozen=True)
class Range:
    """A closed interval [low, high] of a physical input in ``unit``; ``positive``: low is excluded;
    ``symmetric``: the interval holds the magnitude, low <= |value| <= high; ``integer``: a count
    (parsed as an int; '1e6' is not a count)."""

    name: str
    low: float
    high: float
    unit: str
    positive: bool = False
    symmetric: bool = False
    integer: bool = False

    def _show(self, value: float) -> str:
        return f'{int(value):,}' if self.integer else f'{value:g}'

    @property
    def text(self) -> str:
        unit = f' {self.unit}' if self.unit else ''
        if self.symmetric:
            low = f'{self.low:g} <= ' if self.low > 0 else ''
            return f'{low}|{self.name}| <= {self.high:g}{unit}'
        left = '(' if self.positive else '['
        return f'{left}{self._show(self.low)}, {self._show(self.high)}]{unit}'

    def contains(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if self.symmetric:
            return self.low <= abs(value) <= self.high
        above = value > self.low if self.positive else value >= self.low
        return above and value <= self.high

    def check(self, value: float) -> float:
        """``value`` as a float (an int for a count) if it lies in the range, else InputError
        naming the range."""
        number = float(value)
        if not self.contains(number):
            unit = f' {self.unit}' if self.unit else ''
            shown = self._show(number) if self.integer and math.isfinite(number) else f'{number:g}'
            raise InputError(f'{self.name} = {shown}{unit} is outside its range {self.text}')
        return int(value) if self.integer else number


# Inputs of the single track / single wheel (chapter 2) and of the skid-steer models (chapters 3-6).
LOAD_N = Range('load', 0.0, 1e5, 'N')  # 0 .. 10 t on one track or wheel
WIDTH_M = Range('width', 0.005, 2.0, 'm')  # Bekker's k_c / b term diverges as b -> 0 (eq. 2.6)
LENGTH_M = Range('length', 0.01, 10.0, 'm')
RADIUS_M = Range('radius', 0.01, 2.0, 'm')
SPEED_M_S = Range('speed', 0.0, 10.0, 'm/s', symmetric=True)  # quasi-static models; robot <= 1.5 m/s
FORWARD_SPEED_M_S = Range('speed', 0.0, 10.0, 'm/s', positive=True)
TURN_RADIUS_M = Range('turn radius', 1e-3, 1e6, 'm', symmetric=True)  # |R|; inf = straight is separate
PAYLOAD_KG = Range('payload', 0.0, 1000.0, 'kg')
HEIGHT_M = Range('track height', 0.005, 2.0, 'm', positive=True)
FRICTION = Range('coefficient', 0.0, 10.0, '-', positive=True)  # mu_t (Table 3.1), mu: order 1

# Rigid ground (terrain files with ``contact: rigid``; issue 35). Friction: ice about 0.05-0.15, dry
# rubber on concrete 0.75-0.9 (Table 3.1; Noon 1994), soft rubber compounds up to about 1.7; rolling
# resistance from about 0.001 (steel on rail) to 0.35 (tyres on a ploughed field, Wong, Theory of Ground
# Vehicles, ch. 1); the slip modulus K of the friction's mobilisation (eq. 2.3 form): a tyre reaches its
# peak friction at a few percent slip over a patch of 0.05-0.2 m, K of a few mm.
RIGID_FIELD_RANGES: dict[str, Range] = {
    'mu_longitudinal': Range('mu_longitudinal', 0.0, 2.0, '', positive=True),
    'mu_lateral': Range('mu_lateral', 0.0, 2.0, '', positive=True),
    'rolling_resistance': Range('rolling_resistance', 0.0, 0.5, ''),
    'K': Range('K', 1e-5, 0.1, 'm'),
}
"""Physical range of each field of rigid ground (SI): the bounds a calibration may search in."""

# Vehicle files (skidsteer_power.vehicle): the dissertation's robots weigh 20-60 kg with 0.1 m sprockets;
# these bounds hold any small-to-medium skid-steered vehicle and reject numbers without a meaning.
MASS_KG = Range('mass', 0.0, 10_000.0, 'kg', positive=True)  # up to a 10 t vehicle
CG_HEIGHT_M = Range('cg height', 0.0, 5.0, 'm', positive=True)
TREAD_M = Range('tread', 0.0, 10.0, 'm', positive=True)
WHEELBASE_M = Range('wheelbase', 0.0, 20.0, 'm', positive=True)
# K_x / K of a track: a belt in series with the soil adds compliance, never takes it away
LONGITUDINAL_SHEAR_RATIO = Range('track_longitudinal_shear_ratio', 1.0, 100.0, '')
YAW_RATE_RAD_S = Range('yaw rate', 0.0, 20.0, 'rad/s', positive=True)  # robot <= 2 rad/s
COMMAND_YAW_RATE_RAD_S = Range('yaw rate', 0.0, 10.0, 'rad/s', symmetric=True)  # a signed command
YAW_INERTIA_KG_M2 = Range('yaw inertia', 0.0, 1e6, 'kg m^2', positive=True)

# Amounts of work (issue 28): every input that sets how long a command runs or how much memory it
# takes has a maximum, checked and shown in --help by the same Range. Measured on the 2-core CI
# machine: the twin runs about 0.5 s of CPU and 0.07 MB per simulated second.
SIM_DURATION_S = Range('simulated time', 0.0, 3600.0, 's', positive=True)  # ~30 min CPU, ~0.3 GB
LEAD_IN_S = Range('lead-in', 0.0, 60.0, 's')
LEG_LENGTH_M = Range('leg length', 0.0, 1e5, 'm', positive=True)  # 100 km: far beyond a battery
LEG_DURATION_S = Range('leg duration', 0.0, 1e6, 's', positive=True)  # 11.6 days
MAP_RINGS = Range('rings', 2, 64, '', integer=True)  # default 16
MAP_ANGLES = Range('angles', 3, 401, '', integer=True)  # default 101
MAP_ELEMENTS = Range('elements', 2, 200, '', integer=True)  # default 40 per contact
MIN_RADIUS_M = Range('min radius', 0.0, 100.0, 'm', positive=True)
CLOCK_HZ = Range('clock rate', 0.0, 1000.0, 'Hz', positive=True)
REPLAY_RATE = Range('rate', 1e-3, 1e3, 'x')
BAG_TIME_S = Range('bag time', 0.0, 1e7, 's')  # 116 days; int64 nanoseconds hold 292 years
SUBSCRIBER_WAIT_S = Range('wait', 0.0, 3600.0, 's')
RECORD_DURATION_S = Range('duration', 0.0, 1e7, 's', positive=True)
SAMPLES = Range('samples', 0, 10_000, '', integer=True)
SEED = Range('seed', 0, 2**32 - 1, '', integer=True)  # numpy's SeedSequence takes non-negative ints
LOCAL_WORKERS = Range('local workers', 1, os.cpu_count() or 1, '', integer=True)  # more: --scheduler
ROUTE_CSV_BYTES = 64 * 2**20
"""Largest route or command CSV read [bytes] (a 200 000-row route is about 8 MB)."""
COMMAND_ROWS = 1_000_000
"""Most rows a command CSV may have (0.5 ms rows for 500 s; the twin steps at 2 ms)."""

DEFAULT_TRACK_HEIGHT_M = 0.2
"""Track height assumed when none is given [m]: twice the test robot's 0.1 m sprocket radius (the
track wraps the sprockets, config/vehicles/test_robot_track.yaml), the order of every vehicle here."""

MAX_RESOLUTION_NODES = 1_000_000
"""Largest number of integration nodes (product of a ``--resolution`` pair) a solve may use: the
defaults are tens to hundreds; a million already takes minutes per Newton step."""


def check_file_size(path: str | os.PathLike[str], limit: int = ROUTE_CSV_BYTES) -> None:
    """InputError when the file at ``path`` is larger than ``limit`` bytes (checked before reading)."""
    size = os.path.getsize(path)
    if size > limit:
        raise InputError(f'{os.fspath(path)}: {size:,} bytes; at most {limit:,} are read')


def check_sinkage(sinkage_m: float, limit_m: float, what: str) -> float:
    """``sinkage_m`` [m] if finite and within ``limit_m`` [m] (the ``what``), else InputError."""
    if not math.isfinite(sinkage_m):
        raise InputError(f'sinkage is not finite ({sinkage_m}): the load cannot be carried on this soil')
    if sinkage_m > limit_m:
        raise InputError(
            f'sinkage {sinkage_m:.4g} m exceeds the {what} {limit_m:g} m: the vehicle would plough the '
            'soil, outside the validity of the model (eqs. 2.6-2.34)'
        )
    return sinkage_m


def check_resolution(resolution: tuple[int, ...]) -> tuple[int, ...]:
    """A ``--resolution`` pair whose product is at most :data:`MAX_RESOLUTION_NODES`."""
    nodes = math.prod(resolution)
    if nodes > MAX_RESOLUTION_NODES:
        raise InputError(
            f'resolution {",".join(map(str, resolution))} has {nodes:,} nodes; at most '
            f'{MAX_RESOLUTION_NODES:,} are allowed'
        )
    return resolution
