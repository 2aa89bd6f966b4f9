"""What the dissertation measured on the real test robot on sand (ch. 7.3.4): the truth every
twin and model figure answers to. Nothing here is computed.

* :data:`APPENDIX_D_RADII`: the 14 turning cells of Appendix D ("Trace of the Test Robot and the
  Curve Fitted Circle", the data behind Figure 7.38): configuration, commanded V [m/s], commanded
  yaw rate [rad/s], measured radius [m] (SVD circle fit, eqs. 7.8-7.10) and average speed [m/s].
  The track's cells are the 0.1 m/s section's seven and the 0.2 m/s section's first two; the
  6-wheel cells are the last five of the 0.2 m/s section, so they belong to its five highest yaw
  rates. The project's one copy: the twin, FESS (``models/appendix_d.py``) and the main job read it.
* :data:`TABLE_7_3_COMPLETED`: the cells of Table 7.3 with an entry (the run completed); the text:
  "skid steering tests failed (cells with no entry in Table 7.3), when the turning radius was
  small ... the test robot got stuck in the sand". One grid for all three configurations.
* :func:`table_7_3_segments`: the experiment as commands, every completed set held from rest.
"""

from __future__ import annotations

from dataclasses import dataclass

from skidsteer_power.commands import Segment

TABLE_7_3_YAW_RATES = (0.0, 0.01, 0.02, 0.04, 0.08, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35)
"""Table 7.3's yaw-rate columns [rad/s]."""
TABLE_7_3_SPEEDS = (0.1, 0.2)
"""Table 7.3's forward-velocity rows [m/s]."""
TABLE_7_3_COMPLETED: dict[float, tuple[float, ...]] = {
    0.1: (0.0, 0.01, 0.02, 0.04, 0.08, 0.1, 0.15, 0.2),
    0.2: TABLE_7_3_YAW_RATES,
}
"""Completed cells per commanded speed [m/s]: yaw rates [rad/s] (Table 7.3); the others got stuck."""
TABLE_7_3_CONFIGURATIONS = ('test_robot_4wheel', 'test_robot_6wheel', 'test_robot_track')


@dataclass(frozen=True)
class AppendixDCell:
    """One Appendix D run: configuration, command (V [m/s], yaw rate [rad/s]), the fitted circle's
    radius [m] and the average forward speed printed beside it [m/s]."""

    vehicle: str
    speed_cmd: float
    yaw_cmd: float
    radius_m: float
    speed_m_s: float

    @property
    def commanded_radius_m(self) -> float:
        """V_cmd / yaw rate_cmd [m]: the radius if the robot followed its command."""
        return self.speed_cmd / self.yaw_cmd


APPENDIX_D_RADII: tuple[AppendixDCell, ...] = (
    # track, 0.1 m/s (dissertation text lines 2174-2216)
    AppendixDCell('test_robot_track', 0.1, 0.01, 19.44, 0.10),
    AppendixDCell('test_robot_track', 0.1, 0.02, 7.40, 0.10),
    AppendixDCell('test_robot_track', 0.1, 0.04, 3.64, 0.10),
    AppendixDCell('test_robot_track', 0.1, 0.08, 1.83, 0.10),
    AppendixDCell('test_robot_track', 0.1, 0.1, 1.44, 0.10),
    AppendixDCell('test_robot_track', 0.1, 0.15, 1.00, 0.09),
    AppendixDCell('test_robot_track', 0.1, 0.2, 0.84, 0.08),
    # track, 0.2 m/s (lines 2239-2246)
    AppendixDCell('test_robot_track', 0.2, 0.01, 33.49, 0.20),
    AppendixDCell('test_robot_track', 0.2, 0.02, 17.48, 0.20),
    # six wheels, 0.2 m/s (lines 2131-2158)
    AppendixDCell('test_robot_6wheel', 0.2, 0.15, 2.45, 0.20),
    AppendixDCell('test_robot_6wheel', 0.2, 0.2, 1.92, 0.19),
    AppendixDCell('test_robot_6wheel', 0.2, 0.25, 1.62, 0.18),
    AppendixDCell('test_robot_6wheel', 0.2, 0.3, 1.44, 0.17),
    AppendixDCell('test_robot_6wheel', 0.2, 0.35, 1.26, 0.17),
)
"""The 14 Appendix D cells (the only copy in the project: the twin, FESS and the main job read it)."""
TRACK_FIT_CELLS = tuple(c for c in APPENDIX_D_RADII if c.vehicle == 'test_robot_track' and c.speed_cmd == 0.1)
"""The only cells a model may fit to (issue 25): the track's seven at 0.1 m/s; the other seven are
the check."""


def table_7_3_completed(speed_m_s: float, yaw_rate_rad_s: float) -> bool:
    """True if Table 7.3 has an entry (the real robot completed the run) at this command."""
    return yaw_rate_rad_s in TABLE_7_3_COMPLETED[speed_m_s]


def table_7_3_cells() -> list[tuple[str, float, float, bool]]:
    """The 66 cells: (configuration, V [m/s], yaw rate [rad/s], completed)."""
    return [
        (name, v, w, table_7_3_completed(v, w))
        for name in TABLE_7_3_CONFIGURATIONS
        for v in TABLE_7_3_SPEEDS
        for w in TABLE_7_3_YAW_RATES
    ]


def table_7_3_segments(hold_s: float = 4.0, pause_s: float = 1.0) -> list[Segment]:
    """Every completed Table 7.3 set (:data:`TABLE_7_3_COMPLETED`) as a constant command held
    ``hold_s`` [s], each followed by a stop of ``pause_s`` [s] (V = yaw rate = 0), so each set starts
    from rest as in the experiments (ch. 7.3.4)."""
    segments = []
    for speed, yaw_rates in TABLE_7_3_COMPLETED.items():
        for yaw_rate in yaw_rates:
            segments.append(Segment(speed, yaw_rate, hold_s))
            if pause_s > 0:
                segments.append(Segment(0.0, 0.0, pause_s))
    return segments
