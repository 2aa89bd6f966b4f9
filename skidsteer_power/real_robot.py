"""What the dissertation measured on the real test robot on sand (ch. 7.3.4): the truth every
twin and model figure answers to. Nothing here is computed.

* :data:`APPENDIX_D_RADII`: the 14 turning cells of Appendix D ("Trace of the Test Robot and the
  Curve Fitted Circle", the data behind Figure 7.38): configuration, commanded V [m/s], commanded
  yaw rate [rad/s], measured radius [m] (SVD circle fit, eqs. 7.8-7.10). The track's cells are the
  0.1 m/s section's seven and the 0.2 m/s section's first two; the 6-wheel cells are the last five
  of the 0.2 m/s section, so they belong to its five highest yaw rates.
* :data:`TABLE_7_3_COMPLETED`: the cells of Table 7.3 with an entry (the run completed); the text:
  "skid steering tests failed (cells with no entry in Table 7.3), when the turning radius was
  small ... the test robot got stuck in the sand". One grid for all three configurations.
"""

from __future__ import annotations

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

APPENDIX_D_RADII: tuple[tuple[str, float, float, float], ...] = (
    ('test_robot_track', 0.1, 0.01, 19.44),
    ('test_robot_track', 0.1, 0.02, 7.40),
    ('test_robot_track', 0.1, 0.04, 3.64),
    ('test_robot_track', 0.1, 0.08, 1.83),
    ('test_robot_track', 0.1, 0.1, 1.44),
    ('test_robot_track', 0.1, 0.15, 1.00),
    ('test_robot_track', 0.1, 0.2, 0.84),
    ('test_robot_track', 0.2, 0.01, 33.49),
    ('test_robot_track', 0.2, 0.02, 17.48),
    ('test_robot_6wheel', 0.2, 0.15, 2.45),
    ('test_robot_6wheel', 0.2, 0.2, 1.92),
    ('test_robot_6wheel', 0.2, 0.25, 1.62),
    ('test_robot_6wheel', 0.2, 0.3, 1.44),
    ('test_robot_6wheel', 0.2, 0.35, 1.26),
)
"""(configuration, commanded V [m/s], commanded yaw rate [rad/s], measured radius [m]), Appendix D."""


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
