"""Where a study's tasks run: an embedded Dask LocalCluster, or an existing Dask cluster.

``Engine()`` starts a LocalCluster sized to the machine (one single-threaded worker process per core,
or ``workers``), so a laptop user needs nothing; ``Engine(scheduler='tcp://HOST:8786')`` connects to a
cluster the user started (``dask scheduler`` and ``dask worker tcp://HOST:8786`` on each machine, with
this package installed in the workers' Python). :meth:`Engine.map` runs a module-level function over a
list of items and returns the results in the items' order, whatever worker ran each, so a study with a
fixed seed gives the same numbers locally and on a cluster (the samples are drawn before submission).
A rich progress bar on stderr follows the tasks as they finish (only on a terminal).

Small jobs run in this process: without a scheduler, a map of at most ``IN_PROCESS_MAX_TASKS``
light items (a mission sample: about 0.6 s), or any map with one local worker, is a plain loop, and
the LocalCluster is started only for the first larger map or a map of ``heavy`` items (a design-study
chunk, a bag). Its workers run one BLAS/OpenMP thread each (``ONE_THREAD_ENV``) and keep
glibc's default malloc: Dask's default ``MALLOC_TRIM_THRESHOLD_=65536`` turns off glibc's dynamic
mmap threshold, and every numpy temporary of a map build was then mmap'ed and zero-filled anew
(8 mission samples in one process: 4.5 s of system time with it, 0.16 s without; docs/STUDIES.md).

Tasks that raise stop the study with the task's own exception (a bug shows its traceback; the
project's errors are the user's). Studies that must survive a failing item (fleet validation) catch
inside the task and return a failure record.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar, cast

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.errors import InputError
from skidsteer_power.progress import progress_bar
from skidsteer_power.terramechanics.ranges import LOCAL_WORKERS

if TYPE_CHECKING:
    from argparse import _ActionsContainer

    from dask.distributed import Client, LocalCluster

Item = TypeVar('Item')
Result = TypeVar('Result')

CONNECT_TIMEOUT_S = 10.0
IN_PROCESS_MAX_TASKS = 32
"""Largest map run in-process without a scheduler (a pool's start-up costs more; docs/STUDIES.md)."""
ONE_THREAD_ENV = {'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1'}
"""Environment of each local worker process, set before it starts: one BLAS thread per worker."""


class Engine:
    """A Dask client on a LocalCluster (default) or on ``scheduler``; use as a context manager."""

    def __init__(
        self, scheduler: str | None = None, workers: int | None = None, progress: bool | None = None
    ):
        if workers is not None:
            LOCAL_WORKERS.check(workers)  # more processes than cores only slow a study: use a cluster
        if scheduler is not None and workers is not None:
            raise InputError('give either a scheduler address or a number of local workers, not both')
        self.scheduler = scheduler
        self.workers = workers or os.cpu_count() or 1
        self.progress = sys.stderr.isatty() if progress is None else progress
        self.cluster: LocalCluster | None = None
        self.client: Client | None = None

    def __enter__(self) -> Engine:
        if self.scheduler is not None:
            from dask.distributed import Client

            try:
                self.client = Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError, ValueError) as err:
                raise InputError(f'cannot reach the Dask scheduler {self.scheduler}: {err}') from err
        return self  # a LocalCluster starts with the first map that needs one

    def _start_local_cluster(self) -> None:
        import dask
        from dask.distributed import Client, LocalCluster

        with dask.config.set({'distributed.nanny.pre-spawn-environ': ONE_THREAD_ENV}):
            self.cluster = LocalCluster(
                n_workers=self.workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=':0',  # any free port (8787 may be another cluster's)
                silence_logs=logging.ERROR,
            )
        self.client = Client(self.cluster)

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def in_process(self, n_items: int, heavy: bool = False) -> bool:
        """Whether a map of ``n_items`` runs as a loop in this process (see the module doc)."""
        if self.client is not None or self.scheduler is not None:
            return False
        return self.workers == 1 or (not heavy and n_items <= IN_PROCESS_MAX_TASKS)

    @property
    def n_workers(self) -> int:
        """Workers the scheduler knows now (1: in this process)."""
        if self.client is None:
            return 1
        return len(self.client.scheduler_info(n_workers=-1)['workers'])

    def worker_cpu_s(self) -> float:
        """CPU seconds [s] the worker processes have used so far (this process's when in-process)."""
        if self.client is None:
            return time.process_time()
        return float(sum(self.client.run(time.process_time).values()))

    @property
    def description(self) -> str:
        if self.client is None:
            return 'in-process (no Dask cluster needed), 1 worker(s)'
        where = self.scheduler or 'embedded LocalCluster'
        return f'dask {where}, {self.n_workers} worker(s)'

    def map(
        self,
        fn: Callable[[Item], Result],
        items: Sequence[Item],
        label: str = 'tasks',
        *,
        heavy: bool = False,
    ) -> list[Result]:
        """``[fn(item) for item in items]``, run on the cluster (or here: :meth:`in_process`); results
        in the items' order. ``heavy``: each item is seconds of work or more."""
        from dask.distributed import as_completed

        if not items:
            return []
        if self.in_process(len(items), heavy):
            with progress_bar(self.progress, label, len(items)) as advance:
                return [_done(fn(item), advance) for item in items]
        if self.client is None:
            self._start_local_cluster()
        client = cast('Client', self.client)  # started just above
        futures = client.map(fn, list(items), pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        results = cast('list[Result]', [None] * len(futures))  # each set below, or the map raises
        with progress_bar(self.progress, label, len(futures)) as advance:
            try:
                for future in as_completed(futures):
                    results[index[future.key]] = future.result()
                    advance()
            except BaseException:
                client.cancel(futures)
                raise
        return results


def _done(result: Result, advance: Callable[[], None]) -> Result:
    advance()
    return result


def add_engine_args(parser: _ActionsContainer, jobs_flag: str | None = None) -> None:
    """``--scheduler ADDR`` and, with ``jobs_flag`` ('--jobs'), local worker processes on ``parser``."""
    parser.add_argument(
        '--scheduler',
        metavar='ADDR',
        default=None,
        help='run on an existing Dask cluster, e.g. tcp://HOST:8786 (default: a local cluster)',
    )
    if jobs_flag is None:
        return
    parser.add_argument(
        jobs_flag,
        dest='workers',
        type=range_arg(LOCAL_WORKERS),
        default=None,
        metavar='N',
        help=range_help(LOCAL_WORKERS, 'local worker processes (default: one per core; more: --scheduler)'),
    )
