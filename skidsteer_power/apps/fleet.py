"""Fleet validation: many bags validated in parallel on Dask, one report per bag and a fleet summary.

``validate DIR|GLOB|BAG ... --jobs N | --scheduler ADDR --report OUT``: every bag goes through the
single-bag :func:`skidsteer_power.validation.validate.validate` (unchanged, in a Dask task), its report in
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
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.jsonout import FieldsAsJson, JsonObject

if TYPE_CHECKING:
    from skidsteer_power.distributed.engine import Engine
    from skidsteer_power.validation.series import Inputs
    from skidsteer_power.validation.validate import ValidateOptions

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


@dataclass(frozen=True)
class Validated:
    """What a validated bag adds to its fleet row: the bag's integrity, its length [s], the distance
    driven [m] and where it came from ('poses', 'cmd_vel'), the energies [J], the error [%], the
    energy per metre [J/m] (of the measured energy where there is one, else the predicted)."""

    complete: bool
    messages_expected: int | None
    messages_read: int | None
    duration_s: float
    distance_m: float
    distance_source: str
    energy_measured_J: float
    energy_predicted_J: float
    energy_error_pct: float
    energy_per_m_J_m: float


@dataclass(frozen=True)
class FleetRow:
    """One bag of a fleet validation (a Dask task's result): ``validated`` None if it failed
    (``error`` says why); :meth:`as_json` is its row of ``validate --json`` with several bags."""

    bag: str
    vehicle: str
    terrain: str
    report_dir: str
    error: str
    processing_s: float
    validated: Validated | None = None

    @property
    def ok(self) -> bool:
        return self.validated is not None

    @property
    def energy_error_pct(self) -> float:
        return math.nan if self.validated is None else self.validated.energy_error_pct

    def as_json(self) -> JsonObject:
        head: JsonObject = {
            'bag': self.bag,
            'vehicle': self.vehicle,
            'terrain': self.terrain,
            'report_dir': self.report_dir,
            'ok': self.ok,
            'error': self.error,
        }
        body = {} if self.validated is None else asdict(self.validated)
        return {**head, **body, 'processing_s': self.processing_s}


@dataclass(frozen=True)
class FleetGroup(FieldsAsJson):
    """Per (vehicle, terrain): bags, distance [m], energy per metre [J/m] (distance-weighted), mean
    energy error [%]."""

    vehicle: str
    terrain: str
    bags: int
    distance_m: float
    energy_per_m_J_m: float
    energy_error_pct_mean: float


@dataclass(frozen=True)
class FleetSummary:
    """A fleet validation (:func:`validate_fleet`): counts, the energy error's mean and largest |.|
    [%], the groups, the rows, the files written and the engine."""

    bags: int
    ok: int
    failed: int
    incomplete: int
    energy_error_pct_mean: float
    energy_error_pct_abs_max: float
    groups: list[FleetGroup]
    rows: list[FleetRow]
    engine: str
    files: dict[str, str] = field(default_factory=dict)

    def as_json(self) -> JsonObject:
        return {
            'bags': self.bags,
            'ok': self.ok,
            'failed': self.failed,
            'incomplete': self.incomplete,
            'energy_error_pct_mean': self.energy_error_pct_mean,
            'energy_error_pct_abs_max': self.energy_error_pct_abs_max,
            'groups': [g.as_json() for g in self.groups],
            'rows': [r.as_json() for r in self.rows],
            'files': dict(self.files),
            'engine': self.engine,
        }


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


def validate_job(job: BagJob) -> FleetRow:
    """Validate one bag (a Dask task): a fleet row; never raises (a failure is a row with the error)."""
    import time

    began = time.perf_counter()
    row = FleetRow(job.bag, job.vehicle, job.terrain, job.report_dir, error='', processing_s=math.nan)
    try:
        from skidsteer_power.bag_io.reader import open_bag
        from skidsteer_power.validation.validate import read_inputs, validate

        options = job.options
        with open_bag(job.bag, salvage=job.salvage, warn_unknown=False) as bag:
            bag.count_all()  # what the bag holds against what it says it holds (salvage: no raise)
            summary = validate(bag, options)
            distance, source = distance_driven(read_inputs(bag, options))
            complete, expected, read = bag.complete, bag.messages_expected, bag.messages_read
    except Exception as err:  # any failure of one bag is that bag's row, the fleet goes on
        last = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
        where = f' ({Path(last.filename).name}:{last.lineno})' if last else ''
        error = f'{type(err).__name__}: {err}{where}'.replace('\n', ' ')
        return replace(row, error=error, processing_s=time.perf_counter() - began)
    m = summary.metrics
    measured, predicted = m.energy_measured_J, m.energy_predicted_J
    basis = measured if summary.has_motor_data and np.isfinite(measured) else predicted
    validated = Validated(
        complete=complete,  # a salvaged bag is validated but never complete
        messages_expected=expected,
        messages_read=read,
        duration_s=summary.duration_s,
        distance_m=distance,
        distance_source=source,
        energy_measured_J=measured,
        energy_predicted_J=predicted,
        energy_error_pct=m.energy_error_pct,
        energy_per_m_J_m=basis / distance if distance > 0 else math.nan,
    )
    return replace(row, validated=validated, processing_s=time.perf_counter() - began)


def distance_driven(inputs: Inputs) -> tuple[float, str]:
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
    engine: Engine, jobs: list[BagJob], out_dir: str | Path, plots: bool = True
) -> FleetSummary:
    """Run every job on ``engine``; write fleet.csv, summary.md and plots to ``out_dir``; the summary."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[FleetRow] = engine.map(validate_job, jobs, label=f'validate {len(jobs)} bags', heavy=True)
    files = {'csv': str(out / 'fleet.csv'), 'markdown': str(out / 'summary.md')}
    _write_csv(Path(files['csv']), rows)
    groups = group_means(rows)
    Path(files['markdown']).write_text(_markdown(rows, groups, engine.description), encoding='utf-8')
    if plots:
        files |= _plots(out, rows, groups)
    ok = [r.validated for r in rows if r.validated is not None]
    errors = np.array([v.energy_error_pct for v in ok], dtype=float)
    errors = errors[np.isfinite(errors)]
    return FleetSummary(
        bags=len(rows),
        ok=len(ok),
        failed=len(rows) - len(ok),
        incomplete=sum(not v.complete for v in ok),  # validated from part of the bag
        energy_error_pct_mean=float(np.mean(errors)) if errors.size else math.nan,
        energy_error_pct_abs_max=float(np.max(np.abs(errors))) if errors.size else math.nan,
        groups=groups,
        rows=rows,
        files=files,
        engine=engine.description,
    )


def group_means(rows: list[FleetRow]) -> list[FleetGroup]:
    """Per (vehicle, terrain): bags, distance [m], energy per metre [J/m] (distance-weighted) and the
    mean energy error [%]."""
    groups: dict[tuple[str, str], list[Validated]] = {}
    for r in rows:
        if r.validated is not None:
            groups.setdefault((r.vehicle, r.terrain), []).append(r.validated)
    out = []
    for (vehicle, terrain), members in sorted(groups.items()):
        distance = sum(v.distance_m for v in members)
        energy = sum(v.energy_per_m_J_m * v.distance_m for v in members if np.isfinite(v.energy_per_m_J_m))
        errs = [v.energy_error_pct for v in members if np.isfinite(v.energy_error_pct)]
        out.append(
            FleetGroup(
                vehicle=vehicle,
                terrain=terrain,
                bags=len(members),
                distance_m=distance,
                energy_per_m_J_m=energy / distance if distance > 0 else math.nan,
                energy_error_pct_mean=float(np.mean(errs)) if errs else math.nan,
            )
        )
    return out


def fmt(value: float | int | str | bool | None, fmt: str = '.4g') -> str:
    if value is None:
        return ''
    if isinstance(value, float):
        return '' if math.isnan(value) else format(value, fmt)
    return str(value)


def _write_csv(path: Path, rows: list[FleetRow]) -> None:
    with path.open('w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(CSV_COLUMNS)
        for r in rows:
            values = r.as_json()
            writer.writerow([fmt(values.get(c, math.nan), '.6g') for c in CSV_COLUMNS])


def _status(row: FleetRow) -> str:
    v = row.validated
    if v is None:
        return f'FAILED: {row.error}'.replace('|', '/')
    if v.complete:
        return 'ok'
    expected = v.messages_expected
    return f'ok, INCOMPLETE: read {v.messages_read} of {"?" if expected is None else expected}'


def _markdown(rows: list[FleetRow], groups: list[FleetGroup], engine: str) -> str:
    lines = [
        '# Fleet validation',
        '',
        f'{len(rows)} bags, {sum(r.ok for r in rows)} validated, '
        f'{sum(not r.ok for r in rows)} failed ({engine}).',
        '',
        '| bag | vehicle | terrain | distance [m] | energy measured [J] | predicted [J] | error [%] | J/m '
        '| status |',
        '| --- | --- | --- | --- | --- | --- | --- | --- | --- |',
    ]
    for r in rows:
        v = r.validated
        figures = (
            (math.nan,) * 5
            if v is None
            else (
                v.distance_m,
                v.energy_measured_J,
                v.energy_predicted_J,
                v.energy_error_pct,
                v.energy_per_m_J_m,
            )
        )
        cells = [
            Path(r.bag).name,
            r.vehicle,
            r.terrain,
            *(fmt(x) for x in figures[:3]),
            fmt(figures[3], '+.1f'),
            fmt(figures[4]),
            _status(r),
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
            f'| {g.vehicle} | {g.terrain} | {g.bags} | {fmt(g.distance_m)} | '
            f'{fmt(g.energy_per_m_J_m)} | {fmt(g.energy_error_pct_mean, "+.1f")} |'
        )
    return '\n'.join(lines) + '\n'


def _plots(out: Path, rows: list[FleetRow], groups: list[FleetGroup]) -> dict[str, str]:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    files = {}
    fig, ax = plt.subplots(figsize=(7, 4))
    labels = [f'{g.vehicle}\n{g.terrain}' for g in groups]
    ax.bar(range(len(groups)), [g.energy_per_m_J_m for g in groups])
    ax.set_xticks(range(len(groups)), labels, fontsize=7)
    ax.set_ylabel('motor energy per metre [J/m]')
    ax.set_title('Energy per metre by vehicle and terrain')
    fig.tight_layout()
    files['energy_per_metre_png'] = str(out / 'energy_per_metre.png')
    fig.savefig(files['energy_per_metre_png'], dpi=100)
    plt.close(fig)
    errors = [r.energy_error_pct for r in rows if r.ok and np.isfinite(r.energy_error_pct)]
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
