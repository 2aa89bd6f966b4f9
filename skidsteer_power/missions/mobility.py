"""Mobility indices of ch. 8: maximum drawbar pull (and its ratio to the weight) in straight running.

The dissertation's mobility indices (ch. 8.2, Figure 8.9; ch. 8.3's X axis) are the maximum drawbar
pull over the vehicle weight, and the sinkage. The maximum drawbar pull is the largest net pull the
running gear can develop on level ground over all slips, with the weight shared equally (CG at the
centre, straight running):

* tracks: two tracks of load W/2, F_d(s) = F_s(s) - R_c (eq. 2.18), maximized over s in [0, 1];
* wheels: n rigid wheels of load W/n, F_d(s) = F_x(s) of the Wong-Reece wheel (eqs. 2.27-2.28),
  maximized over s in [0, 0.99].

Each is one vectorized array call over (distinct running gear, slip): candidates that differ only
in what the pull does not depend on (tread; a wheeled vehicle's wheelbase, a track's sprocket
radius) share one row, so the 729 Table 8.4 candidates need 27 track and 54 wheel rows.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from skidsteer_power.numeric import distinct_rows
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.terramechanics.track import drawbar_pull as track_drawbar_pull
from skidsteer_power.terramechanics.wheel import wheel_at_slip
from skidsteer_power.vehicle import TrackGear, Vehicle, WheelGear

TRACK_SLIPS = np.linspace(0.0, 1.0, 101)
WHEEL_SLIPS = np.linspace(0.0, 0.99, 34)


def max_drawbar_pull(vehicles: Sequence[Vehicle], terrain: Terrain) -> np.ndarray:
    """Maximum straight-running drawbar pull [N] of each vehicle (see module doc), one array call
    per running-gear type."""
    out = np.empty(len(vehicles))
    tracked = [(k, v.weight_N, v.gear) for k, v in enumerate(vehicles) if isinstance(v.gear, TrackGear)]
    wheeled = [(k, v.weight_N, v.gear) for k, v in enumerate(vehicles) if isinstance(v.gear, WheelGear)]
    if tracked:
        rows, inverse = distinct_rows(
            np.array([[w / 2.0, g.track_width_m, g.track_length_m] for _, w, g in tracked])
        )
        load, width, length = (rows[:, k : k + 1] for k in range(3))
        dp = track_drawbar_pull(terrain, load, width, length, TRACK_SLIPS[None, :])
        out[[k for k, _, _ in tracked]] = 2.0 * dp.max(axis=1)[inverse]
    if wheeled:
        n = np.array([g.n_wheels for _, _, g in wheeled], dtype=float)
        rows, inverse = distinct_rows(
            np.array([[w / g.n_wheels, g.wheel_radius_m, g.wheel_width_m] for _, w, g in wheeled])
        )
        load, radius, width = (rows[:, k : k + 1] for k in range(3))
        state = wheel_at_slip(terrain, load, WHEEL_SLIPS[None, :], radius, width)
        out[[k for k, _, _ in wheeled]] = n * np.asarray(state.Fx_N).max(axis=1)[inverse]
    return out
