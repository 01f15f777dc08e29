"""control_msgs' gripper commands in terms of a move, without control_msgs or rclpy.

ParallelGripperCommand: MoveIt's parallel-gripper handle sends a ``sensor_msgs/JointState``
command: the position of the gripper joint (here ``finger_joint``, the finger's travel from
fully open, m), optionally a most velocity and a most effort per joint (MoveIt fills them from
its ``max_velocity`` and ``max_effort``, none when 0), and names that may be empty. The result
is the gripper's state as a JointState and ``stalled`` and ``reached_goal``.

GripperCommand: MoveIt's gripper handle sends ``command.position``, the last trajectory point's
position of its command joint, and ``command.max_effort`` (the point's effort, else its
``max_effort``, 0 by default); ros2_controllers' GripperActionController commands that position
to the joint. The result is ``position``, ``effort``, ``stalled`` and ``reached_goal``.

The functions here map both ways on plain attributes, so the mapping is tested without
control_msgs; the action node fills the messages.
"""
from __future__ import annotations

import dataclasses
import enum
import math

from gripper_ros.core.supervision.requests import MoveRequest, RequestError
from gripper_ros.wire import FINGER_JOINT, Outcome, Phase


class GoalEnd(enum.Enum):
    """How an action goal ends."""

    SUCCEEDED = 'succeeded'
    ABORTED = 'aborted'
    CANCELED = 'canceled'


def move_request_of(command, travel_m: float, joint: str = FINGER_JOINT) -> MoveRequest:
    """Return the move a ParallelGripperCommand ``command`` (a JointState) asks for.

    With names, the entry named ``joint`` is used (other joints are refused: this gripper has
    one); without names, exactly one position. A velocity or effort entry that is missing or
    0 means the default speed and the motor's effort limit. RequestError says what is wrong;
    the ranges of speed and effort are checked with the move (``validate_move``).
    """
    names = list(command.name)
    positions = list(command.position)
    if names:
        others = sorted(set(names) - {joint})
        if others:
            raise RequestError(f'command names joints {others}; this gripper has one joint, '
                               f'{joint!r}')
        index = names.index(joint)
        if len(positions) <= index:
            raise RequestError(f'command names {names} but gives {len(positions)} positions')
    elif len(positions) != 1:
        raise RequestError(f'command must give one position (of {joint!r}), got '
                           f'{len(positions)}')
    else:
        index = 0
    position_m = positions[index]
    if not (isinstance(position_m, (int, float)) and math.isfinite(position_m)
            and 0.0 <= position_m <= travel_m):
        raise RequestError(f'position of {joint!r} must be in [0, {travel_m:g}] m (the travel '
                           f'of the finger from fully open), got {position_m!r}')
    velocities, efforts = list(command.velocity), list(command.effort)
    speed_mps = velocities[index] if len(velocities) > index else 0.0
    effort_n = efforts[index] if len(efforts) > index else 0.0
    return MoveRequest(travel_m - position_m, float(speed_mps), float(effort_n))


def gripper_command_move_of(command, travel_m: float,
                            joint: str = FINGER_JOINT) -> MoveRequest:
    """Return the move a GripperCommand ``command`` (``position``, ``max_effort``) asks for.

    ``position`` is the joint's: ``joint``'s travel from fully open (m), as MoveIt sends it and
    GripperActionController commands it (the action's comment calls it the gap). ``max_effort``
    0 (MoveIt's default) is the motor's effort limit; the speed is the default move speed.
    RequestError says what is wrong; the effort's range is checked with the move.
    """
    position_m, effort_n = command.position, command.max_effort
    if not (isinstance(position_m, (int, float)) and math.isfinite(position_m)
            and 0.0 <= position_m <= travel_m):
        raise RequestError(f'position of {joint!r} must be in [0, {travel_m:g}] m (the travel '
                           f'of the finger from fully open), got {position_m!r}')
    if not (isinstance(effort_n, (int, float)) and math.isfinite(effort_n)):
        raise RequestError(f"max_effort must be a finite number (N; 0: the motor's limit), "
                           f'got {effort_n!r}')
    return MoveRequest(travel_m - position_m, 0.0, float(effort_n))


def gripper_command_fields(position_m: float, effort_n: float, stalled: bool = False,
                           reached_goal: bool = False) -> dict:
    """Return GripperCommand's result (and feedback) fields: the joint's position, the force."""
    return {'position': float(position_m), 'effort': float(effort_n), 'stalled': bool(stalled),
            'reached_goal': bool(reached_goal)}


def joint_state_fields(position_m: float, effort_n: float, velocity_mps: float | None = None,
                       joint: str = FINGER_JOINT) -> dict:
    """Return the fields of the JointState that reports the gripper's state.

    The velocity is left empty (JointState's "not measured") only when none is known.
    """
    return {'name': [joint], 'position': [float(position_m)],
            'velocity': [] if velocity_mps is None else [float(velocity_mps)],
            'effort': [float(effort_n)]}


def result_fields(move_result, velocity_mps: float | None = None,
                  joint: str = FINGER_JOINT) -> dict:
    """Return ParallelGripperCommand.Result's fields from a srv/Move answer and the velocity."""
    return {'state': joint_state_fields(move_result.position_m, move_result.effort_n,
                                        velocity_mps, joint),
            'stalled': bool(move_result.stalled),
            'reached_goal': bool(move_result.reached_goal)}


def goal_end(move_result, allow_stalling: bool, cancel_requested: bool) -> GoalEnd:
    """Return how a goal ends after the move's answer ``move_result``.

    Succeeded on reaching the goal, or on a stall when stalls are allowed (as
    ros2_controllers' ``allow_stalling``); canceled when a cancel stopped the move.
    """
    if cancel_requested and move_result.outcome == Outcome.STOPPED:
        return GoalEnd.CANCELED
    if move_result.reached_goal or (allow_stalling and move_result.stalled):
        return GoalEnd.SUCCEEDED
    return GoalEnd.ABORTED


class JointCommandStream:
    """Which commands of a ``joint_commands`` stream are new setpoints.

    ros2_control's topic-based hardware publishes the command on every controller update while
    the joint is away from it; only a new setpoint (position, speed or effort) is a new request,
    a repeat of the one in force (the same numbers) is not. A command out of the travel or for
    another joint raises RequestError; the move's limits are judged once, by ``validate_move``
    (a refused setpoint never equals the one in force). A setpoint becomes the one in force
    only once accepted (:meth:`accept`), so that a refused one changes nothing.
    """

    def __init__(self, plant, joint: str = FINGER_JOINT):
        self.plant, self.joint = plant, joint
        self.last: MoveRequest | None = None

    def take(self, command) -> MoveRequest | None:
        """Return the move of ``command`` (a JointState) if it is a new setpoint, else None.

        Its velocity and effort are limits: one beyond the motor (faster than the free speed,
        more than the stall force at the voltage limit) is the motor's own; pass a new one to
        ``validate_move``.
        """
        move = move_request_of(command, self.plant.max_travel_m, self.joint)
        if math.isfinite(move.speed_mps) and math.isfinite(move.max_effort_n):
            move = dataclasses.replace(
                move, speed_mps=min(move.speed_mps, self.plant.max_free_speed_mps),
                max_effort_n=min(move.max_effort_n, self.plant.max_force_n))
        return None if move == self.last else move

    def accept(self, move: MoveRequest) -> None:
        """Make ``move`` the setpoint in force: its repeats are no new request."""
        self.last = move


_OK_OUTCOMES = frozenset({Outcome.MOVED, Outcome.STALLED, Outcome.HOLDING, Outcome.RELEASED})
_NO_OBJECT_OUTCOMES = frozenset({Outcome.NO_OBJECT, Outcome.OBJECT_LOST, Outcome.FAULT})
LEVEL_OK, LEVEL_WARN, LEVEL_ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""
PROGRESS_WORDS = {Phase.MOVING: 'moving', Phase.RELEASING: 'releasing',
                  Phase.POSITION: 'grasping', Phase.FORCE: 'grasping', Phase.HOLDING: 'grasping'}
"""What ``gripper_status`` says while a request runs, by its phase."""


def _status_values(outcome_word: str, force_n: float, detect_n: float, position_m: float,
                   travel_m: float, grasp_id: int, stalled: bool = False,
                   verdict_no_object: bool = False) -> dict:
    values = {'outcome': outcome_word, 'stalled': stalled,
              'object_detected': not verdict_no_object and force_n >= detect_n,
              'position_m': position_m, 'width_m': travel_m - position_m, 'effort_n': force_n,
              'grasp_id': grasp_id}
    return {k: (str(v).lower() if isinstance(v, bool) else
                format(v, '.6g') if isinstance(v, float) else str(v)) for k, v in values.items()}


def grip_status_fields(outcome: int, position_m: float, force_n: float, travel_m: float,
                       grasp_id: int, detect_n: float) -> dict:
    """Return the DiagnosticStatus fields of how a request ended, for ``gripper_status``.

    ``stalled``: the finger stopped short of its goal on the effort limit (a move STALLED, as
    GripperCommand's result). ``object_detected``: the fingers press on an object, whatever
    the request: the force sensor reads at least ``detect_n`` (its activation force), unless
    the outcome itself says there is none (NO_OBJECT, OBJECT_LOST, FAULT). Level OK for an
    outcome that did what was asked, ERROR for FAULT, WARN otherwise.
    """
    outcome = Outcome(outcome)
    level = LEVEL_OK if outcome in _OK_OUTCOMES else \
        LEVEL_ERROR if outcome is Outcome.FAULT else LEVEL_WARN
    return {'level': level, 'message': outcome.name.lower(),
            'values': _status_values(outcome.name, force_n, detect_n, position_m, travel_m,
                                     grasp_id, outcome is Outcome.STALLED,
                                     outcome in _NO_OBJECT_OUTCOMES)}


def grip_idle_fields(position_m: float, force_n: float, travel_m: float, grasp_id: int,
                     detect_n: float) -> dict:
    """Return the DiagnosticStatus fields of a gripper that has run no request since it started.

    Published once the gripper's first status comes, so that a client connecting to an idle
    gripper gets one at once: ``idle`` as the message and, upper case, the ``outcome`` value;
    ``grasp_id`` the last id given (0 for none); level OK.
    """
    return {'level': LEVEL_OK, 'message': 'idle',
            'values': _status_values('IDLE', force_n, detect_n, position_m, travel_m, grasp_id)}


def grip_progress_fields(phase: int, position_m: float, force_n: float, travel_m: float,
                         grasp_id: int, detect_n: float) -> dict:
    """Return the DiagnosticStatus fields of a request that has started and runs.

    Published at once, so that a client waits for its own request's id, then its outcome.
    The word (``moving``, ``grasping``, ``releasing``) is the message and, upper case, the
    ``outcome`` value; level OK.
    """
    word = PROGRESS_WORDS.get(Phase(phase), 'running')
    return {'level': LEVEL_OK, 'message': word,
            'values': _status_values(word.upper(), force_n, detect_n, position_m, travel_m,
                                     grasp_id)}
