"""On a world simulator's clock (``use_sim_time``): the gripper runs in step with /clock.

The world publishes /clock as Gazebo does through ros_gz_bridge, at half the wall clock's pace
(:mod:`world_clock`, which names the upstream sources it follows). The gripper's nodes take it
as every rclpy node does under ``use_sim_time`` (rclpy ``time_source.py``: a best-effort,
depth-1 subscription that sets the node's ROS clock), the graph's through the plant's.

Known answers: joint_states carry the world's time, never ahead of what the world had published
when they were sent and, from the gripper's first 0.1 s on, within 20 ms behind it; a move
takes the simulated time it takes at any pace (the finger's samples, relative to the move's
start, equal a fast-mode graph's bit for bit), so at half pace at least twice that in wall
time, and no more of the world's time than that; while /clock stands still nothing moves and
no watchdog fires, however long; two grippers on one clock publish the same stamps.
"""
from __future__ import annotations

import re
import threading
import time

from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import Outcome, qualified, TimeMode, TOPIC_CLOCK, TOPIC_JOINT_STATES
import pytest
from sensor_msgs.msg import JointState
from world_clock import following, lags_ns, PACE, World, WORLD_START_NS

STATE_PERIOD_NS = 10_000_000
"""joint_states at state_rate_hz 100."""
WITHIN_NS = 20_000_000
"""How far behind the world's time a joint_states stamp may be when it is sent."""
CLOSED_M = 0.10
"""A 50 mm move: from fully open (0.15 m) to 0.10 m."""


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
        with following(ns) as graph:
            assert graph.plant.time_mode is TimeMode.SIM_TIME
            assert wait_until(lambda: len(world.samples[ns]) >= 50, 30.0)
            # the gripper publishes no /clock: the world's is the one
            assert graph.client_node.count_publishers(TOPIC_CLOCK) == 1
            # and takes it once: the plant's subscription sets every node's clock
            assert graph.client_node.count_subscribers(TOPIC_CLOCK) == 1
            idle = list(world.samples[ns])
            stamps = [s[1] for s in idle]
            assert stamps[0] >= WORLD_START_NS and stamps[0] % STATE_PERIOD_NS == 0
            assert {b - a for a, b in zip(stamps, stamps[1:])} == {STATE_PERIOD_NS}
            lags = lags_ns(world, idle)
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
            lags = lags_ns(world, world.since(ns, 0))           # idle, moving, idle again
            print(f'joint_states behind the world when sent: {min(lags) * 1e-6:.0f}-'
                  f'{max(lags) * 1e-6:.0f} ms over {len(lags)} samples')
            assert 0 <= min(lags) and max(lags) <= WITHIN_NS, (min(lags), max(lags))
    finally:
        world.close()


def test_while_the_world_stands_still_nothing_moves_and_no_watchdog_fires(reference):
    ns = 'sim_time_still'
    world = World((ns,))
    try:
        with following(ns) as graph:
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
        with following('sim_time_left'):
            assert wait_until(lambda: len(world.samples['sim_time_left']) >= 20, 30.0)
            with following('sim_time_right'):      # started later: the world's time, too
                assert wait_until(lambda: len(world.samples['sim_time_right']) >= 50, 30.0)
                with world.lock:
                    right = [s[1] for s in world.samples['sim_time_right']]
                # each gripper publishes as its process is scheduled: compare once the left one
                # has sent the stamps up to the right one's newest
                assert wait_until(lambda: world.samples['sim_time_left'][-1][1] >= right[-1],
                                  30.0)
                with world.lock:
                    left = {s[1] for s in world.samples['sim_time_left']}
                assert set(right[-40:]) <= left
                for ns in world.samples:
                    lags = lags_ns(world, world.since(ns, right[0]))
                    assert 0 <= min(lags) and max(lags) <= WITHIN_NS, (ns, min(lags), max(lags))
    finally:
        world.close()


def test_on_the_world_clock_sim_pause_and_step_are_refused_and_fast_mode_is_not_started():
    from gripper_ros.nodes.startup import StartupError
    world = World(('sim_time_refusals',))
    try:
        with following('sim_time_refusals') as graph:
            assert wait_until(lambda: world.samples['sim_time_refusals'], 30.0)
            for answer in (graph.pause(), graph.resume(), graph.step(ticks=3)):
                assert not answer.success and 'use_sim_time' in answer.message, answer.message
        with pytest.raises(StartupError, match='use_sim_time .* time_mode must be realtime'):
            GripperGraph.in_own_context(GraphOptions(
                namespace='sim_time_refusals', time_mode=TimeMode.FAST.parameter,
                use_sim_time=True))
    finally:
        world.close()
