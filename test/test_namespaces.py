"""Two namespaced grippers side by side on one domain, and one graph per namespace.

A bimanual robot: ``left`` and ``right`` grasp at the same time, in one process and in two.
Known answers: each holds its own object at its own width; each bag holds only its own topics
(``/clock`` is in none: a bag's time is its own messages' stamps) and, per topic, exactly what
its own graph published: one reference and one command for each of its own ticks; on /tf
and /tf_static only its own frames, the links of its robot_description (``left_`` before each).
A second graph in a namespace already taken exits 2 with one line naming what it found, and
publishes nothing.
"""
import subprocess
import sys
import threading
import time

from gripper_ros.bags.reader import read_bag
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import (DESCRIPTION_TOPICS, FRAME_BASE, FRAME_FIXED_FINGER,
                              FRAME_MOVING_FINGER, Outcome, qualified, TOPIC_FORCE_REFERENCE,
                              TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND, TOPIC_POSITION_REFERENCE,
                              TOPIC_ROBOT_DESCRIPTION, TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TICK)
from helpers import frames_of_bag, tf_as_robot_state_publisher, urdf_tree
import pytest

OBJECTS = {'left': (0.05, 1.69), 'right': (0.10, 0.75)}


GLOBAL = (TOPIC_TF, TOPIC_TF_STATIC)
"""The description's global topics (as every robot's /tf), beside the namespace's."""
LINKS = (FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER)
"""The URDF's links, each a TF frame: ``left_`` before each in /left (the default prefix)."""


def _check_bag(bag_dir, namespace):
    bag = read_bag(bag_dir)
    counts = {t.name: t.count for t in bag.topics.values() if t.count}
    # its own topics, and its own fingers on the global /tf and /tf_static
    assert all(t.startswith(f'/{namespace}/') or t in GLOBAL for t in counts), sorted(counts)
    tf, expected = tf_as_robot_state_publisher(bag, namespace)   # as robot_state_publisher
    assert tf == expected and len(tf) >= counts[qualified(namespace, TOPIC_JOINT_STATES)] // 5
    # the frames: its own URDF's (the other gripper's differ in name), each under its parent
    (description,) = [bag.decode(m).data for m in bag.messages
                      if m.topic == qualified(namespace, TOPIC_ROBOT_DESCRIPTION)]
    links, joints = urdf_tree(description)
    assert links == {f'{namespace}_{link}' for link in LINKS}
    assert frames_of_bag(bag) == {child: {parent} for _, parent, child, _, _ in joints.values()}
    ticks = counts[qualified(namespace, TOPIC_TICK)]
    references = counts.get(qualified(namespace, TOPIC_POSITION_REFERENCE), 0) + \
        counts.get(qualified(namespace, TOPIC_FORCE_REFERENCE), 0)
    assert ticks > 500
    assert references == counts[qualified(namespace, TOPIC_MOTOR_COMMAND)] == ticks
    return counts


@pytest.fixture
def two_grippers():
    graphs = {'left': GripperGraph.in_own_context(GraphOptions(namespace='left')),
              'right': GripperGraph.in_own_context(GraphOptions(namespace='right',
                                                                publish_clock=False))}
    try:
        yield graphs
    finally:
        for g in graphs.values():
            g.close()


def test_left_and_right_in_one_process_each_hold_their_object_with_a_clean_bag(
        two_grippers, tmp_path):
    runs = {}

    def grasp(name):
        width, mass = OBJECTS[name]
        runs[name] = recorded_grasp(two_grippers[name], tmp_path / name, width, mass)

    threads = [threading.Thread(target=grasp, args=(name,)) for name in OBJECTS]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=180)
    for name, (width, _mass) in OBJECTS.items():
        run = runs[name]
        assert run.response.outcome == Outcome.HOLDING, run.response.message
        assert run.response.final_width_m == pytest.approx(width, abs=1e-9)   # the rigid face
        assert not run.recording_error
        recorded = {t: n for t, n in run.recorded.items() if n}
        described = {qualified(name, t) for t in DESCRIPTION_TOPICS}
        assert {t: n for t, n in recorded.items() if t not in described} == \
            {t: n for t, n in run.published.items() if n}                  # its own, all
        assert _check_bag(run.bag_dir, name) == recorded


def test_left_and_right_in_two_processes_each_hold_their_object_with_a_clean_bag(tmp_path):
    procs = {}
    for name, (width, mass) in OBJECTS.items():
        cmd = [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--namespace', name,
               '--width', str(width), '--mass', str(mass), '--output', str(tmp_path / name),
               '--no-plot'] + (['--no-clock'] if name == 'right' else [])
        procs[name] = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True, stdin=subprocess.DEVNULL)
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=180)
        assert proc.returncode == 0, out + err
        bags = [p for p in (tmp_path / name).iterdir() if p.is_dir()]
        assert len(bags) == 1
        _check_bag(bags[0], name)


def test_a_second_graph_in_a_taken_namespace_exits_2_and_publishes_nothing():
    first = GripperGraph.in_own_context(GraphOptions(namespace='taken'))
    try:
        ticks = qualified('taken', TOPIC_TICK)
        publishers = []
        stop = threading.Event()

        def watch():
            while not stop.is_set():
                publishers.append(first.client_node.count_publishers(ticks))
                time.sleep(0.01)

        watcher = threading.Thread(target=watch)
        watcher.start()
        result = subprocess.run(
            [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--namespace', 'taken',
             '--width', '0.05', '--mass', '1.69', '--no-record'],
            capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        time.sleep(0.3)
        stop.set()
        watcher.join()
        assert result.returncode == 2, result.stdout + result.stderr
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert lines == [lines[0]] and 'namespace /taken is taken' in lines[0]
        assert '/taken/plant_simulator (process ' in lines[0] and '/taken/supervisor' in lines[0]
        assert set(publishers) == {1}, 'the refused graph published a tick'
        with pytest.raises(StartupError, match='taken'):     # in one process, the same
            GripperGraph.in_own_context(GraphOptions(namespace='taken'))
        assert first.set_object(0.05).success and first.grasp(0.05, 1.69).success
    finally:
        first.close()


@pytest.mark.parametrize('module, found', [
    ('plant_simulator_node', '/taken_node/plant_simulator'),
    ('supervisor_node', '/taken_node/supervisor')])
def test_a_standalone_node_in_a_taken_namespace_exits_2_in_one_line(module, found):
    first = GripperGraph.in_own_context(GraphOptions(namespace='taken_node'))
    try:
        result = subprocess.run(
            [sys.executable, '-m', f'gripper_ros.nodes.{module}', '--ros-args', '-r',
             '__ns:=/taken_node'], capture_output=True, text=True, timeout=60,
            stdin=subprocess.DEVNULL)
        assert result.returncode == 2, result.stdout + result.stderr
        assert 'Traceback' not in result.stderr and found in result.stderr, result.stderr
    finally:
        first.close()


def test_a_gripper_claimed_elsewhere_is_still_found_by_discovery(tmp_path, monkeypatch):
    """A graph whose claims live elsewhere (another machine, another user) is still found.

    Discovery on the domain finds its plant, its supervisor and its grasp server. The check's
    wait is long here: a participant that has just joined often learns of another only at its
    next announcement, up to Fast DDS's 3 s period later, the delay the half-second default
    accepts (docs/USING.md) and not what this test is about; the check ends when it sees them.
    """
    from gripper_ros.nodes import names
    monkeypatch.setattr(names, 'DISCOVERY_WAIT_S', 10.0)
    monkeypatch.setenv('GRIPPER_ROS_CLAIMS_DIR', str(tmp_path / 'there'))
    first = GripperGraph.in_own_context(GraphOptions(namespace='elsewhere'))
    try:
        assert _discovered_elsewhere('/elsewhere', 'supervisor'), 'discovery never found it'
        monkeypatch.setenv('GRIPPER_ROS_CLAIMS_DIR', str(tmp_path / 'here'))
        try:
            second = GripperGraph.in_own_context(GraphOptions(namespace='elsewhere'))
        except StartupError as refused:
            message = str(refused)
        else:
            second.close()                      # never left running: its threads outlive pytest
            pytest.fail('a second gripper in /elsewhere was started')
        assert 'process' not in message
        for found in ('/elsewhere/plant_simulator', '/elsewhere/supervisor',
                      'service /elsewhere/grasp'):
            assert found in message
    finally:
        first.close()


def _discovered_elsewhere(namespace: str, node_name: str, timeout_s: float = 30.0) -> bool:
    """Wait until a participant of its own sees ``node_name`` in ``namespace`` (DDS discovery).

    The claim's check waits a fixed half second; on a loaded machine a graph started a moment
    ago may need longer to be seen at all, which is discovery's delay, not the check's.
    """
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context)
    try:
        probe = rclpy.create_node('discovery_watch', context=context)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if (node_name, namespace) in probe.get_node_names_and_namespaces():
                return True
            time.sleep(0.05)
        return False
    finally:
        rclpy.try_shutdown(context=context)


def test_namespaces_that_give_one_prefix_are_refused_until_one_takes_another():
    """``a/b`` and ``a_b`` both give the prefix ``a_b_``: the second graph is refused in a line.

    Both would publish ``a_b_gripper_base`` on the global /tf and a joint ``a_b_finger_joint``.
    With a prefix of its own it starts; once the first is closed the prefix is free again.
    """
    first = GripperGraph.in_own_context(GraphOptions(namespace='pfx/one'))
    try:
        with pytest.raises(StartupError) as refused:
            GripperGraph.in_own_context(GraphOptions(namespace='pfx_one'))
        assert str(refused.value) == (
            "prefix 'pfx_one_' of namespace /pfx_one is taken on ROS_DOMAIN_ID "
            f'{first.context.get_domain_id()} by namespace /pfx/one on this machine: both '
            'would publish the same TF frames and joint; give one another prefix '
            '(-p prefix:=NAME_)')
        own = GripperGraph.in_own_context(GraphOptions(namespace='pfx_one', prefix='flat_'))
        own.close()
    finally:
        first.close()
    second = GripperGraph.in_own_context(GraphOptions(namespace='pfx_one'))
    second.close()


def test_names_are_free_again_once_the_graph_is_closed():
    first = GripperGraph.in_own_context(GraphOptions(namespace='reused'))
    first.close()
    second = GripperGraph.in_own_context(GraphOptions(namespace='reused'))
    try:
        assert second.set_object(0.05).success
    finally:
        second.close()
