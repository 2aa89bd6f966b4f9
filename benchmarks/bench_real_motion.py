"""BorealTC's real Husky (issue 36): the yaw rate predicted from the recorded wheel speeds (the set
points: no command is recorded) against the gyro, per surface with at least 7 runs, calibrated on the
even runs (``calibrate``'s motion fit: FESS at the set points against the gyro, no torque), checked
on the odd runs. Beside it: the no-slip kinematics (tread from the URDF), an ICR model (chapter 3.4:
the effective tread fitted to the same even runs) and the preset terrain uncalibrated.

Goals (per surface): the calibrated prediction no worse than the preset (calibration never hurts on
data it did not see) and better than the no-slip kinematics. The ICR fit is the simplest fitted
alternative and stands beside it, without a goal. About 1 min of CPU.
"""

from __future__ import annotations

from benchmarks import realdata
from benchmarks.harness import Report
from skidsteer_power.errors import SkidsteerError

TABLE = 'real_motion'


def table(rows: list[realdata.MotionRow], failed: dict[str, str]) -> str:
    lines = [
        '| surface | segments fit / check | no-slip kinematics | ICR fit (even runs) | FESS preset | '
        'FESS calibrated (even runs) | calibration |',
        '| --- | ---: | ---: | ---: | ---: | ---: | --- |',
    ]
    for r in rows:
        lines.append(
            f'| {r.surface} | {r.segments_fit} / {r.segments_check} | {r.no_slip:.3f} | {r.icr:.3f} | '
            f'{r.preset:.3f} | {r.calibrated:.3f} | {r.status} |'
        )
    for surface, why in failed.items():
        lines.append(f'| {surface} | - | - | - | - | - | failed: {why} |')
    return '\n'.join(lines) + "\n\nYaw-rate MAE [rad/s] on the odd runs' steady segments."


def run(report: Report) -> None:
    rows, failed = [], {}
    for surface in realdata.surfaces():
        numbers = realdata.runs(surface)
        try:
            row = realdata.motion_row(surface, numbers[0::2], numbers[1::2])
        except SkidsteerError as err:  # a failed model is a visible row with its reason
            failed[surface] = str(err)
            report.figure(f'{surface}: calibrated yaw-rate MAE', float('nan'), 'rad/s', goal='a value',
                          met=False, note=str(err))  # fmt: skip
            continue
        rows.append(row)
        note = f'no-slip {row.no_slip:.3f}, ICR fit {row.icr:.3f}, preset {row.preset:.3f}; {row.status}'
        report.under(f'{surface}: calibrated yaw-rate MAE vs preset', row.calibrated, 'rad/s',
                     row.preset, inclusive=True, note=note)  # fmt: skip
        report.under(f'{surface}: calibrated yaw-rate MAE vs no-slip kinematics', row.calibrated, 'rad/s',
                     row.no_slip, note=note)  # fmt: skip
        report.figure(f'{surface}: ICR fit yaw-rate MAE (reference)', row.icr, 'rad/s')
    report.tables[TABLE] = table(rows, failed)
