"""On a world simulator's clock (``use_sim_time``): the gripper runs in step with /clock.

The world here publishes /clock as Gazebo does through ros_gz_bridge: one message every physics
step (1 ms of simulated time), and while paused the same time again every millisecond of wall
time (gz-sim ``src/SimulationRunner.cc``: ``PublishStats`` sends a clock message every
iteration, "not throttled", paused iterations included); on a reliable, volatile
keep_last(10) publisher (ros_gz_bridge ``src/factory.hpp``, ``create_ros_publisher``:
``rclcpp::QoS(rclcpp::KeepLast(queue_size))``, ``kDefaultPublisherQueue`` 10). Its steps are
scheduled at half the wall clock's pace, and a step that comes late moves the schedule rather
than bursting to catch up (``SimulationRunner::Run``: ``if (nextUpdateTime < now)
nextUpdateTime = now + updatePeriod``), so a starved world runs slower, never jumps.
The gripper's nodes take it as every rclpy node does under ``use_sim_time``
(rclpy ``time_source.py``: a best-effort, depth-1 subscription that sets the node's ROS clock).

Known answers: joint_states carry the world's time, never ahead of what the world had published
when they were sent and within 20 ms behind it; a move takes the simulated time it takes at
any pace (the finger's samples, relative to the move's start, equal a fast-mode graph's bit for
bit), so at half pace at least twice that in wall time, and no more of the world's time than
that; while /clock stands still nothing moves and no watchdog fires, however long; two grippers
on one clock publish the same stamps.
"""
from __future__ import annotations

import bisect
import re
import threading
import time

from gripper_interfaces.msg import SimStatus
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (Outcome, qualified, TimeMode, TOPIC_CLOCK, TOPIC_JOINT_STATES,
                              TOPIC_SIM_STATUS)
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

PACE = 0.5
"""The world's simulated seconds per wall second."""
STEP_NS = 1_000_000
"""Gazebo's default physics step (max_step_size 0.001): one /clock a step."""
WORLD_START_NS = 7_300_000_000
"""The world has run for a while before the gripper starts."""
STATE_PERIOD_NS = 10_000_000
"""joint_states at state_rate_hz 100."""
WITHIN_NS = 20_000_000
"""How far behind the world's time a joint_states stamp may be when it is sent."""
CLOSED_M = 0.10
"""A 50 mm move: from fully open (0.15 m) to 0.10 m."""


class World:
    """A world simulator's /clock, and what a robot stack's node receives of the gripper.

    ``history`` holds (system time ns, world time ns) of every /clock, noted just before it is
    published: the world's time at any instant, as DDS stamps a message's sending (its
    ``source_timestamp``, system clock).
    """

    def __init__(self, namespaces: tuple[str, ...]):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('world', context=self.context)
        self._clock_pub = self.node.create_publisher(Clock, TOPIC_CLOCK, QoSProfile(depth=10))
        self.lock = threading.Lock()
        self.history: list[tuple[int, int]] = []
        self.samples: dict[str, list] = {ns: [] for ns in namespaces}
        self.statuses: list[SimStatus] = []
        for ns in namespaces:
            self.node.create_subscription(
                JointState, qualified(ns, TOPIC_JOINT_STATES),
                lambda msg, info, ns=ns: self._on_joint(ns, msg, info), GRAPH_QOS)
        self.node.create_subscription(SimStatus, qualified(namespaces[0], TOPIC_SIM_STATUS),
                                      self.statuses.append, GRAPH_QOS)
        self._world_now_ns = WORLD_START_NS
        self.paused = False
        self._stop = threading.Event()
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._threads = [threading.Thread(target=self._publish, daemon=True),
                         threading.Thread(target=self._spin, daemon=True)]
        for thread in self._threads:
            thread.start()

    def _publish(self) -> None:
        """One /clock an iteration: a step of STEP_NS at PACE, or the same time while paused."""
        period_s = STEP_NS * 1e-9 / PACE
        next_update = time.monotonic() + period_s
        while not self._stop.is_set():
            with self.lock:
                if not self.paused:
                    self._world_now_ns += STEP_NS
                t_ns = self._world_now_ns
                self.history.append((time.time_ns(), t_ns))
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 1_000_000_000)
            self._clock_pub.publish(msg)
            if self.paused:
                time.sleep(0.001)
                next_update = time.monotonic() + period_s
                continue
            now = time.monotonic()
            if next_update > now:
                time.sleep(next_update - now)
            next_update += period_s
            if next_update < time.monotonic():
                next_update = time.monotonic() + period_s

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_joint(self, ns: str, msg: JointState, info: dict) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            self.samples[ns].append((info['source_timestamp'], stamp_ns, msg.position[0]))

    def at(self, system_ns: int) -> int:
        """Return the world's newest time published before ``system_ns`` (-1: none yet)."""
        with self.lock:
            k = bisect.bisect_right(self.history, (system_ns, 1 << 62))
            return self.history[k - 1][1] if k else -1

    def now_ns(self) -> int:
        with self.lock:
            return self.history[-1][1] if self.history else -1

    def pause(self) -> int:
        """Stand still (and go on publishing that time, as Gazebo paused); return the time."""
        with self.lock:
            self.paused = True
            return self._world_now_ns

    def resume(self) -> None:
        with self.lock:
            self.paused = False

    def since(self, ns: str, stamp_ns: int) -> list:
        with self.lock:
            return [s for s in self.samples[ns] if s[1] >= stamp_ns]

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _following(namespace: str) -> GripperGraph:
    return GripperGraph.in_own_context(GraphOptions(
        namespace=namespace, time_mode=TimeMode.REALTIME.parameter, use_sim_time=True))


def _lags_ns(world: World, samples: list) -> list[int]:
    """Return the world's time when each sample was sent, minus its stamp."""
    return [world.at(sent) - stamp for sent, stamp, _ in samples]


def _move_samples(samples: list) -> list[tuple[int, float]]:
    """Return (stamp from the first sample off the open stop, position) of a move's samples."""
    first = next(k for k, s in enumerate(samples) if s[2] != 0.0)
    return [(stamp - samples[first][1], position) for _, stamp, position in samples[first:]]


def _move_s(answer) -> float:
    """Return the simulated time a move took, as its answer says (``after 1.950 s``)."""
    return float(re.search(r'after (\d+\.\d+) s', answer.message).group(1))


@pytest.fixture(scope='module')
def reference():
    """Return the finger's samples of the move on a fast-mode graph, and its time."""
    with GripperGraph.in_own_context(GraphOptions(namespace='sim_time_reference')) as graph:
        seen = []
        graph.client_node.create_subscription(
            JointState, qualified(graph.namespace, TOPIC_JOINT_STATES),
            lambda m: seen.append((0, m.header.stamp.sec * 1_000_000_000 +
                                   m.header.stamp.nanosec, m.position[0])), GRAPH_QOS)
        assert wait_until(lambda: graph.plant.count_subscribers(TOPIC_JOINT_STATES) > 0, 10.0)
        assert graph.wait_still()                       # the first tick is decided
        answer = graph.move(CLOSED_M)
        assert answer.outcome == Outcome.MOVED, answer.message
        assert graph.wait_still()
        assert wait_until(lambda: seen and seen[-1][1] >= graph.sim_time_ns - STATE_PERIOD_NS,
                          10.0)
        return _move_samples(seen), _move_s(answer)


def test_at_half_pace_the_stamps_are_the_world_s_and_a_move_takes_twice_the_wall_time(
        reference):
    ns = 'sim_time_half'
    world = World((ns,))
    try:
        with _following(ns) as graph:
            assert graph.plant.time_mode is TimeMode.SIM_TIME
            assert wait_until(lambda: len(world.samples[ns]) >= 50, 30.0)
            # the gripper publishes no /clock: the world's is the one
            assert graph.client_node.count_publishers(TOPIC_CLOCK) == 1
            idle = list(world.samples[ns])
            stamps = [s[1] for s in idle]
            assert stamps[0] >= WORLD_START_NS and stamps[0] % STATE_PERIOD_NS == 0
            assert {b - a for a, b in zip(stamps, stamps[1:])} == {STATE_PERIOD_NS}
            lags = _lags_ns(world, idle)
            assert 0 <= min(lags) and max(lags) <= WITHIN_NS, (min(lags), max(lags))

            samples, duration_s = reference
            mark_ns = graph.sim_time_ns
            world_before, wall_before = world.now_ns(), time.monotonic()
            answer = graph.move(CLOSED_M)
            wall_s = time.monotonic() - wall_before
            world_s = (world.now_ns() - world_before) * 1e-9
            assert answer.outcome == Outcome.MOVED, answer.message
            assert _move_s(answer) == duration_s        # as at any pace, to the tick
            assert wait_until(lambda: len(world.since(ns, mark_ns)) > len(samples) + 20, 30.0)
            moved = world.since(ns, mark_ns)
            assert _move_samples(moved)[:len(samples)] == samples    # the same positions
            # never ahead of the world: at half pace twice the wall time, at least ...
            assert wall_s >= duration_s / PACE - 2 * STATE_PERIOD_NS * 1e-9, wall_s
            # ... and no more of the world's time than the move takes (it kept the pace)
            assert world_s <= duration_s + 3 * WITHIN_NS * 1e-9, (world_s, duration_s)
            lags = _lags_ns(world, moved)
            assert 0 <= min(lags) and max(lags) <= WITHIN_NS, (min(lags), max(lags))
    finally:
        world.close()


def test_while_the_world_stands_still_nothing_moves_and_no_watchdog_fires(reference):
    ns = 'sim_time_still'
    world = World((ns,))
    try:
        with _following(ns) as graph:
            tick_timeout_s = graph.supervisor.tick_timeout_s
            assert wait_until(lambda: len(world.samples[ns]) >= 10, 30.0)
            mark_ns = graph.sim_time_ns
            done = []
            mover = threading.Thread(target=lambda: done.append(graph.move(CLOSED_M)))
            mover.start()
            # the world stops mid-move (the finger on its way), as a paused Gazebo does
            assert wait_until(lambda: any(s[2] > 0.02 for s in world.since(ns, mark_ns)), 30.0)
            frozen_ns = world.pause()
            assert wait_until(lambda: graph.plant.paused, 10.0)   # the world stood still
            still_ns, still_m = graph.sim_time_ns, graph.plant.tick.position_m
            assert 0.02 < still_m < 0.05 and still_ns <= frozen_ns
            time.sleep(tick_timeout_s + 0.5)    # longer than the supervisor's watchdog waits
            assert graph.sim_time_ns == still_ns and graph.plant.tick.position_m == still_m
            assert all(s[1] <= frozen_ns for s in world.since(ns, mark_ns))
            assert graph.supervisor.logic.running and not done      # no FAULT, still moving
            with world.lock:
                assert any(s.paused and s.time_mode == TimeMode.SIM_TIME
                           for s in world.statuses)
            world.resume()
            mover.join(timeout=60.0)
            (answer,) = done
            assert answer.outcome == Outcome.MOVED, answer.message
            # the stop took no simulated time from the move, nor changed a sample of it
            samples, duration_s = reference
            assert _move_s(answer) == duration_s
            assert wait_until(lambda: len(world.since(ns, mark_ns)) > len(samples) + 20, 30.0)
            assert _move_samples(world.since(ns, mark_ns))[:len(samples)] == samples
    finally:
        world.close()


def test_two_grippers_on_one_world_clock_publish_the_same_stamps():
    world = World(('sim_time_left', 'sim_time_right'))
    try:
        with _following('sim_time_left'):
            assert wait_until(lambda: len(world.samples['sim_time_left']) >= 20, 30.0)
            with _following('sim_time_right'):      # started later: the world's time, too
                assert wait_until(lambda: len(world.samples['sim_time_right']) >= 50, 30.0)
                with world.lock:
                    left = {s[1] for s in world.samples['sim_time_left']}
                    right = [s[1] for s in world.samples['sim_time_right']]
                assert set(right[-40:]) <= left
                for ns in world.samples:
                    lags = _lags_ns(world, world.since(ns, right[0]))
                    assert 0 <= min(lags) and max(lags) <= WITHIN_NS, (ns, min(lags), max(lags))
    finally:
        world.close()


def test_on_the_world_clock_sim_pause_and_step_are_refused_and_fast_mode_is_not_started():
    from gripper_ros.nodes.startup import StartupError
    world = World(('sim_time_refusals',))
    try:
        with _following('sim_time_refusals') as graph:
            assert wait_until(lambda: world.samples['sim_time_refusals'], 30.0)
            for answer in (graph.pause(), graph.resume(), graph.step(ticks=3)):
                assert not answer.success and 'use_sim_time' in answer.message, answer.message
        with pytest.raises(StartupError, match='use_sim_time .* time_mode must be realtime'):
            GripperGraph.in_own_context(GraphOptions(
                namespace='sim_time_refusals', time_mode=TimeMode.FAST.parameter,
                use_sim_time=True))
    finally:
        world.close()
