"""Physical ranges of the inputs the terramechanics and skid-steer models accept, and validity checks
of their results.

The models hold for a small skid-steered robot (the dissertation's vehicles weigh 20-60 kg, run at up
to 1.5 m/s, chapter 3.5) on soil described by plate-sinkage parameters. The ranges below are wide
around that, so that every physically meaningful question is accepted, and they stop at values where
the equations overflow or lose their meaning (a 1e-300 m wide track, a 1e300 N load, a wheel at
1e308 m/s). A value outside its range is an :class:`~skidsteer_power.errors.InputError` naming the
range; each CLI option shows its range in ``--help``.

Results: a sinkage deeper than the wheel radius (wheel) or the track's height (track) means the hub
or the belly would plough the soil, which none of eqs. 2.6-2.34 describe: :func:`check_sinkage`
makes that an error.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass

from skidsteer_power.errors import InputError


@dataclass(frozen=True)
class Range:
    """A closed interval [low, high] of a physical input in ``unit``; ``positive``: low is excluded;
    ``symmetric``: the interval holds the magnitude, low <= |value| <= high."""

    name: str
    low: float
    high: float
    unit: str
    positive: bool = False
    symmetric: bool = False

    @property
    def text(self) -> str:
        if self.symmetric:
            low = f'{self.low:g} <= ' if self.low > 0 else ''
            return f'{low}|{self.name}| <= {self.high:g} {self.unit}'
        left = '(' if self.positive else '['
        return f'{left}{self.low:g}, {self.high:g}] {self.unit}'

    def contains(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if self.symmetric:
            return self.low <= abs(value) <= self.high
        above = value > self.low if self.positive else value >= self.low
        return above and value <= self.high

    def check(self, value: float) -> float:
        """``value`` as a float if it lies in the range, else InputError naming the range."""
        value = float(value)
        if not self.contains(value):
            raise InputError(f'{self.name} = {value:g} {self.unit} is outside its range {self.text}')
        return value

    def arg(self) -> Callable[[str], float]:
        """argparse ``type=``: a number in this range (one-line error otherwise)."""

        def parse(text: str) -> float:
            try:
                return self.check(float(text))
            except ValueError as err:  # InputError is a ValueError too
                message = str(err) if isinstance(err, InputError) else f'not a number: {text!r}'
                raise argparse.ArgumentTypeError(message) from None

        parse.__name__ = self.name  # argparse names the type in some messages
        return parse

    def help(self, what: str) -> str:
        """``what`` with the unit and the range, for ``--help``."""
        return f'{what} [{self.unit}], range {self.text}'


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

DEFAULT_TRACK_HEIGHT_M = 0.2
"""Track height assumed when none is given [m]: twice the test robot's 0.1 m sprocket radius (the
track wraps the sprockets, config/vehicles/test_robot_track.yaml), the order of every vehicle here."""

MAX_RESOLUTION_NODES = 1_000_000
"""Largest number of integration nodes (product of a ``--resolution`` pair) a solve may use: the
defaults are tens to hundreds; a million already takes minutes per Newton step."""


def turn_radius_arg(text: str) -> float:
    """argparse type: a signed turning radius [m], ``inf`` (straight) or 1e-3 <= |R| <= 1e6."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if math.isinf(value):
        return value
    if value == 0:
        raise argparse.ArgumentTypeError('turning radius must be non-zero (inf = straight)')
    return TURN_RADIUS_M.arg()(text)


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
