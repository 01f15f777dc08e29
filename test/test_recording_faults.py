"""A recording that fails never stops the gripper, and bag names never collide.

A full disk is an ENOSPC from the bag file's ``write``, injected where the recorder opens it
(the one call a full disk makes fail first). Known answers: the error names the bag and the
number of messages a reader gets back from it, and that number is what ``read_bag`` reads;
``grasp_demo`` stops the grasp and exits 2 at once with that one line; a serving graph reports
it in the grasp's answer and serves and records the next grasp.
"""
from concurrent.futures import ThreadPoolExecutor
import errno
from pathlib import Path
import re
import signal
import subprocess
import sys
import threading
import time

from gripper_ros.bags import recorder as recorder_module
from gripper_ros.bags.reader import read_bag
from gripper_ros.bags.recorder import BagRecorder, unique_bag_dir
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.recording import graph_tap, recorded_grasp, ServeRecorder
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (DESCRIPTION_TOPICS, LATCHED_DESCRIPTION_TOPICS, Outcome, qualified,
                              TOPIC_JOINT_STATES, TOPIC_TF, TOPIC_TICK)
from helpers import tf_as_robot_state_publisher, wait_for_recording
import pytest

FULL_AFTER_BYTES = 100_000         # a few chunks into the first grasp's bag (about 20 kB each)

_FULL_DISK = """
import builtins, errno, sys
import gripper_ros.bags.recorder as recorder
limit = int(sys.argv[1])
real_open = builtins.open

class Full:
    def __init__(self, f):
        self.f, self.n = f, 0
    def write(self, data):
        if self.n + len(data) > limit:
            raise OSError(errno.ENOSPC, 'No space left on device')
        self.n += len(data)
        return self.f.write(data)
    def __getattr__(self, name):
        return getattr(self.f, name)

def full_open(path, mode='r', *args, **kwargs):
    f = real_open(path, mode, *args, **kwargs)
    return Full(f) if str(path).endswith('.mcap') and 'w' in mode else f

recorder.open = full_open
from gripper_ros.apps.grasp_demo import main
sys.exit(main(sys.argv[2:]))
"""


class _FullFile:
    """A bag file on a disk with ``limit`` bytes free."""

    def __init__(self, f, limit):
        self.f, self.n, self.limit = f, 0, limit

    def write(self, data):
        if self.n + len(data) > self.limit:
            raise OSError(errno.ENOSPC, 'No space left on device')
        self.n += len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


def _readable_count(message: str) -> int:
    return int(re.search(r'the bag holds (\d+) messages, readable up to there', message)[1])


def test_grasp_demo_on_a_full_disk_stops_at_once_with_one_line_and_a_readable_bag(tmp_path):
    t0 = time.monotonic()
    result = subprocess.run(
        [sys.executable, '-c', _FULL_DISK, str(FULL_AFTER_BYTES), '--output', str(tmp_path),
         '--no-plot'], capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert result.returncode == 2, result.stdout + result.stderr
    assert 'Traceback' not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith('grasp_demo:')]
    assert len(errors) == 1, result.stderr
    line = errors[0]
    assert 'No space left on device' in line
    bags = sorted(p for p in tmp_path.iterdir() if p.is_dir())
    assert len(bags) == 1, 'the first grasp only: the demo stops there'
    assert str(bags[0]) in line
    bag = read_bag(bags[0])
    assert bag.message_count == _readable_count(line) > 0
    assert '[2/3]' not in result.stdout
    assert time.monotonic() - t0 < 120


@pytest.fixture
def serving(tmp_path):
    graph = GripperGraph.in_own_context(GraphOptions(namespace='serve_full_disk',
                                                     time_mode='fast'))
    recorder = ServeRecorder(graph, tmp_path)
    try:
        yield graph, recorder
    finally:
        graph.close()


def test_serve_reports_a_full_disk_in_the_answer_and_serves_and_records_the_next_grasp(
        serving, tmp_path, monkeypatch):
    graph, recorder = serving
    real_open = open
    monkeypatch.setattr(recorder_module, 'open', lambda path, mode='r': _FullFile(
        real_open(path, mode), FULL_AFTER_BYTES), raising=False)
    assert graph.set_object(0.01).success
    first = graph.grasp(0.01, 1.27)
    assert first.outcome == Outcome.HOLDING, 'the grasp itself goes on'
    assert 'recording stopped' in first.message and 'No space left on device' in first.message
    assert recorder.errors and recorder.errors[0] in first.message
    bag = read_bag(recorder.bags[0])
    assert bag.message_count == _readable_count(recorder.errors[0]) > 0

    monkeypatch.setattr(recorder_module, 'open', real_open, raising=False)   # space again
    graph.release()
    assert graph.set_object(0.05).success
    second = graph.grasp(0.05, 1.69)
    assert second.outcome == Outcome.HOLDING and 'recording' not in second.message
    assert graph.wait_still()
    assert wait_until(lambda: len(recorder.bags) >= 2 and not recorder.recording, 30.0)
    assert len(recorder.bags) == 2                   # one per grasp (a release is not one)
    assert not read_bag(recorder.bags[-1]).truncated


def test_a_taken_bag_folder_name_is_never_reused(tmp_path):
    stem = 'grasp_20261201_120000_id1'
    first = unique_bag_dir(tmp_path, stem)
    (tmp_path / f'{first.name}_1').mkdir()           # someone else's, by chance
    second = unique_bag_dir(tmp_path, stem)
    assert len({first, second, tmp_path / f'{first.name}_1'}) == 3
    assert first.is_dir() and second.is_dir()


_NAMER = """
import sys
from pathlib import Path
from gripper_ros.bags.recorder import unique_bag_dir
for _ in range(int(sys.argv[2])):
    print(unique_bag_dir(Path(sys.argv[1]), 'grasp_20261201_120000_id1'))
"""


def test_two_servers_naming_bags_in_one_folder_in_the_same_second_never_collide(tmp_path):
    """Four processes, and threads within one, each take 50 names for the same stem at once."""
    procs = [subprocess.Popen([sys.executable, '-c', _NAMER, str(tmp_path), '50'],
                              stdout=subprocess.PIPE, text=True) for _ in range(4)]
    with ThreadPoolExecutor(4) as pool:
        here = list(pool.map(lambda _: str(unique_bag_dir(tmp_path, 'grasp_20261201_120000_id1')),
                             range(50)))
    names = here + [line for p in procs for line in p.communicate(timeout=60)[0].split()]
    assert all(p.returncode == 0 for p in procs)
    assert len(names) == 250 == len(set(names))
    assert len([p for p in Path(tmp_path).iterdir() if p.is_dir()]) == 250


@pytest.fixture
def graph(tmp_path):
    graph = GripperGraph.in_own_context(GraphOptions(namespace='late_failure', time_mode='fast'))
    try:
        yield graph
    finally:
        graph.close()


def test_a_writer_failing_after_the_last_tick_ends_the_recording_with_one_line(
        graph, tmp_path, monkeypatch):
    """The bag's writer fails as the bag is finished: the one line, the answer stands.

    The bag reads back up to the failure, as many messages as the line says.
    """
    from gripper_ros.bags.mcap_file import McapFile

    def full(self):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(McapFile, 'finish', full)
    run = recorded_grasp(graph, tmp_path / 'late', 0.05, 1.69)
    assert run.response.outcome == Outcome.HOLDING
    assert run.recording_error.startswith(f'recording stopped: {tmp_path / "late"}: '
                                          'No space left on device')
    assert read_bag(tmp_path / 'late').message_count == _readable_count(run.recording_error) > 0


def test_the_tap_adds_no_subscription_and_counts_equal_published(graph, tmp_path):
    """Recording taps the graph's publishers: no DDS reader of its own, every message seen."""
    run = recorded_grasp(graph, tmp_path / 'tapped', 0.1, 0.75)
    assert not run.recording_error
    described = {qualified(graph.namespace, t) for t in DESCRIPTION_TOPICS}
    assert {t: n for t, n in run.recorded.items() if t not in described} == run.published
    assert all(n > 0 for n in run.published.values())
    # the latched description once, at the start; transforms at 20 Hz of joint states
    assert [run.recorded[qualified(graph.namespace, t)] for t in LATCHED_DESCRIPTION_TOPICS] \
        == [1, 1]
    tf, expected = tf_as_robot_state_publisher(read_bag(tmp_path / 'tapped'), graph.namespace)
    assert tf == expected and len(tf) == run.recorded[TOPIC_TF] >= \
        run.published[qualified(graph.namespace, TOPIC_JOINT_STATES)] // 5
    assert read_bag(tmp_path / 'tapped').counts() == run.recorded
    tap = graph.recording_tap
    assert not [s for node in graph.nodes for s in node.subscriptions
                if s.topic_name in tap.topics and node is graph.client_node]
    publishers = [p for node in graph.nodes for p in getattr(node, 'graph_publishers', ())
                  if p.topic_name in tap.topics]
    assert {p.topic_name for p in publishers} == set(tap.topics)   # every recorded topic
    assert all(p.taps == (tap._on_message,) for p in publishers)
    tap.close()
    assert all(p.taps == () for p in publishers)


def test_a_second_signal_while_closing_leaves_a_complete_bag_and_no_traceback(tmp_path):
    proc = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--width',
                             '0.01', '--mass', '1.27', '--time-mode', 'realtime', '--output',
                             str(tmp_path), '--no-plot', '--namespace', 'second_signal'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        if 'grasping width' in line:
            break
    wait_for_recording(tmp_path)            # recording: the grasp takes 3.8 s, paced
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)                        # while the bag is being closed
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)   # beyond its own stop bound
    assert proc.returncode == 130, out
    assert 'Traceback' not in out
    bags = sorted(tmp_path.glob('grasp_*'))
    assert len(bags) == 1 and (bags[0] / 'metadata.yaml').is_file()
    bag = read_bag(bags[0])
    assert not bag.truncated and bag.message_count > 0


class _StalledSide:
    """A stage's lockstep side whose next reference stalls the graph's executor until released.

    The tick and its reference have been published (and seen by the tap) when the stage takes
    the reference; its command comes only after :attr:`release`. A starved process looks so.
    """

    def __init__(self, side):
        self._side = side
        self.stalled = threading.Event()
        self.release = threading.Event()

    def take_reference(self, data):
        self.stalled.set()
        self.release.wait()
        return self._side.take_reference(data)

    def __getattr__(self, name):
        return getattr(self._side, name)


def test_a_realtime_recording_stopped_while_the_executor_stalls_mid_tick_says_it_is_incomplete(
        tmp_path):
    """Stopped while its executor is stalled between a tick and its command, a bag says so.

    ``GraphTap.stop`` waits for the command of the bag's last tick (lockstep: the stage answers
    each tick); one that does not come within the bound is named in the tap's error, which
    ``recorded_grasp`` hands on and ``grasp_demo`` exits 2 with. Known answer: the bag read
    back ends with that tick and holds no command for it.
    """
    graph = GripperGraph.in_own_context(GraphOptions(namespace='stalled', time_mode='realtime'))
    stall = _StalledSide(graph.force.side)
    try:
        assert graph.set_object(graph.simulated_width_m(0.05, None), 0.0, 0.0).success
        assert graph.grasp(0.05, 1.69).outcome == Outcome.HOLDING   # the force stage answers
        tap = graph_tap(graph)
        bag_dir = tmp_path / 'stalled'
        recorder = BagRecorder(graph.client_node, bag_dir, tap.topics, subscribe=False,
                               time_source=lambda: graph.sim_time_ns)
        tap.start(recorder, 'next_tick')
        tick = qualified(graph.namespace, TOPIC_TICK)
        assert wait_until(lambda: recorder.counts.get(tick, 0) >= 10, timeout_s=60)
        graph.force.side = stall
        assert stall.stalled.wait(timeout=60)
        assert tap.stop(timeout_s=0.2) is recorder
        error = tap.error
        stall.release.set()
        recorder.close()
        series = load_grasp_series(bag_dir)
    finally:
        stall.release.set()
        graph.close()
    last_tick_ns = int(series.ticks['stamp_ns'][-1])
    assert re.fullmatch(f'recording incomplete: {re.escape(str(bag_dir))}: the motor command of '
                        rf'its last tick \({last_tick_ns} ns\) did not come within [0-9.]+ s',
                        error), error
    assert last_tick_ns not in set(series.commands['stamp_ns'].tolist())
    assert set(series.ticks['stamp_ns'][:-1].tolist()) <= \
        set(series.commands['stamp_ns'].tolist())        # whole up to the stalled tick
