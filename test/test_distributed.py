"""Studies on a real Dask cluster (issue 19): ``dask scheduler`` and two ``dask worker`` processes on
localhost run a small uncertain design study and a fleet validation through ``--scheduler``; the
design study equals the embedded LocalCluster's to the last bit for the same seed."""

from __future__ import annotations

import csv
import json
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.cli.main import main
from skidsteer_power.commands import Segment

DASK = str(Path(sys.executable).with_name('dask'))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port: int = s.getsockname()[1]
        return port


def _stop(processes: list[subprocess.Popen[bytes]]) -> None:
    for p in processes:
        if p.poll() is None:
            p.terminate()
    for p in processes:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@pytest.fixture(scope='module')
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """tcp:// address of a scheduler with two single-threaded workers (separate processes)."""
    from dask.distributed import Client

    work = tmp_path_factory.mktemp('dask')
    port = _free_port()
    address = f'tcp://127.0.0.1:{port}'
    quiet: dict[str, Any] = {'stdout': subprocess.DEVNULL, 'stderr': subprocess.DEVNULL, 'cwd': work}
    processes = [
        subprocess.Popen(
            [DASK, 'scheduler', '--host', '127.0.0.1', '--port', str(port), '--no-dashboard'], **quiet
        )
    ]
    try:
        for k in range(2):
            processes.append(
                subprocess.Popen(
                    [
                        DASK,
                        'worker',
                        address,
                        '--nthreads',
                        '1',
                        '--host',
                        '127.0.0.1',
                        '--no-dashboard',
                        '--local-directory',
                        str(work / f'w{k}'),
                        '--name',
                        f'w{k}',
                    ],
                    **quiet,
                )
            )
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        _stop(processes)


def _design(capsys: pytest.CaptureFixture[str], *extra: str) -> dict[str, Any]:
    argv = ['design-study', '--configuration', 'track', '--samples', '3', '--seed', '7', '--json']
    assert main([*argv, *extra]) == 0
    design: dict[str, Any] = json.loads(capsys.readouterr().out)
    return design


def test_design_study_on_a_cluster_equals_the_local_one(
    scheduler: str, capsys: pytest.CaptureFixture[str]
) -> None:
    remote = _design(capsys, '--scheduler', scheduler)
    assert '2 worker' in remote['uncertainty']['engine'] and scheduler in remote['uncertainty']['engine']
    local = _design(capsys, '--workers', '2')
    assert 'LocalCluster' in local['uncertainty']['engine']
    for study in (remote, local):
        study['uncertainty'].pop('engine')
    assert remote == local  # every merit percentile, probability and nominal value, bit for bit
    ranked = remote['best_probability']['track']
    assert sum(c['p_best'] for c in ranked) == pytest.approx(1.0)
    assert all(c['merit_p05'] <= c['merit_p50'] <= c['merit_p95'] for c in ranked)
    assert remote['n_candidates'] == 243  # 3^5 track candidates of Table 8.4


def test_fleet_validation_on_a_cluster_reports_every_bag(
    scheduler: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bags = tmp_path / 'bags'
    bags.mkdir()
    # 2 s straight at 0.2 m/s, then 2 s at 0.1 m/s turning: 0.4 + 0.2 = 0.6 m of path (odometry)
    for name in ('a', 'b'):
        write_drive_bag(bags / f'{name}.mcap', [Segment(0.2, 0.0, 2.0), Segment(0.1, 0.3, 2.0)], rate_hz=20)
    (bags / 'broken.mcap').write_bytes(b'not a bag')
    out = tmp_path / 'fleet'
    argv = ['validate', str(bags / '*.mcap'), '--vehicle', 'test_robot_track', '--terrain', 'dry_sand']
    fleet_options = ['--scheduler', scheduler, '--no-plots', '--cmd-hold', '0.7', '--json']
    code = main([*argv, '--report', str(out), *fleet_options])
    assert code == 1  # one bag failed, and said so
    summary = json.loads(capsys.readouterr().out)
    assert (summary['bags'], summary['ok'], summary['failed']) == (3, 2, 1)
    rows = {Path(r['bag']).name: r for r in summary['rows']}
    assert 'corrupt' in rows['broken.mcap']['error'] or 'not' in rows['broken.mcap']['error']
    for name in ('a.mcap', 'b.mcap'):
        assert rows[name]['ok'] and rows[name]['distance_source'] == 'poses'
        assert rows[name]['distance_m'] == pytest.approx(0.6, rel=0.02)
        single = json.loads((Path(rows[name]['report_dir']) / 'summary.json').read_text())  # its own report
        assert single['cmd_hold_s'] == 0.7  # every single-bag option reaches every bag of the fleet
    with open(out / 'fleet.csv', newline='') as stream:
        assert len(list(csv.DictReader(stream))) == 3
    assert 'FAILED' in (out / 'summary.md').read_text()


def test_unreachable_scheduler_is_one_clear_error(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ['design-study', '--configuration', 'track', '--samples', '1', '--scheduler']
    assert main([*argv, f'tcp://127.0.0.1:{_free_port()}']) == 2
    err = capsys.readouterr().err
    assert 'cannot reach the Dask scheduler' in err and err.count('\n') == 1


def test_a_small_map_runs_in_this_process_without_a_cluster() -> None:
    """Issue 28: 30 mission samples took 63 s wall and 30 s of system time on a LocalCluster; a
    handful of light tasks now runs as a loop here, and no process is started."""
    from skidsteer_power.distributed.engine import IN_PROCESS_MAX_TASKS, Engine

    with Engine(workers=2, progress=False) as engine:
        assert engine.map(abs, [-1, 2, -3]) == [1, 2, 3]
        assert engine.cluster is None and engine.client is None
        assert engine.description.startswith('in-process')
        assert not engine.in_process(IN_PROCESS_MAX_TASKS + 1) and not engine.in_process(2, heavy=True)


def test_local_workers_run_one_blas_thread_and_glibc_default_malloc() -> None:
    """Each LocalCluster worker gets OMP/MKL/OPENBLAS_NUM_THREADS = 1 before it starts, and not
    Dask's default MALLOC_TRIM_THRESHOLD_ (which made numpy's temporaries fresh mmaps: 4.5 s of
    system time for 8 samples in one process instead of 0.16 s)."""
    from skidsteer_power.distributed.engine import Engine

    keys = ['OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MALLOC_TRIM_THRESHOLD_']
    with Engine(workers=2, progress=False) as engine:
        seen = engine.map(lambda key: __import__('os').environ.get(key), keys, heavy=True)
        assert engine.cluster is not None  # a heavy map ran on the workers
    assert seen == ['1', '1', '1', None]
