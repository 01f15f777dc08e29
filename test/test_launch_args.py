"""Every node started exactly as ``ros2 launch gripper_ros gripper.launch.py`` starts it.

launch_ros runs each executable as ``NAME --ros-args -r __node:=NAME -r __ns:=/NS
--params-file FILE ...`` with one parameters file (``/**: ros__parameters:``) per dictionary of
the Node action; users add ``-p`` overrides. ``-r __node:=`` is a global remap: it renames every
node of the process, so it must not rename the helper nodes (the name-claim probe, the deferred
services' servers). This runs on the wheels, without launch: the six processes must come up in
one namespace and grasp (known answer: HOLDING at the requested width's setpoint), and a missing
or garbled parameters file is refused in one line.
"""
from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from gripper_interfaces.srv import Grasp, SetObject
from gripper_ros.core.config import default_config_path
from gripper_ros.nodes import LAUNCHED_MODULES
from gripper_ros.wire import (GRAPH_NOT_READY, NODE_PLANT, NODE_SUPERVISOR, Outcome,
                              SERVICE_GRASP, SERVICE_SET_OBJECT)
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

MODULES = LAUNCHED_MODULES
OVERRIDES = {NODE_PLANT: ['-p', 'real_time_factor:=1.0'],   # what a user adds after the file
             NODE_SUPERVISOR: ['-p', 'tick_timeout_s:=5.0']}
WIDTH, MASS = 0.05, 1.69
START_TIMEOUT_S = 90.0


def _command(node: str) -> list[str]:
    """Return the installed executable launch_ros runs (the module where none is installed)."""
    try:
        from ament_index_python.packages import get_package_prefix
        exe = Path(get_package_prefix('gripper_ros')) / 'lib' / 'gripper_ros' / node
        if exe.is_file():
            return [str(exe)]
    except (ImportError, LookupError, ValueError):
        pass
    return [sys.executable, '-m', f'gripper_ros.nodes.{MODULES[node]}']


def _params_file(folder: Path, name: str, values: dict) -> Path:
    """Write a parameters file as launch_ros writes one for a Node action's dictionary."""
    path = folder / f'launch_params_{name}'
    lines = ['/**:', '  ros__parameters:'] + [f'    {k}: {v}' for k, v in values.items()]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def _launch_args(node: str, namespace: str, folder: Path) -> list[str]:
    files = [_params_file(folder, f'{node}_config', {'config_file': str(default_config_path())})]
    if node == NODE_PLANT:
        files.append(_params_file(folder, f'{node}_plant', {
            'time_mode': 'realtime', 'real_time_factor': 1.0, 'publish_clock': 'false'}))
    args = ['--ros-args', '-r', f'__node:={node}', '-r', f'__ns:=/{namespace}']
    for f in files:
        args += ['--params-file', str(f)]
    return args + OVERRIDES.get(node, [])


def _call(node, executor, client, request, timeout_s):
    future = client.call_async(request)
    deadline = time.monotonic() + timeout_s
    while not future.done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return future.result() if future.done() else None


def test_the_six_nodes_started_as_launch_ros_starts_them_come_up_and_grasp(tmp_path):
    namespace = f'launched_{os.getpid()}'
    procs = {node: subprocess.Popen(_command(node) + _launch_args(node, namespace, tmp_path),
                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, text=True)
             for node in MODULES}
    context = Context()
    rclpy.init(context=context)
    try:
        client_node = rclpy.create_node('launch_args_client', namespace=namespace,
                                        context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(client_node)
        place = client_node.create_client(SetObject, SERVICE_SET_OBJECT)
        grasp = client_node.create_client(Grasp, SERVICE_GRASP)

        def up():
            names = {n for n, ns in client_node.get_node_names_and_namespaces()
                     if ns == f'/{namespace}'}
            return set(MODULES) <= names and place.service_is_ready() and \
                grasp.service_is_ready()

        deadline = time.monotonic() + START_TIMEOUT_S
        while not up() and time.monotonic() < deadline and \
                all(p.poll() is None for p in procs.values()):
            executor.spin_once(timeout_sec=0.1)
        dead = {n: (p.returncode, p.stderr.read()[-500:]) for n, p in procs.items()
                if p.poll() is not None}
        assert not dead, dead
        assert up(), 'the six nodes did not come up'
        placed = _call(client_node, executor, place, SetObject.Request(
            width_m=WIDTH, open_fingers=True), 30.0)
        assert placed is not None and placed.success, placed
        answer = None
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:        # the supervisor refuses until it sees all
            answer = _call(client_node, executor, grasp, Grasp.Request(
                width_m=WIDTH, mass_kg=MASS), 60.0)
            if answer is None or GRAPH_NOT_READY not in answer.message:
                break
            time.sleep(0.5)
        assert answer is not None and answer.outcome == Outcome.HOLDING, answer
        assert abs(answer.final_width_m - WIDTH) < 1e-3
        executor.shutdown()
        client_node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.communicate()


@pytest.mark.parametrize('content', [None, b'\x00\xff garbage: [', b'/**:\n  ros__parameters'])
def test_a_missing_or_garbled_parameters_file_is_refused_in_one_line(tmp_path, content):
    path = tmp_path / 'params.yaml'
    if content is not None:
        path.write_bytes(content)
    run = subprocess.run(_command(NODE_SUPERVISOR) + [
        '--ros-args', '-r', f'__ns:=/params_{os.getpid()}', '--params-file', str(path)],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2, run.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith(f'{NODE_SUPERVISOR}: bad --ros-args'), \
        run.stderr[-2000:]


@pytest.mark.parametrize('node', list(MODULES))
def test_help_prints_usage_and_starts_no_node(node):
    run = subprocess.run(_command(node) + ['--help'], stdin=subprocess.DEVNULL,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.startswith(f'usage: {node} [--ros-args') and not run.stderr
