"""The batch engine of every multi-grasp job: Dask (``dask.distributed``), local or a cluster.

:func:`map_cases` cuts a batch into chunks and sends each chunk to a Dask worker as one task, so
that the engine's cost per task (about a millisecond) stays small against the grasps of a chunk.
Without a scheduler address the workers are a ``LocalCluster`` of this machine's processes,
started on first use and kept for the rest of the process (a study sends many batches); with
``tcp://HOST:8786`` the same chunks go to a cluster started by ``dask scheduler`` and
``dask worker`` on each machine. Results come back in the cases' order, each computed by the
same code whatever worker ran it: the same bytes whatever the engine and the worker count
(on one kind of machine: numba compiles for the CPU it runs on).
"""
from __future__ import annotations

import atexit
from contextlib import contextmanager
import logging
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
from typing import Callable, Iterator, Sequence

WORKER_PRELOAD = 'gripper_ros.core.runtime.batch_worker'
"""Imported by each worker as it starts (``dask worker --preload``): loads the compiled core."""
CHUNKS_PER_WORKER = 4
"""A batch is cut into this many chunks per worker: few tasks, balanced load."""
CLUSTER_START_TIMEOUT_S = 120.0
"""How long :func:`dask_cluster` waits for its scheduler and workers."""

_local: dict[int, object] = {}
"""The local clients of this process, by worker count (started once, closed at exit)."""
_remote: dict[str, object] = {}
"""The clients of this process to scheduler addresses."""


class EngineError(RuntimeError):
    """The engine could not run a batch (no scheduler at the address, a worker lost)."""


def _quiet_logs() -> None:
    """Log only errors of this process's scheduler: its start and shut-down are no news."""
    import distributed  # noqa: F401 - its import configures the loggers set below
    for name in [*logging.root.manager.loggerDict, 'distributed']:
        if name.startswith('distributed'):
            logging.getLogger(name).setLevel(logging.ERROR)


def _close_all() -> None:
    for client in (*_local.values(), *_remote.values()):
        try:
            cluster = client.cluster
            client.close(timeout=5)
            if cluster is not None:
                cluster.close(timeout=5)
        except Exception:       # noqa: B902 - at exit, a cluster already gone is no error
            pass
    _local.clear()
    _remote.clear()


atexit.register(_close_all)


def local_client(workers: int):
    """Return this process's local Dask client with ``workers`` worker processes.

    One thread each (a grasp holds the GIL), the dashboard on a free port; started on first use.
    """
    client = _local.get(workers)
    if client is None or client.status != 'running':
        from distributed import Client, LocalCluster
        _quiet_logs()
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=':0', preload=[WORKER_PRELOAD],
                               silence_logs=logging.ERROR)
        client = _local[workers] = Client(cluster, set_as_default=False)
    return client


def remote_client(address: str):
    """Return a client connected to the scheduler at ``address``; EngineError if none answers."""
    client = _remote.get(address)
    if client is None or client.status != 'running':
        from distributed import Client
        try:
            client = Client(address, timeout=20, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise EngineError(f'no Dask scheduler answers at {address} ({exc})') from None
        _remote[address] = client
    return client


def check_address(address: str) -> str:
    """Return ``address`` if it looks like a scheduler address; ValueError naming it if not."""
    scheme, sep, rest = address.partition('://')
    host, colon, port = rest.rpartition(':')
    if not sep or scheme not in ('tcp', 'tls', 'inproc', 'ws', 'wss') or not colon or not host \
            or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f'--scheduler must be an address like tcp://HOST:8786, got {address!r}')
    return address


def _run_chunk(fn: Callable, chunk: list) -> list:
    """Run ``fn`` over one chunk of cases in a worker (module level: it is pickled)."""
    return [fn(case) for case in chunk]


def _workers_can_start() -> bool:
    """Tell whether local worker processes can start here.

    A spawned worker re-imports the main script by its path; a script read from standard input
    has none, and its workers would die at start.
    """
    path = getattr(sys.modules.get('__main__'), '__file__', None)
    return path is None or os.path.isfile(path)


def chunked(cases: list, workers: int, chunks_per_worker: int = CHUNKS_PER_WORKER) -> list:
    """Cut ``cases`` into about ``workers x chunks_per_worker`` chunks, in order."""
    size = max(1, math.ceil(len(cases) / (workers * chunks_per_worker)))
    return [cases[i:i + size] for i in range(0, len(cases), size)]


MAX_JOBS_PER_CPU = 4
"""Local workers beyond this many per CPU only share the cores, each a process of its own."""


def jobs_problem(jobs) -> str:
    """Return why ``jobs`` local workers cannot be started here ('' if they can)."""
    cpus = os.cpu_count() or 1
    limit = MAX_JOBS_PER_CPU * cpus
    if isinstance(jobs, bool) or not isinstance(jobs, int) or not 1 <= jobs <= limit:
        return (f'jobs must be a whole number in [1, {limit}] ({MAX_JOBS_PER_CPU} per CPU of '
                f'the {cpus} here; more only share the cores), got {jobs!r}')
    return ''


def add_engine_arguments(parser, work: str = 'the grasps'):
    """Add the batch programs' ``--jobs N`` or ``--scheduler ADDRESS`` (one or the other).

    ``--jobs`` left out is None: one worker per CPU (:func:`worker_count`). Check the values
    with :func:`options_problem`. ``work``: what runs on the cluster, for the help.
    """
    engine = parser.add_mutually_exclusive_group()
    engine.add_argument('--jobs', type=int, default=None, metavar='N',
                        help='local worker processes (default: one per CPU; 1 = this process)')
    engine.add_argument('--scheduler', default=None, metavar='tcp://HOST:8786',
                        help=f'run {work} on the Dask cluster of this scheduler (started with '
                             '`dask scheduler` and `dask worker` on each machine)')
    return engine


def worker_count(jobs: int | None) -> int:
    """Return the local workers ``jobs`` asks for (None: one per CPU)."""
    return jobs if jobs is not None else (os.cpu_count() or 1)


def options_problem(jobs: int | None = None, scheduler: str | None = None) -> str:
    """Return why a program's ``--jobs`` or ``--scheduler`` cannot be used ('' if they can).

    ``jobs`` None: the engine's default; with a ``scheduler`` the local count is not used.
    """
    if scheduler is not None:
        try:
            check_address(scheduler)
        except ValueError as exc:
            return str(exc)
        return ''
    return '--' + jobs_problem(jobs) if jobs is not None and jobs_problem(jobs) else ''


def map_cases(fn: Callable, cases: Sequence, jobs: int | None = None,
              chunks_per_job: int = CHUNKS_PER_WORKER, *, scheduler=None,
              progress: Callable[[int], None] | None = None) -> list:
    """Return ``[fn(case) for case in cases]``, computed by the engine.

    ``scheduler`` None: ``jobs`` local worker processes (None = one per core, 1 = in this
    process); an address (``tcp://HOST:8786``) or a ``distributed.Client``: that cluster's
    workers (``jobs`` is then ignored). ``progress(n)`` is called in this process as each
    ``n`` cases are done. ``fn`` and the cases must pickle (module-level functions,
    ``functools.partial``). Raises EngineError when the cluster cannot run the batch.
    """
    cases = list(cases)
    jobs = worker_count(jobs)
    if scheduler is None and jobs_problem(jobs):
        raise ValueError(jobs_problem(jobs))
    if scheduler is None and (jobs == 1 or len(cases) <= 1 or not _workers_can_start()):
        out = []
        for case in cases:
            out.append(fn(case))
            if progress is not None:
                progress(1)
        return out
    if scheduler is None:
        client = local_client(jobs)
    elif isinstance(scheduler, str):
        client = remote_client(check_address(scheduler))
    else:
        client = scheduler
    workers = max(1, sum(client.nthreads().values()))
    chunks = chunked(cases, workers, chunks_per_job)
    from distributed import as_completed
    futures = client.map(_run_chunk, [fn] * len(chunks), chunks, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    results: list = [None] * len(chunks)
    try:
        for future in as_completed(futures, loop=client.loop):
            results[index[future.key]] = future.result()
            if progress is not None:
                progress(len(chunks[index[future.key]]))
    except BaseException:
        client.cancel(futures)
        raise
    return [r for chunk in results for r in chunk]


@contextmanager
def dask_cluster(workers: int = 2, host: str = '127.0.0.1',
                 env: dict | None = None) -> Iterator[str]:
    """Start ``dask scheduler`` and ``workers`` x ``dask worker`` here; yield the address.

    The same commands a cluster of machines runs (docs/STUDIES.md), one thread a worker, each
    worker preloading the compiled core; all are stopped on exit. For the benchmark and the tests.
    """
    procs: list[subprocess.Popen] = []
    address = None
    with tempfile.TemporaryDirectory(prefix='gripper_dask_') as tmp:
        info = Path(tmp) / 'scheduler.json'
        dask = [sys.executable, '-m', 'dask']
        quiet = {'stdin': subprocess.DEVNULL, 'stdout': subprocess.DEVNULL,
                 'stderr': subprocess.DEVNULL, 'env': env}
        try:
            procs.append(subprocess.Popen(
                [*dask, 'scheduler', '--host', host, '--port', '0', '--no-dashboard',
                 '--scheduler-file', str(info)], **quiet))
            procs += [subprocess.Popen(
                [*dask, 'worker', '--scheduler-file', str(info), '--nthreads', '1',
                 '--nworkers', '1', '--no-dashboard', '--host', host,
                 '--preload', WORKER_PRELOAD], **quiet) for _ in range(workers)]
            address = _wait_for_workers(info, workers, procs)
            yield address
        finally:
            if address is not None:
                client = _remote.pop(address, None)
                if client is not None:
                    client.close(timeout=5)
            for proc in reversed(procs):
                if proc.poll() is None:
                    proc.terminate()
            for proc in reversed(procs):
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


def _wait_for_workers(info: Path, workers: int, procs: list) -> str:
    import json
    deadline = time.monotonic() + CLUSTER_START_TIMEOUT_S
    while not info.exists() or not info.read_text():
        if time.monotonic() > deadline or procs[0].poll() is not None:
            raise EngineError('dask scheduler did not start')
        time.sleep(0.1)
    time.sleep(0.1)
    address = json.loads(info.read_text())['address']
    client = remote_client(address)
    try:
        client.wait_for_workers(workers, timeout=max(1.0, deadline - time.monotonic()))
    except TimeoutError:
        raise EngineError(f'{workers} dask workers did not join {address}') from None
    return address


__all__ = ['check_address', 'chunked', 'dask_cluster', 'EngineError', 'local_client',
           'map_cases', 'remote_client']
