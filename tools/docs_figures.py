"""Every figure in README.md, docs/*.md and bags/README.md written by a command (issue 38, "Docs that
drift"): the blocks between ``<!-- BEGIN generated: NAME -->`` and ``<!-- END generated: NAME -->``
(syntax: :mod:`skidsteer_power.doc_blocks`) hold what NAME's generator below returns.

    python -m tools.docs_figures                  # rewrite every generated block (and its figures)
    python -m tools.docs_figures --check          # write nothing; exit 1 naming each stale block
    python -m tools.docs_figures --list           # the generators, with the command each runs
    python -m tools.docs_figures --only NAME ...  # just these blocks
    python -m tools.docs_figures --measured NAME  # rerun a slow (measured) block's command, dated

A generator calls the project's CLI or API with fixed arguments and returns deterministic text
(physics figures, a command's printed figures, API text read from the code): no clock, no benchmark
timing. A block named ``skidsteer-power ARGS`` is that command's stdout (apps/doc_examples.py).
A slow command (the main job: minutes) makes a ``measured`` block instead: its first line says
``Measured DATE with `COMMAND`.``; the check only requires that line (the date and the registered
command), ``--measured NAME`` reruns it. test/test_docs_figures.py runs ``--check`` (``make test``).
Bad markers, an unknown block name or a failing command: one line on stderr, exit 2.
"""

from __future__ import annotations

import argparse
import datetime
import inspect
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from pathlib import Path

import tomllib

from skidsteer_power.apps.doc_examples import example_block, is_example, run_cli
from skidsteer_power.doc_blocks import MEASURED_LINE, Block, DocBlockError, find_blocks, replace_bodies

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / 'shared'
JOBS = 2  # generators run at once (most are subprocesses of the CLI)


def doc_files(root: Path = ROOT) -> list[Path]:
    """The documents the tool reads: README.md, docs/*.md, bags/README.md."""
    return [root / 'README.md', *sorted((root / 'docs').glob('*.md')), root / 'bags' / 'README.md']


@dataclass
class Context:
    """What a generator may use: ``write`` (False under --check: write no file) and ``scratch``, a
    temporary folder for the commands' outputs; ``figures``: files to copy into the tree on write
    (destination relative to the repository root -> the file a command wrote); ``runs``: the
    commands run so far in this run (one run per command line, whichever generators ask)."""

    write: bool
    scratch: Path
    figures: dict[str, Path] = field(default_factory=dict)
    runs: dict[str, tuple[str, Path]] = field(default_factory=dict)  # cli_run's, by command line
    lock: threading.Lock = field(default_factory=threading.Lock)


@dataclass(frozen=True)
class Generator:
    """``make(ctx)`` returns a block's text; ``command`` is what a reader runs for the same figures."""

    name: str
    command: str
    make: Callable[[Context], str]
    kind: str = 'generated'  # or 'measured' (slow: the check only wants its dated command line)
    needs_shared: bool = False  # reads ../shared (the real bags)


REGISTRY: dict[str, Generator] = {}


def generator(
    name: str, command: str, *, kind: str = 'generated', needs_shared: bool = False
) -> Callable[[Callable[[Context], str]], Callable[[Context], str]]:
    def register(make: Callable[[Context], str]) -> Callable[[Context], str]:
        if name in REGISTRY:
            raise ValueError(f'generator {name!r} registered twice')
        REGISTRY[name] = Generator(name, command, make, kind, needs_shared)
        return make

    return register


# --- running the CLI once per command line --------------------------------------------------------


def cli_run(command: str, ctx: Context) -> tuple[str, Path]:
    """stdout of ``command`` (``skidsteer-power ...``) and the folder ``{scratch}`` stands for in it (a
    fresh one under ``ctx.scratch``, where the command writes its files); run once per ``ctx``."""
    with ctx.lock:
        if command not in ctx.runs:
            folder = Path(tempfile.mkdtemp(prefix='run_', dir=ctx.scratch))
            argv = shlex.split(command.replace('{scratch}', str(folder)))
            ctx.runs[command] = (run_cli(argv[1:]).stdout, folder)
        return ctx.runs[command]


def cli_stdout(command: str, ctx: Context) -> str:
    return cli_run(command, ctx)[0]


def lines_starting(text: str, *prefixes: str) -> str:
    """The lines of ``text`` that start with one of ``prefixes``, in their order."""
    return ''.join(line + '\n' for line in text.splitlines() if line.startswith(prefixes))


def fenced(text: str) -> str:
    return f'```\n{text}```\n'


# --- the layers (pyproject.toml's import-linter contract) ----------------------------------------


def layers() -> list[list[str]]:
    """The layer contract's layers, top first, each a list of sibling packages."""
    config = tomllib.loads((ROOT / 'pyproject.toml').read_text(encoding='utf-8'))
    contract = next(c for c in config['tool']['importlinter']['contracts'] if c['type'] == 'layers')
    return [[p.strip() for p in layer.split('|')] for layer in contract['layers']]


@generator('layers', 'the layers contract in pyproject.toml ([tool.importlinter])')
def _layers_line(_: Context) -> str:
    return ' > '.join(', '.join(f'`{p}`' for p in layer) for layer in layers())


LAYER_ROLES = {
    'cli': 'command line',
    'apps': 'applications and ROS nodes',
    'twin': 'users of recordings',
    'validation': 'single-bag validation against the estimator',
    'analysis': 'studies and helpers',
    'estimator': 'on-board estimator',
    'missions': 'missions',
    'maps': 'look-up maps',
    'models': 'steady-state models (Steeds, ICR, Wong, fast, FESS)',
    'des': 'DES 70/10 amplifier protocol, client, simulator',
    'drive': "the robot's drive controller: cmd_vel -> wheel set points (docs/DRIVE.md)",
    'vehicle': 'vehicle and powertrain descriptions',
    'terramechanics': 'soil; bag I/O (read, write, record, replay, salvage)',
}


@generator('layers table', 'the layers contract in pyproject.toml ([tool.importlinter])')
def _layers_table(_: Context) -> str:
    rows = ['| layer (top first) | packages |', '| --- | --- |']
    for layer in layers():
        role = LAYER_ROLES.get(layer[0])
        if role is None:
            raise DocBlockError(f'layer {layer} has no description: add it to LAYER_ROLES in {__file__}')
        rows.append(f'| {role} | {", ".join(f"`{p}`" for p in layer)} |')
    return '\n'.join(rows) + '\n'


# --- node parameter tables (the same rendering as nodes/param_files.py) ------------------------


def _params(node: str) -> Callable[[Context], str]:
    def make(_: Context) -> str:
        from skidsteer_power.nodes import param_files, param_spec

        entry = next(e for e in param_files.NODES if e.node == node)
        return param_spec.render_table(entry.specs)

    return make


for _node in ('des_driver', 'power_estimator'):
    generator(f'params {_node}', 'python -m skidsteer_power.nodes.param_files')(_params(_node))


# --- API text read from the code ------------------------------------------------------------------


def _signature(owner: str, fn: Callable[..., object]) -> str:
    """``owner(a, b, *, c=1, **options) -> Result``: names and defaults, no annotations but the return."""
    sig = inspect.signature(fn)
    params = [
        p.replace(annotation=inspect.Parameter.empty)
        for p in sig.parameters.values()
        if p.name not in ('self', 'cls')
    ]
    bare = sig.replace(parameters=params, return_annotation=inspect.Signature.empty)
    return f'{owner}{bare} -> {sig.return_annotation}'


@generator('maps api', 'inspect.signature of skidsteer_power.maps.power_map')
def _maps_api(_: Context) -> str:
    from skidsteer_power.maps import power_map as pm

    flags = [f.name for f in fields(pm.MapQuery) if f.type == 'Flags']
    values = [f.name for f in fields(pm.MapQuery) if f.type != 'Flags']
    lines = [
        _signature('PowerMap.build', pm.PowerMap.build),
        _signature('PowerMap.load', pm.PowerMap.load) + '   # MapMismatchError if not built for them',
        _signature('PowerMap.save', pm.PowerMap.save),
        _signature('load_or_build', pm.load_or_build),
        _signature('PowerMap.query', pm.PowerMap.query) + '   # vectorized; per point:',
        '    ' + ', '.join(values) + ' (floats or arrays);',
        '    ' + ', '.join(flags) + ' (bools; MapQuery docstring)',
    ]
    return '```python\n' + '\n'.join(_wrap(lines)) + '\n```\n'


def _wrap(lines: Iterable[str], width: int = 104) -> list[str]:
    out = []
    for line in lines:
        while len(line) > width:
            cut = line.rfind(', ', 0, width) + 1
            out.append(line[:cut])
            line = '    ' + line[cut:].lstrip()
        out.append(line)
    return out


# --- the calibration walk-through (docs/CALIBRATION.md, README.md) -------------------------------

CALIBRATE = (
    'skidsteer-power calibrate bags/test_robot_4wheel_dry_sand.mcap --vehicle test_robot_4wheel '
    '--terrain dry_sand --out-terrain {scratch}/my_terrain.yaml --plot {scratch}/calibration.png'
)
CALIBRATION_FIGURE = 'docs/figures/calibration_walkthrough.png'


def _calibrate(ctx: Context) -> str:
    out, folder = cli_run(CALIBRATE, ctx)
    if ctx.write:
        ctx.figures[CALIBRATION_FIGURE] = folder / 'calibration.png'
    return out


@generator('calibrate walkthrough', CALIBRATE.replace('{scratch}/', ''))
def _calibrate_block(ctx: Context) -> str:
    # every line it prints but the files written and its wall time (the last line, "0.8 s")
    text = ''.join(
        line + '\n'
        for line in _calibrate(ctx).splitlines()
        if not line.startswith('wrote ') and not re.fullmatch(r'[\d.]+ s', line)
    )
    return fenced(text)


@generator('calibrate walkthrough energy', CALIBRATE.replace('{scratch}/', ''))
def _calibrate_energy(ctx: Context) -> str:
    m = re.search(r'energy error: (\S+?)% -> (\S+?)%', _calibrate(ctx))
    if not m:
        raise DocBlockError(f'{CALIBRATE.split(" --")[0]}: no "energy error: A% -> B%" line')
    return f'{m[1]} % -> {m[2]} %'


# --- validate runs quoted in the README and docs/ROS.md ------------------------------------------

WRONG_TERRAIN = (
    'skidsteer-power validate bags/test_robot_4wheel_dry_sand.mcap --vehicle test_robot_4wheel '
    '--terrain {terrain} --report {{scratch}}'
)


def _energy_error(terrain: str, ctx: Context) -> str:
    out = cli_stdout(WRONG_TERRAIN.format(terrain=terrain), ctx)
    m = re.search(r'^energy predicted .*, error (\S+) %$', out, re.M)
    if not m:
        raise DocBlockError(f'validate --terrain {terrain}: no "energy predicted ..., error X %" line')
    return f'{float(m[1]):+.0f} %'


def _wrong_terrain(terrain: str) -> Callable[[Context], str]:
    return lambda ctx: _energy_error(terrain, ctx)


for _terrain in ('dry_sand', 'clay'):
    generator(
        f'wrong terrain energy error {_terrain}',
        WRONG_TERRAIN.format(terrain=_terrain).replace(' {scratch}', ' out'),
    )(_wrong_terrain(_terrain))

NEATO = (
    'skidsteer-power validate ../shared/realbags/neato-teleop --vehicle leo_rover --terrain sandy_loam '
    '--report {scratch}'
)


@generator('neato validate', NEATO.replace('{scratch}', 'out'), needs_shared=True)
def _neato(ctx: Context) -> str:
    out = cli_stdout(NEATO, ctx)
    kept = ('no motor data', 'cmd_vel published', 'outside the power map', 'trace:', 'predicted from')
    return fenced(lines_starting(out, *kept))


# --- the bundled bags (bags/README.md) ------------------------------------------------------------

BUNDLED = {  # bag -> (vehicle, the twin's truth terrain, a note); how bags/make_bundled_bags.sh made them
    'test_robot_track_sand_bin.mcap': ('test_robot_track', '`sand_bin`'),
    'test_robot_4wheel_sand_bin.mcap': ('test_robot_4wheel', '`sand_bin`'),
    'test_robot_6wheel_sand_bin.mcap': ('test_robot_6wheel', '`sand_bin`'),
    'test_robot_4wheel_dry_sand.mcap': ('test_robot_4wheel', '**`clay`** (not what the name says)'),
}
BUNDLED_TOPICS = ('/cmd_vel', '/joint_states', '/odom', '/ground_truth/odom', '/battery/measured')


@generator('bundled bags', 'skidsteer-power info bags/BAG.mcap (skidsteer_power.cli.bag_info.bag_info)')
def _bundled_bags(_: Context) -> str:
    from skidsteer_power.cli.bag_info import bag_info

    rows = [
        '| bag | vehicle | twin (truth) terrain | duration [s] | ' + ' | '.join(BUNDLED_TOPICS) + ' |',
        '| --- | --- | --- | ---: | ' + ' | '.join('---:' for _ in BUNDLED_TOPICS) + ' |',
    ]
    for bag, (vehicle, terrain) in BUNDLED.items():
        info = bag_info(str(ROOT / 'bags' / bag))
        counts = {t['topic']: t['count'] for t in info['topics']}
        cells = [f'`{bag}`', f'`{vehicle}`', terrain, f'{info["duration_s"]:.1f}']
        rows.append('| ' + ' | '.join(cells + [str(counts.get(t, 0)) for t in BUNDLED_TOPICS]) + ' |')
    return '\n'.join(rows) + '\n'


def _motion_error(terrain: str, ctx: Context) -> str:
    out = cli_stdout(WRONG_TERRAIN.format(terrain=terrain), ctx)
    m = re.search(r'^predicted from the measured motion \(\w+\): energy error (\S+) %', out, re.M)
    if not m:
        raise DocBlockError(f'validate --terrain {terrain}: no "predicted from the measured motion" line')
    return f'{float(m[1]):+.0f} %'


def _wrong_terrain_motion(terrain: str) -> Callable[[Context], str]:
    return lambda ctx: _motion_error(terrain, ctx)


for _terrain in ('dry_sand', 'clay'):
    generator(
        f'wrong terrain motion error {_terrain}',
        WRONG_TERRAIN.format(terrain=_terrain).replace(' {scratch}', ' out'),
    )(_wrong_terrain_motion(_terrain))


# --- benchmark figures, quoted from docs/BENCHMARKS.md's goal table (which names its run) --------


def _goal_rows(section: str) -> list[list[str]]:
    from benchmarks.docs import BEGIN, END

    doc = (ROOT / 'docs' / 'BENCHMARKS.md').read_text(encoding='utf-8')
    table = doc.split(BEGIN, 1)[1].split(END, 1)[0]
    rows = [re.split(r'(?<!\\)\|', line)[1:-1] for line in table.splitlines() if line.startswith('| ')]
    return [[c.strip().replace('\\|', '|') for c in r] for r in rows if r and r[0].strip() == section]


def _span(values: Sequence[float], digits: int = 1) -> str:
    lo, hi = min(values), max(values)
    return (
        f'{lo:.{digits}f}' if round(lo, digits) == round(hi, digits) else f'{lo:.{digits}f}-{hi:.{digits}f}'
    )


@generator('compare summary', "docs/BENCHMARKS.md's goal table, area compare (make bench)")
def _compare_summary(_: Context) -> str:
    rows = _goal_rows('compare')
    split: dict[str, list[float]] = {'same_range': [], 'extrapolation': [], 'transfer': []}
    best: dict[str, list[float]] = {k: [] for k in split}
    runs = set()
    for _section, figure, goal, measured, *_rest, run in rows:
        m = re.match(r'\S+ (same_range|extrapolation|transfer): \|E\| FESS calibrated \+ online', figure)
        b = re.search(r'best baseline \S+ ([\d.]+) %', goal)
        if m and b:
            split[m[1]].append(float(measured.split()[0]))
            best[m[1]].append(float(b[1]))
            runs.add(run)
    if not all(split.values()) or len(runs) != 1:
        raise DocBlockError('docs/BENCHMARKS.md: the compare rows (three splits, one run) are missing')
    return (
        f'(`make bench` area `compare`, run {runs.pop()}; docs/BENCHMARKS.md): a three-coefficient linear '
        f'fit predicts the energy of new commands inside its training range to {_span(best["same_range"])} '
        f'%, FESS calibrated with the online correction to {_span(split["same_range"])} % (FESS loses '
        f'there); on faster, tighter commands FESS is {_span(split["extrapolation"])} % off against '
        f'{_span(best["extrapolation"])} % for the best fitted model; with a 10 kg payload and no new '
        f'data, FESS is {_span(split["transfer"])} % off and the best fitted model '
        f'{_span(best["transfer"])} %'
    )


# --- the main job (minutes: measured, not in the fast check) -------------------------------------


@generator('main job', 'bash bags/twin_main_job.sh OUT', kind='measured')
def _main_job(ctx: Context) -> str:
    out = ctx.scratch / 'main_job'
    load, start = os.getloadavg()[0], time.monotonic()
    done = subprocess.run(
        ['bash', str(ROOT / 'bags' / 'twin_main_job.sh'), str(out)], cwd=ROOT, capture_output=True, text=True
    )
    wall_s = time.monotonic() - start
    if done.returncode != 0:
        raise DocBlockError(f'bags/twin_main_job.sh exited {done.returncode}: {done.stderr.strip()[-300:]}')
    summary = (out / 'summary.md').read_text(encoding='utf-8')
    tables = summary.split('\n\n', 1)[1].rstrip('\n')  # below the title
    return f'{tables}\n\nWall time: {wall_s:.0f} s ({os.cpu_count()} cores, load {load:.1f} at the start).\n'


def _markdown_tables(text: str) -> list[list[list[str]]]:
    """The Markdown tables of ``text``: rows of cells (header and rule lines dropped)."""
    tables: list[list[list[str]]] = []
    for chunk in re.split(r'\n\s*\n', text):
        lines = [ln for ln in chunk.splitlines() if ln.startswith('| ')]
        if len(lines) > 2:
            tables.append([[c.strip() for c in re.split(r'(?<!\\)\|', ln)[1:-1]] for ln in lines[2:]])
    return tables


def _main_job_block() -> str:
    doc = (ROOT / 'README.md').read_text(encoding='utf-8')
    block = next((b for b in find_blocks(doc, 'README.md') if b.name == 'main job'), None)
    if block is None:
        raise DocBlockError("README.md: no 'main job' block to read")
    return block.body


def _range(values: Sequence[float], digits: int = 1, sign: bool = False) -> str:
    fmt = f'{{:{"+" if sign else ""}.{digits}f}}'
    lo, hi = (fmt.format(v) for v in (min(values), max(values)))
    return lo if lo == hi else f'{lo} to {hi}' if sign else f'{lo}-{hi}'


@generator('main job summary', "README.md's main job block (bash bags/twin_main_job.sh OUT)")
def _main_job_summary(_: Context) -> str:
    """The main job's first table and its dated command line, copied from README.md's block."""
    body = _main_job_block().strip('\n')
    first, rest = body.split('\n', 1)
    table = next((c.strip() for c in re.split(r'\n\s*\n', rest) if c.strip().startswith('| ')), None)
    if not MEASURED_LINE.match(first) or table is None:
        raise DocBlockError("README.md's main job block: no dated command line or no table")
    return f"{first.rstrip('.')} (README.md's block).\n\n{table}\n"


@generator('main job reading', "README.md's main job block (bash bags/twin_main_job.sh OUT)")
def _main_job_reading(_: Context) -> str:
    """The figures of "What it means", read from the measured tables above it."""
    body = _main_job_block()
    try:
        summary, radii = _markdown_tables(body)[:2]
        by = {row[0].removeprefix('test_robot_'): row for row in summary}
        track, wheeled = by['track'], [by['4wheel'], by['6wheel']]
        sides = [[float(x) for x in re.findall(r'[\d.]+', row[5])[:2]] for row in wheeled]
        fess_r = {k: [float(x) for x in by[k][7].split(' / ')] for k in ('track', '6wheel')}
        cells = {
            k: [(float(r[3]), float(r[4]), float(r[5])) for r in radii if r[0] == f'test_robot_{k}']
            for k in ('track', '6wheel')
        }
        all_cells = re.search(
            r'FESS from set points against the real robot: .*? ([\d.]+) %, max ([\d.]+) % over (\d+)', body
        )
        if all_cells is None:
            raise KeyError('FESS from set points against the real robot: median ... over N cells')
    except (ValueError, KeyError, IndexError) as exc:
        raise DocBlockError(f"README.md's main job block: not the tables it should hold ({exc!r})") from None
    twin_x = {k: _range([twin / cmd for cmd, _real, twin in v]) for k, v in cells.items()}
    real_x = _range([real / cmd for v in cells.values() for cmd, real, _twin in v])
    torque = f'{track[5]} % (track, left / right) and {_range([s[0] for s in sides])} % / '
    torque += f'{_range([s[1] for s in sides])} %'
    energy = f'{float(track[2]):+.1f} % (track) and {_range([float(r[2]) for r in wheeled], sign=True)} %'
    fess_real = f'{fess_r["track"][1]:.0f} % (track) and {fess_r["6wheel"][1]:.0f} % (6-wheel)'
    fess_twin = f'{fess_r["track"][0]:.0f} % and {fess_r["6wheel"][0]:.0f} %'
    every = f'{all_cells[3]} cells against the real robot: median {all_cells[1]} %, max {all_cells[2]} %'
    motion = f'{float(track[3]):+.1f} % for the track and '
    motion += f'{_range([float(r[3]) for r in wheeled], sign=True)} % for the wheeled robots'
    return (
        'in the steady part of each set (the last 1.5 s of each 4 s hold), FESS given the motion the twin '
        f'really makes predicts its axle torques to a median |error| of {torque} on the two sides of the '
        'wheeled robots (|error|, so the sides cannot cancel). From the command alone, FESS at the '
        f'wheel-speed set points misses the energy by {energy} (wheels). In the Appendix D cells the twin '
        f'turns on {twin_x["track"]}x (track) and {twin_x["6wheel"]}x (6-wheel) the commanded radius, as '
        f"the real robot did on {real_x}x; FESS from the set points predicts the real robot's radii to a "
        f"median {fess_real}, the twin's to {fess_twin} (all {every}). Over the whole run, predicting "
        f'from the true motion (`validate --kinematics ground_truth`) is {motion}'
    )


# --- the run --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Found:
    path: Path
    block: Block


def _where(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def collect(paths: Sequence[Path], only: set[str] | None = None) -> list[Found]:
    """Every block of ``paths`` (those named in ``only``, if given); DocBlockError for a bad marker or
    a name with no generator."""
    found = []
    for path in paths:
        where = _where(path)
        for block in find_blocks(path.read_text(encoding='utf-8'), where):
            if only is not None and block.name not in only:
                continue
            gen = REGISTRY.get(block.name)
            if gen is None and not is_example(block.name):
                raise DocBlockError(f'{where}:{block.line}: no generator named {block.name!r} ({__file__})')
            kind = gen.kind if gen else 'generated'
            if block.kind != kind:
                raise DocBlockError(
                    f'{where}:{block.line}: {block.name!r} is a {kind} block, not {block.kind}'
                )
            found.append(Found(path, block))
    return found


def make(name: str, ctx: Context) -> str:
    return example_block(name) if is_example(name) else REGISTRY[name].make(ctx)


def measured_body(name: str, text: str, today: datetime.date) -> str:
    return f'Measured {today.isoformat()} with `{REGISTRY[name].command}`.\n\n{text}'


def check_measured(found: Found) -> str | None:
    """Why a measured block's text is wrong (no dated command line, another command), or None."""
    first = found.block.body.strip().split('\n', 1)[0]
    m = MEASURED_LINE.fullmatch(first.rstrip('.'))
    command = REGISTRY[found.block.name].command
    if not m or m['command'] != command:
        return f'its first line must be "Measured YYYY-MM-DD with `{command}`."'
    return None


def run(
    paths: Sequence[Path], *, check: bool, only: set[str] | None = None, measured: set[str] | None = None
) -> list[str]:
    """Regenerate (or with ``check``, compare) the blocks of ``paths``; the stale ones, as
    ``FILE:LINE NAME: why``. ``measured`` names the measured blocks to rerun (their commands)."""
    found = collect(paths, only)
    missing_shared = not SHARED.is_dir()
    todo = sorted(
        {
            f.block.name
            for f in found
            if f.block.kind == 'generated' or f.block.name in (measured or set())
            if not (missing_shared and REGISTRY.get(f.block.name) and REGISTRY[f.block.name].needs_shared)
        }
    )
    stale: list[str] = []
    with tempfile.TemporaryDirectory(prefix='docs_figures_') as scratch:
        ctx = Context(write=not check, scratch=Path(scratch))
        with ThreadPoolExecutor(JOBS) as pool:
            texts = dict(zip(todo, pool.map(lambda n: make(n, ctx), todo), strict=True))
        today = datetime.datetime.now(datetime.timezone.utc).date()
        for path in paths:
            mine = [f for f in found if f.path == path]
            if not mine:
                continue
            text = path.read_text(encoding='utf-8')
            bodies = {}
            for f in mine:
                where = f'{_where(path)}:{f.block.line} {f.block.name}'
                if f.block.kind == 'measured' and f.block.name not in texts:
                    why = check_measured(f)
                    if why:
                        stale.append(f'{where}: {why}')
                    continue
                if f.block.name not in texts:
                    continue  # needs ../shared, which is missing (the test says so)
                new = texts[f.block.name]
                if f.block.kind == 'measured':
                    new = measured_body(f.block.name, new, today)
                bodies[(f.block.kind, f.block.name)] = new
            new_text = replace_bodies(text, bodies, str(path))
            if new_text != text:
                changed = [f for f in mine if (f.block.kind, f.block.name) in bodies]
                new_blocks = {(b.kind, b.name): b.body for b in find_blocks(new_text)}
                stale += [
                    f'{_where(path)}:{f.block.line} {f.block.name}: differs from its command'
                    for f in changed
                    if new_blocks[(f.block.kind, f.block.name)] != f.block.body
                ]
                if not check:
                    path.write_text(new_text, encoding='utf-8')
        if not check:
            for dest, src in ctx.figures.items():
                shutil.copyfile(src, ROOT / dest)
    return stale


def unused(paths: Sequence[Path]) -> list[str]:
    """Registered generators no document uses (a block was removed: remove its generator too)."""
    used = {f.block.name for f in collect(paths)}
    return sorted(set(REGISTRY) - used)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='python -m tools.docs_figures', description=__doc__.split('\n\n')[0]
    )
    parser.add_argument('--check', action='store_true', help='write nothing; exit 1 if a block differs')
    parser.add_argument('--list', action='store_true', help='print the generators and their commands')
    parser.add_argument('--only', nargs='+', metavar='NAME', help='only the blocks with these names')
    parser.add_argument('--measured', nargs='+', metavar='NAME', default=[], help='rerun these slow blocks')
    parser.add_argument('files', nargs='*', type=Path, help='documents (default: README.md, docs/*.md, ...)')
    args = parser.parse_args(argv)
    if args.list:
        for gen in REGISTRY.values():
            print(f'{gen.kind:9} {gen.name:32} {gen.command}')
        return 0
    paths = [p.resolve() for p in args.files] or doc_files()
    only = set(args.only or ()) | set(args.measured) if args.only or args.measured else None
    try:
        bad = [n for n in args.measured if REGISTRY.get(n) is None or REGISTRY[n].kind != 'measured']
        if bad:
            raise DocBlockError(f'not a measured block: {", ".join(bad)} (see --list)')
        stale = run(paths, check=args.check, only=only, measured=set(args.measured))
        dead = unused(paths) if only is None and not args.files else []
    except (DocBlockError, RuntimeError, OSError) as exc:
        print(f'docs_figures: {exc}', file=sys.stderr)
        return 2
    if dead:
        print(f'docs_figures: generators no document uses: {", ".join(dead)}', file=sys.stderr)
        return 2
    if stale:
        verb = 'differ from their commands' if args.check else 'rewritten'
        print(f'docs blocks {verb} (python -m tools.docs_figures):', file=sys.stderr)
        print('\n'.join(f'  {s}' for s in stale), file=sys.stderr)
        return 1 if args.check else 0
    return 0


if __name__ == '__main__':
    sys.exit(main())
