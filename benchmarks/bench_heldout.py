"""Issue 35's held-out check, as a PROXY (benchmarks/heldout_proxy.py: twin recordings of a Husky whose
powertrain the user's vehicle file does not know; no real robot): calibrated on the first half of its
drive, the second half's battery V x I energy. Goal per case: |error| <= 15 % and below the linear
fit's |error| (P = a|v| + b|w| + c fitted to the same first half).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

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
