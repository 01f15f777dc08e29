"""The gripper in a ROS system, over the real graph and DDS: its description, /tf, joint_commands.

One graph for the module: a late subscriber gets robot_description and /tf_static; a
JointState on ``joint_commands`` (what ros2_control's JointStateTopicSystem publishes) closes
the finger onto an object with the command's effort limit, joint_states' effort (the applied
force) never passes it, /tf follows the finger, gripper_status says idle from the start,
moving at once and then stalled on an object, and bad commands are refused without moving
anything.
"""
from __future__ import annotations

import math
import threading
import xml.etree.ElementTree as ET

from diagnostic_msgs.msg import DiagnosticStatus
from gripper_ros.core.config import load_config
from gripper_ros.core.description import urdf_text
from gripper_ros.core.supervision.gripper_command import grip_status_fields, JointCommandStream
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER,
                              Outcome, qualified, TOPIC_GRIPPER_STATUS, TOPIC_JOINT_COMMANDS,
                              TOPIC_JOINT_STATES, TOPIC_ROBOT_DESCRIPTION, TOPIC_TF,
                              TOPIC_TF_STATIC)
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

CONFIG = load_config()
TRAVEL_M = CONFIG.plant.max_travel_m
OBJECT_WIDTH_M = 0.05
EFFORT_N = 10.0
EFFORT_TOLERANCE = 0.05
"""How far the measured force may pass a move's effort limit (the rigid contact: none)."""


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        placed = g.set_object(OBJECT_WIDTH_M)
        assert placed.success, placed.message
        g.wait_still()
        yield g


class Listener:
    """The newest message of each topic a test node subscribes to."""

    def __init__(self, graph, topics: dict):
        self.newest, self.count = {}, dict.fromkeys(topics, 0)
        self.every = {topic: [] for topic in topics}
        self.lock = threading.Lock()
        node = graph.client_node
        for topic, (msgtype, qos) in topics.items():
            node.create_subscription(msgtype, qualified(graph.namespace, topic),
                                     lambda msg, t=topic: self._take(t, msg), qos)

    def _take(self, topic, msg) -> None:
        with self.lock:
            self.newest[topic] = msg
            self.every[topic].append(msg)
            self.count[topic] += 1


def _command(position, effort=(), velocity=(), name=(FINGER_JOINT,)) -> JointState:
    return JointState(name=list(name), position=list(position), velocity=list(velocity),
                      effort=list(effort))


def _publisher(graph):
    node = graph.client_node
    pub = node.create_publisher(JointState, qualified(graph.namespace, TOPIC_JOINT_COMMANDS),
                                GRAPH_QOS)
    assert wait_until(lambda: pub.get_subscription_count() > 0, 10.0)
    return pub


def test_a_late_subscriber_gets_the_description_and_the_fixed_finger(graph):
    seen = Listener(graph, {TOPIC_ROBOT_DESCRIPTION: (String, LATCHED_QOS),
                            TOPIC_TF_STATIC: (TFMessage, LATCHED_QOS)})
    assert wait_until(lambda: all(seen.count.values()), 10.0), seen.count
    assert seen.newest[TOPIC_ROBOT_DESCRIPTION].data == urdf_text(CONFIG)
    (fixed,) = seen.newest[TOPIC_TF_STATIC].transforms
    assert (fixed.header.frame_id, fixed.child_frame_id) == (FRAME_BASE, FRAME_FIXED_FINGER)
    assert fixed.transform.translation.x == pytest.approx(TRAVEL_M / 2)


@pytest.mark.parametrize('overrides, expected_ms', [
    ({}, [50, 100, 150, 200]),                                   # 20 Hz: every 50 ms
    ({'publish_frequency': 30.0}, [40, 80, 120, 160, 200]),      # 33 whole ms
    ({'ignore_timestamp': True}, list(range(0, 201, 10)))])
def test_description_paces_tf_and_stamps_tf_static_as_robot_state_publisher(
        overrides, expected_ms):
    """A transform per joint_states stamp at least 1000 / publish_frequency whole ms past the last.

    Follows ros/robot_state_publisher src/robot_state_publisher.cpp (3.3):
    ``callbackJointState`` (the first transform one interval past 0, every message with
    ``ignore_timestamp``) and ``publishFixedTransforms`` (/tf_static stamped with the node's
    time at start).
    """
    import time
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message
    from gripper_ros.nodes.description_node import DescriptionPublisher
    context = Context()
    rclpy.init(context=context)
    node = None
    try:
        before_ns = time.time_ns()
        node = DescriptionPublisher(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        (fixed,) = node.latched[TOPIC_TF_STATIC].transforms
        assert before_ns <= fixed.header.stamp.sec * 10**9 + fixed.header.stamp.nanosec <= \
            time.time_ns()
        published_ms = []
        for ms in range(0, 201, 10):                            # joint_states at 100 Hz
            state = _command([0.01])
            state.header.stamp.nanosec = ms * 1_000_000
            count = node.published[TOPIC_TF]
            node._on_joint_states(serialize_message(state))
            if node.published[TOPIC_TF] > count:
                published_ms.append(ms)
        assert published_ms == expected_ms
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('frequency', [0.0, 1000.5, math.nan])
def test_description_refuses_a_publish_frequency_out_of_range(frequency):
    """As robot_state_publisher, (0, 1000] Hz; 0 too, which divides by zero there."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from gripper_ros.nodes.description_node import DescriptionPublisher
    from gripper_ros.nodes.startup import StartupError
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(StartupError, match=r'"publish_frequency" must be in \(0, 1000\] Hz'):
            DescriptionPublisher(context=context, parameter_overrides=[
                Parameter('publish_frequency', value=frequency)])
    finally:
        rclpy.try_shutdown(context=context)


def test_a_joint_command_closes_on_the_object_with_its_effort_limit(graph):
    seen = Listener(graph, {TOPIC_TF: (TFMessage, GRAPH_QOS),
                            TOPIC_JOINT_STATES: (JointState, GRAPH_QOS)})
    status = Listener(graph, {TOPIC_GRIPPER_STATUS: (DiagnosticStatus, LATCHED_QOS)})
    supervisor = graph.supervisor
    taken, first_id = supervisor.joint_commands_taken, supervisor.logic.grasp_id + 1
    pub = _publisher(graph)
    command = _command([TRAVEL_M - 0.01], effort=[EFFORT_N])     # 1 cm past the object's face
    for _ in range(5):                       # a stream, as JointStateTopicSystem sends it
        pub.publish(command)
    assert wait_until(lambda: _values(status.newest.get(TOPIC_GRIPPER_STATUS)).get(
        'outcome') == 'STALLED', 60.0)
    graph.wait_still()
    assert supervisor.joint_commands_taken == taken + 1     # the repeats were no new moves
    with status.lock:
        reports = [r for r in status.every[TOPIC_GRIPPER_STATUS]
                   if _values(r)['grasp_id'] == str(first_id)]
    # the command's own status at once, then how it ended
    assert [(r.message, _values(r)['grasp_id']) for r in reports] == [
        ('moving', str(first_id)), ('stalled', str(first_id))]
    logic = supervisor.logic
    assert logic.outcome == Outcome.STALLED and logic.grasp_id == first_id, logic.message
    answer = _values(reports[-1])
    assert float(answer['width_m']) == pytest.approx(OBJECT_WIDTH_M, abs=1e-4)
    assert 0.9 * EFFORT_N <= float(answer['effort_n']) <= (1 + EFFORT_TOLERANCE) * EFFORT_N, \
        answer['effort_n']
    with seen.lock:
        (moving,) = seen.newest[TOPIC_TF].transforms
        at_stamp = [s for s in seen.every[TOPIC_JOINT_STATES]
                    if s.header.stamp == moving.header.stamp]
    assert (moving.header.frame_id, moving.child_frame_id) == (FRAME_BASE, FRAME_MOVING_FINGER)
    # the finger where the joint state of its stamp puts it (/tf is paced, 20 Hz of stamps)
    (state,) = at_stamp
    assert (moving.transform.translation.x, moving.transform.translation.y,
            moving.transform.translation.z) == graph.description.frames.moving_finger_xyz(
                state.position[0])
    # joint_states as JointStateTopicSystem reads it: position, velocity and effort of the joint
    with seen.lock:
        states = list(seen.every[TOPIC_JOINT_STATES])
    assert all(list(s.name) == [FINGER_JOINT] and len(s.position) == len(s.velocity) ==
               len(s.effort) == 1 for s in states)
    efforts = [s.effort[0] for s in states]
    assert max(efforts) <= EFFORT_N * (1 + EFFORT_TOLERANCE), max(efforts)   # the limit holds
    last = states[-1]
    assert last.position[0] == pytest.approx(TRAVEL_M - OBJECT_WIDTH_M, abs=1e-4)
    assert abs(last.velocity[0]) < CONFIG.supervisor.move_rest_speed_mps
    assert last.effort[0] == pytest.approx(float(answer['effort_n']), rel=1e-5)
    # effort is the force the plant applies (the shipped sensor has no noise)
    assert CONFIG.sensor_noise.force_noise_n == 0.0
    assert last.effort[0] == pytest.approx(graph.plant.plant.sample().force_n, rel=1e-9)
    assert last.effort[0] >= 0.9 * EFFORT_N
    # how it ended, for a ros2_control user: latched gripper_status, in standard types
    report = reports[-1]
    assert (report.level, report.name, report.message) == (DiagnosticStatus.OK, FINGER_JOINT,
                                                           'stalled')
    assert (answer['outcome'], answer['stalled'], answer['object_detected']) == \
        ('STALLED', 'true', 'true')


def _values(report) -> dict:
    return {kv.key: kv.value for kv in report.values} if report is not None else {}


def test_a_client_of_an_idle_gripper_gets_its_status_without_any_request():
    """gripper_status is latched from the start: idle, the finger fully open, no object.

    A subscriber that connects later, as a ros2_control user's node does, gets it at once
    (transient local, depth 1), before anything is asked of the gripper.
    """
    with GripperGraph.in_own_context(GraphOptions(namespace='idle_status')) as idle:
        assert wait_until(lambda: idle.move_action_server.grip_statuses_published == 1, 30.0)
        late = Listener(idle, {TOPIC_GRIPPER_STATUS: (DiagnosticStatus, LATCHED_QOS)})
        assert wait_until(lambda: late.count[TOPIC_GRIPPER_STATUS] == 1, 30.0)
        report = late.newest[TOPIC_GRIPPER_STATUS]
        assert (report.level, report.name, report.message) == (
            DiagnosticStatus.OK, idle.move_action_server.joint_name, 'idle')
        values = _values(report)
        assert (values['outcome'], values['stalled'], values['object_detected']) == \
            ('IDLE', 'false', 'false')
        assert (float(values['position_m']), float(values['width_m'])) == (0.0, TRAVEL_M)
        assert int(values['grasp_id']) == idle.supervisor.logic.grasp_id    # none asked since
        assert not idle.supervisor.logic.running


ACTIVATION_N = CONFIG.force_sensor.activation_force_n


@pytest.mark.parametrize('outcome, force_n, level, stalled, detected', [
    (Outcome.STALLED, 9.5, 0, 'true', 'true'), (Outcome.MOVED, 0.0, 0, 'false', 'false'),
    (Outcome.MOVED, 9.5, 0, 'false', 'true'), (Outcome.HOLDING, 9.5, 0, 'false', 'true'),
    (Outcome.STOPPED, 9.5, 1, 'false', 'true'), (Outcome.NO_OBJECT, 0.0, 1, 'false', 'false'),
    (Outcome.OBJECT_LOST, 9.5, 1, 'false', 'false'), (Outcome.FAULT, 9.5, 2, 'false', 'false'),
    (Outcome.MOVED, ACTIVATION_N, 0, 'false', 'true'),
    (Outcome.MOVED, ACTIVATION_N * 0.99, 0, 'false', 'false'),
])
def test_gripper_status_says_stalled_and_object_detected(outcome, force_n, level, stalled,
                                                         detected):
    """Say object_detected when the force sensor feels a press, whatever the request.

    The press is the sensor's activation force; an outcome that says there is no object wins.
    """
    fields = grip_status_fields(outcome, 0.1, force_n, TRAVEL_M, 7, ACTIVATION_N)
    assert fields['level'] == level and fields['message'] == outcome.name.lower()
    assert fields['values'] == {'outcome': outcome.name, 'stalled': stalled,
                                'object_detected': detected, 'position_m': '0.1',
                                'width_m': '0.05', 'effort_n': format(force_n, '.6g'),
                                'grasp_id': '7'}


def test_a_move_that_stalls_on_a_held_object_says_object_detected(graph):
    """Say object_detected for a move that stalls at once on a held object.

    The grasp holds more than 10 N; a move closing at 10 N stalls on the object at once: the
    status says stalled and object_detected, the force sensor pressed all along.
    """
    status = Listener(graph, {TOPIC_GRIPPER_STATUS: (DiagnosticStatus, LATCHED_QOS)})
    held = graph.grasp(OBJECT_WIDTH_M, 1.5)
    assert held.outcome == Outcome.HOLDING and held.final_force_n > EFFORT_N, held.message
    answer = graph.move(OBJECT_WIDTH_M - 0.01, max_effort_n=EFFORT_N)
    assert answer.outcome == Outcome.STALLED, answer.message
    assert wait_until(lambda: _values(status.newest.get(TOPIC_GRIPPER_STATUS)).get(
        'grasp_id') == str(answer.grasp_id) and status.newest[TOPIC_GRIPPER_STATUS].message ==
        'stalled', 10.0)
    values = _values(status.newest[TOPIC_GRIPPER_STATUS])
    assert (values['stalled'], values['object_detected']) == ('true', 'true')


@pytest.mark.parametrize('command', [
    _command([math.nan]), _command([math.inf]), _command([-0.01]), _command([TRAVEL_M + 0.01]),
    _command([0.05], effort=[-1.0]), _command([0.05], effort=[math.nan]),
    _command([0.05], velocity=[-0.01]), _command([0.05], name=['other_joint']),
], ids=['nan', 'inf', 'negative', 'beyond_travel', 'negative_effort', 'nan_effort',
        'negative_velocity', 'other_joint'])
def test_a_bad_joint_command_is_refused_and_moves_nothing(graph, command):
    supervisor = graph.supervisor
    refused, taken = supervisor.joint_commands_refused, supervisor.joint_commands_taken
    grasp_id = supervisor.logic.grasp_id
    t_ns = graph.sim_time_ns
    _publisher(graph).publish(command)
    assert wait_until(lambda: supervisor.joint_commands_refused == refused + 1, 10.0)
    assert supervisor.joint_commands_taken == taken
    assert supervisor.logic.grasp_id == grasp_id and not supervisor.logic.pending
    assert graph.sim_time_ns == t_ns         # fast mode: no request, no time


def test_limits_beyond_the_motor_are_the_motors_own():
    """Take a velocity or effort entry beyond the motor as the motor's own limit.

    Above the free speed or the stall force at 24 V it is the motor's
    (parallel_gripper_action_controller's default max_velocity is 0.1 m/s).
    """
    stream = JointCommandStream(CONFIG.plant)
    move = stream.take(_command([0.05], velocity=[0.1], effort=[100.0]))
    assert move.speed_mps == CONFIG.plant.max_free_speed_mps
    assert move.max_effort_n == CONFIG.plant.max_force_n
    stream.accept(move)
    assert stream.take(_command([0.05], velocity=[0.2], effort=[50.0])) is None   # the same


def test_a_prefix_names_the_joint_of_joint_states_joint_commands_and_the_urdf():
    """The xacro's prefix:=left_ on the graph: left_finger_joint on the wire, left_ links."""
    options = GraphOptions(namespace='prefixed', prefix='left_')
    with GripperGraph.in_own_context(options) as g:
        assert g.set_object(OBJECT_WIDTH_M).success
        g.wait_still()
        seen = Listener(g, {TOPIC_JOINT_STATES: (JointState, GRAPH_QOS)})
        supervisor = g.supervisor
        pub = _publisher(g)
        pub.publish(_command([0.05]))                        # the unprefixed joint: refused
        assert wait_until(lambda: supervisor.joint_commands_refused == 1, 10.0)
        pub.publish(_command([TRAVEL_M - 0.01], effort=[EFFORT_N], name=['left_finger_joint']))
        assert wait_until(lambda: supervisor.logic.outcome == Outcome.STALLED, 60.0), \
            supervisor.logic.message
        with seen.lock:
            assert {tuple(s.name) for s in seen.every[TOPIC_JOINT_STATES]} == {
                ('left_finger_joint',)}
        root = ET.fromstring(g.description.urdf)
        assert {j.get('name') for j in root.iter('joint')} == {'left_finger_joint',
                                                               'left_fixed_finger_joint'}
        assert {link.get('name') for link in root.iter('link')} == {
            'left_gripper_base', 'left_fixed_finger', 'left_moving_finger'}
