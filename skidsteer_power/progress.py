"""Progress of long work on stderr: one rich bar, shown only on a terminal (stdout stays clean)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.progress import Progress


class progress_bar:
    """A rich progress bar on stderr (or nothing), as a context manager yielding ``advance(amount=1)``.

    ``enabled`` None: only when stderr is a terminal. ``total`` in the caller's units (tasks,
    simulated seconds)."""

    def __init__(self, enabled: bool | None, label: str, total: float) -> None:
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.label, self.total = label, total
        self.bar: Progress | None = None

    def __enter__(self) -> Callable[..., None]:
        if not self.enabled:
            return lambda amount=1.0: None
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        self.bar = bar = Progress(
            TextColumn('{task.description}'),
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
        )
        bar.start()
        task = bar.add_task(self.label, total=self.total)
        return lambda amount=1.0: bar.advance(task, amount)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()
