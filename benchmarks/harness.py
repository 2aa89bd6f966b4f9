"""Tiny benchmark harness: figures with units, goals, and ratios to a reference measured in the
same run (machines are noisy, so a ratio beats an absolute time). No assertions: benchmarks report.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Figure:
    name: str
    value: float
    unit: str
    goal: str = ''
    met: bool | None = None
    note: str = ''


@dataclass
class Report:
    section: str = ''
    figures: list[Figure] = field(default_factory=list)
    tables: dict[str, str] = field(default_factory=dict)
    """Markdown tables by name, written into docs/BENCHMARKS.md's block of that name (benchmarks/docs.py)."""

    def figure(
        self, name: str, value: float, unit: str, *, goal: str = '', met: bool | None = None, note: str = ''
    ) -> Figure:
        met = None if met is None else bool(met)  # numpy bools would escape the `is False` count
        fig = Figure(f'{self.section}: {name}' if self.section else name, float(value), unit, goal, met, note)
        self.figures.append(fig)
        print(format_figure(fig), flush=True)
        return fig

    def under(
        self,
        name: str,
        value: float,
        unit: str,
        limit: float | None,
        *,
        inclusive: bool = False,
        note: str = '',
    ) -> Figure:
        """``value`` with the goal ``value < limit`` (``<=`` if ``inclusive``); none if ``limit`` is None."""
        if limit is None:
            return self.figure(name, value, unit, note=note)
        sign, met = ('<=', value <= limit) if inclusive else ('<', value < limit)
        return self.figure(name, value, unit, goal=f'{sign} {limit:g} {unit}', met=met, note=note)

    def ratio(
        self,
        name: str,
        numerator: float,
        denominator: float,
        *,
        goal: str = '',
        met: bool | None = None,
        note: str = '',
    ) -> Figure:
        return self.figure(name, numerator / denominator, 'x', goal=goal, met=met, note=note)


def format_figure(fig: Figure) -> str:
    status = '' if fig.met is None else ('  [goal met]' if fig.met else '  [GOAL MISSED]')
    goal = f'  (goal {fig.goal})' if fig.goal else ''
    note = f'  -- {fig.note}' if fig.note else ''
    return f'{fig.name:<60} {fig.value:>14.6g} {fig.unit:<8}{goal}{status}{note}'


def best_time(func: Callable[[], Any], *, repeat: int = 5, number: int = 1) -> float:
    """Best wall time of ``number`` calls of ``func`` over ``repeat`` rounds, per call [s]."""
    best = float('inf')
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            func()
        best = min(best, (time.perf_counter() - start) / number)
    return best
