"""FollowJointTrajectory goals the motor can follow are tracked within 1 mm, over DDS.

Follows ros-controls/ros2_controllers (Jazzy), joint_trajectory_controller:
``src/trajectory.cpp`` (a goal's points interpolated linearly with positions alone, by cubic
Hermite splines with velocities, quintic ones with accelerations) and
``src/joint_trajectory_controller.cpp`` (``update``: the trajectory sampled at each update for
the position, velocity and acceleration command interfaces), as the graph's
trajectory_action_server serves them on ``joint_trajectory_controller/follow_joint_trajectory``
and hands each sample to the position servo with its velocity and acceleration
(``servo_setpoint``). A client sends the goal as MoveIt's time parameterization does (points
0.1 s apart with velocities and accelerations), or with less: positions alone, velocities.

Known answers: each trajectory is a closed form (``studies/servo_runs.py``: a trapezoidal
velocity profile, a sine from rest to rest, a cubic spline through five knots sent as its four
knots, which JTC's cubic or quintic segments reproduce exactly) that needs at most 80 % of
24 V at any instant (its feed-forward's peak, ``k_v v + k_a a``, computed from the plant and
printed beside the error). The finger, moved to its start first, is held to the closed form at
every joint_states sample of the goal, as one move, and the goal succeeds.

The graph is ``grasp_demo --serve``'s (realtime); the client is rclpy's ActionClient in
another node.
"""
from __future__ import annotations

import threading

from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.services import wait_until
from gripper_ros.studies.servo_runs import needed_peak_v, Sine, Spline, Trapezoid
from gripper_ros.wire import qualified, stamp_ns, TimeMode, TOPIC_JOINT_STATES
from helpers import trajectory_action_client, wait_future
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectoryPoint

control_msgs = pytest.importorskip('control_msgs.action', reason='control_msgs is not '
                                   'installed (the ros-jazzy wheels have none; the overlay has)')

FollowJointTrajectory = control_msgs.FollowJointTrajectory
CONFIG = load_config()
P = CONFIG.plant
TRAVEL_M = P.max_travel_m
SEC = 1_000_000_000
WAIT_S = 180.0                 # wall time a goal may take on a slow machine
POINT_S = 0.1                  # the client's points: as MoveIt's time parameterization's
TOLERANCE_M = 1e-3

TRAJECTORIES = {
    'trapezoid': Trapezoid(0.01, 0.14, 0.036, 0.015),
    'sine': Sine(0.075, 0.06, 9.0),
    'spline': Spline(((0.0, 0.02), (4.0, 0.08), (6.0, 0.07), (10.0, 0.135), (14.0, 0.02))),
}
CASES = [('trapezoid', 'accelerations'), ('trapezoid', 'positions'),
         ('sine', 'accelerations'), ('sine', 'velocities'),
         ('spline', 'velocities'), ('spline', 'accelerations')]
"""(trajectory, what each point carries): the spline's knots need their velocities at least
(positions alone are joined by straight lines)."""


class States:
    """The joint_states read over DDS: (stamp ns, position)."""

    def __init__(self, graph):
        self.lock = threading.Lock()
        self.rows: list[tuple[int, float]] = []
        self.sub = graph.client_node.create_subscription(
            JointState, qualified(graph.namespace, TOPIC_JOINT_STATES), self._take,
            qos_profile_sensor_data)

    def _take(self, msg: JointState) -> None:
        with self.lock:
            self.rows.append((stamp_ns(msg.header.stamp), msg.position[0]))

    def between(self, start_ns: int, end_ns: int) -> np.ndarray:
        with self.lock:
            return np.array([row for row in self.rows if start_ns <= row[0] <= end_ns])


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(namespace='trajectory_tracking',
                                                  time_mode=TimeMode.REALTIME.parameter)) as g:
        yield g


@pytest.fixture(scope='module')
def client(graph):
    action = trajectory_action_client(graph)
    yield action
    graph.run_in_executor(action.destroy)


@pytest.fixture(scope='module')
def states(graph):
    rec = graph.run_in_executor(lambda: States(graph))
    assert wait_until(lambda: len(rec.rows) > 0, 30.0)
    yield rec
    graph.run_in_executor(lambda: graph.client_node.destroy_subscription(rec.sub))


def _duration(t_s: float) -> Duration:
    ns = round(t_s * SEC)
    return Duration(sec=ns // SEC, nanosec=ns % SEC)


def _goal(joint: str, trajectory, given: str):
    """Return the goal of ``trajectory``'s points, carrying ``given``.

    The first is its start at time 0 (as MoveIt's: the state it plans from); a spline's points
    are its knots, the others' POINT_S apart, the last at rest at the end (its acceleration the
    trajectory's as it arrives there).
    """
    if isinstance(trajectory, Spline):
        times = np.array([t for t, _ in trajectory.knots]) - trajectory.knots[0][0]
    else:
        count = int(np.ceil(trajectory.duration_s / POINT_S))
        times = np.minimum(np.arange(0, count + 1) * POINT_S, trajectory.duration_s)
    positions, velocities, accelerations = trajectory.at(times)
    accelerations[-1] = trajectory.at(np.nextafter(times[-1], 0.0))[2]    # as it arrives
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = [joint]
    for t_s, p, v, a in zip(times, positions, velocities, accelerations):
        point = JointTrajectoryPoint(positions=[float(p)], time_from_start=_duration(t_s))
        if given != 'positions':
            point.velocities = [float(v)]
        if given == 'accelerations':
            point.accelerations = [float(a)]
        goal.trajectory.points.append(point)
    return goal


@pytest.mark.parametrize('name,given', CASES)
def test_a_goal_within_80_percent_of_24_v_is_tracked_within_1_mm(graph, client, states, name,
                                                                 given):
    trajectory = TRAJECTORIES[name]
    needed_v = needed_peak_v(CONFIG, trajectory)
    assert needed_v <= 0.8 * P.voltage_limit_v
    if graph.supervisor.logic.running:               # a test that failed half-way
        graph.stop()
    assert graph.set_object(0.0, open_fingers=True).success
    moved = graph.move(TRAVEL_M - trajectory.start_m, 0.05)
    assert moved.reached_goal, moved.message
    before_id = graph.supervisor.logic.grasp_id
    feedback = []
    joint = graph.trajectory_action_server.joint_name
    handle = wait_future(client.send_goal_async(
        _goal(joint, trajectory, given), feedback_callback=lambda m: feedback.append(m.feedback)),
        WAIT_S)
    assert handle.accepted
    wrapped = wait_future(handle.get_result_async(), WAIT_S)
    assert wrapped.status == GoalStatus.STATUS_SUCCEEDED, wrapped.result.error_string
    assert graph.supervisor.logic.grasp_id == before_id + 1      # one move for the goal
    start_ns = stamp_ns(feedback[0].header.stamp)   # its first update: the trajectory starts
    assert (feedback[0].desired.time_from_start.sec,
            feedback[0].desired.time_from_start.nanosec) == (0, 0)
    rows = states.between(start_ns, start_ns + round(trajectory.duration_s * SEC))
    reference_m = trajectory.at((rows[:, 0] - start_ns) / SEC)[0]
    errors_m = np.abs(reference_m - rows[:, 1])
    worst_m = float(np.max(errors_m))
    print(f'{trajectory.name} ({given}), FollowJointTrajectory: needs {needed_v:.2f} V of '
          f'{P.voltage_limit_v:g} V, {len(rows)} joint_states samples, worst error '
          f'{worst_m * 1e3:.3f} mm at {(rows[np.argmax(errors_m), 0] - start_ns) / SEC:.2f} s')
    assert len(rows) >= 0.5 * trajectory.duration_s * 100     # 100 Hz, a share lost at most
    assert worst_m <= TOLERANCE_M
