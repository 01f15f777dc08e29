"""launch/gripper.launch.py on a system ROS 2 Jazzy: its description, and the graph it starts.

The graph in one process (``gripper_graph``, the default) or one process per node
(``per_node:=true``), the namespace, config file and time mode as launch arguments; Ctrl-C
(SIGINT to the process group, as a terminal sends it) stops every process, each exiting 0
before launch escalates. With ``use_sim_time:=true`` the launched gripper runs on a world's
/clock (:mod:`world_clock`); a namespace that is no ROS name is one line, no node started.
The ros-jazzy wheels have no launch_ros (nor the ros2 launch command): there these tests
skip, unless ``setup.sh --ros2-cli`` built them (scripts/test.sh then sets ``ROS2_OVERLAY``,
and a failure to import is an error); test_install_layout checks that the file is installed
either way.
"""
import importlib.util
import os
from pathlib import Path
import shutil
import signal
import subprocess
import time

from ament_index_python.packages import get_package_prefix, get_package_share_directory
from gripper_ros.wire import Outcome
import pytest

try:
    import launch_ros  # noqa: F401
except ImportError:
    pytest.skip('launch_ros is not installable from the ros-jazzy wheels; run on a system '
                'ROS 2 Jazzy', allow_module_level=True)

from launch import LaunchContext  # noqa: I100 - after the skip
from launch.actions import DeclareLaunchArgument
from launch.utilities import perform_substitutions
from launch_ros.actions import Node

from gripper_ros.nodes import launched_executables, robot_state_publisher_installed  # noqa: I100
from gripper_ros.nodes.live_view import DEFAULT_ADDRESS, DEFAULT_PORT  # noqa: I100
from gripper_ros.wire import LAUNCHED_NODES  # noqa: I100

LAUNCHED = launched_executables(robot_state_publisher_installed())
EXECUTABLES = {name for package, name in LAUNCHED if package == 'gripper_ros'}
DEFAULTS = {'namespace': 'gripper', 'time_mode': 'realtime', 'real_time_factor': '1.0',
            'publish_clock': 'true', 'use_sim_time': 'false', 'prefix': '', 'per_node': 'false',
            'foxglove': 'false', 'foxglove_port': str(DEFAULT_PORT),
            'foxglove_address': DEFAULT_ADDRESS}
LAYOUTS = {'one_process': 'false', 'per_node': 'true'}
STOP_WITHIN_S = 30.0
"""Ctrl-C to every process gone: each ends within a few seconds by its own bound; launch would
escalate to SIGTERM after 5 s (and say so, which the test also rules out), SIGKILL after 10."""


def _installed_launch_file() -> Path:
    return Path(get_package_share_directory('gripper_ros')) / 'launch' / 'gripper.launch.py'


@pytest.fixture(scope='module')
def description():
    spec = importlib.util.spec_from_file_location('gripper_launch', _installed_launch_file())
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def test_the_launch_arguments_and_their_defaults(description):
    context = LaunchContext()
    declared = {a.name: perform_substitutions(context, a.default_value)
                for a in description.entities if isinstance(a, DeclareLaunchArgument)}
    installed = Path(get_package_share_directory('gripper_ros')) / 'config' / 'gripper.yaml'
    assert declared == {**DEFAULTS, 'config_file': str(installed)}


def _started(description, per_node: str) -> list[tuple[str, str]]:
    """Return (package, executable) of each Node action that runs with ``per_node:=VALUE``."""
    context = LaunchContext()
    context.launch_configurations['per_node'] = per_node
    return sorted((n.node_package, n.node_executable) for n in description.entities
                  if isinstance(n, Node) and n.condition.evaluate(context))


def test_one_process_by_default_one_per_node_as_an_argument(description):
    assert _started(description, 'false') == [('gripper_ros', 'gripper_graph')]
    assert _started(description, 'true') == sorted(LAUNCHED)
    prefix = Path(get_package_prefix('gripper_ros'))
    for name in EXECUTABLES:
        assert os.access(prefix / 'lib' / 'gripper_ros' / name, os.X_OK), name


def _group_alive(pgid: int) -> bool:
    """Whether a process of group ``pgid`` still runs (a zombie waiting for its parent: not)."""
    from gripper_ros.bench.common import group_pids
    return bool(group_pids(pgid))


@pytest.fixture(params=list(LAYOUTS), ids=list(LAYOUTS))
def launched(request, tmp_path):
    """``ros2 launch`` in its own process group, in fast time, in a namespace of its own.

    Its output goes to a file (``proc.log``): a pipe nobody reads would stop it when full.
    """
    ros2 = shutil.which('ros2')
    if ros2 is None:
        pytest.skip('the ros2 command is not on PATH')
    namespace = f'launch_test_{request.param}'
    log = tmp_path / 'launch.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen([ros2, 'launch', 'gripper_ros', 'gripper.launch.py',
                                 f'namespace:={namespace}', 'time_mode:=fast',
                                 f'per_node:={LAYOUTS[request.param]}'],
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    proc.log = log
    yield namespace, proc
    if _group_alive(proc.pid):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def test_the_launched_graph_moves_the_finger(launched):
    import rclpy
    from gripper_interfaces.srv import Move, SetObject
    from rclpy.action import get_action_names_and_types
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    namespace, proc = launched
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('launch_test_client', namespace=namespace, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def call(client, request, timeout_s=60.0):
            future = client.call_async(request)
            executor.spin_until_future_complete(future, timeout_sec=timeout_s)
            assert future.done(), f'{client.srv_name} did not answer'
            return future.result()

        set_object = node.create_client(SetObject, 'sim/set_object')
        move = node.create_client(Move, 'move')
        assert set_object.wait_for_service(timeout_sec=60.0), proc.poll()
        assert move.wait_for_service(timeout_sec=60.0), proc.poll()
        assert call(set_object, SetObject.Request(width_m=0.0, open_fingers=True)).success
        deadline = time.monotonic() + 60.0
        while True:          # until every node is discovered and the first tick is in
            answer = call(move, Move.Request(width_m=0.05, speed_mps=0.03))
            if answer.outcome != Outcome.REFUSED or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert answer.reached_goal and answer.outcome == Outcome.MOVED, answer.message
        expected = EXECUTABLES if namespace.endswith('per_node') else set(LAUNCHED_NODES)
        ours = _discovered_nodes(node, executor, namespace, expected)
        assert ours >= expected, proc.poll()
        try:
            import control_msgs  # noqa: F401
        except ImportError:
            return
        actions = {name for name, _ in get_action_names_and_types(node)}
        assert f'/{namespace}/gripper_cmd' in actions
    finally:
        rclpy.try_shutdown(context=context)
    _ctrl_c_stops_every_process(proc)


def _discovered_nodes(node, executor, namespace: str, expected: set, timeout_s=60.0) -> set:
    """Return the node names seen under ``namespace`` once ``expected`` are, or at the timeout.

    A node's name reaches another process by discovery, apart from its topics: a move answered
    through the position controller does not mean its name is known here yet.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        ours = {name for name, ns in node.get_node_names_and_namespaces()
                if ns == f'/{namespace}'}
        if ours >= expected or time.monotonic() > deadline:
            return ours
        executor.spin_once(timeout_sec=0.2)


def _ctrl_c_stops_every_process(proc) -> None:
    """SIGINT to the group, as Ctrl-C: all gone, each process reported finished cleanly."""
    os.killpg(proc.pid, signal.SIGINT)
    deadline = time.monotonic() + STOP_WITHIN_S
    while _group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    output = proc.log.read_text()
    assert not _group_alive(proc.pid), f'a launched process outlived Ctrl-C\n{output}'
    started = output.count('process started with pid')
    assert started >= 1 and output.count('process has finished cleanly') == started, output
    assert 'escalating' not in output and proc.wait() == 0, output


def test_a_namespace_that_is_no_ros_name_is_one_line_and_starts_nothing():
    """launch_ros alone says it over lines naming ``<LaunchConfiguration object at 0x...>``."""
    ros2 = shutil.which('ros2')
    if ros2 is None:
        pytest.skip('the ros2 command is not on PATH')
    run = subprocess.run([ros2, 'launch', 'gripper_ros', 'gripper.launch.py',
                          'namespace:=left-arm'], stdin=subprocess.DEVNULL, capture_output=True,
                         text=True, timeout=120, start_new_session=True)
    errors = [line for line in (run.stdout + run.stderr).splitlines() if '[ERROR]' in line]
    assert run.returncode == 1 and len(errors) == 1, run.stdout + run.stderr
    assert "namespace 'left-arm' is not a ROS name" in errors[0], errors
    assert 'process started' not in run.stdout + run.stderr


def test_launched_on_a_world_clock_the_stamps_are_the_world_s():
    """``use_sim_time:=true``: no /clock of its own; joint_states stamped with the world's time.

    Never ahead of the world's time when sent, and typically within 20 ms behind it. Every
    sample within 20 ms is test_sim_time's, where the world runs in the gripper's process: here
    the two are processes of a shared machine, and a starved gripper falls behind a world that
    is not (it catches up at its loop's pace, the stamps still the world's).
    """
    from world_clock import lags_ns, World, WORLD_START_NS
    ros2 = shutil.which('ros2')
    if ros2 is None:
        pytest.skip('the ros2 command is not on PATH')
    namespace = 'launch_sim_time'
    world = World((namespace,))
    proc = subprocess.Popen([ros2, 'launch', 'gripper_ros', 'gripper.launch.py',
                             f'namespace:={namespace}', 'use_sim_time:=true'],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120.0
        while len(world.samples[namespace]) < 50 and time.monotonic() < deadline:
            time.sleep(0.05)
        with world.lock:
            samples = list(world.samples[namespace])
        assert len(samples) >= 50, proc.poll()
        assert samples[0][1] >= WORLD_START_NS
        lags = sorted(lags_ns(world, samples))
        assert 0 <= lags[0] and lags[len(lags) // 2] <= 20_000_000, lags
        assert world.node.count_publishers('/clock') == 1
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            assert proc.wait(timeout=STOP_WITHIN_S) == 0
        finally:
            if _group_alive(proc.pid):
                os.killpg(proc.pid, signal.SIGKILL)
            world.close()
