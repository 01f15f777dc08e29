"""MoveIt's three gripper handles, played over DDS with docs/MOVEIT.md's configuration.

Follows moveit/moveit2 (Jazzy), ``moveit_plugins/moveit_simple_controller_manager``:
``src/moveit_simple_controller_manager.cpp`` (which YAML keys each handle reads, and their
defaults), ``include/.../action_based_controller_handle.hpp`` (the action's name
``<controller>/<action_ns>`` in move_group's namespace; the result code to an ExecutionStatus),
``gripper_command_controller_handle.hpp`` (the last point's position of the command joint, the
point's effort else ``max_effort``; ``allow_failure``), ``parallel_gripper_command_controller_
handle.hpp`` (a JointState of ``joints[0]``, velocity and effort only when above 0) and
``src/follow_joint_trajectory_controller_handle.cpp`` (the trajectory as planned, no
tolerances); and ``moveit_ros/planning``: ``trajectory_execution_manager.cpp`` (an execution
longer than its plan x 1.1 + 0.5 s is cancelled: TIMED_OUT), ``current_state_monitor.cpp``
(``joint_states`` in move_group's namespace, SystemDefaultsQoS; ``waitForCurrentState(now)``)
and ``time_optimal_trajectory_generation.cpp`` (a plan sampled every 0.1 s with positions,
velocities and accelerations: for one joint between two states, the trapezoid of its
velocity and acceleration limits).

move_group is a node with ``use_sim_time`` in namespace ``/moveit_test``; the gripper runs in
``/moveit_test/gripper`` (its controller name ``gripper``) with its ``joint_states`` remapped to
move_group's, as docs/MOVEIT.md says. Known answers: what MoveIt reports for each handle, the
doc's settings and the motor's bounds the doc states.
"""
from __future__ import annotations

import math
import re
import threading
import xml.etree.ElementTree as ET

from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import stamp_ns, TimeMode
from helpers import REPO, wait_future
import pytest
from rclpy.action import ActionClient
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_system_default
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
import yaml

control_msgs = pytest.importorskip('control_msgs.action', reason='control_msgs is not '
                                   'installed (the ros-jazzy wheels have none; the overlay has)')
import rclpy  # noqa: E402, I100 - after the skip

DOC = (REPO / 'docs' / 'MOVEIT.md').read_text(encoding='utf-8')
CONFIG = load_config()
P = CONFIG.plant
MOVE_GROUP_NS = '/moveit_test'
SEC = 1_000_000_000
WAIT_S = 240.0
SCALING, MARGIN_S = 1.1, 0.5          # allowed_execution_duration_scaling, _goal_duration_margin
RESAMPLE_S = 0.1                       # TOTG's resample_dt
OBJECT_M = 0.05


def _blocks(language: str) -> list[str]:
    return re.findall(rf'```{language}\n(.*?)```', DOC, re.DOTALL)


def _controllers() -> dict[str, tuple[str, dict]]:
    """Return {type: (controller name, its keys)} of the doc's moveit_controllers.yaml."""
    found = {}
    for text in _blocks('yaml'):
        data = yaml.safe_load(text)
        if isinstance(data, dict) and 'moveit_simple_controller_manager' in data:
            assert data['moveit_controller_manager'] == \
                'moveit_simple_controller_manager/MoveItSimpleControllerManager'
            manager = data['moveit_simple_controller_manager']
            (name,) = manager['controller_names']
            found[manager[name]['type']] = (name, manager[name])
    return found


CONTROLLERS = _controllers()
LIMITS = next(yaml.safe_load(t)['joint_limits']['finger_joint'] for t in _blocks('yaml')
              if 'joint_limits' in t)
SERVER_PARAMETERS = next(yaml.safe_load(t) for t in _blocks('yaml') if 'ros__parameters' in t)
SRDF = ET.fromstring('<robot>' + _blocks('xml')[0] + '</robot>')
STATES = {s.get('name'): float(s.find('joint').get('value'))
          for s in SRDF.iter('group_state')}


# ====================================================================== the doc's numbers
def test_the_doc_configures_each_handle_as_moveit_reads_it():
    assert set(CONTROLLERS) == {'GripperCommand', 'ParallelGripperCommand',
                                'FollowJointTrajectory'}
    read = {'GripperCommand': {'max_effort', 'allow_failure', 'command_joint', 'parallel'},
            'ParallelGripperCommand': {'max_effort', 'max_velocity'},
            'FollowJointTrajectory': set()}
    for kind, (_, keys) in CONTROLLERS.items():
        assert set(keys) - {'type', 'action_ns', 'joints', 'default'} <= read[kind], kind
        assert keys['joints'] == ['finger_joint']
    assert STATES == {'open': 0.0, 'close': P.max_travel_m}


def test_the_docs_joint_limits_need_at_most_80_percent_of_the_voltage():
    """A trapezoid's worst point: full speed still accelerating, (v + tau a) / (V per m/s)."""
    v, a = LIMITS['max_velocity'], LIMITS['max_acceleration']
    volts = (v + P.mechanical_time_constant_s * a) / P.free_speed_per_volt_mps
    assert volts <= 0.8 * P.voltage_limit_v
    said = re.search(r'need at most (\d+\.\d) V \((\d+) % of 24 V\)', DOC)
    assert said and float(said.group(1)) == round(volts, 1)
    assert int(said.group(2)) == int(100 * volts / P.voltage_limit_v)
    planned = re.search(r'a full close is planned at (\d+\.\d) s', DOC)
    assert float(planned.group(1)) == round(_trapezoid(0.0, P.max_travel_m)[-1][0], 1)


def test_the_docs_effort_caps_the_speed_as_it_says():
    """The effort's stall voltage caps the voltage; the free speed at it caps the speed."""
    for effort_n, volts, speed in re.findall(r'At (\d+) N \((\d+\.\d) V\) the finger moves at '
                                             r'up to (\d\.\d+) m/s', DOC) + re.findall(
            r'at (\d+) N \((\d+\.\d) V\) it moves at (\d\.\d+) m/s', DOC):
        cap_v = float(effort_n) / P.stall_force_per_volt_n
        assert float(volts) == round(cap_v, 1)
        assert float(speed) == round(cap_v * P.free_speed_per_volt_mps, 3)
    efforts = {keys.get('max_effort') for kind, (_, keys) in CONTROLLERS.items()
               if kind != 'FollowJointTrajectory'}
    assert efforts == {20.0}
    assert 20.0 / P.stall_force_per_volt_n * P.free_speed_per_volt_mps > LIMITS['max_velocity']


# ====================================================================== move_group's side
def _trapezoid(p0: float, p1: float) -> list[tuple[float, float, float, float]]:
    """Return TOTG's samples (t, p, v, a) of p0 -> p1 under the doc's joint limits."""
    v_max, a_max = LIMITS['max_velocity'], LIMITS['max_acceleration']
    d, sign = abs(p1 - p0), math.copysign(1.0, p1 - p0)
    t_a = min(v_max / a_max, math.sqrt(d / a_max))        # a triangle when short
    v_top = a_max * t_a
    t_c = (d - a_max * t_a ** 2) / v_top if v_top > 0.0 else 0.0
    total = 2 * t_a + t_c

    def at(t):
        if t < t_a:
            return a_max * t ** 2 / 2, a_max * t, a_max
        if t < t_a + t_c:
            return a_max * t_a ** 2 / 2 + v_top * (t - t_a), v_top, 0.0
        r = total - t
        return d - a_max * r ** 2 / 2, a_max * r, -a_max
    times = [min(k * RESAMPLE_S, total) for k in range(math.ceil(total / RESAMPLE_S) + 1)]
    out = []
    for t in times:
        s, v, a = at(t)
        out.append((t, p0 + sign * s, sign * v if t < total else 0.0, sign * a))
    return out


def _duration(t_s: float) -> Duration:
    ns = round(t_s * SEC)
    return Duration(sec=ns // SEC, nanosec=ns % SEC)


def _joint_trajectory(samples, joint='finger_joint') -> JointTrajectory:
    traj = JointTrajectory(joint_names=[joint])
    for t, p, v, a in samples:
        traj.points.append(JointTrajectoryPoint(positions=[p], velocities=[v], accelerations=[a],
                                                time_from_start=_duration(t)))
    return traj


SUCCEEDED, ABORTED, PREEMPTED = 'SUCCEEDED', 'ABORTED', 'PREEMPTED'


def _execution_status(code: int) -> str:
    """``finishControllerExecution``: the goal's status -> MoveIt's ExecutionStatus."""
    return {GoalStatus.STATUS_SUCCEEDED: SUCCEEDED, GoalStatus.STATUS_ABORTED: ABORTED,
            GoalStatus.STATUS_CANCELED: PREEMPTED}.get(code, 'FAILED')


class Handle:
    """``ActionBasedControllerHandle``: the action ``<name>/<action_ns>`` of one controller."""

    def __init__(self, node, name: str, keys: dict):
        action = {'GripperCommand': control_msgs.GripperCommand,
                  'ParallelGripperCommand': control_msgs.ParallelGripperCommand,
                  'FollowJointTrajectory': control_msgs.FollowJointTrajectory}[keys['type']]
        self.action, self.keys, self.joints = action, keys, keys['joints']
        self.client = ActionClient(node, action, f'{name}/{keys["action_ns"]}')

    def goal(self, traj: JointTrajectory):
        """``sendTrajectory``: the goal this handle makes of a planned trajectory."""
        keys, last = self.keys, traj.points[-1]
        goal = self.action.Goal()
        if keys['type'] == 'GripperCommand':
            command_joint = keys.get('command_joint', self.joints[0])
            i = traj.joint_names.index(command_joint) if command_joint in traj.joint_names else 0
            goal.command.position = last.positions[i]
            goal.command.max_effort = (last.effort[i] if len(last.effort) > i
                                       else float(keys.get('max_effort', 0.0)))
        elif keys['type'] == 'ParallelGripperCommand':
            i = traj.joint_names.index(self.joints[0])
            goal.command.name = [self.joints[0]]
            goal.command.position = [last.positions[i]]
            if keys.get('max_velocity', 0.0) > 0.0:
                goal.command.velocity = [float(keys['max_velocity'])]
            if keys.get('max_effort', 0.0) > 0.0:
                goal.command.effort = [float(keys['max_effort'])]
        else:
            goal.trajectory = traj
        return goal

    def done(self, status: int) -> str:
        """``controllerDoneCallback``: GripperCommand's ``allow_failure`` takes ABORTED."""
        if self.keys['type'] == 'GripperCommand' and status == GoalStatus.STATUS_ABORTED and \
                self.keys.get('allow_failure', False):
            return SUCCEEDED
        return _execution_status(status)


class MoveGroup:
    """move_group's clock (``use_sim_time``) and its CurrentStateMonitor on ``joint_states``."""

    def __init__(self, context):
        self.node = rclpy.create_node('move_group', namespace=MOVE_GROUP_NS, context=context,
                                      parameter_overrides=[Parameter('use_sim_time',
                                                                     value=True)])
        self.lock = threading.Lock()
        self.joint_time: dict[str, int] = {}    # joint -> stamp of its newest update
        self.positions: dict[str, float] = {}
        self.current_state_ns = -1
        self.node.create_subscription(JointState, 'joint_states', self._on_joint_states,
                                      qos_profile_system_default)

    def _on_joint_states(self, msg: JointState) -> None:
        if len(msg.name) != len(msg.position):
            return
        with self.lock:
            self.current_state_ns = stamp_ns(msg.header.stamp)
            for name, position in zip(msg.name, msg.position):
                self.joint_time[name] = self.current_state_ns
                self.positions[name] = position

    def now_ns(self) -> int:
        return self.node.get_clock().now().nanoseconds

    def wait_for_current_state(self, joint: str) -> float:
        """``waitForCurrentState(now(), 1.0)``: a state stamped at or after now; its position."""
        t_ns = self.now_ns()
        assert t_ns > 0, 'move_group has no /clock'
        assert wait_until(lambda: self.current_state_ns >= t_ns, WAIT_S)
        with self.lock:
            assert self.joint_time[joint] >= t_ns and self.current_state_ns - t_ns <= SEC
            return self.positions[joint]


@pytest.fixture(scope='module')
def setup():
    context = Context()
    rclpy.init(context=context, args=[
        '--ros-args', '-r', f'{MOVE_GROUP_NS}/gripper/joint_states:={MOVE_GROUP_NS}/joint_states'])
    graph = None
    try:
        graph = GripperGraph(GraphOptions(namespace=MOVE_GROUP_NS.strip('/') + '/gripper',
                                          prefix='', time_mode=TimeMode.REALTIME.parameter),
                             context=context)
        move_group = graph.run_in_executor(lambda: MoveGroup(context))
        graph.add_node(move_group.node)
        handles = {kind: graph.run_in_executor(lambda n=name, k=keys: Handle(move_group.node, n,
                                                                             k))
                   for kind, (name, keys) in CONTROLLERS.items()}
        for handle in handles.values():
            assert handle.client.wait_for_server(timeout_sec=30.0)
        yield graph, move_group, handles
    finally:
        if graph is not None:
            graph.close()
        rclpy.try_shutdown(context=context)


def _server_settings(graph, stalling_allowed: bool) -> None:
    """Set move_action_server's parameters: the doc's params file, or the upstream default."""
    doc = SERVER_PARAMETERS['/gripper/move_action_server']['ros__parameters']
    assert doc == {'allow_stalling': True}
    graph.move_action_server.set_parameters(
        [Parameter('allow_stalling', value=stalling_allowed)])


def _execute(setup, kind: str, state: str, keys: dict | None = None) -> str:
    """Plan from the current state to the SRDF ``state``, execute it as MoveIt; its status.

    The execution must end within MoveIt's bound, on move_group's clock.
    """
    graph, move_group, handles = setup
    handle = handles[kind]
    if keys is not None:
        handle.keys = {**handle.keys, **keys}
    start_m = move_group.wait_for_current_state('finger_joint')
    samples = _trapezoid(start_m, STATES[state])
    bound_ns = round((samples[-1][0] * SCALING + MARGIN_S) * SEC)
    began_ns = move_group.now_ns()
    goal_handle = wait_future(handle.client.send_goal_async(
        handle.goal(_joint_trajectory(samples))), WAIT_S)
    assert goal_handle.accepted
    wrapped = wait_future(goal_handle.get_result_async(), WAIT_S)
    took_ns = move_group.now_ns() - began_ns
    assert took_ns <= bound_ns, f'TIMED_OUT: {took_ns / SEC:.2f} s > {bound_ns / SEC:.2f} s'
    return handle.done(wrapped.status)


@pytest.mark.parametrize('kind', ['GripperCommand', 'ParallelGripperCommand',
                                  'FollowJointTrajectory'])
def test_open_and_a_grasp_that_stalls_succeed_with_the_docs_settings(setup, kind):
    graph = setup[0]
    _server_settings(graph, stalling_allowed=True)
    assert wait_until(lambda: not graph.supervisor.logic.running, WAIT_S)
    assert graph.set_object(OBJECT_M, open_fingers=True).success
    assert _execute(setup, kind, 'close') == SUCCEEDED               # stalled on the object
    assert abs(graph.supervisor._tick.position_m - (P.max_travel_m - OBJECT_M)) < 1e-6
    assert _execute(setup, kind, 'open') == SUCCEEDED


@pytest.mark.parametrize('kind, keys, status', [
    ('GripperCommand', {'allow_failure': False}, ABORTED),
    ('GripperCommand', {'allow_failure': True}, SUCCEEDED),
    ('ParallelGripperCommand', {}, ABORTED),
    ('FollowJointTrajectory', {}, SUCCEEDED)])
def test_a_grasp_that_stalls_as_upstream_by_default(setup, kind, keys, status):
    graph = setup[0]
    _server_settings(graph, stalling_allowed=False)
    assert wait_until(lambda: not graph.supervisor.logic.running, WAIT_S)
    assert graph.set_object(OBJECT_M, open_fingers=True).success
    assert _execute(setup, kind, 'close', keys) == status


def test_joint_states_reaches_move_group_on_its_clock(setup):
    _, move_group, _ = setup
    position = move_group.wait_for_current_state('finger_joint')
    assert 0.0 <= position <= P.max_travel_m
