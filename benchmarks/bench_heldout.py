"""Issues 35 and 36's held-out checks, as PROXIES (twin recordings, no real robot).

Energy (benchmarks/heldout_proxy.py: a Husky whose powertrain the user's vehicle file does not know):
calibrated on the first half of its drive, the second half's battery V x I energy. Goal per case:
|error| <= 15 % and below the linear fit's |error| (P = a|v| + b|w| + c fitted to the same first half).

Motion (benchmarks/heldout_motion_proxy.py: a Husky's own recording layout, odometry but no current):
``calibrate --fit auto`` on the first half, ``predict --commands`` on the second half's held commands.
Goal per case (issue 36): yaw rate MAE <= 0.08 rad/s and vx MAE <= 0.07 m/s, each below the linear
fit's (v = a v_cmd + b, w_z = c w_cmd + d on the first half).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from benchmarks import heldout_motion_proxy as motion
from benchmarks.harness import Report
from benchmarks.heldout_proxy import Case, Outcome, run_case

CASES = (
    Case('grass', 1),
    Case('grass', 2),
    Case('asphalt', 3),
    Case('grass', 4),
    Case('flooring', 7),
    Case('sandy_loam', 8),
    Case('concrete', 9),
)
TABLE = 'heldout-proxy'
MOTION_CASES = (Case('grass', 5), Case('sandy_loam', 4), Case('lete_sand', 6))
MOTION_TABLE = 'heldout-motion-proxy'
MOTION_MODELS = ('no-slip kinematics', 'linear fit', 'FESS preset', 'FESS calibrated')


def table(outcomes: list[Outcome]) -> str:
    lines = [
        '| twin terrain | seed | measured [kJ] | effective start | calibrated | linear fit | met | fitted |',
        '| --- | ---: | ---: | ---: | ---: | ---: | --- | --- |',
    ]
    for o in outcomes:
        met = 'yes' if _met(o) else 'no'
        lines.append(
            f'| {o.case.terrain} | {o.case.seed} | {o.measured_J / 1e3:.2f} | {o.start_pct:+.1f} % | '
            f'{o.calibrated_pct:+.1f} % | {o.linear_pct:+.1f} % | {met} | {o.fitted} |'
        )
    within = sum(abs(o.calibrated_pct) <= 15.0 for o in outcomes)
    better = sum(abs(o.calibrated_pct) < abs(o.linear_pct) for o in outcomes)
    n = len(outcomes)
    mean_cal = sum(abs(o.calibrated_pct) for o in outcomes) / max(n, 1)
    mean_lin = sum(abs(o.linear_pct) for o in outcomes) / max(n, 1)
    lines += [
        '',
        f"Goal (|error| <= 15 % and below the linear fit's): within 15 % in {within} of {n}, better than "
        f'the linear fit in {better} of {n} (**{sum(_met(o) for o in outcomes)} of {n} met**); mean '
        f'|error| calibrated {mean_cal:.1f} %, linear fit {mean_lin:.1f} %.',
    ]
    return '\n'.join(lines)


def _met(o: Outcome) -> bool:
    return abs(o.calibrated_pct) <= 15.0 and abs(o.calibrated_pct) < abs(o.linear_pct)


def run(report: Report) -> None:
    outcomes = []
    with tempfile.TemporaryDirectory(prefix='heldout_') as tmp:
        for case in CASES:
            o = run_case(case, Path(tmp) / f'{case.terrain}_{case.seed}')
            outcomes.append(o)
            label = f'{case.terrain} seed {case.seed}: |energy error|'
            note = f'start {o.start_pct:+.1f} %, calibrated {o.calibrated_pct:+.1f} %, '
            note += f'linear {o.linear_pct:+.1f} %'
            goal = '<= 15 % and < linear'
            err = abs(o.calibrated_pct)
            report.figure(f'{label} calibrated', err, '%', goal=goal, met=_met(o), note=note)
            report.figure(f'{label} linear fit', abs(o.linear_pct), '%')
    report.tables[TABLE] = table(outcomes)
    print(report.tables[TABLE])
    run_motion(report)


def motion_table(outcomes: list[motion.MotionOutcome]) -> str:
    head = ' | '.join(f'{m} vx / yaw' for m in MOTION_MODELS)
    lines = [f'| twin terrain | seed | windows fit / check | {head} | met | fitted |',
             '| --- | ---: | ---: |' + ' ---: |' * len(MOTION_MODELS) + ' --- | --- |']  # fmt: skip
    for o in outcomes:
        cells = ' | '.join(f'{o.mae[m][0]:.3f} / {o.mae[m][1]:.3f}' for m in MOTION_MODELS)
        lines.append(
            f'| {o.case.terrain} | {o.case.seed} | {o.windows_fit} / {o.windows_check} | {cells} | '
            f'{"yes" if _motion_met(o) else "no"} | {o.fitted} |'
        )
    n = len(outcomes)
    goal = f'vx <= {motion.GOAL_VX_M_S} m/s, yaw rate <= {motion.GOAL_YAW_RAD_S} rad/s'
    goal += ', each below the linear fit'
    lines += ['', f'MAE of the steady windows, vx [m/s] / yaw rate [rad/s]. Goal ({goal}\'s): '
              f'**{sum(_motion_met(o) for o in outcomes)} of {n} met**.']  # fmt: skip
    return '\n'.join(lines)


def _motion_met(o: motion.MotionOutcome) -> bool:
    vx, yaw = o.mae['FESS calibrated']
    lin_vx, lin_yaw = o.mae['linear fit']
    return vx <= motion.GOAL_VX_M_S and yaw <= motion.GOAL_YAW_RAD_S and vx < lin_vx and yaw < lin_yaw


def run_motion(report: Report) -> None:
    outcomes = []
    with tempfile.TemporaryDirectory(prefix='heldout_motion_') as tmp:
        for case in MOTION_CASES:
            o = motion.run_case(case, Path(tmp) / f'{case.terrain}_{case.seed}')
            outcomes.append(o)
            vx, yaw = o.mae['FESS calibrated']
            lin_vx, lin_yaw = o.mae['linear fit']
            label = f'motion, {case.terrain} seed {case.seed}'
            note = f'linear fit {lin_vx:.3f} m/s, {lin_yaw:.3f} rad/s; preset {o.mae["FESS preset"][0]:.3f}, '
            note += f'{o.mae["FESS preset"][1]:.3f}; {o.windows_check} windows, {o.limited} limited'
            report.figure(f'{label}: yaw rate MAE calibrated', yaw, 'rad/s', goal='<= 0.08 and < linear',
                          met=yaw <= motion.GOAL_YAW_RAD_S and yaw < lin_yaw, note=note)  # fmt: skip
            report.figure(f'{label}: vx MAE calibrated', vx, 'm/s', goal='<= 0.07 and < linear',
                          met=vx <= motion.GOAL_VX_M_S and vx < lin_vx)  # fmt: skip
    report.tables[MOTION_TABLE] = motion_table(outcomes)
    print(report.tables[MOTION_TABLE])
