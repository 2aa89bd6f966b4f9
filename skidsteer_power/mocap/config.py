"""Target thresholds and the board pattern string (no OpenCV import, so the CLI can build its parser
without loading cv2)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from skidsteer_power.errors import ConfigError, InputError

_PATTERN = re.compile(r'^\s*(\d+)\s*[xX]\s*(\d+)\s*$')


@dataclass(frozen=True)
class TargetConfig:
    """Thresholds for the red target (8-bit channel values; OpenCV HSV saturation 0-255).

    A pixel is target when R >= red_min, G <= green_max, B <= blue_max and S >= saturation_min.
    min_area_px : smallest accepted blob [px]; min_roundness : 4 pi area / perimeter^2 of the blob's
    outline (1 for a perfect circle, about 0.9 for a digitized disc, about 0.66 for a 3:1 ellipse).
    """

    red_min: int = 120
    green_max: int = 100
    blue_max: int = 100
    saturation_min: int = 120
    min_area_px: int = 30
    min_roundness: float = 0.6

    def __post_init__(self) -> None:
        for name in ('red_min', 'green_max', 'blue_max', 'saturation_min'):
            value = getattr(self, name)
            if not 0 <= value <= 255:
                raise ConfigError(f'target threshold {name} must be within 0..255, got {value}')
        if self.min_area_px < 1:
            raise ConfigError(f'min_area_px must be >= 1, got {self.min_area_px}')
        if not 0 <= self.min_roundness <= 1:
            raise ConfigError(f'min_roundness must be within 0..1, got {self.min_roundness}')


MAX_PATTERN_SIDE = 100
"""Most inner corners along one side of a checkerboard (printed boards have 5-30)."""


def parse_pattern(text: str) -> tuple[int, int]:
    """'COLSxROWS' (inner corners, e.g. '9x6') -> (cols, rows); InputError if malformed."""
    match = _PATTERN.match(text or '')
    if match is None:
        raise InputError(f'bad pattern {text!r}: expected inner corners as COLSxROWS, e.g. 9x6')
    cols, rows = int(match.group(1)), int(match.group(2))
    if cols < 2 or rows < 2:
        raise InputError(f'bad pattern {text!r}: needs at least 2x2 inner corners')
    if max(cols, rows) > MAX_PATTERN_SIDE:  # 100000x100000 once asked for 149 GiB
        raise InputError(f'bad pattern {text!r}: at most {MAX_PATTERN_SIDE} inner corners a side')
    return cols, rows
