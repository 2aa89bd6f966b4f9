"""argparse types and ``--help`` texts of the physical ranges (:mod:`skidsteer_power.terramechanics.ranges`).

Kept out of the physics packages on purpose: their source is hashed into the cache digest
(:func:`skidsteer_power.cache.physics_digest`), so a help text edited there would invalidate every
cached map. Every parse error is one line (argparse prints it with the usage and exits with 2).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import TURN_RADIUS_M, Range


def range_arg(bounds: Range) -> Callable[[str], float]:
    """argparse ``type=``: a number in ``bounds`` (one-line error otherwise)."""

    def parse(text: str) -> float:
        try:
            return bounds.check(int(text) if bounds.integer else float(text))
        except ValueError as err:  # InputError is a ValueError too
            what = 'an integer' if bounds.integer else 'a number'
            message = str(err) if isinstance(err, InputError) else f'not {what}: {text!r}'
            raise argparse.ArgumentTypeError(message) from None

    parse.__name__ = bounds.name  # argparse names the type in some messages
    return parse


def range_help(bounds: Range, what: str) -> str:
    """``what`` with the unit and the range of ``bounds``, for ``--help``."""
    unit = f' [{bounds.unit}]' if bounds.unit else ''
    return f'{what}{unit}, range {bounds.text}'


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
    return range_arg(TURN_RADIUS_M)(text)
