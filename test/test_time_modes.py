"""Simulated hardware in both time modes: it streams, holds, pauses and steps as it says.

Over the real node graph (DDS, services), watched as a ROS system watches a gripper: the raw
``joint_states`` and ``/clock`` streams. Known answers: the state streams are stamped every
1 / state_rate_hz of simulated time; realtime never runs ahead of the wall clock; idle fingers
at rest under position control do not move; after HOLDING the force loop keeps the grip at its
setpoint (within the settle band) for a further second; a paused simulation's time stands
still and a step of n ticks advances it by exactly n ticks.
"""
import threading
import time

from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.loop_io import clock_template, joint_state_template
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.wire import Outcome, qualified, TOPIC_CLOCK, TOPIC_JOINT_STATES
import pytest
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

CONFIG = load_config()
STATE_PERIOD_NS = 10_000_000                # state_rate_hz 100
WIDTH, MASS = 0.14, 1.0                     # 10 mm of travel: a short grasp
DELIVERY_JITTER_PERIODS = 5
"""State periods a sample may reach this test late on a loaded machine (a plant running at
twice the wall clock gains 10 of them over the 20 samples looked at)."""


class Streams:
    """Every joint_states and /clock sample: (wall s, simulated ns, position m, effort N)."""

    def __init__(self, graph):
        self.joint: list = []
        self.clock: list = []
        self._lock = threading.Lock()
        self._joint_layout = joint_state_template(graph.plant.joint_name, graph.plant.frame_id)
        self._clock_layout = clock_template()
        node = graph.client_node
        self._subs = [
            node.create_subscription(JointState, qualified(graph.namespace, TOPIC_JOINT_STATES),
                                     self._on_joint, GRAPH_QOS, raw=True),
            node.create_subscription(Clock, TOPIC_CLOCK, self._on_clock, GRAPH_QOS, raw=True)]
        deadline = time.monotonic() + 10.0
        while any(s.get_publisher_count() == 0 for s in self._subs):
            assert time.monotonic() < deadline, 'the state streams were not discovered'
            time.sleep(0.01)

    def _on_joint(self, data):
        sec, nanosec, position, _velocity, effort = self._joint_layout.unpack(data)
        with self._lock:
            self.joint.append((time.monotonic(), sec * 10 ** 9 + nanosec, position, effort))

    def _on_clock(self, data):
        sec, nanosec = self._clock_layout.unpack(data)
        with self._lock:
            self.clock.append((time.monotonic(), sec * 10 ** 9 + nanosec))

    def since(self, wall_s):
        with self._lock:
            return [j for j in self.joint if j[0] >= wall_s]

    def clock_since(self, wall_s):
        with self._lock:
            return [c for c in self.clock if c[0] >= wall_s]


def _wait_for(predicate, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline
        time.sleep(0.01)


def _stamps_every_state_period(samples):
    stamps = [s[1] for s in samples]
    assert len(stamps) >= 3
    gaps = {b - a for a, b in zip(stamps, stamps[1:])}
    assert gaps == {STATE_PERIOD_NS}, sorted(gaps)[:5]


def _graph_with_streams(time_mode: str, namespace: str = ''):
    """Yield a graph in ``time_mode`` (a namespace of its own) and its watched streams."""
    graph = GripperGraph.in_own_context(GraphOptions(
        time_mode=time_mode, namespace=namespace or f'time_modes_{time_mode}'))
    try:
        yield graph, Streams(graph)
    finally:
        graph.close()


@pytest.fixture
def realtime():
    yield from _graph_with_streams('realtime')


@pytest.fixture
def fast():
    yield from _graph_with_streams('fast')


@pytest.fixture(scope='module')
def fast_refusing():
    """One graph in fast time for every refused step: a refusal changes nothing."""
    yield from _graph_with_streams('fast', 'time_modes_refused_steps')


def test_realtime_streams_idle_and_after_holding_never_ahead_of_the_wall_clock(realtime):
    graph, streams = realtime
    start = time.monotonic()
    _wait_for(lambda: len(streams.since(start)) >= 20)
    idle = streams.since(start)
    _stamps_every_state_period(idle)
    positions = {s[2] for s in idle}
    assert max(positions) - min(positions) < 1e-9          # idle fingers hold still
    assert len(streams.clock_since(start)) >= 10
    # the plant is paced: simulated time never gains on the wall clock (beyond what a late
    # delivery of the first sample to this subscriber can take from the wall interval)
    (w0, t0, *_), (w1, t1, *_) = idle[0], idle[-1]
    assert (t1 - t0) * 1e-9 <= (w1 - w0) + DELIVERY_JITTER_PERIODS * STATE_PERIOD_NS * 1e-9

    assert graph.set_object(WIDTH).success
    response = graph.grasp(WIDTH, MASS)
    assert response.outcome == Outcome.HOLDING, response.message
    held = time.monotonic()
    _wait_for(lambda: len(streams.since(held)) >= 30)      # 0.3 s of simulated time on
    after = streams.since(held)
    _stamps_every_state_period(after)
    band = CONFIG.supervisor.force_settle_band_fraction * response.force_setpoint_n
    assert all(abs(s[3] - response.force_setpoint_n) <= band for s in after)
    assert len(streams.clock_since(held)) >= 20
    assert graph.supervisor.logic.outcome is Outcome.HOLDING


def test_fast_mode_holds_the_grip_at_its_setpoint_for_a_further_second(fast):
    graph, streams = fast
    assert graph.set_object(WIDTH).success
    response = graph.grasp(WIDTH, MASS)
    assert response.outcome == Outcome.HOLDING, response.message
    graph.wait_still()
    t_answer_ns = graph.sim_time_ns
    mark = time.monotonic()
    stepped = graph.step(duration_s=1.0)
    assert stepped.success, stepped.message
    assert stepped.time_s == pytest.approx(t_answer_ns * 1e-9 + 1.0, abs=1e-9)
    _wait_for(lambda: streams.since(mark) and streams.since(mark)[-1][1] >= t_answer_ns + 10 ** 9
              - STATE_PERIOD_NS)
    hold = streams.since(mark)
    assert len(hold) == 100                                # 1 s at 100 Hz of simulated time
    _stamps_every_state_period(hold)
    band = CONFIG.supervisor.force_settle_band_fraction * response.force_setpoint_n
    worst = max(abs(s[3] - response.force_setpoint_n) for s in hold)
    assert worst <= band, worst
    assert graph.supervisor.logic.outcome is Outcome.HOLDING


def test_fast_mode_idle_fingers_hold_and_time_waits_for_a_request(fast):
    graph, streams = fast
    assert graph.set_object(WIDTH).success
    graph.wait_still()
    t0 = graph.sim_time_ns
    time.sleep(0.3)
    assert graph.sim_time_ns == t0                         # nothing needs time: it pauses
    mark = time.monotonic()
    assert graph.step(duration_s=0.5).success
    _wait_for(lambda: len(streams.since(mark)) >= 50)
    idle = streams.since(mark)
    _stamps_every_state_period(idle)
    assert max(s[2] for s in idle) - min(s[2] for s in idle) < 1e-9


def test_pause_stops_simulated_time_and_a_step_advances_it_by_exactly_n_ticks(realtime):
    graph, streams = realtime
    _wait_for(lambda: len(streams.joint) >= 5)
    assert graph.pause().success
    assert graph.wait_still()                              # a tick in flight is answered
    t_paused = graph.sim_time_ns
    time.sleep(0.3)
    assert graph.sim_time_ns == t_paused
    assert not graph.pause().success                       # already paused: says so
    stepped = graph.step(ticks=5)
    assert stepped.success, stepped.message
    assert graph.sim_time_ns == t_paused + 5 * STATE_PERIOD_NS      # idle ticks: 10 ms each
    assert stepped.time_s == pytest.approx(graph.sim_time_ns * 1e-9, abs=1e-12)
    time.sleep(0.2)
    assert graph.sim_time_ns == t_paused + 5 * STATE_PERIOD_NS      # still paused
    assert graph.resume().success
    t_resumed = graph.sim_time_ns
    _wait_for(lambda: graph.sim_time_ns > t_resumed + 5 * STATE_PERIOD_NS)


@pytest.mark.parametrize('ticks, duration_s, words', [
    (0, 0.0, 'exactly one'), (3, 0.5, 'exactly one'), (0, float('nan'), 'finite'),
    (0, -1.0, '>= 0'), (0, 601.0, '<= 600')])
def test_bad_steps_are_refused_and_time_does_not_move(fast_refusing, ticks, duration_s, words):
    graph, _streams = fast_refusing
    graph.wait_still()
    t0 = graph.sim_time_ns
    response = graph.step(ticks=ticks, duration_s=duration_s)
    assert not response.success and words in response.message, response.message
    assert graph.sim_time_ns == t0
