"""Stopping the gripper as a user does: Ctrl-C (SIGINT) or SIGTERM, idle and holding.

Two ways to run it: ``grasp_demo --serve`` (the graph in one process, recording bags) and one
process per node, started with the arguments ``launch_ros`` gives them (``--ros-args -r
__ns:=/NS --params-file FILE``). Each process must be gone within ``EXIT_WITHIN_S`` of the
signal, exit 0, print no traceback and nothing at FATAL or ERROR, and leave every bag it
wrote closed (metadata.yaml written, nothing truncated). A second signal while closing, and
a SIGINT that arrives at a process started with SIGINT ignored (a script's background job),
are covered too. Each scenario runs ``REPEATS`` times; run the module in a loop for more.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from gripper_ros.nodes import LAUNCHED_MODULES
from gripper_ros.wire import NODE_PLANT
import pytest

EXIT_WITHIN_S = 5.0
"""'At once', with room for a loaded machine: a hung process is waited for 10 s more."""
START_TIMEOUT_S = 90.0
REPEATS = 1
MODULES = LAUNCHED_MODULES
ALARMING = ('Traceback', 'FATAL', 'ERROR', 'Fatal Python error', 'Exception')
HOLD_OBJECT = ('--width', '0.1', '--mass', '0.75')   # Table V's widest: the shortest approach


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


def _client(namespace: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client',
                           '--namespace', namespace, '--wait', '60', *args],
                          capture_output=True, text=True, timeout=180, env=os.environ.copy())


def _ask(namespace: str, *args: str) -> subprocess.CompletedProcess:
    """Call grasp_client until the graph is up (refused until the supervisor heard every peer)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        result = _client(namespace, *args)
        starting = 'graph not ready' in result.stdout or 'no measurement' in result.stdout
        if not starting or time.monotonic() > deadline:
            return result
        time.sleep(0.5)


def _hold(namespace: str) -> None:
    result = _ask(namespace, *HOLD_OBJECT)
    assert 'outcome: HOLDING' in result.stdout, result.stdout + result.stderr


def _stop(procs: dict[str, subprocess.Popen], sig: signal.Signals,
          second_signal_after_s: float | None = None) -> list[Stopped]:
    """Signal every process at once; return how each ended, timed from the signal."""
    sent = time.monotonic()
    for proc in procs.values():
        proc.send_signal(sig)
    if second_signal_after_s is not None:
        time.sleep(second_signal_after_s)
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(sig)
    ended = {}
    while len(ended) < len(procs) and time.monotonic() - sent < EXIT_WITHIN_S + 10.0:
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
        assert s.returncode == 0 and s.exit_s <= EXIT_WITHIN_S, \
            f'{s.name}: exit {s.returncode} after {s.exit_s:.2f} s\n{s.output}'
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


def _per_node(tmp_path: Path, sig: signal.Signals, holding: bool, tag: str) -> None:
    """Start the six nodes as launch_ros does (a params file, the namespace remapped)."""
    namespace = f'shut_nodes_{tag}'
    params = tmp_path / f'{tag}.yaml'
    params.write_text(f'{NODE_PLANT}:\n  ros__parameters:\n    time_mode: realtime\n')
    procs = {name: _python(f'gripper_ros.nodes.{module}', '--ros-args', '-r',
                           f'__ns:=/{namespace}', '--params-file', str(params))
             for name, module in MODULES.items()}
    try:
        if holding:
            _hold(namespace)
        else:                            # every node up: the graph answers a release
            result = _ask(namespace, '--release')
            assert result.returncode == 0, result.stdout + result.stderr
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


@pytest.mark.parametrize('sig', SIGNALS.values(), ids=SIGNALS.keys())
def test_one_process_per_node_stops_at_once_while_holding(tmp_path, sig):
    """Idle, each node alone: test_node_executables (the same bound, every node, both signals)."""
    _per_node(tmp_path, sig, True, sig.name.lower())


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
