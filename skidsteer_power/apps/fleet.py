"""Fleet validation: many bags validated in parallel on Dask, one report per bag and a fleet summary.

``validate DIR|GLOB|BAG ... --jobs N | --scheduler ADDR --report OUT``: every bag goes through the
single-bag :func:`skidsteer_power.bags.validate.validate` (unchanged, in a Dask task), its report in
``OUT/<bag name>/``. A bag that fails (unreadable, no commands, any error) is a row with ``ok`` false
and the error; the others go on. The fleet summary in ``OUT``:

* ``fleet.csv``: one row per bag (:data:`CSV_COLUMNS`, SI units);
* ``summary.md``: the same as a table, plus means per vehicle and terrain;
* ``energy_per_metre.png``: measured (else predicted) motor energy per metre driven [J/m] (both
  motors' terminal energy, as ``metrics.energy_measured_J`` of the single-bag report), per vehicle
  and terrain; ``prediction_error.png``: distribution of the energy error [%] of the bags
  with motor data (``metrics.energy_error_pct`` of each report).

Distance driven [m]: the path length of the bag's odometry/poses when it has at least two, else the
commanded |V| integrated over the time each command was fresh (held at most ``cmd_timeout_s`` =
0.5 s), labelled ``distance_source`` = ``poses`` or ``cmd_vel``.

Vehicle and terrain: ``--vehicle`` / ``--terrain`` for every bag, or per bag from ``--manifest
FILE.csv`` with columns ``bag`` (file name or path), ``vehicle``, ``terrain``.
"""

from __future__ import annotations

import csv
import glob
import math
import traceback
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from skidsteer_power.bags.validate import ValidateOptions

BAG_SUFFIXES = ('.mcap', '.db3')
CMD_HOLD_S = 0.5  # [s] a command counts as driven for at most this long (the estimator's staleness)
CSV_COLUMNS = (
    'bag',
    'vehicle',
    'terrain',
    'ok',
    'error',
    'complete',
    'messages_expected',
    'messages_read',
    'duration_s',
    'distance_m',
    'distance_source',
    'energy_measured_J',
    'energy_predicted_J',
    'energy_error_pct',
    'energy_per_m_J_m',
    'processing_s',
    'report_dir',
)


@dataclass(frozen=True)
class BagJob:
    """One bag to validate: its path, whether to salvage it, and the single-bag options (vehicle,
    terrain and report folder set for this bag; every other option shared by the fleet)."""

    bag: str
    options: ValidateOptions
    salvage: bool = False

    @property
    def vehicle(self) -> str:
        return self.options.vehicle

    @property
    def terrain(self) -> str:
        return self.options.terrain

    @property
    def report_dir(self) -> str:
        return str(self.options.report_dir)


def is_bag(path: Path) -> bool:
    """A bag file (.mcap, .db3) or a rosbag2 directory (holds metadata.yaml)."""
    return (path.is_file() and path.suffix in BAG_SUFFIXES) or (path / 'metadata.yaml').is_file()


def expand(specs: list[str]) -> list[Path]:
    """Bags named by files, rosbag2 directories, folders of bags and glob patterns (sorted, unique)."""
    found: list[Path] = []
    for spec in specs:
        if glob.has_magic(spec):
            matches = [Path(p) for p in sorted(glob.glob(spec, recursive=True))]
            found += [p for p in matches if is_bag(p)]
            if not matches:
                raise InputError(f'{spec}: no file matches')
        elif is_bag(Path(spec)) or Path(spec).is_file():
            found.append(Path(spec))
        elif Path(spec).is_dir():
            found += [p for p in sorted(Path(spec).iterdir()) if is_bag(p)]
        else:
            raise InputError(f'{spec}: no such bag, folder or pattern')
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise InputError(f'no bags in {" ".join(specs)}')
    return unique


def read_manifest(path: str) -> dict[str, tuple[str, str]]:
    """``--manifest`` CSV: bag (name or path) -> (vehicle, terrain)."""
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            rows = list(csv.DictReader(stream))
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f'cannot read manifest {path}: {err}') from err
    out = {}
    for k, row in enumerate(rows, start=2):
        if not all((row.get(c) or '').strip() for c in ('bag', 'vehicle', 'terrain')):
            raise InputError(f'{path}:{k}: manifest rows need bag, vehicle and terrain')
        out[row['bag'].strip()] = (row['vehicle'].strip(), row['terrain'].strip())
    return out


def plan_jobs(
    bags: list[Path],
    shared: ValidateOptions,
    manifest: dict[str, tuple[str, str]] | None = None,
    salvage: bool = False,
) -> list[BagJob]:
    """One :class:`BagJob` per bag, with ``shared``'s options; vehicle and terrain from the manifest
    where it names the bag; report folders ``shared.report_dir/<bag name>`` (made unique)."""
    jobs, used = [], set()
    for bag in bags:
        v, t = shared.vehicle, shared.terrain
        for key in (str(bag), bag.name, bag.stem):
            if manifest and key in manifest:
                v, t = manifest[key]
                break
        name, k = bag.stem if bag.is_file() else bag.name, 1
        while name in used:
            k += 1
            name = f'{bag.stem}_{k}'
        used.add(name)
        report_dir = str(Path(shared.report_dir) / name)
        jobs.append(BagJob(str(bag), replace(shared, vehicle=v, terrain=t, report_dir=report_dir), salvage))
    return jobs


def validate_job(job: BagJob) -> dict[str, Any]:
    """Validate one bag (a Dask task): a fleet row; never raises (a failure is a row with the error)."""
    import time

    began = time.perf_counter()
    row: dict[str, Any] = {
        'bag': job.bag,
        'vehicle': job.vehicle,
        'terrain': job.terrain,
        'report_dir': job.report_dir,
    }
    try:
        from skidsteer_power.bag_io.reader import open_bag
        from skidsteer_power.bags.validate import read_inputs, validate

        options = job.options
        with open_bag(job.bag, salvage=job.salvage, warn_unknown=False) as bag:
            bag.count_all()  # what the bag holds against what it says it holds (salvage: no raise)
            summary = validate(bag, options)
            distance, source = distance_driven(read_inputs(bag, options))
            integrity = bag.integrity()
    except Exception as err:  # any failure of one bag is that bag's row, the fleet goes on
        last = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
        where = f' ({Path(last.filename).name}:{last.lineno})' if last else ''
        row.update(ok=False, error=f'{type(err).__name__}: {err}{where}'.replace('\n', ' '))
        row['processing_s'] = time.perf_counter() - began
        return row
    m = summary['metrics']
    measured, predicted = m.get('energy_measured_J', math.nan), m.get('energy_predicted_J', math.nan)
    basis = measured if summary['has_motor_data'] and np.isfinite(measured) else predicted
    row.update(
        ok=True,
        error='',
        complete=integrity['complete'],  # a salvaged bag is validated but never complete
        messages_expected=integrity['messages_expected'],
        messages_read=integrity['messages_read'],
        duration_s=summary['duration_s'],
        distance_m=distance,
        distance_source=source,
        energy_measured_J=measured,
        energy_predicted_J=predicted,
        energy_error_pct=m.get('energy_error_pct', math.nan),
        energy_per_m_J_m=basis / distance if distance > 0 else math.nan,
        processing_s=time.perf_counter() - began,
    )
    return row


def distance_driven(inputs: Any) -> tuple[float, str]:
    """Path length [m] from poses, else from held commands (module doc)."""
    if inputs.pose_xy.shape[0] >= 2:
        step = np.diff(inputs.pose_xy, axis=0)
        return float(np.sum(np.hypot(step[:, 0], step[:, 1]))), 'poses'
    t = inputs.cmd_t
    if t.size == 0:
        return 0.0, 'cmd_vel'
    hold = np.minimum(np.diff(np.r_[t, t[-1] + CMD_HOLD_S]), CMD_HOLD_S)
    return float(np.sum(np.abs(inputs.cmd[:, 0]) * hold)), 'cmd_vel'


def validate_fleet(
    engine: Any, jobs: list[BagJob], out_dir: str | Path, plots: bool = True
) -> dict[str, Any]:
    """Run every job on ``engine``; write fleet.csv, summary.md and plots to ``out_dir``; the summary."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = engine.map(validate_job, jobs, label=f'validate {len(jobs)} bags', heavy=True)
    files = {'csv': str(out / 'fleet.csv'), 'markdown': str(out / 'summary.md')}
    _write_csv(Path(files['csv']), rows)
    groups = group_means(rows)
    Path(files['markdown']).write_text(_markdown(rows, groups, engine.description), encoding='utf-8')
    if plots:
        files |= _plots(out, rows, groups)
    ok = [r for r in rows if r['ok']]
    errors = np.array([r['energy_error_pct'] for r in ok], dtype=float)
    errors = errors[np.isfinite(errors)]
    return {
        'bags': len(rows),
        'ok': len(ok),
        'failed': len(rows) - len(ok),
        'incomplete': sum(not r['complete'] for r in ok),  # validated from part of the bag
        'energy_error_pct_mean': float(np.mean(errors)) if errors.size else math.nan,
        'energy_error_pct_abs_max': float(np.max(np.abs(errors))) if errors.size else math.nan,
        'groups': groups,
        'rows': rows,
        'files': files,
        'engine': engine.description,
    }


def group_means(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (vehicle, terrain): bags, distance [m], energy per metre [J/m] (distance-weighted) and the
    mean energy error [%]."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        if r['ok']:
            groups.setdefault((r['vehicle'], r['terrain']), []).append(r)
    out = []
    for (vehicle, terrain), members in sorted(groups.items()):
        distance = sum(r['distance_m'] for r in members)
        energy = sum(
            r['energy_per_m_J_m'] * r['distance_m'] for r in members if np.isfinite(r['energy_per_m_J_m'])
        )
        errs = [r['energy_error_pct'] for r in members if np.isfinite(r['energy_error_pct'])]
        out.append(
            {
                'vehicle': vehicle,
                'terrain': terrain,
                'bags': len(members),
                'distance_m': distance,
                'energy_per_m_J_m': energy / distance if distance > 0 else math.nan,
                'energy_error_pct_mean': float(np.mean(errs)) if errs else math.nan,
            }
        )
    return out


def fmt(value: Any, fmt: str = '.4g') -> str:
    if value is None:
        return ''
    if isinstance(value, float):
        return '' if math.isnan(value) else format(value, fmt)
    return str(value)


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open('w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(CSV_COLUMNS)
        for r in rows:
            writer.writerow([fmt(r.get(c, math.nan), '.6g') for c in CSV_COLUMNS])


def _status(row: dict[str, Any]) -> str:
    if not row['ok']:
        return f'FAILED: {row["error"]}'.replace('|', '/')
    if row.get('complete'):
        return 'ok'
    expected = row.get('messages_expected')
    return f'ok, INCOMPLETE: read {row.get("messages_read")} of {"?" if expected is None else expected}'


def _markdown(rows: list[dict[str, Any]], groups: list[dict[str, Any]], engine: str) -> str:
    lines = [
        '# Fleet validation',
        '',
        f'{len(rows)} bags, {sum(r["ok"] for r in rows)} validated, '
        f'{sum(not r["ok"] for r in rows)} failed ({engine}).',
        '',
        '| bag | vehicle | terrain | distance [m] | energy measured [J] | predicted [J] | error [%] | J/m '
        '| status |',
        '| --- | --- | --- | --- | --- | --- | --- | --- | --- |',
    ]
    for r in rows:
        status = _status(r)
        cells = [
            Path(r['bag']).name,
            r['vehicle'],
            r['terrain'],
            *(fmt(r.get(k, math.nan)) for k in ('distance_m', 'energy_measured_J', 'energy_predicted_J')),
            fmt(r.get('energy_error_pct', math.nan), '+.1f'),
            fmt(r.get('energy_per_m_J_m', math.nan)),
            status,
        ]
        lines.append('| ' + ' | '.join(cells) + ' |')
    lines += [
        '',
        '## Per vehicle and terrain',
        '',
        '| vehicle | terrain | bags | distance [m] | J/m | mean error [%] |',
    ]
    lines.append('| --- | --- | --- | --- | --- | --- |')
    for g in groups:
        lines.append(
            f'| {g["vehicle"]} | {g["terrain"]} | {g["bags"]} | {fmt(g["distance_m"])} | '
            f'{fmt(g["energy_per_m_J_m"])} | {fmt(g["energy_error_pct_mean"], "+.1f")} |'
        )
    return '\n'.join(lines) + '\n'


def _plots(out: Path, rows: list[dict[str, Any]], groups: list[dict[str, Any]]) -> dict[str, str]:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    files = {}
    fig, ax = plt.subplots(figsize=(7, 4))
    labels = [f'{g["vehicle"]}\n{g["terrain"]}' for g in groups]
    ax.bar(range(len(groups)), [g['energy_per_m_J_m'] for g in groups])
    ax.set_xticks(range(len(groups)), labels, fontsize=7)
    ax.set_ylabel('motor energy per metre [J/m]')
    ax.set_title('Energy per metre by vehicle and terrain')
    fig.tight_layout()
    files['energy_per_metre_png'] = str(out / 'energy_per_metre.png')
    fig.savefig(files['energy_per_metre_png'], dpi=100)
    plt.close(fig)
    errors = [
        r['energy_error_pct'] for r in rows if r['ok'] and np.isfinite(r.get('energy_error_pct', math.nan))
    ]
    fig, ax = plt.subplots(figsize=(6, 4))
    if errors:
        ax.hist(errors, bins=max(5, min(30, len(errors))))
    ax.set_xlabel('energy error, predicted vs measured [%]')
    ax.set_ylabel('bags')
    ax.set_title(f'Prediction error distribution ({len(errors)} bags with motor data)')
    fig.tight_layout()
    files['prediction_error_png'] = str(out / 'prediction_error.png')
    fig.savefig(files['prediction_error_png'], dpi=100)
    plt.close(fig)
    return files
