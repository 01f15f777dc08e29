"""Test isolation: DDS traffic stays on this machine and on a domain of this run's own.

scripts/test.sh picks free domain ids per run, one for each pytest-xdist worker
(``GRIPPER_ROS_WORKER_DOMAINS``); worker ``gwK`` takes the K-th, and a worker started in place of
one that died takes a free id of its own. Run directly, pytest falls back to a PID-derived id.
"""
import os

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def _lock_free_domain(avoid) -> tuple[int, object]:
    """Return a ROS_DOMAIN_ID (1..100) no other holder of its lock file has, and the open lock.

    The lock files are scripts/test.sh's (``$TMPDIR/gripper_ros_domains.<uid>``); the lock is
    held while the returned file stays open. ``avoid``: ids whose neighbours (a test's id + 1)
    must stay free too.
    """
    import fcntl
    from pathlib import Path
    lockdir = Path(os.environ.get('TMPDIR', '/tmp')) / f'gripper_ros_domains.{os.getuid()}'
    lockdir.mkdir(parents=True, exist_ok=True)
    start = (os.getpid() + 50) % 100
    for i in range(100):
        candidate = (start + i) % 100 + 1
        if any(abs(candidate - taken) <= 1 for taken in avoid):
            continue
        lock = open(lockdir / f'{candidate}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return candidate, lock
    raise RuntimeError('no free ROS_DOMAIN_ID in 1..100')


_worker = os.environ.get('PYTEST_XDIST_WORKER', '')
_domains = os.environ.get('GRIPPER_ROS_WORKER_DOMAINS', '').split()
if _worker.startswith('gw') and _worker[2:].isdigit():
    if int(_worker[2:]) < len(_domains):
        os.environ['ROS_DOMAIN_ID'] = _domains[int(_worker[2:])]
    else:
        # a worker started in place of one that died: the dead one's processes may live on in
        # its domain, so this one takes a domain of its own, held until it exits
        _domain, _REPLACEMENT_DOMAIN_LOCK = _lock_free_domain([int(d) for d in _domains])
        os.environ['ROS_DOMAIN_ID'] = str(_domain)
os.environ.setdefault('ROS_DOMAIN_ID', str(40 + os.getpid() % 50))

SERIAL_MODULES = frozenset({'test_launch.py', 'test_sim_time.py', 'test_time_modes.py'})
"""Modules that measure against the wall clock itself: run alone, after the rest
(scripts/test.sh), so that other workers' load cannot starve them. test_launch: launch's own
escalation (SIGTERM, then SIGKILL, after wall-clock timeouts) races each process's stop.
test_sim_time: a stamp within 20 ms of a world clock that runs in wall time (a latency).
test_time_modes: a realtime plant paced by the wall clock, whose controllers must keep its grip
within the settle band for a second (a rate). A test of another module that does so carries
``@pytest.mark.serial`` itself, with its reason (a race between a signal and a paced grasp; six
processes stopping at once). The rest run on the workers however loaded: they wait on events
(discovery, an answer, a line, a process's CPU: helpers.ProgressWatch) with bounds that scale
with the machine's load (process.load_bound_s), never on a wall-clock pace, and each worker has
a domain of its own. Watchdogs count only the time in which their executor ran, so a starved
process trips none."""


MODULE_SECONDS = {
    'test_docs_bag_tools.py': 154, 'test_docs_transcripts.py': 106,
    'test_node_executables.py': 100, 'test_shutdown.py': 73, 'test_grasp_client.py': 66,
    'test_trajectory_tracking.py': 66,
    'test_moveit_handles.py': 46, 'test_stock_clients.py': 44, 'test_engine.py': 30,
    'test_namespaces.py': 41, 'test_docs_grip.py': 32, 'test_hostile_graph.py': 31,
    'test_follow_joint_trajectory.py': 30, 'test_faults.py': 27, 'test_live_view.py': 25,
    'test_parameters.py': 24, 'test_bag_recorder.py': 21, 'test_rerun.py': 20, 'test_lift.py': 18,
    'test_portability.py': 17, 'test_identify.py': 17, 'test_recording_faults.py': 16,
    'test_cond_wait_fix.py': 12,
}
"""The longest modules' time on a worker (wall time from each module's first test to the next
module's, three workers, load 3: main f1b29da with test_node_executables' stops made parallel).

A module stays on one worker (scripts/test.sh), and pytest-xdist hands the modules out in the
order collected: the longest go first, so that none starts last and keeps one worker busy while
the others are done. The rest follow in pytest-xdist's own order (most tests first). A figure
here orders the modules; no test depends on it."""


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    """Keep a fatal error's stacks on pytest's own stream when rclpy re-enables faulthandler.

    rclpy's EventsExecutor (every graph's default executor) calls ``faulthandler.enable()``
    onto ``sys.stderr``, which during a test is pytest's capture: a worker that then dies of
    a fatal signal writes its stacks into a capture file nobody reads. A call without a file
    now writes where pytest's faulthandler plugin does (its copy of the real stderr).
    """
    import faulthandler
    from _pytest.faulthandler import fault_handler_stderr_fd_key
    stream_fd = config.stash.get(fault_handler_stderr_fd_key, None)
    if stream_fd is None:
        return
    enable = faulthandler.enable

    def enable_on_pytests_stream(file=None, all_threads=True):
        enable(file=stream_fd if file is None else file, all_threads=all_threads)

    faulthandler.enable = enable_on_pytests_stream


def pytest_testnodedown(node, error):
    """Say how a pytest-xdist worker that died ended: the signal that killed it, or its code.

    pytest-xdist says only "Not properly terminated"; a worker ended by a signal nobody
    handles (SIGKILL, SIGTERM) or by ``_exit`` leaves no stack, so its status is the one clue.
    """
    if not error:
        return
    import signal
    import subprocess
    import sys
    popen = getattr(getattr(node.gateway, '_io', None), 'popen', None)
    if popen is None:
        return
    try:
        code = popen.wait(timeout=10)
    except subprocess.TimeoutExpired:
        return
    try:
        how = f'killed by {signal.Signals(-code).name}' if code < 0 else f'exit code {code}'
    except ValueError:
        how = f'status {code}'
    sys.stderr.write(f'\n[test] pytest-xdist worker {node.gateway.id} ended: {how}\n')


def pytest_ignore_collect(collection_path, config):
    """In the serial phase (``-m serial``), leave out the modules that hold no serial test.

    Importing and collecting the whole suite costs a process several seconds of CPU; the serial
    phase runs a few modules' tests.
    """
    if (config.getoption('markexpr') != 'serial' or collection_path.suffix != '.py'
            or not collection_path.name.startswith('test_')
            or collection_path.name in SERIAL_MODULES):
        return None
    return None if 'pytest.mark.serial' in collection_path.read_text(encoding='utf-8') else True


def pytest_collection_modifyitems(config, items):
    """Mark the tests of :data:`SERIAL_MODULES` ``serial`` (others are marked in their module).

    On a pytest-xdist worker, order the modules longest first (:data:`MODULE_SECONDS`).
    """
    for item in items:
        if item.path.name in SERIAL_MODULES:
            item.add_marker(pytest.mark.serial)
    if os.environ.get('PYTEST_XDIST_WORKER'):
        tests, first = {}, {}
        for i, item in enumerate(items):
            first.setdefault(item.path.name, i)
            tests[item.path.name] = tests.get(item.path.name, 0) + (
                item.get_closest_marker('serial') is None)
        items.sort(key=lambda item: (-MODULE_SECONDS.get(item.path.name, 0),
                                     -tests[item.path.name], first[item.path.name]))


@pytest.fixture(scope='module')
def spare_domain_id():
    """Yield a ROS_DOMAIN_ID (1..100) of this run's own, for a test's second graph.

    It is locked as scripts/test.sh locks the run's ids (a file under
    ``$TMPDIR/gripper_ros_domains.<uid>``), so no concurrent run on this machine takes it.
    """
    taken = [int(d) for d in os.environ.get('GRIPPER_ROS_WORKER_DOMAINS', '').split()]
    try:
        candidate, lock = _lock_free_domain(taken + [int(os.environ['ROS_DOMAIN_ID'])])
    except RuntimeError:
        pytest.fail('no free ROS_DOMAIN_ID in 1..100 for a second graph')
    try:
        yield candidate
    finally:
        lock.close()
