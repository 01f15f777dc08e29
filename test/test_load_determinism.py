"""Lockstep determinism under CPU load.

The same grasps are recorded twice through the node graph (real DDS, real bags): once on a
machine as quiet as it gets, once while CPU-bound spinner processes keep the other core(s) busy.
Simulated time advances only with the commands of the lockstep protocol, so the recorded
position, force and voltage series must be bit-identical; only the wall time may differ (it is
printed, never asserted).
"""
import os
import subprocess
import sys
import time

from gripper_ros.bags.reader import read_bag
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.core.series import seconds
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.wire import DEFAULT_NAMESPACE, qualified, TOPIC_JOINT_STATES, TOPIC_TF
from helpers import cpu_s, tf_as_robot_state_publisher
import numpy as np
import pytest

OBJECTS = ((0.05, 1.69), (0.10, 0.75))       # two Table V objects, ~1-2 s wall each here
JOINT_STATES = qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES)
SPIN = 'while True: pass\n'                 # killed once the loaded grasps are done


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        yield g


def _record(graph, out, tag):
    runs = []
    for i, (w, m) in enumerate(OBJECTS):
        run = recorded_grasp(graph, out / f'{tag}_{i}', w, m)
        assert run.response.success, run.response.message
        runs.append(run)
    return runs


def _simulated(counts: dict) -> dict:
    """Keep the counts of the lockstep topics, one message per tick.

    The state topics are sampled on the absolute grid of simulated time, on which two grasps
    start at different phases, and sim/status comes once a wall second.
    """
    return {t: n for t, n in counts.items() if '/loop/' in t}


def _series(run):
    s = load_grasp_series(run.bag_dir)
    rel = lambda t: np.round((t - t[0]) * 1e9).astype(np.int64)  # noqa: E731
    return {
        'joint_t': rel(s.t_s), 'position_m': s.ticks['position_m'],
        'force_n': s.ticks['force_n'], 'sensor_voltage_v': s.ticks['sensor_voltage_v'],
        'motor_voltage_v': s.ticks['motor_voltage_v'], 'command_t': rel(seconds(s.commands)),
        'command_voltage_v': s.commands['voltage_v'], 'phase': s.decisions['phase'],
    }


def test_loaded_grasps_record_bit_identical_series(graph, tmp_path):
    quiet = _record(graph, tmp_path, 'quiet')
    spinners = [subprocess.Popen([sys.executable, '-c', SPIN])
                for _ in range(max(1, (os.cpu_count() or 2) - 1))]
    try:
        time.sleep(0.2)
        cpu0 = [cpu_s(p.pid) for p in spinners]
        loaded = _record(graph, tmp_path, 'loaded')
        burnt = [cpu_s(p.pid) - c for p, c in zip(spinners, cpu0)]
        assert all(p.poll() is None for p in spinners), 'a spinner died early'
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    loaded_wall = sum(r.wall_s for r in loaded)
    print(f'\nquiet {sum(r.wall_s for r in quiet):.2f} s, loaded {loaded_wall:.2f} s wall; '
          f'spinners used {sum(burnt):.2f} s CPU meanwhile')
    # the load was there: each spinner ran while the loaded grasps did (how much of the CPU it
    # got depends on what else the machine runs, which no test may assert)
    assert all(b > 0 for b in burnt), burnt
    for q, l in zip(quiet, loaded):
        assert _simulated(q.published) == _simulated(l.published)
        assert _simulated(q.recorded) == _simulated(l.recorded)
        loop = {t: n for t, n in q.recorded.items() if t in q.published}
        assert loop == q.published                     # nothing the loop's nodes sent is lost
        tf, expected = tf_as_robot_state_publisher(read_bag(q.bag_dir))   # as upstream's
        assert tf == expected and len(tf) == q.recorded[TOPIC_TF] >= q.published[JOINT_STATES] // 5
        a, b = _series(q), _series(l)
        for key in a:
            assert len(a[key]) > 0, key
            assert np.array_equal(a[key], b[key]), key
        assert q.response.final_position_m == l.response.final_position_m
        assert q.response.final_force_n == l.response.final_force_n
        assert q.response.switch_time_s == l.response.switch_time_s
