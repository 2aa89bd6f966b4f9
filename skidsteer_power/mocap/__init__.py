"""Motion capture of a red target with one calibrated camera (dissertation chapter 7.3.3).

Three steps, as in the text: camera calibration from checkerboard images (:mod:`.calibration`),
the ground plane from a checkerboard lying in the plane of the target (:mod:`.plane`), and per-frame
detection of the red disc (:mod:`.target`, thresholds in :mod:`.config`) over a sampled video or image
folder (:mod:`.tracking`). The trace's circle fit and mean speed come from
:mod:`skidsteer_power.analysis.trace`. :mod:`.synthetic` renders test scenes from a known camera.

Names are loaded on first use (PEP 562), so importing the package does not load OpenCV.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    'CameraCalibration': 'calibration',
    'calibrate_camera': 'calibration',
    'load_calibration': 'calibration',
    'parse_pattern': 'config',
    'save_calibration': 'calibration',
    'undistort_image': 'calibration',
    'GroundPlane': 'plane',
    'estimate_ground_plane': 'plane',
    'pixels_to_plane': 'plane',
    'TargetConfig': 'config',
    'TargetDetection': 'target',
    'TargetMiss': 'target',
    'detect_target': 'target',
    'TrackResult': 'tracking',
    'track': 'tracking',
    'write_trace_csv': 'tracking',
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:  # Any: the lazily loaded names' own types (no TYPE_CHECKING imports yet)
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return getattr(importlib.import_module(f'{__name__}.{module}'), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
