"""move_action_server: the move as actions, ours and control_msgs' gripper commands.

A thin front end over the graph's ``move`` and ``stop`` services and ``supervisor/status``,
as ``grasp_action_server`` is for the grasp:

- ``move_action`` (gripper_interfaces/action/Move): a goal becomes a ``move`` call, feedback
  comes from the status (phase, position, opening, force), a cancel calls ``stop`` (the move
  ends STOPPED, the goal canceled). Succeeded only when the width was reached.
- ``gripper_cmd`` (control_msgs/action/ParallelGripperCommand), where control_msgs loads
  (:mod:`gripper_ros.nodes.control_actions`), so that MoveIt's parallel-gripper controller
  handle (``action_ns: gripper_cmd``) drives this gripper: the command's
  ``<prefix>finger_joint`` position (travel from fully open, m) and optional velocity and
  effort become the move (:mod:`gripper_ros.core.supervision.gripper_command`); a malformed
  command is rejected. The result is the finger's JointState, ``stalled`` and ``reached_goal``.
  Feedback and result are the finger's JointState, stamped with the simulated time of the
  newest status; its velocity is the newest ``joint_states`` sample's.
- ``gripper_action_controller/gripper_cmd`` (control_msgs/action/GripperCommand), where
  ros2_controllers' GripperActionController serves it, for MoveIt's gripper handle and the
  drivers that speak it: ``command.position`` (the joint's position) and ``max_effort`` (0: the
  motor's limit) become the move; the result is ``position``, ``effort`` (the force sensor's),
  ``stalled`` and ``reached_goal``, and so is the feedback (GripperActionController sends none).
- Either control_msgs goal succeeds on reaching the goal, and on a stall only with
  ``allow_stalling`` (as ros2_controllers' gripper controllers), else it is aborted.
- ``gripper_status`` (diagnostic_msgs/DiagnosticStatus, latched), for a ros2_control user who
  reads no gripper_interfaces message: ``idle`` from the gripper's first status on (a client of
  an idle gripper gets it at once), a request's ``moving`` (``grasping``, ``releasing``) with
  its id as soon as it starts, then how it ended (``supervisor/outcome`` in standard types),
  ``stalled`` and ``object_detected`` (the fingers press on an object) among its values. The
  supervisor serves ``joint_commands`` itself.

One goal at a time (the gripper does one request at a time). A control_msgs gripper goal while
another executes preempts it, as ros2_controllers' gripper controllers do
(``preempt_active_goal``): the running goal's move is stopped and that goal ends canceled, then
the new goal's move runs. A ``move_action`` goal while another executes is aborted at once
(REFUSED in our result). Feedback is throttled to ``feedback_period_s`` of wall time and sent
on every phase change.
"""
from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from gripper_interfaces.action import Move as MoveAction
from gripper_interfaces.msg import SupervisorStatus
from gripper_interfaces.srv import Move
from gripper_ros.core.supervision.gripper_command import (goal_end, GoalEnd,
                                                          grip_idle_fields,
                                                          grip_progress_fields,
                                                          grip_status_fields,
                                                          gripper_command_fields,
                                                          gripper_command_move_of,
                                                          joint_state_fields,
                                                          move_request_of, result_fields)
from gripper_ros.core.supervision.requests import check_move_limits, RequestError
from gripper_ros.nodes.actions import (accept_goal, cancel_by_stop, declare_feedback_period,
                                       end_preempted, joint_velocity_mps, NewestJoint,
                                       RunningGoal)
from gripper_ros.nodes.control_actions import (GripperCommand, not_served,
                                               ParallelGripperCommand, PROBLEM)
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import read_status, StatusView
from gripper_ros.nodes.parameters import declare_config, declare_prefix, follow
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import LATCHED_QOS, SERVICE_QOS
from gripper_ros.wire import (ACTION_FOLLOW_JOINT_TRAJECTORY, ACTION_GRIPPER_CMD,
                              ACTION_GRIPPER_COMMAND, ACTION_MOVE, FINGER_JOINT, NODE_MOVE_ACTION,
                              Outcome, Phase, ROBOT_NAME, SERVICE_MOVE, SERVICE_STOP, stamp_ns,
                              TOPIC_GRIPPER_STATUS, TOPIC_JOINT_STATES,
                              TOPIC_OUTCOME, TOPIC_STATUS)
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionServer, GoalResponse
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger


_REQUEST_FIELDS = ('width_m', 'speed_mps', 'max_effort_n', 'timeout_s')
_RESULT_FIELDS = ('success', 'outcome', 'message', 'position_m', 'width_m', 'effort_n',
                  'stalled', 'reached_goal', 'grasp_id')


class MoveActionServer(GripperNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_MOVE_ACTION, **kwargs)
        config = declare_config(self)
        self.plant = config.plant                     # read-only: the supervisor's move
        self.travel_m = self.plant.max_travel_m       # settings are judged by the supervisor
        self.feedback_period_s = declare_feedback_period(self)
        self.allow_stalling = self.declare_parameter(
            'allow_stalling', False, ParameterDescriptor(
                description=f'{ACTION_GRIPPER_CMD} and {ACTION_GRIPPER_COMMAND}: a stalled move '
                            '(blocked by an object at the effort limit) succeeds rather than '
                            'aborts')).value
        follow(self, {'feedback_period_s': float, 'allow_stalling': bool})   # next status
        self._move = self.create_client(Move, SERVICE_MOVE, qos_profile=SERVICE_QOS)
        self._stop = self.create_client(Trigger, SERVICE_STOP, qos_profile=SERVICE_QOS)
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self._status_data: bytes | None = None   # the newest status, read when needed
        self.running = RunningGoal()
        self._feedback = None             # makes the running goal's feedback from a status
        self._running_ended = Future()    # done once the running goal's move has answered
        self._running_ended.set_result(None)
        self._newest_goal = None          # the goal accepted last (it preempts the others)
        self._preempted: set[int] = set()   # ids of the goal handles a newer goal preempted
        self.own(ActionServer(self, MoveAction, ACTION_MOVE, execute_callback=self._execute_move,
                              goal_callback=accept_goal, cancel_callback=self._on_cancel))
        self.gripper_command_served = ParallelGripperCommand is not None
        if PROBLEM:      # the graph's trajectory action is not served either: one line for all
            self.get_logger().warning(not_served((ACTION_GRIPPER_CMD, ACTION_GRIPPER_COMMAND,
                                                  ACTION_FOLLOW_JOINT_TRAJECTORY)))
        self.joint_name = declare_prefix(self) + FINGER_JOINT
        self._joint = NewestJoint(self.joint_name)
        self.graph_subscription(JointState, TOPIC_JOINT_STATES, self._joint.keep)
        self.detect_n = config.force_sensor.activation_force_n    # the sensor feels a press
        self._announced_id = -1                  # the request whose start gripper_status said
        self._grip_status_pub = self.tapped_publisher(DiagnosticStatus, TOPIC_GRIPPER_STATUS,
                                                      LATCHED_QOS)
        self.grip_statuses_published = 0
        self.latched: dict = {}
        """The newest gripper_status, as a late subscriber gets it (a recording, a live view)."""
        self.create_subscription(SupervisorStatus, TOPIC_OUTCOME, self._on_outcome, LATCHED_QOS,
                                 raw=True)
        if self.gripper_command_served:
            self.own(ActionServer(self, ParallelGripperCommand, ACTION_GRIPPER_CMD,
                                  execute_callback=self._execute_gripper_command,
                                  goal_callback=self._check_gripper_command,
                                  cancel_callback=self._on_cancel))
            self.own(ActionServer(self, GripperCommand, ACTION_GRIPPER_COMMAND,
                                  execute_callback=self._execute_gripper_action,
                                  goal_callback=self._check_gripper_action,
                                  cancel_callback=self._on_cancel))

    # ------------------------------------------------------------------ goals
    def _check_gripper_command(self, goal_request) -> GoalResponse:
        """Reject a command that is no move of this gripper (as ros2_controllers does)."""
        try:
            check_move_limits(move_request_of(goal_request.command, self.travel_m,
                                              self.joint_name), self.plant)
        except RequestError as exc:
            self.get_logger().warning(f'{ACTION_GRIPPER_CMD} goal rejected: {exc}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _check_gripper_action(self, goal_request) -> GoalResponse:
        """Reject a GripperCommand that is no move of this gripper (bad numbers), saying why."""
        try:
            check_move_limits(gripper_command_move_of(goal_request.command, self.travel_m,
                                                      self.joint_name), self.plant)
        except RequestError as exc:
            self.get_logger().warning(f'{ACTION_GRIPPER_COMMAND} goal rejected: {exc}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle):
        """Cancel = stop the running move; the service then answers STOPPED."""
        return cancel_by_stop(goal_handle, self.running.handle, self._stop)

    async def _call_move(self, goal_handle, request: Move.Request, feedback,
                         preempts: bool = False) -> Move.Response:
        """Return the move service's answer for this goal.

        When busy: REFUSED, uncalled; with ``preempts``, the running goal's move is stopped
        first and this goal's move runs once that goal has ended (a newer goal preempting
        this one meanwhile ends it STOPPED, uncalled).
        """
        if preempts:
            self._newest_goal = goal_handle
            if self.running.handle is not None:
                await self._preempt_running()
            if self._newest_goal is not goal_handle:
                self._preempted.add(id(goal_handle))
                return self._answer_uncalled(Outcome.STOPPED, 'preempted by a newer goal')
        refusal = ''
        if not self._move.service_is_ready():
            refusal = f'{SERVICE_MOVE} is not available'
        elif self.running.handle is not None:
            refusal = 'refused: a move goal is already executing'
        if refusal:
            return self._answer_uncalled(Outcome.REFUSED, refusal)
        self.running.start(goal_handle)
        self._feedback = feedback
        self._running_ended = Future(executor=self.executor)
        try:
            return await self._move.call_async(request)
        finally:
            self.running.end()
            self._feedback = None
            self._running_ended.set_result(None)

    async def _preempt_running(self) -> None:
        """Stop the running goal's move, mark that goal preempted and wait until it ends."""
        self._preempted.add(id(self.running.handle))
        ended = self._running_ended
        if self._stop.service_is_ready():
            await self._stop.call_async(Trigger.Request())
        await ended

    def _answer_uncalled(self, outcome: Outcome, message: str) -> Move.Response:
        """Return an answer of the move service not called: the finger where it is now."""
        status = read_status(self._status_data) if self._status_data else None
        position_m = status.position_m if status is not None else 0.0
        return Move.Response(outcome=int(outcome), message=message, position_m=position_m,
                             width_m=self.travel_m - position_m,
                             effort_n=status.force_n if status is not None else 0.0)

    async def _execute_move(self, goal_handle) -> MoveAction.Result:
        goal = goal_handle.request
        request = Move.Request(**{f: getattr(goal, f) for f in _REQUEST_FIELDS})
        response = await self._call_move(goal_handle, request, self._move_feedback)
        result = MoveAction.Result(**{f: getattr(response, f) for f in _RESULT_FIELDS})
        self._end(goal_handle, goal_end(response, False, goal_handle.is_cancel_requested))
        return result

    async def _call_control_move(self, goal_handle, move, feedback, action: str):
        """Run a control_msgs goal's ``move`` as a preempting move; say a refusal in a line."""
        request = Move.Request(width_m=move.width_m, speed_mps=move.speed_mps,
                               max_effort_n=move.max_effort_n)
        response = await self._call_move(goal_handle, request, feedback, preempts=True)
        if response.outcome == Outcome.REFUSED:
            self.get_logger().warning(f'{action} goal aborted: {response.message}')
        return response

    async def _execute_gripper_command(self, goal_handle):
        move = move_request_of(goal_handle.request.command, self.travel_m,
                               self.joint_name)                     # checked at goal
        response = await self._call_control_move(goal_handle, move, self._gripper_feedback,
                                                 ACTION_GRIPPER_CMD)
        fields = result_fields(response, self._velocity_mps(), self.joint_name)
        result = ParallelGripperCommand.Result(
            state=JointState(header=self._status_header(), **fields.pop('state')), **fields)
        self._end_control_goal(goal_handle, response)
        return result

    async def _execute_gripper_action(self, goal_handle):
        move = gripper_command_move_of(goal_handle.request.command, self.travel_m,
                                       self.joint_name)                 # checked at goal
        response = await self._call_control_move(goal_handle, move,
                                                 self._gripper_action_feedback,
                                                 ACTION_GRIPPER_COMMAND)
        result = GripperCommand.Result(**gripper_command_fields(
            response.position_m, response.effort_n, response.stalled, response.reached_goal))
        self._end_control_goal(goal_handle, response)
        return result

    def _end_control_goal(self, goal_handle, response: Move.Response) -> None:
        """End a control_msgs goal: canceled when preempted, else by the move's answer."""
        if id(goal_handle) in self._preempted:
            self._preempted.discard(id(goal_handle))
            end_preempted(goal_handle)
        else:
            self._end(goal_handle, goal_end(response, self.allow_stalling,
                                            goal_handle.is_cancel_requested))

    @staticmethod
    def _end(goal_handle, end: GoalEnd) -> None:
        if end is GoalEnd.CANCELED:
            goal_handle.canceled()
        elif end is GoalEnd.SUCCEEDED:
            goal_handle.succeed()
        else:
            goal_handle.abort()

    # ------------------------------------------------------------------ feedback
    def _move_feedback(self, msg: StatusView) -> MoveAction.Feedback:
        return MoveAction.Feedback(
            grasp_id=msg.grasp_id, phase=msg.phase,
            elapsed_s=(stamp_ns(msg) - self.running.start_ns) * 1e-9,
            position_m=msg.position_m, width_m=self.travel_m - msg.position_m,
            force_n=msg.force_n)

    def _gripper_feedback(self, msg: StatusView):
        return ParallelGripperCommand.Feedback(state=JointState(
            header=self._status_header(msg),
            **joint_state_fields(msg.position_m, msg.force_n, self._velocity_mps(),
                                 self.joint_name)))

    @staticmethod
    def _gripper_action_feedback(msg: StatusView):
        return GripperCommand.Feedback(**gripper_command_fields(msg.position_m, msg.force_n))

    def _status_header(self, msg: StatusView | None = None) -> Header:
        """Return a header stamped with the simulated time of ``msg`` (the newest status)."""
        header = Header()
        if msg is None and self._status_data is not None:
            msg = read_status(self._status_data)
        if msg is not None:
            header.stamp.sec, header.stamp.nanosec = msg.sec, msg.nanosec
        return header

    # ------------------------------------------------------------------ gripper_status
    def _on_outcome(self, data: bytes) -> None:
        """Publish how the request ended as a DiagnosticStatus on gripper_status.

        The outcome of a request older than the one gripper_status already announced (a late
        delivery: outcomes come over DDS, statuses through the graph) is not the newest request's
        and is left out.
        """
        msg = read_status(data)
        if msg.grasp_id < self._announced_id:
            return
        self._announced_id = msg.grasp_id
        self._publish_grip_status(grip_status_fields(msg.outcome, msg.position_m, msg.force_n,
                                                     self.travel_m, msg.grasp_id, self.detect_n))

    def _publish_grip_status(self, fields: dict) -> None:
        msg = DiagnosticStatus(
            level=bytes([fields['level']]), name=self.joint_name, hardware_id=ROBOT_NAME,
            message=fields['message'],
            values=[KeyValue(key=k, value=v) for k, v in fields['values'].items()])
        self._grip_status_pub.publish(msg)
        self.latched[TOPIC_GRIPPER_STATUS] = msg
        self.grip_statuses_published += 1

    def _velocity_mps(self) -> float | None:
        """Return the finger's velocity in the newest joint_states sample (None before one)."""
        sample = self._joint.read()
        return joint_velocity_mps(*sample) if sample is not None else None

    def _on_status(self, data: bytes) -> None:
        self._status_data = data
        msg = read_status(data)
        if not self.grip_statuses_published and not msg.running:   # latched from the start
            self._publish_grip_status(grip_idle_fields(msg.position_m, msg.force_n,
                                                       self.travel_m, msg.grasp_id,
                                                       self.detect_n))
        if msg.running and msg.grasp_id > self._announced_id:     # a request has started
            self._announced_id = msg.grasp_id
            self._publish_grip_status(grip_progress_fields(
                msg.phase, msg.position_m, msg.force_n, self.travel_m, msg.grasp_id,
                self.detect_n))
        running, feedback = self.running, self._feedback
        if running.handle is None:
            return
        if running.feedback_due(msg, (Phase.MOVING,), self.feedback_period_s):
            running.handle.publish_feedback(feedback(msg))


def main(args=None):
    return run_node(MoveActionServer, NODE_MOVE_ACTION, args)


if __name__ == '__main__':
    sys.exit(main())
