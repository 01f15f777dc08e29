"""grasp_demo --serve --foxglove, watched by Foxglove's own client library during a grasp.

The client is ``test/interop/live_client.mjs``: ``@foxglove/ws-protocol``'s FoxgloveClient over
``ws``, offering the subprotocols ``foxglove.sdk.v1`` and ``foxglove.websocket.v1`` as the
Foxglove app does (the SDK's server, ``rust/foxglove/src/websocket/handshake.rs`` in
foxglove/foxglove-sdk, accepts only the first); every schema parsed by ``@foxglove/rosmsg``,
every message decoded by ``@foxglove/rosmsg2-serialization`` (pinned in
test/interop/package-lock.json, installed by scripts/setup.sh). ``hostile_client.mjs`` sends
what a broken or malicious client might, and then stops reading (the SDK drops the oldest of a
slow client's messages: ``send_lossy.rs``).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import threading

from gripper_ros.core.config import load_config
from gripper_ros.core.description import finger_frames
from gripper_ros.nodes.object_marker import COLORS
from gripper_ros.wire import (DEFAULT_NAMESPACE, HoldState, LIVE_TOPICS, qualified,
                              TOPIC_GRIPPER_STATUS, TOPIC_JOINT_STATES, TOPIC_OBJECT_MARKER,
                              TOPIC_ROBOT_DESCRIPTION, TOPIC_TF, TOPIC_TF_STATIC)
import pytest
from test_foxglove_interop import _node_skip_reason, NPM_DIR

INTEROP = Path(__file__).resolve().parent / 'interop'
GRASP = (0.05, 1.69)                    # Table V's second object
URL = re.compile(r'Foxglove live view at (ws://\S+)')
SERVED = {qualified(DEFAULT_NAMESPACE, t): msgtype for t, msgtype in LIVE_TOPICS.items()}
STATE_PERIOD_NS = 10_000_000            # joint_states at state_rate_hz 100


def _lines_until(stream, pattern: re.Pattern, timeout_s: float, seen: list) -> re.Match:
    """Read ``stream`` line by line until ``pattern`` matches (or it ends, or time runs out)."""
    found: list = []

    def read():
        for line in stream:
            seen.append(line)
            match = pattern.search(line)
            if match:
                found.append(match)
                return
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout_s)
    assert found, f'no line matching {pattern.pattern!r}; read: {"".join(seen)[-2000:]}'
    return found[0]


def _script(name: str) -> str:
    """Copy an interop script beside the installed npm packages (node resolves them there)."""
    target = NPM_DIR / name
    staged = target.with_name(f'.{name}.{os.getpid()}')
    shutil.copyfile(INTEROP / name, staged)
    os.replace(staged, target)
    return str(target)


@pytest.fixture(scope='module')
def node() -> str:
    reason = _node_skip_reason()
    if reason:
        pytest.skip(reason)
    return shutil.which('node')


@pytest.fixture(scope='module')
def served():
    """``grasp_demo --serve --foxglove 0``: (process, url, its output so far)."""
    seen: list = []
    proc = subprocess.Popen(
        [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve', '--no-record',
         '--foxglove', '0', '--ros-args', '--log-level', 'warn'],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        url = _lines_until(proc.stdout, URL, 120.0, seen).group(1)
        _lines_until(proc.stdout, re.compile(r'grasp_demo: serving'), 60.0, seen)
        yield proc, url, seen
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(30.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class _Published:
    """The joint_states stamps the graph publishes, as a ROS subscriber in this process gets."""

    def __init__(self):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from gripper_ros.nodes.loop_io import joint_state_template
        from gripper_ros.nodes.qos import GRAPH_QOS
        from sensor_msgs.msg import JointState
        self.stamps: list[int] = []
        self._context = Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node('live_view_test_listener', context=self._context)
        layout = joint_state_template('finger_joint', 'gripper_base')

        def on_joint_states(data: bytes) -> None:
            sec, nanosec = layout.unpack(data)[:2]
            self.stamps.append(sec * 1_000_000_000 + nanosec)
        self._node.create_subscription(JointState, qualified(DEFAULT_NAMESPACE,
                                                             TOPIC_JOINT_STATES),
                                       on_joint_states, GRAPH_QOS, raw=True)
        self._stop = threading.Event()
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self._executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy
        self._stop.set()
        self._thread.join(10.0)
        self._executor.shutdown()
        self._node.destroy_node()
        rclpy.try_shutdown(context=self._context)


def _assert_every_published_one_arrived(received: list[int], published: list[int]) -> None:
    """Hold what a Foxglove client got to what the graph published, over both their spans."""
    first, last = max(received[0], published[0]), min(received[-1], published[-1])
    assert last - first > 100 * STATE_PERIOD_NS, (first, last)
    assert [s for s in received if first <= s <= last] == \
        [s for s in published if first <= s <= last]


def _grasp(width_m: float, mass_kg: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client', '--width',
                           str(width_m), '--mass', str(mass_kg)],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300)


def _watch(node: str, url: str, during, *clients: tuple[str, ...]) -> list[dict]:
    """Run a live client on ``url`` per argument list of ``clients`` while ``during()`` runs.

    Return their reports, in order.
    """
    procs = [subprocess.Popen([node, _script('live_client.mjs'), url, *extra],
                              stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for extra in clients]
    reports = []
    try:
        for proc in procs:
            _lines_until(proc.stdout, re.compile(r'^subscribed \d+'), 60.0, [])
        during()
    finally:
        for proc in procs:
            proc.send_signal(signal.SIGTERM)
        for proc in procs:
            out, err = proc.communicate(timeout=60)
            assert proc.returncode == 0, err
            reports.append(json.loads(out.strip().splitlines()[-1]))
    return reports


JOINT_STATES_ONLY = ('--topics', qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES))
"""A client of joint_states alone: 100 Hz, which any machine keeps up with. (A client of every
topic takes the loop's 10 kHz topics too; one that cannot keep up loses its oldest messages, as
the SDK decides, joint_states among them.)"""


@pytest.fixture(scope='module')
def watched(node, served):
    """Return what a client of every topic got during a grasp, the answer, and the stamps.

    The stamps: of the joint_states a client of joint_states alone got, and of those the graph
    published meanwhile.
    """
    proc, url, _ = served
    answers: list = []
    published = _Published()
    try:
        every, joints = _watch(node, url, lambda: answers.append(_grasp(*GRASP)), (),
                               JOINT_STATES_ONLY)
    finally:
        published.close()
    assert proc.poll() is None
    received = joints['topics'][qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES)]
    return every, answers[0], ([s for s, _ in received['joint_states']], published.stamps)


def test_the_server_speaks_the_sdk_protocol_and_takes_nothing_from_a_client(watched):
    report, answer, _ = watched
    assert answer.returncode == 0, answer.stdout + answer.stderr
    assert report['protocol'] == 'foxglove.sdk.v1'
    assert report['server'] == {'name': 'gripper_ros', 'capabilities': []}
    assert report['errors'] == []


def test_every_live_topic_is_advertised_with_its_ros2_schema_and_parses(watched):
    topics = watched[0]['topics']
    assert {t: e['schema'] for t, e in topics.items()} == SERVED
    assert {t: (e['schema_encoding'], e['message_encoding']) for t, e in topics.items()} == \
        dict.fromkeys(SERVED, ('ros2msg', 'cdr'))
    assert {t: e['schema_error'] for t, e in topics.items()} == dict.fromkeys(SERVED, '')
    assert {t: (e['failed'], e['error']) for t, e in topics.items()} == \
        dict.fromkeys(SERVED, (0, ''))
    assert all(e['decoded'] == e['received'] for e in topics.values())


def test_joint_states_arrive_one_by_one_and_show_the_finger_closing(watched):
    """Every joint_states the graph published during the grasp reaches a client: none dropped.

    At 100 Hz of simulated time, the same stamps as a ROS subscriber of the topic gets. Its
    log time is its stamp, as in a bag; the finger runs from open to the object's face.
    """
    report, _, (alone, published) = watched
    assert len(alone) >= 200                               # the grasp takes about 3 s
    _assert_every_published_one_arrived(alone, published)
    entry = report['topics'][qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES)]
    stamps = [s for s, _ in entry['joint_states']]          # the client of every topic
    positions = [p for _, p in entry['joint_states']]
    assert entry['last_log_ns'] == stamps[-1]
    travel = load_config(None).plant.max_travel_m
    assert positions[0] < 0.01
    assert math.isclose(positions[-1], travel - GRASP[0], abs_tol=1e-3)
    assert all(b >= a - 1e-6 for a, b in zip(positions, positions[1:]))   # closing only


def test_latched_description_and_moving_tf_reach_a_late_subscriber(watched):
    topics = watched[0]['topics']
    description = topics[qualified(DEFAULT_NAMESPACE, TOPIC_ROBOT_DESCRIPTION)]
    assert description['received'] >= 1
    assert description['first']['data'].startswith('<?xml')
    static = topics[TOPIC_TF_STATIC]['first']['transforms'][0]
    assert (static['header']['frame_id'], static['child_frame_id']) == ('gripper_base',
                                                                        'fixed_finger')
    frames = finger_frames(load_config(None))
    moving = topics[TOPIC_TF]['last']['transforms'][0]
    assert moving['child_frame_id'] == 'moving_finger'
    x = moving['transform']['translation']['x']
    assert math.isclose(x, frames.moving_finger_xyz(frames.travel_m - GRASP[0])[0],
                        abs_tol=1e-3)


def test_the_object_marker_is_the_object_between_the_pads(watched):
    marker = watched[0]['topics'][qualified(DEFAULT_NAMESPACE, TOPIC_OBJECT_MARKER)]['last']
    config = load_config(None)
    fixed_x = finger_frames(config).fixed_finger_xyz[0]
    assert marker['header']['frame_id'] == 'gripper_base'
    assert (marker['ns'], marker['id'], marker['type'], marker['action']) == ('object', 0, 1, 0)
    assert math.isclose(marker['scale']['x'], GRASP[0], rel_tol=1e-6)
    assert math.isclose(marker['pose']['position']['x'], fixed_x - GRASP[0] / 2, abs_tol=1e-9)
    color = marker['color']
    assert (color['r'], color['g'], color['b'], color['a']) == pytest.approx(
        COLORS[HoldState.RESTING])                          # held, not lifted


def test_gripper_status_says_how_the_grasp_ended(watched):
    status = watched[0]['topics'][qualified(DEFAULT_NAMESPACE, TOPIC_GRIPPER_STATUS)]['last']
    values = {kv['key']: kv['value'] for kv in status['values']}
    assert values['object_detected'] == 'true'


def test_a_hostile_then_stalled_client_leaves_the_graph_and_other_clients_alone(node, served):
    """Garbage, unknown channels, publishing, parameters, services, assets; then no reading.

    The server answers each with a status (foxglove-sdk ``connected_client.rs``); the graph
    grasps again, and another client gets every joint_states of that grasp meanwhile.
    """
    proc, url, _ = served
    hostile = subprocess.Popen([node, _script('hostile_client.mjs'), url],
                               stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        stalled = _lines_until(hostile.stdout, re.compile(r'^stalled (\d+)'), 60.0, [])
        assert int(stalled.group(1)) == len(SERVED)
        answers: list = []

        def release_and_grasp():
            answers.append(subprocess.run(
                [sys.executable, '-m', 'gripper_ros.apps.grasp_client', '--release'],
                stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300))
            answers.append(_grasp(0.1, 0.75))
        published = _Published()
        try:
            report, = _watch(node, url, release_and_grasp, JOINT_STATES_ONLY)
        finally:
            published.close()
    finally:
        hostile.send_signal(signal.SIGTERM)
        out, _ = hostile.communicate(timeout=60)
    statuses = json.loads(out.strip().splitlines()[-1])
    for refusal in ('Invalid message', 'Unknown channel ID: 999999',
                    'Server does not support clientPublish capability',
                    'Server does not support parameters capability',
                    'Server does not support assets capability'):
        assert any(s.startswith(refusal) for s in statuses), (refusal, statuses)
    assert [a.returncode for a in answers] == [0, 0], [a.stdout + a.stderr for a in answers]
    assert proc.poll() is None
    stamps = [s for s, _ in report['topics'][qualified(DEFAULT_NAMESPACE,
                                                       TOPIC_JOINT_STATES)]['joint_states']]
    assert len(stamps) >= 200
    _assert_every_published_one_arrived(stamps, published.stamps)


@pytest.mark.parametrize('args,words', [
    (['--foxglove', '70000', '--serve'], '--foxglove: a port is 0-65535, got 70000'),
    (['--foxglove'], '--foxglove shows the graph as it runs: use it with --serve or '
                     '--time-mode realtime'),
])
def test_grasp_demo_refuses_a_bad_live_view_in_one_line(args, words):
    done = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', *args],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stdout, done.stderr) == (2, '', f'grasp_demo: {words}\n')


def test_a_taken_port_is_one_line_and_the_graph_stops(served):
    """A second live view on the port of the first: refused in one line, exit 2, no traceback."""
    _, url, _ = served
    port = url.rsplit(':', 1)[1]
    done = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve',
                           '--no-record', '--namespace', 'second_view', '--foxglove', port],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stdout + done.stderr
    # the nodes' own log lines may come on either side of it, as their threads run (on a loaded
    # machine a realtime plant's warning that it cannot keep pace among them)
    ours = [line for line in done.stderr.splitlines()
            if not re.match(r'\[(INFO|WARN)\] \[[\d.]+\] \[second_view\.', line)]
    assert ours == [
        f'grasp_demo: the Foxglove live view cannot listen on 127.0.0.1:{port}: Failed to bind '
        'port: Address already in use (os error 98)'], done.stderr
    assert 'Traceback' not in done.stderr


def test_the_launch_file_refuses_the_live_view_beside_one_process_per_node():
    if shutil.which('ros2') is None:
        if os.environ.get('ROS2_OVERLAY'):
            raise AssertionError('ROS2_OVERLAY is set but ros2 is not on the PATH')
        pytest.skip('no ros2 command (bash scripts/setup.sh --ros2-cli builds it)')
    done = subprocess.run(['ros2', 'launch', 'gripper_ros', 'gripper.launch.py',
                           'foxglove:=true', 'per_node:=true'], stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert 'foxglove:=true serves the graph from its one process: it does not go with ' \
           'per_node:=true' in done.stdout + done.stderr
