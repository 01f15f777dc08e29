"""trajectory_action_server: FollowJointTrajectory for the finger, through the position servo.

Serves ``joint_trajectory_controller/follow_joint_trajectory``
(control_msgs/action/FollowJointTrajectory) where control_msgs loads, as ros2_controllers'
joint_trajectory_controller serves it for a joint with position, velocity and acceleration
commands (:mod:`gripper_ros.core.supervision.joint_trajectory` holds the numerics):

- A goal JTC would refuse (another joint, no points, times not increasing, a final velocity,
  efforts, an end in the past), or a point outside the travel, is rejected with one warning
  line; nothing moves.
- Each ``joint_states`` sample is an update, on its stamp (the gripper's clock: simulated time,
  /clock's under ``use_sim_time``): the trajectory is sampled for the next sample's time and
  that sample (position, velocity, acceleration) is sent to the supervisor's position servo on
  ``servo_setpoint``, which feeds the motor forward with them (between points of positions
  alone the servo estimates them from the samples instead: a straight segment's velocity steps
  at each point). A goal starts at once from the newest sample (the state before the
  trajectory: its position and velocity), or at its header's stamp, read on the node's clock.
- Path tolerance until the last point's time (PATH_TOLERANCE_VIOLATED), then the goal
  tolerance within ``constraints.goal_time`` (GOAL_TOLERANCE_VIOLATED; 0: it waits); success
  holds the last point, an abort or a cancel the measured position. A new goal preempts the
  running one (aborted, INVALID_GOAL, as JTC). Feedback (desired, actual, error) at most
  ``action_monitor_rate`` times per second of the gripper's clock.
- The gripper has one command in force: when a request of another client (``stop``, a grasp,
  a move, a gripper action) ends the move the trajectory drives, the goal is aborted
  (INVALID_GOAL, the supervisor's reason) and the trajectory sends no more.

Parameters (JTC's names): ``constraints.goal_time``, ``constraints.stopped_velocity_tolerance``,
``constraints.<joint>.trajectory``, ``constraints.<joint>.goal``,
``allow_nonzero_velocity_at_trajectory_end`` (settable at run time, for the next goal) and
``action_monitor_rate``.
"""
from __future__ import annotations

import math
import sys
from types import SimpleNamespace

from gripper_interfaces.msg import ServoSetpoint, SupervisorStatus
from gripper_ros.core.supervision.joint_trajectory import (check_trajectory, default_tolerances,
                                                           resolve_tolerances, State,
                                                           Trajectory, TrajectoryError,
                                                           TrajectoryRun, Update, Verdict)
from gripper_ros.nodes.actions import joint_velocity_mps, NewestJoint
from gripper_ros.nodes.control_actions import (FollowJointTrajectory, JointTrajectoryPoint,
                                               not_served, PROBLEM)
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import read_status
from gripper_ros.nodes.parameters import declare_config, declare_prefix
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import LATCHED_QOS
from gripper_ros.nodes.stamps import duration_ns, ns_to_duration, ns_to_time
from gripper_ros.wire import (ACTION_FOLLOW_JOINT_TRAJECTORY, DEFAULT_STATE_RATE_HZ,
                              FINGER_JOINT, NODE_TRAJECTORY_ACTION, Outcome, Phase, stamp_ns,
                              TOPIC_JOINT_STATES, TOPIC_OUTCOME, TOPIC_SERVO_SETPOINT,
                              TOPIC_STATUS)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from sensor_msgs.msg import JointState

PREEMPTED = 'Current goal preempted by new incoming action.'
"""JTC's error_string of a goal a newer goal preempted (INVALID_GOAL)."""
OWN_OUTCOMES = frozenset({Outcome.MOVED, Outcome.STALLED})
"""How the trajectory's own moves end while it streams: nobody else took the gripper."""


def _point(state: State, time_from_start_ns: int) -> JointTrajectoryPoint:
    """Return ``state`` as a JointTrajectoryPoint (what is not known left empty)."""
    point = JointTrajectoryPoint(positions=[float(state.position)],
                                 time_from_start=ns_to_duration(time_from_start_ns))
    if state.velocity is not None:
        point.velocities = [float(state.velocity)]
    if state.acceleration is not None:
        point.accelerations = [float(state.acceleration)]
    return point


class _Goal:
    """An accepted goal: its run, how it ends (``done``), the ids of the moves it drives."""

    def __init__(self, handle, run: TrajectoryRun, executor):
        self.handle = handle
        self.run = run
        self.done = Future(executor=executor)   # (Verdict, message); Verdict None: canceled
        self.last_feedback_ns: int | None = None
        self.last_command: State | None = None
        self.first_id: int | None = None     # grasp ids from which its moves are counted
        self.move_ids: set[int] = set()      # the supervisor's moves it drove


class TrajectoryActionServer(GripperNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_TRAJECTORY_ACTION, **kwargs)
        config = declare_config(self)
        self.plant = config.plant
        self.joint_name = declare_prefix(self) + FINGER_JOINT
        joint = self.joint_name
        self._parameter_names = {
            'goal_time': 'constraints.goal_time',
            'stopped_velocity': 'constraints.stopped_velocity_tolerance',
            'trajectory': f'constraints.{joint}.trajectory',
            'goal': f'constraints.{joint}.goal',
            'nonzero_end': 'allow_nonzero_velocity_at_trajectory_end'}
        names = self._parameter_names
        nonnegative = [FloatingPointRange(from_value=0.0, to_value=1000.0)]
        for key, default, text in (
                ('goal_time', 0.0, 's after the last point by which the goal tolerance must '
                                   'hold (0: wait for it)'),
                ('stopped_velocity', 0.01, 'm/s: the goal tolerance of the velocity'),
                ('trajectory', 0.0, f'm: the path tolerance of {joint} (0: not checked)'),
                ('goal', 0.0, f'm: the goal tolerance of {joint} (0: not checked)')):
            self.declare_parameter(names[key], default, ParameterDescriptor(
                description=text, floating_point_range=nonnegative))
        self.declare_parameter(names['nonzero_end'], False, ParameterDescriptor(
            description='accept a goal whose last point has a velocity'))
        rate = ParameterDescriptor(
            description='feedback per second of the gripper clock at most', read_only=True,
            floating_point_range=[FloatingPointRange(from_value=0.1, to_value=1000.0)])
        self.monitor_rate_hz = self.declare_parameter('action_monitor_rate', 20.0, rate).value
        self._setpoints = self.graph_publisher(ServoSetpoint, TOPIC_SERVO_SETPOINT)
        self.setpoints_published = 0
        self._joint = NewestJoint(self.joint_name)
        self._read_ns = -1                       # the stamp of the newest one read
        self._period_ns = round(1e9 / DEFAULT_STATE_RATE_HZ)
        self.graph_subscription(JointState, TOPIC_JOINT_STATES, self._on_joint_state)
        self._status_data: bytes | None = None   # the newest status, read when needed
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self.create_subscription(SupervisorStatus, TOPIC_OUTCOME, self._on_outcome, LATCHED_QOS,
                                 raw=True)
        self._goal: _Goal | None = None
        self.served = FollowJointTrajectory is not None
        if PROBLEM:
            self.get_logger().warning(not_served((ACTION_FOLLOW_JOINT_TRAJECTORY,)))
        if self.served:
            self.own(ActionServer(self, FollowJointTrajectory, ACTION_FOLLOW_JOINT_TRAJECTORY,
                                  execute_callback=self._execute, goal_callback=self._check,
                                  cancel_callback=self._on_cancel))

    # ------------------------------------------------------------------ goals
    def _parameter(self, key: str):
        return self.get_parameter(self._parameter_names[key]).value

    def _check(self, goal_request) -> GoalResponse:
        """Reject what JTC's validate_trajectory_msg refuses, or what leaves the travel."""
        traj = goal_request.trajectory
        if self._sample() is None:
            self.get_logger().warning(f'{ACTION_FOLLOW_JOINT_TRAJECTORY} goal rejected: no '
                                      f'{TOPIC_JOINT_STATES} yet (the gripper is not running)')
            return GoalResponse.REJECT
        try:
            check_trajectory(traj.joint_names, self._points_of(traj), self.joint_name,
                             self.plant.max_travel_m, stamp_ns(traj.header.stamp),
                             self.get_clock().now().nanoseconds,
                             bool(self._parameter('nonzero_end')))
        except TrajectoryError as exc:
            self.get_logger().warning(f'{ACTION_FOLLOW_JOINT_TRAJECTORY} goal rejected: {exc}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    @staticmethod
    def _points_of(traj) -> list:
        return [SimpleNamespace(time_from_start_ns=duration_ns(p.time_from_start),
                                positions=p.positions, velocities=p.velocities,
                                accelerations=p.accelerations, effort=p.effort)
                for p in traj.points]

    def _tolerances(self, goal_request):
        defaults = default_tolerances(self._parameter('trajectory'), self._parameter('goal'),
                                      self._parameter('stopped_velocity'),
                                      self._parameter('goal_time'))
        return resolve_tolerances(defaults, self.joint_name, goal_request.path_tolerance,
                                  goal_request.goal_tolerance,
                                  duration_ns(goal_request.goal_time_tolerance) * 1e-9)

    async def _execute(self, goal_handle):
        request = goal_handle.request
        traj = request.trajectory
        points = check_trajectory(traj.joint_names, self._points_of(traj), self.joint_name,
                                  self.plant.max_travel_m,
                                  allow_nonzero_velocity_at_end=True)   # checked at goal
        sample = self._sample()
        start_ns = stamp_ns(traj.header.stamp)
        if start_ns:                 # the node's clock -> the gripper's (its joint_states)
            start_ns -= self.get_clock().now().nanoseconds - sample[0]
        tolerances, why_defaults = self._tolerances(request)
        if why_defaults:
            self.get_logger().error(why_defaults)
        goal = _Goal(goal_handle, TrajectoryRun(Trajectory(points, start_ns), tolerances),
                     self.executor)
        newest = read_status(self._status_data) if self._status_data is not None else None
        goal.first_id = newest.grasp_id + 1 if newest is not None else 0
        if self._goal is not None:            # the stream goes on: its moves are the new goal's
            goal.first_id, goal.move_ids = self._goal.first_id, set(self._goal.move_ids)
            self._finish(self._goal, Verdict.INVALID_GOAL, PREEMPTED)
        self._goal = goal
        self._read_ns = -1                      # the sample period is measured from here
        self._update(goal, *sample)             # at once: a paused simulation wakes
        verdict, message = await goal.done
        result = FollowJointTrajectory.Result(error_code=int(verdict or 0), error_string=message)
        if verdict is None:
            goal_handle.canceled()
        elif verdict is Verdict.SUCCESSFUL:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _on_cancel(self, goal_handle) -> CancelResponse:
        """Cancel the running goal: it ends canceled and the finger holds where it is."""
        goal = self._goal
        sample = self._sample()
        if goal is not None and goal.handle is goal_handle and sample is not None:
            t_ns, position, _ = sample
            self._hold(goal, State(position, 0.0, 0.0), t_ns)
            self._finish(goal, None, '')
        return CancelResponse.ACCEPT

    def _finish(self, goal: _Goal, verdict: Verdict | None, message: str) -> None:
        if self._goal is goal:
            self._goal = None
        if not goal.done.done():
            goal.done.set_result((verdict, message))

    # ------------------------------------------------------------------ updates
    def _on_joint_state(self, data: bytes) -> None:
        """Keep the newest sample of the joint; with a goal running, it is an update."""
        if self._joint.keep(data) and self._goal is not None:
            sample = self._sample()
            if sample is not None and math.isfinite(sample[1]):
                self._update(self._goal, *sample)

    def _sample(self) -> tuple[int, float, float | None] | None:
        """Return the newest sample (stamp ns, position, velocity or None); None before one."""
        sample = self._joint.read()
        if sample is None:
            return None
        msg, i = sample
        t_ns = stamp_ns(msg.header.stamp)
        if t_ns > self._read_ns >= 0 and self._goal is not None:   # between two updates
            self._period_ns = t_ns - self._read_ns
        self._read_ns = max(self._read_ns, t_ns)
        return t_ns, float(msg.position[i]), joint_velocity_mps(msg, i)

    def _update(self, goal: _Goal, t_ns: int, position: float, velocity: float | None) -> None:
        """Run one update of ``goal`` on the sample at ``t_ns``: command, feedback, verdict."""
        update = goal.run.update(t_ns, position, velocity, self._period_ns)
        if update.command is not None:
            traj = goal.run.trajectory
            linear = traj.points[0].velocity is None and update.command_ns < traj.end_ns
            self._send(goal, update.command, update.command_ns, motion_given=not linear)
        self._feedback(goal, update)
        if update.verdict is not None:
            if update.hold is not None:
                self._hold(goal, update.hold, t_ns)
            if update.verdict is Verdict.SUCCESSFUL:
                self.get_logger().info(f'{ACTION_FOLLOW_JOINT_TRAJECTORY}: {update.message}')
            else:
                self.get_logger().warning(f'{ACTION_FOLLOW_JOINT_TRAJECTORY}: {update.message}')
            self._finish(goal, update.verdict, update.message)

    def _send(self, goal: _Goal, state: State, sample_ns: int, motion_given: bool = True) -> None:
        """Send ``state`` (a sample of ``sample_ns``) to the position servo.

        Without ``motion_given`` (a linear segment between points of positions alone, whose
        velocity steps at each point) its velocity and acceleration are left to the servo to
        estimate from the stream, as a joint_commands stream's are.
        """
        nan = math.nan
        given = motion_given and state.velocity is not None
        msg = ServoSetpoint(name=self.joint_name, position_m=float(state.position),
                            velocity_mps=float(state.velocity) if given else nan,
                            acceleration_mps2=(float(state.acceleration) if given and
                                               state.acceleration is not None else nan),
                            speed_mps=float(self.plant.max_free_speed_mps), max_effort_n=0.0)
        msg.header.stamp = ns_to_time(sample_ns)
        self._setpoints.publish(msg)
        goal.last_command = state
        self.setpoints_published += 1

    def _hold(self, goal: _Goal, state: State, t_ns: int) -> None:
        """Hold ``state`` from now, unless it is what was last commanded."""
        if goal.last_command != state:
            self._send(goal, state, t_ns)

    def _feedback(self, goal: _Goal, update: Update) -> None:
        period_ns = 1e9 / self.monitor_rate_hz
        if goal.last_feedback_ns is not None and \
                update.t_ns - goal.last_feedback_ns < period_ns and update.verdict is None:
            return
        goal.last_feedback_ns = update.t_ns
        since_ns = update.t_ns - goal.run.trajectory.start_ns
        feedback = FollowJointTrajectory.Feedback(
            joint_names=[self.joint_name],
            desired=_point(update.desired, since_ns),
            actual=_point(update.actual, since_ns),
            error=_point(update.error, since_ns))
        feedback.header.stamp = ns_to_time(update.t_ns)
        goal.handle.publish_feedback(feedback)

    # ------------------------------------------------------------------ who is in command
    def _on_status(self, data: bytes) -> None:
        """Keep the newest status; with a goal running, note the moves its setpoints drive."""
        self._status_data = data
        goal = self._goal
        if goal is None or goal.last_command is None:
            return
        msg = read_status(data)
        if msg.running and msg.phase == Phase.MOVING and msg.grasp_id >= goal.first_id:
            goal.move_ids.add(msg.grasp_id)

    def _on_outcome(self, data: bytes) -> None:
        """Abort the goal when another client's request ended the move it drives."""
        msg = read_status(data)
        goal = self._goal
        if goal is None or msg.grasp_id not in goal.move_ids or msg.outcome in OWN_OUTCOMES:
            return
        text = deserialize_message(data, SupervisorStatus).message
        self._finish(goal, Verdict.INVALID_GOAL,
                     f'the gripper was taken over: move {msg.grasp_id} '
                     f'{Outcome(msg.outcome).name}: {text}')
        self.get_logger().warning(f'{ACTION_FOLLOW_JOINT_TRAJECTORY} goal aborted: move '
                                  f'{msg.grasp_id} {Outcome(msg.outcome).name}: {text}')


def main(args=None):
    return run_node(TrajectoryActionServer, NODE_TRAJECTORY_ACTION, args)


if __name__ == '__main__':
    sys.exit(main())
