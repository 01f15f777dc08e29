"""The batch engine on a real Dask cluster: ``dask scheduler`` and two ``dask worker`` processes.

The cluster is started once for the module, with the commands docs/STUDIES.md gives for a
cluster of machines (on localhost here). Known answers: ``contact_sweep --quick --scheduler
ADDR`` prints the same table, byte for byte, as the sweep run in one process; a batch comes back
in the cases' order with every case counted once by the progress callback; a malformed address is
refused in one line with exit 2.
"""
from __future__ import annotations

import functools

from gripper_ros.apps import contact_sweep
from gripper_ros.core.runtime.engine import check_address, chunked, dask_cluster, map_cases
import pytest


@pytest.fixture(scope='module')
def scheduler():
    with dask_cluster(workers=2) as address:
        yield address


def _sweep_json(capsys, *args) -> str:
    assert contact_sweep.main(['--quick', '--json', '--quiet', *args]) == 0
    return capsys.readouterr().out


def test_contact_sweep_on_the_cluster_prints_the_local_table(scheduler, capsys):
    remote = _sweep_json(capsys, '--scheduler', scheduler)
    local = _sweep_json(capsys, '--jobs', '1')
    assert remote == local
    assert remote.count('"outcome": "HOLDING"') == 30


def test_a_batch_comes_back_in_order_and_progress_counts_every_case(scheduler):
    done = []
    cases = list(range(37))
    # a builtin: the workers import what they run, and they cannot import this test module
    out = map_cases(functools.partial(pow, 3), cases, scheduler=scheduler, progress=done.append)
    assert out == [3 ** x for x in cases]
    assert sum(done) == len(cases) and len(done) == len(chunked(cases, 2))


def test_chunks_keep_every_case_once_in_order():
    cases = list(range(101))
    chunks = chunked(cases, workers=2, chunks_per_worker=4)
    assert len(chunks) == 8 and [x for c in chunks for x in c] == cases


@pytest.mark.parametrize('address', ['localhost:8786', 'tcp://host', 'tcp://host:0',
                                     'http://host:8786', 'tcp://host:port'])
def test_a_malformed_scheduler_address_is_refused_in_one_line(address, capsys):
    with pytest.raises(ValueError, match='tcp://HOST:8786'):
        check_address(address)
    assert contact_sweep.main(['--quick', '--scheduler', address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('contact_sweep: --scheduler')


QUIET_CLOSE = """
import asyncio, functools, operator
from distributed.deploy.spec import SpecCluster
from gripper_ros.core.runtime.engine import map_cases
_close = SpecCluster._close


async def scheduler_first(self):        # as a close a loaded machine delays can order it
    await self.scheduler.close()
    await asyncio.sleep(3.0)            # the workers still run: their heartbeats find it gone
    await _close(self)

if __name__ == '__main__':
    print(sum(map_cases(functools.partial(operator.mul, 2), list(range(40)), jobs=2)))
    SpecCluster._close = scheduler_first
"""


def test_a_batch_program_ends_with_nothing_from_dask_on_its_stderr(tmp_path):
    """The local cluster closes at exit without a word, even when its scheduler goes first.

    Its scheduler lives in the program's process; a worker that outlives it (a loaded machine
    stops them slowly) logs into the program's stderr, where a study's output is (a
    "Failed to communicate with scheduler during heartbeat" traceback once reached a document).
    Each worker's last try to reach the gone scheduler gives up after Dask's connect timeout:
    5 s here instead of the default 30 s, the same path sooner.
    """
    import os
    import subprocess
    import sys
    script = tmp_path / 'batch_program.py'        # local workers re-import the main script
    script.write_text(QUIET_CLOSE, encoding='utf-8')
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=600, stdin=subprocess.DEVNULL,
                          env={**os.environ, 'DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT': '5s'})
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout == f'{2 * sum(range(40))}\n'
    assert done.stderr == ''
