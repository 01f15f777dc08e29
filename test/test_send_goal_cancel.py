"""Ctrl-C of ``ros2 action send_goal`` on ``gripper_cmd``: which side answers the cancel.

The real CLI from the overlay (ros2/ros2cli, ``ros2action/verb/send_goal.py``) against the
realtime graph. Jazzy's send_goal (0.32.2, the overlay's) cancels in its ``finally`` clause
after Ctrl-C has interrupted ``spin_until_future_complete``; by then rclpy's SIGINT handler
(ros2/rclpy, ``src/rclpy/signal_handler.cpp``) has shut its context down, so it sends the cancel
request but cannot spin for the answer, and prints ``Exception while canceling goal: None``
(ros2/rclpy issue 1390; ros2cli moved the cancel into a SIGINT handler of its own, pull
request 956, which runs once the executor wakes: on the server's feedback).

Known answer: the server takes the cancel the CLI sent: the goal ends CANCELED (its status on
``gripper_cmd/_action/status``), the move STOPPED, and the finger stops; the same server's
answer to a client that can wait for it (rclpy's ActionClient) names the goal it cancels.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import threading

from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import LATCHED_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import ACTION_GRIPPER_CMD, qualified, TimeMode, TOPIC_GRIPPER_STATUS
from helpers import wait_future
import pytest

pytest.importorskip('control_msgs.action', reason='control_msgs is not installed')
if shutil.which('ros2') is None:
    pytest.skip('no ros2 CLI (source the overlay: ROS2_OVERLAY)', allow_module_level=True)

from action_msgs.msg import GoalStatus, GoalStatusArray  # noqa: E402, I100 - after the skip
from action_msgs.srv import CancelGoal  # noqa: E402
from control_msgs.action import ParallelGripperCommand  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

NAMESPACE = 'cli_cancel'
WAIT_S = 120.0
GOAL_ID = re.compile(r'Goal accepted with ID: ([0-9a-f]{32})')


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(namespace=NAMESPACE,
                                                  time_mode=TimeMode.REALTIME.parameter)) as g:
        yield g


class Watch:
    """The goal statuses of ``gripper_cmd`` and the latest gripper_status, over DDS."""

    def __init__(self, graph):
        node = graph.client_node
        self.lock = threading.Lock()
        self.final: dict[str, int] = {}          # goal id (hex) -> last status seen
        self.grip: DiagnosticStatus | None = None
        status_topic = qualified(graph.namespace, ACTION_GRIPPER_CMD) + '/_action/status'
        self.subs = [node.create_subscription(GoalStatusArray, status_topic, self._status,
                                              LATCHED_QOS),
                     node.create_subscription(DiagnosticStatus,
                                              qualified(graph.namespace, TOPIC_GRIPPER_STATUS),
                                              self._grip, LATCHED_QOS)]

    def _status(self, msg: GoalStatusArray) -> None:
        with self.lock:
            for s in msg.status_list:
                self.final[bytes(s.goal_info.goal_id.uuid).hex()] = s.status

    def _grip(self, msg: DiagnosticStatus) -> None:
        with self.lock:
            self.grip = msg

    def status_of(self, goal_id: str) -> int | None:
        with self.lock:
            return self.final.get(goal_id)


def test_ctrl_c_of_send_goal_cancels_the_goal_on_the_server(graph):
    assert graph.set_object(0.0, open_fingers=True).success
    watch = graph.run_in_executor(lambda: Watch(graph))
    joint = graph.move_action_server.joint_name
    goal = f'{{command: {{name: [{joint}], position: [0.14], velocity: [0.01]}}}}'
    cli = subprocess.Popen(
        ['ros2', 'action', 'send_goal', '--feedback',
         qualified(graph.namespace, ACTION_GRIPPER_CMD),
         'control_msgs/action/ParallelGripperCommand', goal],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=os.environ.copy(),
        stdin=subprocess.DEVNULL)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(cli.stdout), daemon=True)
    reader.start()
    try:
        # send_goal prints feedback from a callback, which can come before its own line of the
        # goal's acceptance (ros2action verb/send_goal.py): both are waited for
        assert wait_until(lambda: GOAL_ID.search(''.join(lines)) and
                          any('Feedback:' in line for line in lines), WAIT_S), lines
        goal_id = GOAL_ID.search(''.join(lines)).group(1)
        assert watch.status_of(goal_id) == GoalStatus.STATUS_EXECUTING
        cli.send_signal(signal.SIGINT)                          # Ctrl-C
        assert cli.wait(timeout=30.0) is not None
    finally:
        if cli.poll() is None:
            cli.kill()
    reader.join(5.0)
    output = ''.join(lines)
    assert 'Canceling goal...' in output, output
    said = [line.strip() for line in lines if 'Exception while canceling goal' in line]
    assert said in ([], ['Exception while canceling goal: None']), output   # the CLI's own
    # the server took the cancel: the goal CANCELED, the move STOPPED, the finger still
    assert wait_until(lambda: watch.status_of(goal_id) == GoalStatus.STATUS_CANCELED, WAIT_S)
    assert wait_until(lambda: watch.grip is not None and watch.grip.message == 'stopped', WAIT_S)
    assert not graph.supervisor.logic.running
    for sub in watch.subs:
        graph.run_in_executor(lambda s=sub: graph.client_node.destroy_subscription(s))


def test_the_server_answers_a_cancel_naming_the_goal_it_cancels(graph):
    """What send_goal checks of the answer, with a client whose context is still up."""
    assert graph.set_object(0.0, open_fingers=True).success
    client = graph.run_in_executor(lambda: ActionClient(
        graph.client_node, ParallelGripperCommand,
        qualified(graph.namespace, ACTION_GRIPPER_CMD)))
    try:
        assert client.wait_for_server(timeout_sec=30.0)
        moving = threading.Event()
        command = JointState(name=[graph.move_action_server.joint_name], position=[0.14],
                             velocity=[0.01])
        handle = wait_future(client.send_goal_async(
            ParallelGripperCommand.Goal(command=command),
            feedback_callback=lambda _f: moving.set()))
        assert handle.accepted and moving.wait(WAIT_S)
        answer = wait_future(handle.cancel_goal_async())
        assert answer.return_code == CancelGoal.Response.ERROR_NONE
        assert [bytes(g.goal_id.uuid) for g in answer.goals_canceling] == [
            bytes(handle.goal_id.uuid)]
        assert wait_future(handle.get_result_async()).status == GoalStatus.STATUS_CANCELED
    finally:
        graph.run_in_executor(client.destroy)
