"""Run every benchmark module (``benchmarks/bench_*.py``) or the ones named on the command line.

    python -m benchmarks.run              # all
    python -m benchmarks.run fess maps    # bench_fess.py and bench_maps.py

Each module defines ``run(report: benchmarks.harness.Report) -> None``. The exit code is 1 when any
goal was missed (so ``make bench`` fails), 0 when every goal was met.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

from benchmarks.harness import Report


def main(argv: list[str] | None = None) -> int:
    wanted = set(argv if argv is not None else sys.argv[1:])
    names = sorted(
        m.name for m in pkgutil.iter_modules([str(Path(__file__).parent)]) if m.name.startswith('bench_')
    )
    missed = 0
    for name in names:
        short = name.removeprefix('bench_')
        if wanted and short not in wanted and name not in wanted:
            continue
        print(f'\n== {short} ==', flush=True)
        report = Report(section=short)
        importlib.import_module(f'benchmarks.{name}').run(report)
        missed += sum(1 for f in report.figures if f.met is False)
    print(f'\n{missed} goal(s) missed')
    return 1 if missed else 0


if __name__ == '__main__':
    sys.exit(main())
