"""BorealTC's real Husky (issue 35): the measured energy V x I (the motor-current magnitudes x the
24 V nominal bus, ASSUMED; benchmarks/realdata.py says why the current is the motor's) against the
same quantity predicted from the recorded wheel speeds (the set points: 24 V x the predicted motoring
current), per surface with at least 7 runs.

Splits: calibrate on the even runs, predict the odd runs; and a transfer split (calibrate on the runs
below the median mean speed, predict the runs above). Models: the preset (husky_a200 powertrain, the
surface's terrain preset), FESS calibrated with ``--fit auto`` (ground and internal resistance; the
measured motor torque K_t |I| and the gyro's yaw rate together) on the steady segments of the fit
runs, and the linear fit P = a|v| + b|w| + c on every sample of the fit runs. Energy is
sample-and-hold over every sample of the check runs (standing included).

Goals: even/odd |energy error| <= max(linear's + 2 points, 5 %); transfer <= half the linear fit's.
About 2 min of CPU.
"""

from __future__ import annotations

from benchmarks import realdata
from benchmarks.harness import Report
from skidsteer_power.errors import SkidsteerError

TABLE = 'real'
BREAKDOWN = 'real-breakdown'
SPLITS = ('even/odd', 'transfer')


def table(rows: list[realdata.EnergyRow], failed: dict[str, str]) -> str:
    lines = [
        '| surface | split | fit runs -> check runs | measured [kJ] | preset | FESS calibrated | linear | '
        'goal on \\|calibrated\\| | met | calibration |',
        '| --- | --- | --- | ---: | ---: | ---: | ---: | --- | --- | --- |',
    ]
    for r in rows:
        runs = f'{",".join(map(str, r.runs_fit))} -> {",".join(map(str, r.runs_check))}'
        met = 'yes' if abs(r.calibrated_pct) <= limit(r) else 'no'
        lines.append(
            f'| {r.surface} | {r.split} | {runs} | {r.measured_J / 1e3:.1f} | {r.preset_pct:+.1f} % | '
            f'{r.calibrated_pct:+.1f} % | {r.linear_pct:+.1f} % | <= {limit(r):.1f} % | {met} | {r.status} |'
        )
    for key, why in failed.items():
        lines.append(f'| {key} | | | | | failed | | | no | {why} |')
    met_count = sum(abs(r.calibrated_pct) <= limit(r) for r in rows)
    total = len(rows) + len(failed)
    return '\n'.join(lines) + (
        '\n\nEnergy error, predicted / measured - 1, of the check runs. Goals: even/odd |error| <= '
        f"max(linear's + 2 points, 5 %), transfer <= half the linear fit's: **{met_count} of {total} met**."
    )


def breakdown(rows: list[realdata.EnergyRow]) -> str:
    """Where each split's check-run energy goes, by kind of motion (realdata.MOTION_KINDS)."""
    lines = [
        '| surface | split | motion | time [s] | measured [kJ] | FESS calibrated [kJ] | linear [kJ] |',
        '| --- | --- | --- | ---: | ---: | ---: | ---: |',
    ]
    for r in rows:
        for kind, share in r.by_motion.items():
            if share.seconds <= 0.0:
                continue
            lines.append(
                f'| {r.surface} | {r.split} | {kind} | {share.seconds:.0f} | {share.measured_J / 1e3:.1f} | '
                f'{share.calibrated_J / 1e3:.1f} | {share.linear_J / 1e3:.1f} |'
            )
    return '\n'.join(lines) + (
        '\n\nBy command: standing |v| < 0.02 m/s and |w| < 0.1 rad/s; straight |w| < 0.1; turning |w| >= 0.1 '
        'and |v| >= 0.1; spinning |w| >= 0.1 and |v| < 0.1 (`benchmarks/realdata.py` MOTION_KINDS).'
    )


def limit(row: realdata.EnergyRow) -> float:
    """The goal's bound on |calibrated| [%] (module doc)."""
    if row.split == 'transfer':
        return abs(row.linear_pct) / 2.0
    return max(abs(row.linear_pct) + 2.0, 5.0)


def run(report: Report) -> None:
    rows, failed = [], {}
    for surface in realdata.surfaces():
        numbers = realdata.runs(surface)
        below, above = realdata.speed_split(surface)
        for split, (fit, check) in zip(SPLITS, ((numbers[0::2], numbers[1::2]), (below, above)), strict=True):
            try:
                row = realdata.energy_row(surface, split, fit, check)
            except SkidsteerError as err:  # a failed model is a visible row with its reason
                failed[f'{surface} {split}'] = str(err)
                report.figure(f'{surface} {split}: |energy error| calibrated', float('nan'), '%',
                              goal='a value', met=False, note=str(err))  # fmt: skip
                continue
            rows.append(row)
            note = (
                f'calibrated {row.calibrated_pct:+.1f} %, preset {row.preset_pct:+.1f} %, '
                f'linear {row.linear_pct:+.1f} %; {row.status}'
            )
            report.under(f'{surface} {split}: |energy error| calibrated', abs(row.calibrated_pct), '%',
                         limit(row), inclusive=True, note=note)  # fmt: skip
            report.figure(
                f'{surface} {split}: |energy error| linear fit (reference)', abs(row.linear_pct), '%'
            )
    report.tables[TABLE] = table(rows, failed)
    report.tables[BREAKDOWN] = breakdown(rows)
