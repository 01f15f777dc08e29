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
CLUSTER_START_CPU_S = 120.0
"""CPU :func:`dask_cluster`'s scheduler and workers may use, together, before all have joined:
each start costs a few seconds (imports, the compiled core, one grasp), so more means one spins."""
CLUSTER_STALL_S = 60.0
"""How long :func:`dask_cluster` waits while none of its processes uses any CPU: a loaded machine
starts them slowly, but runs each of them several times a second."""

_local: dict[int, object] = {}
"""The local clients of this process, by worker count (started once, closed at exit)."""
_remote: dict[str, object] = {}
"""The clients of this process to scheduler addresses."""


class EngineError(RuntimeError):
    """The engine could not run a batch (no scheduler at the address, a worker lost)."""


def _quiet_logs(level: int = logging.ERROR) -> None:
    """Log only errors of this process's scheduler: its start and shut-down are no news."""
    import distributed  # noqa: F401 - its import configures the loggers set below
    for name in [*logging.root.manager.loggerDict, 'distributed']:
        if name.startswith('distributed'):
            logging.getLogger(name).setLevel(level)


def _silence_worker() -> None:
    """Log nothing more in this worker (run on each by :func:`_close_all`): its batches are done.

    A local cluster's scheduler lives in the program's process. When a loaded machine stops a
    worker slowly, its heartbeat can find the scheduler gone and log a "Failed to communicate
    with scheduler during heartbeat" traceback into the program's stderr, where the program's
    own output is.
    """
    _quiet_logs(logging.CRITICAL + 1)


def _close_all() -> None:
    """Close this process's clients, then their local clusters: workers first, then scheduler.

    A local cluster's workers are silenced first (:func:`_silence_worker`). No wall-time limit
    (the workers' nannies bound their own stop): a close cut short on a loaded machine leaves
    workers running past their scheduler.
    """
    for client in (*_local.values(), *_remote.values()):
        try:
            cluster = client.cluster
            if cluster is not None:
                client.run(_silence_worker)
                _quiet_logs(logging.CRITICAL + 1)       # its scheduler, here
            client.close(timeout=None)
            if cluster is not None:
                cluster.close(timeout=None)
        except Exception:       # noqa: B902 - at exit, a cluster already gone is no error
            pass
    _local.clear()
    _remote.clear()


def _close_at_exit() -> None:
    """Close the clients at exit before ``distributed``'s own exit handler does.

    Registered once a client exists, after ``distributed`` registered its handler (handlers run
    last registered first), which closes each local cluster with a 10 s limit and says nothing
    when a loaded machine needs longer.
    """
    global _close_registered
    if not _close_registered:
        atexit.register(_close_all)
        _close_registered = True


_close_registered = False


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
        _close_at_exit()
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
        _close_at_exit()
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
                    client.close(timeout=None)
            for group in (procs[1:], procs[:1]):        # the workers, then the scheduler
                for proc in group:
                    if proc.poll() is None:
                        proc.terminate()
                for proc in group:
                    try:
                        proc.wait(timeout=20)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()


class _StartWatch:
    """Tell processes that start slowly (a loaded machine) from ones that never will.

    Hung: none of them used any CPU for :data:`CLUSTER_STALL_S`, or together more than
    :data:`CLUSTER_START_CPU_S`.
    """

    def __init__(self, procs: list):
        import psutil
        self._procs = [psutil.Process(p.pid) for p in procs]
        self._first = self._last = self._used()
        self._moved = time.monotonic()

    def _used(self) -> float:
        import psutil
        used = 0.0
        for proc in self._procs:
            try:
                times = proc.cpu_times()
            except psutil.Error:            # ended: the caller sees its exit
                continue
            used += times.user + times.system
        return used

    def hung(self) -> str:
        """Return why the processes count as hung, or '' while they are starting."""
        used, now = self._used(), time.monotonic()
        if used > self._last:
            self._last, self._moved = used, now
        if used - self._first > CLUSTER_START_CPU_S:
            return f'used {used - self._first:.0f} s of CPU'
        if now - self._moved > CLUSTER_STALL_S:
            return f'used no CPU for {CLUSTER_STALL_S:.0f} s'
        return ''


def _wait_for_workers(info: Path, workers: int, procs: list) -> str:
    """Wait until the scheduler wrote its address and ``workers`` workers joined it.

    For as long as they start: on a loaded machine that takes minutes. EngineError once one of
    the processes ended or all of them are hung (:class:`_StartWatch`).
    """
    import json
    watch = _StartWatch(procs)
    while not info.exists() or not info.read_text():
        hung = watch.hung()
        if hung or procs[0].poll() is not None:
            raise EngineError(f'dask scheduler did not start ({hung or "it ended"})')
        time.sleep(0.1)
    time.sleep(0.1)
    address = json.loads(info.read_text())['address']
    while True:
        try:       # again when a slow scheduler dropped the client: it makes a new one
            remote_client(address).wait_for_workers(workers, timeout=1.0)
            return address
        except (TimeoutError, EngineError):
            pass
        ended = [p.args[3] for p in procs if p.poll() is not None]
        hung = watch.hung()
        if ended or hung:
            raise EngineError(f'{workers} dask workers did not join {address} (' +
                              (f'a dask {ended[0]} ended' if ended else hung) + ')')


__all__ = ['check_address', 'chunked', 'dask_cluster', 'EngineError', 'local_client',
           'map_cases', 'remote_client']
