"""Run every benchmark module (``benchmarks/bench_*.py``) or the ones named on the command line.

    python -m benchmarks.run              # all
    python -m benchmarks.run fess maps    # bench_fess.py and bench_maps.py
    python -m benchmarks.run --write-docs # ... and render the goal table into docs/BENCHMARKS.md

Each module defines ``run(report: benchmarks.harness.Report) -> None``. The exit code is 1 when any
goal was missed (so ``make bench`` fails), 0 when every goal was met.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import os
import pkgutil
import sys
from pathlib import Path

from benchmarks.docs import replace_named, update_doc
from benchmarks.harness import Figure, Report

DOC = Path(__file__).resolve().parents[1] / 'docs' / 'BENCHMARKS.md'


def area_names() -> list[str]:
    """Every benchmark module's area (``bench_NAME.py`` -> NAME), sorted."""
    modules = pkgutil.iter_modules([str(Path(__file__).parent)])
    return sorted(m.name.removeprefix('bench_') for m in modules if m.name.startswith('bench_'))


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='python -m benchmarks.run',
        description='Run the benchmark areas (all, or those named) and report every figure beside its goal; '
        'exit code 1 when a goal was missed.',
    )
    parser.add_argument(
        'areas', nargs='*', metavar='AREA', help=f'areas to run (default all): {", ".join(area_names())}'
    )
    parser.add_argument(
        '--write-docs', action='store_true', help='render the goal table into docs/BENCHMARKS.md'
    )
    args = parser.parse_args(argv)
    unknown = sorted({a.removeprefix('bench_') for a in args.areas} - set(area_names()))
    if unknown:
        parser.error(f'no benchmark area {", ".join(unknown)} (areas: {", ".join(area_names())})')
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(list(argv if argv is not None else sys.argv[1:]))
    write_docs = args.write_docs
    wanted = {a.removeprefix('bench_') for a in args.areas}
    names = [f'bench_{a}' for a in area_names()]
    missed = 0
    reports: list[tuple[str, list[Figure]]] = []
    tables: dict[str, str] = {}
    for name in names:
        short = name.removeprefix('bench_')
        if wanted and short not in wanted:
            continue
        print(f'\n== {short} ==', flush=True)
        report = Report(section=short)
        importlib.import_module(f'benchmarks.{name}').run(report)
        missed += sum(1 for f in report.figures if f.met is False)
        reports.append((short, report.figures))
        tables.update(report.tables)
    print(f'\n{missed} goal(s) missed')
    if write_docs:
        run = run_label()
        doc = update_doc(DOC.read_text(), reports, run)
        for name, table in tables.items():
            doc = replace_named(doc, name, table, run)
        DOC.write_text(doc)
        print(f'goal table written to {DOC}')
        for other in sorted(DOC.parent.glob('*.md')):  # a table may live in another doc (docs/REAL.md)
            if other == DOC:
                continue
            text = other.read_text()
            new = text
            for name, table in tables.items():
                new = replace_named(new, name, table, run)
            if new != text:
                other.write_text(new)
                print(f'tables written to {other}')
    return 1 if missed else 0


def run_label() -> str:
    """When and where this run measured: UTC date, cores, 1-minute load average at the end."""
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    day = datetime.datetime.now(datetime.UTC).date().isoformat()
    return f'{day}, {os.cpu_count()} cores, load {load:.1f}'


if __name__ == '__main__':
    sys.exit(main())
