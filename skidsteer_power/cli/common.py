"""Helpers shared by subcommands: JSON output and argument types.

``common`` defines no ``register`` and so adds no subcommand.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value


def print_json(payload: dict[str, Any]) -> None:
    """Print ``payload`` as JSON (numpy values converted; NaN -> null, inf -> "inf")."""
    json.dump(_plain(payload), sys.stdout, indent=2)
    sys.stdout.write('\n')


def print_table(payload: dict[str, Any]) -> None:
    """Print ``key  value`` lines for a human."""
    width = max((len(k) for k in payload), default=0)
    for key, value in _plain(payload).items():
        print(f'{key:<{width}}  {value}')


def emit(payload: dict[str, Any], as_json: bool) -> None:
    (print_json if as_json else print_table)(payload)


def _number(text: str, *, allow_inf: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if math.isnan(value) or (math.isinf(value) and not allow_inf):
        raise argparse.ArgumentTypeError(f'not a finite number: {text!r}')
    return value


def finite_float(text: str) -> float:
    """argparse type: a finite float."""
    return _number(text)


def positive_float(text: str) -> float:
    """argparse type: a finite float > 0."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be > 0: {text!r}')
    return value


def nonnegative_float(text: str) -> float:
    """argparse type: a finite float >= 0."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0: {text!r}')
    return value


def radius_float(text: str) -> float:
    """argparse type: a turning radius in m; 'inf' (straight) allowed, 0 is not (use a yaw rate)."""
    value = _number(text, allow_inf=True)
    if value == 0:
        raise argparse.ArgumentTypeError('turning radius must be non-zero (inf = straight)')
    return value


def add_json_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--json', action='store_true', help='print machine-readable JSON (SI units)')
