"""Stopping the gripper as a user does: Ctrl-C (SIGINT) or SIGTERM, idle and holding.

Three ways to run it: ``grasp_demo --serve`` (the graph in one process, recording bags),
``gripper_graph`` (the graph in one process, as the launch file starts it by default) and one
process per node, started with the arguments ``launch_ros`` gives them (``--ros-args -r __ns:=/NS
--params-file FILE``). Each process must exit 0 (within its own stop bound, past which it ends with
1: ``gripper_ros.nodes.process``), print no traceback and nothing at FATAL or ERROR, and leave
every bag it wrote closed (metadata.yaml written, nothing truncated). A second signal while
closing, and a SIGINT that arrives at a process started with SIGINT ignored (a script's background
job), are covered too. Each scenario runs ``REPEATS`` times; run the module in a loop for more. And
a stop that cannot finish: a node whose destruction blocks in C with the GIL held (as rclpy's
``destroy_when_not_in_use`` was seen to spin) still ends each of them within its bound; those cases
run side by side, and beside the other worker's tests (their bound is far off). Each process's
stop bound scales with the machine's load (``process.load_bound_s``), so these run beside the
other workers' tests too, but for the six processes per node stopped at once (marked serial).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from gripper_interfaces.srv import Grasp, SetObject
from gripper_ros.nodes import LAUNCHED_MODULES
from gripper_ros.wire import (GRAPH_NOT_READY, NODE_PLANT, Outcome, SERVICE_GRASP,
                              SERVICE_SET_OBJECT)
from helpers import ProgressWatch
import pytest

STOP_CPU_S = 60.0
"""CPU a stopping process may use before it counts as hung (a stop costs well under a second;
its bags' last chunks and index a few more); one that uses none for a minute is hung too."""
START_TIMEOUT_S = 90.0
REPEATS = 1
MODULES = LAUNCHED_MODULES
ALARMING = ('Traceback', 'FATAL', 'ERROR', 'Fatal Python error', 'Exception')
HOLD_WIDTH_M, HOLD_MASS_KG = 0.1, 0.75    # Table V's widest object: the shortest approach


@dataclass
class Stopped:
    name: str
    returncode: int | None
    exit_s: float
    output: str = ''
    bags: list[Path] = field(default_factory=list)


def _python(module: str, *args: str, ignore_sigint: bool = False, **kw) -> subprocess.Popen:
    def ignore():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return subprocess.Popen([sys.executable, '-m', module, *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=os.environ.copy(), preexec_fn=ignore if ignore_sigint else None,
                            **kw)


def _hold(namespace: str) -> None:
    """Place Table V's widest object and grasp it over DDS, as grasp_client does: HOLDING.

    Asked again while refused as not ready (until the supervisor heard every peer), or
    unanswered (a request sent as the server was being discovered can be lost).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('shut_client', namespace=namespace, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        place = node.create_client(SetObject, SERVICE_SET_OBJECT)
        grasp = node.create_client(Grasp, SERVICE_GRASP)

        def call(client, request, timeout_s):
            future = client.call_async(request)
            executor.spin_until_future_complete(future, timeout_sec=timeout_s)
            if not future.done():
                client.remove_pending_request(future)
            return future.result() if future.done() else None

        deadline = time.monotonic() + START_TIMEOUT_S
        assert place.wait_for_service(timeout_sec=START_TIMEOUT_S) and \
            grasp.wait_for_service(timeout_sec=START_TIMEOUT_S), f'nothing serves /{namespace}'
        while True:
            placed = call(place, SetObject.Request(width_m=HOLD_WIDTH_M, open_fingers=True), 10.0)
            answer = call(grasp, Grasp.Request(width_m=HOLD_WIDTH_M, mass_kg=HOLD_MASS_KG), 60.0) \
                if placed is not None else None
            if (answer is not None and GRAPH_NOT_READY not in answer.message) or \
                    time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert answer is not None and answer.outcome == Outcome.HOLDING, (placed, answer)
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def _stop(procs: dict[str, subprocess.Popen], sig: signal.Signals | dict[str, signal.Signals],
          second_signal_after_s: float | None = None) -> list[Stopped]:
    """Signal every process at once (``sig``, or each its own); return how each ended, timed."""
    sigs = sig if isinstance(sig, dict) else dict.fromkeys(procs, sig)
    sent = time.monotonic()
    for name, proc in procs.items():
        proc.send_signal(sigs[name])
    if second_signal_after_s is not None:
        time.sleep(second_signal_after_s)
        for name, proc in procs.items():
            if proc.poll() is None:
                proc.send_signal(sigs[name])
    ended = {}
    watch = ProgressWatch([proc.pid for proc in procs.values()], STOP_CPU_S)
    while len(ended) < len(procs) and \
            not watch.hung([p.pid for n, p in procs.items() if n not in ended]):
        for name, proc in procs.items():
            if name not in ended and proc.poll() is not None:
                ended[name] = time.monotonic() - sent
        time.sleep(0.01)
    stopped = []
    for name, proc in procs.items():
        if name not in ended:
            proc.kill()
        out, _ = proc.communicate(timeout=30)
        stopped.append(Stopped(name, proc.returncode if name in ended else None,
                               ended.get(name, float('inf')), out))
    return stopped


def _assert_clean(stopped: list[Stopped]) -> None:
    for s in stopped:
        assert s.returncode == 0, f'{s.name}: exit {s.returncode} after {s.exit_s:.2f} s\n' \
            f'{s.output}'
        alarming = [w for w in ALARMING if w in s.output]
        assert not alarming, f'{s.name}: {alarming}\n{s.output}'


def _assert_bags_closed(output: Path, expected: int) -> None:
    from gripper_ros.bags.reader import read_bag
    bags = sorted(p for p in output.iterdir() if p.is_dir()) if output.exists() else []
    assert len(bags) == expected, bags
    for bag in bags:
        assert (bag / 'metadata.yaml').is_file(), bag
        read = read_bag(bag)
        assert not read.truncated and read.message_count > 0, bag


def _serve(namespace: str, output: Path, **kw) -> subprocess.Popen:
    proc = _python('gripper_ros.apps.grasp_demo', '--serve', '--namespace', namespace,
                   '--output', str(output), **kw)
    deadline = time.monotonic() + START_TIMEOUT_S
    for line in proc.stdout:
        if 'serving' in line or time.monotonic() > deadline:
            break
    assert proc.poll() is None, proc.stdout.read()
    return proc


def _one_process(tmp_path: Path, sig: signal.Signals, holding: bool, tag: str,
                 **kw) -> None:
    namespace = f'shut_one_{tag}'
    output = tmp_path / tag
    proc = _serve(namespace, output, **kw)
    if holding:
        _hold(namespace)
    _assert_clean(_stop({'grasp_demo': proc}, sig))
    _assert_bags_closed(output, 1 if holding else 0)


def _per_node(tmp_path: Path, sig: signal.Signals, tag: str) -> None:
    """Start the six nodes as launch_ros does (a params file, the namespace remapped); hold."""
    namespace = f'shut_nodes_{tag}'
    params = tmp_path / f'{tag}.yaml'
    params.write_text(f'{NODE_PLANT}:\n  ros__parameters:\n    time_mode: realtime\n')
    procs = {name: _python(f'gripper_ros.nodes.{module}', '--ros-args', '-r',
                           f'__ns:=/{namespace}', '--params-file', str(params))
             for name, module in MODULES.items()}
    try:
        _hold(namespace)
        stopped = _stop(procs, sig)
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
    _assert_clean(stopped)


SIGNALS = {'sigint': signal.SIGINT, 'sigterm': signal.SIGTERM}


@pytest.mark.parametrize('repeat', range(REPEATS))
@pytest.mark.parametrize('holding', [False, True], ids=['idle', 'holding'])
@pytest.mark.parametrize('sig', SIGNALS.values(), ids=SIGNALS.keys())
def test_grasp_demo_serve_stops_at_once_and_closes_its_bags(tmp_path, sig, holding, repeat):
    _one_process(tmp_path, sig, holding, f'{sig.name.lower()}_{int(holding)}_{repeat}')


# six processes stop at once: beside another worker's tests (load 6), the supervisor's
# destroy_node (rclpy's destroy_when_not_in_use) was seen to spin past its own stop bound
@pytest.mark.serial
@pytest.mark.parametrize('sig', SIGNALS.values(), ids=SIGNALS.keys())
def test_one_process_per_node_stops_at_once_while_holding(tmp_path, sig):
    """Idle, each node alone: test_node_executables (the same bound, every node, both signals)."""
    _per_node(tmp_path, sig, sig.name.lower())


def test_a_background_job_with_sigint_ignored_still_stops_on_sigint(tmp_path):
    """A script's ``grasp_demo --serve &`` starts with SIGINT ignored; SIGINT still stops it."""
    _one_process(tmp_path, signal.SIGINT, False, 'background', ignore_sigint=True)


def test_a_second_signal_while_closing_changes_nothing(tmp_path):
    """GNU ``timeout`` or Ctrl-C twice: the second signal neither aborts nor cuts a bag short."""
    namespace, output = 'shut_twice', tmp_path / 'twice'
    proc = _serve(namespace, output)
    _hold(namespace)
    stopped = _stop({'grasp_demo': proc}, signal.SIGTERM, second_signal_after_s=0.01)
    _assert_clean(stopped)
    _assert_bags_closed(output, 1)


def _graph_process(namespace: str) -> subprocess.Popen:
    """Start ``gripper_graph`` as the launch file does; return it once it serves."""
    proc = _python('gripper_ros.nodes.graph_process', '--ros-args', '-r', f'__ns:=/{namespace}')
    _wait_for_line(proc, 'serving')
    return proc


def _wait_for_line(proc: subprocess.Popen, word: str) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    for line in proc.stdout:
        if word in line or time.monotonic() > deadline:
            break
    assert proc.poll() is None, proc.stdout.read()


@pytest.mark.parametrize('sig', SIGNALS.values(), ids=SIGNALS.keys())
def test_gripper_graph_stops_at_once_while_holding(sig):
    namespace = f'shut_graph_{sig.name.lower()}'
    proc = _graph_process(namespace)
    try:
        _hold(namespace)
        stopped = _stop({'gripper_graph': proc}, sig)
    finally:
        if proc.poll() is None:
            proc.kill()
    _assert_clean(stopped)


GIL_HELD_FOR_S = 600
"""How long the stuck destruction would hold the GIL: far beyond any bound checked here."""
STUCK = (
    'import ctypes, importlib, sys\n'
    'from gripper_ros.nodes.grasp_action_node import GraspActionServer\n'
    'def stuck(self):\n'
    # a PyDLL call keeps the GIL for its whole duration (a CDLL call would release it)
    f'    ctypes.PyDLL(None).sleep({GIL_HELD_FOR_S})\n'
    'GraspActionServer.destroy_node = stuck\n'
    'sys.argv = sys.argv[1:]\n'
    'sys.exit(importlib.import_module(sys.argv[0]).main())\n')


GIL_HOWS = ('node_executable', 'gripper_graph', 'grasp_demo_serve')


def _stuck(how: str, sig: signal.Signals, output: Path) -> tuple[str, subprocess.Popen]:
    """Start ``how`` with grasp_action_server's destroy stuck; return its namespace and process."""
    namespace = f'shut_gil_{how}_{sig.name.lower()}'
    if how == 'node_executable':
        args = ['gripper_ros.nodes.grasp_action_node', '--ros-args', '-r', f'__ns:=/{namespace}']
    elif how == 'gripper_graph':
        args = ['gripper_ros.nodes.graph_process', '--ros-args', '-r', f'__ns:=/{namespace}']
    else:
        args = ['gripper_ros.apps.grasp_demo', '--serve', '--namespace', namespace,
                '--output', str(output)]
    return namespace, subprocess.Popen([sys.executable, '-c', STUCK, *args],
                                       stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True,
                                       env=os.environ.copy())


@pytest.fixture(scope='module')
def gil_held_stops(tmp_path_factory) -> dict[tuple[str, str], Stopped]:
    """Every stuck case at once: started side by side, all signalled once every one serves.

    Each waits out its own hard bound (seconds, doing nothing): side by side, the waits overlap.
    """
    procs = {}
    try:
        for sig in SIGNALS.values():
            for how in GIL_HOWS:
                procs[how, sig] = _stuck(how, sig, tmp_path_factory.mktemp(f'gil_{how}'))
        for (how, _sig), (namespace, proc) in procs.items():
            if how == 'node_executable':
                _wait_for_node(namespace, 'grasp_action_server', proc)
            else:
                _wait_for_line(proc, 'serving')
        stopped = _stop({f'{how}-{sig.name}': proc for (how, sig), (_, proc) in procs.items()},
                        {f'{how}-{sig.name}': sig for how, sig in procs})
        return {tuple(s.name.split('-')): s for s in stopped}
    finally:
        for _namespace, proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()


@pytest.mark.parametrize('how', GIL_HOWS)
@pytest.mark.parametrize('sig', SIGNALS.values(), ids=SIGNALS.keys())
def test_a_destroy_that_holds_the_gil_still_ends_the_process(gil_held_stops, sig, how):
    """grasp_action_server's destroy blocks in C holding the GIL: no Python timer can run.

    The C watchdog (``process.arm_hard_bound``) ends the process anyway: exit 1, after
    ``Timeout`` and every thread's stack (the stuck ``destroy_node`` among them) on stderr.
    The bound is a few seconds (more on a loaded machine: ``process.load_bound_s``); the
    watchdog's firing is its ``Timeout`` line, its stack and exit 1, and that the block did not
    end by itself is an exit before the block's 600 s would have.
    """
    import re

    from gripper_ros.nodes.process import CLEAN_UP_LIMIT_S, GIL_HELD_MARGIN_S
    stopped = gil_held_stops[how, sig.name]
    bound_s = CLEAN_UP_LIMIT_S + GIL_HELD_MARGIN_S
    assert stopped.returncode == 1, f'exit {stopped.returncode}\n{stopped.output}'
    said = re.search(r'Timeout \((\d+):(\d\d):(\d\d)(\.\d+)?\)!', stopped.output)
    assert said and 3600 * int(said[1]) + 60 * int(said[2]) + int(said[3]) >= int(bound_s), \
        stopped.output
    assert 'in stuck' in stopped.output, stopped.output
    assert stopped.exit_s < GIL_HELD_FOR_S, stopped.exit_s


def _wait_for_node(namespace: str, name: str, proc: subprocess.Popen) -> None:
    """Wait until discovery shows ``name`` in ``namespace`` (the node spins)."""
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context)
    try:
        probe = rclpy.create_node('shut_gil_probe', context=context)
        deadline = time.monotonic() + START_TIMEOUT_S
        while (name, f'/{namespace}') not in probe.get_node_names_and_namespaces():
            assert proc.poll() is None and time.monotonic() < deadline, proc.stdout.read()
            time.sleep(0.1)
        probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
