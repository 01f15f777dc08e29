"""Test isolation: DDS traffic stays on this machine and on a domain of this run's own.

scripts/test.sh picks free domain ids per run, one for each pytest-xdist worker
(``GRIPPER_ROS_WORKER_DOMAINS``); worker ``gwK`` takes the K-th. Run directly, pytest falls back
to a PID-derived id.
"""
import os

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
_worker = os.environ.get('PYTEST_XDIST_WORKER', '')
_domains = os.environ.get('GRIPPER_ROS_WORKER_DOMAINS', '').split()
if _worker.startswith('gw') and _worker[2:].isdigit() and int(_worker[2:]) < len(_domains):
    os.environ['ROS_DOMAIN_ID'] = _domains[int(_worker[2:])]
os.environ.setdefault('ROS_DOMAIN_ID', str(40 + os.getpid() % 50))

SERIAL_MODULES = frozenset({
    'test_node_executables.py', 'test_shutdown.py', 'test_namespaces.py', 'test_hostile_graph.py',
    'test_grasp_client.py', 'test_launch_args.py', 'test_launch.py', 'test_faults.py',
    'test_recording_faults.py', 'test_time_modes.py', 'test_soak.py', 'test_tf_tree.py',
})
"""Modules that start many processes, wait on discovery or watch wall-clock timeouts: run
alone, after the rest (scripts/test.sh), so the other worker's load cannot starve them.
test_parameters is not one: its watchdog tests read the silence the watchdog itself counted
(time in which its executor ran), which another process's load does not change."""


def pytest_collection_modifyitems(config, items):
    """Mark the tests of :data:`SERIAL_MODULES` ``serial``."""
    for item in items:
        if item.path.name in SERIAL_MODULES:
            item.add_marker(pytest.mark.serial)


@pytest.fixture(scope='module')
def spare_domain_id():
    """Yield a ROS_DOMAIN_ID (1..100) of this run's own, for a test's second graph.

    It is locked as scripts/test.sh locks the run's ids (a file under
    ``$TMPDIR/gripper_ros_domains.<uid>``), so no concurrent run on this machine takes it.
    """
    import fcntl
    from pathlib import Path
    lockdir = Path(os.environ.get('TMPDIR', '/tmp')) / f'gripper_ros_domains.{os.getuid()}'
    lockdir.mkdir(parents=True, exist_ok=True)
    taken = {int(d) for d in os.environ.get('GRIPPER_ROS_WORKER_DOMAINS', '').split()}
    start = (os.getpid() + 50) % 100
    for i in range(100):
        candidate = (start + i) % 100 + 1
        if candidate in taken or candidate == int(os.environ['ROS_DOMAIN_ID']):
            continue
        lock = open(lockdir / f'{candidate}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        try:
            yield candidate
        finally:
            lock.close()
        return
    pytest.fail('no free ROS_DOMAIN_ID in 1..100 for a second graph')
