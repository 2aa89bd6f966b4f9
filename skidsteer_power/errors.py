"""Exception tree shared by every layer.

Domain errors subclass built-ins (as python-control does) so callers may catch either.
The CLI turns any :class:`SkidsteerError` into one line on stderr and exit code 2.
"""

from __future__ import annotations


class SkidsteerError(Exception):
    """Base of every error this package raises on purpose."""


class ConfigError(SkidsteerError, ValueError):
    """A terrain, vehicle, powertrain or other configuration is missing, malformed or non-physical."""


class InputError(SkidsteerError, ValueError):
    """An argument (load, width, slip, speed, file ...) is outside its physical or accepted range."""


class ConvergenceError(SkidsteerError, RuntimeError):
    """A numerical solver did not converge; the message names the operating point."""


class MapMismatchError(SkidsteerError, ValueError):
    """A stored look-up map was built for another vehicle, terrain or model version."""
