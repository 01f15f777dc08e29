"""The move (srv/Move, action/Move, control_msgs ParallelGripperCommand's mapping).

A move drives the finger to a width with the request's speed and effort as the position
stage's limits. Known answers: the speed limit is never exceeded and is reached on a long move;
on a rigid object (the paper's contact: the force follows the motor torque) the finger stops at
the face and presses with exactly the stall force of the capped voltage, the effort limit; the
finger comes to rest within the tolerance of the width. The core is tested headless, the
service and the action over the live graph (fast mode), the ParallelGripperCommand mapping on
stand-in objects (no control_msgs).
"""
import math
import threading
import time
from types import SimpleNamespace

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.servo_feedforward import feedforward_gains
from gripper_ros.core.control.stages import PositionStageController
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.core.runtime.headless import MoveRequest, simulate_moves
from gripper_ros.core.runtime.lockstep import PlantSide, StageSide, SupervisorSide
from gripper_ros.core.supervision.gripper_command import (goal_end, GoalEnd, joint_state_fields,
                                                          move_request_of, result_fields)
from gripper_ros.core.supervision.requests import (GraspRequest, MoveTargets, RequestError,
                                                   validate_move, validate_request)
from gripper_ros.core.supervision.supervisor import GraspSupervisor, load_law
from gripper_ros.studies.servo_runs import stopping_m
from gripper_ros.wire import Controller, FINGER_JOINT, Outcome, Phase
import numpy as np
import pytest

CONFIG = load_config()
P, S = CONFIG.plant, CONFIG.supervisor
TRAVEL_M = P.max_travel_m
MS = 1_000_000
SPEED_SLACK = 1e-9          # relative: the cap holds the speed at the limit to rounding


def _targets(width_m=0.05, speed_mps=0.02, max_effort_n=0.0, timeout_s=0.0) -> MoveTargets:
    return validate_move(MoveRequest(width_m, speed_mps, max_effort_n, timeout_s), P, S)


# ====================================================================== request validation
def test_defaults_resolve_from_the_config():
    t = _targets(0.05, 0.0, 0.0)
    assert t.position_setpoint_m == pytest.approx(TRAVEL_M - 0.05)
    assert t.speed_mps == S.move_default_speed_mps
    assert t.max_effort_n == pytest.approx(P.max_force_n)   # the motor's limit ...
    assert t.voltage_limit_v == 0.0                          # ... is no cap below 24 V
    t = _targets(0.05, 0.02, 5.0)
    assert t.voltage_limit_v == pytest.approx(5.0 / P.stall_force_per_volt_n)
    assert _targets(0.0).position_setpoint_m == TRAVEL_M          # closed
    assert _targets(TRAVEL_M).position_setpoint_m == 0.0          # fully open


@pytest.mark.parametrize('fields, words', [
    ({'width_m': math.nan}, 'width_m must be a finite'),
    ({'speed_mps': math.inf}, 'speed_mps must be a finite'),
    ({'max_effort_n': -math.inf}, 'max_effort_n must be a finite'),
    ({'width_m': True}, 'width_m must be a finite'),
    ({'width_m': -1e-6}, 'width_m must be in'),
    ({'width_m': TRAVEL_M + 1e-6}, 'width_m must be in'),
    ({'speed_mps': -0.01}, 'speed_mps must be in'),
    ({'speed_mps': S.move_rest_speed_mps}, 'speed_mps must be in'),
    ({'speed_mps': P.max_free_speed_mps * 1.01}, 'speed_mps must be in'),
    ({'max_effort_n': -1.0}, 'max_effort_n must be in'),
    ({'max_effort_n': P.max_force_n * 1.01}, 'max_effort_n must be in'),
    ({'timeout_s': -1.0}, 'timeout_s must be in'),
    ({'timeout_s': 1e9}, 'timeout_s must be in'),
])
def test_bad_moves_are_refused_with_the_reason(fields, words):
    req = {'width_m': 0.05, 'speed_mps': 0.02, 'max_effort_n': 5.0}
    req.update(fields)
    with pytest.raises(RequestError, match=words):
        validate_move(MoveRequest(**req), P, S)


def test_a_move_is_refused_while_a_request_runs_and_may_follow_a_hold():
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    sup.request_grasp(validate_request(GraspRequest(0.05, 1.0), P, S), 1.0, after_ns=0)
    with pytest.raises(RequestError, match='already waiting'):
        sup.request_move(_targets())
    sup.step(10 * MS, 0.0, 0.0, 0.005)
    with pytest.raises(RequestError, match='grasp is running'):
        sup.request_move(_targets())
    sup.stop()
    sup.request_move(_targets(), after_ns=10 * MS)
    d = sup.step(20 * MS, 0.01, 0.0, 0.005)
    assert d.phase is Phase.MOVING and d.active is Controller.POSITION and d.running
    with pytest.raises(RequestError, match='move is running'):
        sup.request_move(_targets())
    assert (d.speed_limit_mps, d.voltage_limit_v) == (0.02, 0.0)


def test_stop_during_a_move_holds_the_finger_where_it_is():
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    sup.request_move(_targets(0.05, 0.02, 5.0), after_ns=0)
    sup.step(10 * MS, 0.0, 0.0, 0.005)
    sup.step(20 * MS, 0.0123, 0.0, 0.005, speed_mps=0.01)
    d = sup.stop()
    assert d.outcome is Outcome.STOPPED and d.active is Controller.POSITION
    assert d.position_setpoint_m == 0.0123                   # not back where the move began
    assert (d.speed_limit_mps, d.voltage_limit_v) == (0.0, 0.0)


def test_stop_ends_the_press_of_a_stalled_move_where_it_stalled():
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    sup.request_move(_targets(0.0, 0.02, 5.0), after_ns=0)
    sup.step(10 * MS, 0.0, 0.0, 0.005)
    d = sup.step(20 * MS, 0.1, 5.0, 3.0)               # at rest on an object, at the limit
    assert d.answer is Outcome.STALLED and sup.pressing
    assert (d.position_setpoint_m, d.speed_limit_mps) == (TRAVEL_M, 0.02)   # presses on
    assert d.voltage_limit_v == pytest.approx(5.0 / P.stall_force_per_volt_n)
    d = sup.stop()
    assert d.outcome is Outcome.STOPPED and not sup.pressing
    assert (d.position_setpoint_m, d.speed_limit_mps, d.voltage_limit_v) == (0.1, 0.0, 0.0)
    assert sup.stop() is None


# ====================================================================== setpoints (joint_commands)
def _setpoint(position_m, speed_mps=0.0, max_effort_n=0.0) -> MoveTargets:
    return _targets(TRAVEL_M - position_m, speed_mps, max_effort_n)


def test_a_setpoint_stream_is_one_move_whose_reference_moves_on_with_it():
    """Retarget the running setpoint move in place; the reference moves on with the stream.

    The stage is not restarted (one stage_id), the request keeps its id; while the setpoints
    of a 0.04 m/s ramp come, one each 10 ms tick, the reference is the newest moved on to the
    tick by the stream's velocity (a cubic fit: 0.04 m/s exactly), which the reference carries
    for the stage's feed-forward; once they stop it brakes to rest and stands at the setpoint.
    """
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    assert sup.request_servo(_setpoint(0.0), after_ns=0) is None
    d = sup.step(10 * MS, 0.0, 0.0, 0.005, speed_mps=0.001)
    assert d.running and sup.servo and sup.kind == 'move'
    grasp_id, stage_id = d.grasp_id, d.stage_id
    rate_mps = 0.04
    for k in range(1, 31):                      # a ramp, a setpoint at each 10 ms tick
        setpoint_m = rate_mps * k * 0.01
        assert sup.request_servo(_setpoint(setpoint_m)) is None
        d = sup.step((10 + 10 * k) * MS, 0.5 * setpoint_m, 0.0, 0.005, speed_mps=0.02)
        assert (d.grasp_id, d.stage_id, d.phase) == (grasp_id, stage_id, Phase.MOVING)
        assert d.position_setpoint_m == pytest.approx(setpoint_m)
    assert d.approach_setpoint_m == pytest.approx(setpoint_m + rate_mps * 0.01)
    assert d.approach_velocity_mps == pytest.approx(rate_mps)
    assert d.approach_acceleration_mps2 == pytest.approx(0.0, abs=1e-9)
    brake_ticks = math.ceil((S.servo_rate_window_s + rate_mps * feedforward_gains(P)[1]
                             / P.voltage_limit_v) / 0.01)
    for k in range(31, 32 + brake_ticks):       # the stream stops
        d = sup.step((10 + 10 * k) * MS, 0.5 * setpoint_m, 0.0, 0.005, speed_mps=0.02)
    assert d.approach_setpoint_m == pytest.approx(setpoint_m)
    assert d.approach_velocity_mps == 0.0
    assert (d.grasp_id, d.stage_id) == (grasp_id, stage_id)


def test_a_retargeted_setpoint_move_aims_at_the_newest_setpoint():
    """Give the newest setpoint as the targets, though nobody read them as the move started."""
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    sup.request_servo(_setpoint(0.01), after_ns=0)
    d = sup.step(10 * MS, 0.0, 0.0, 0.005)
    assert d.running and sup.servo
    assert sup.request_servo(_setpoint(0.03)) is None       # retargeted in place
    assert sup.targets.position_setpoint_m == pytest.approx(0.03)
    d = sup.step(20 * MS, 0.001, 0.0, 0.005, speed_mps=0.01)
    assert sup.targets.position_setpoint_m == pytest.approx(d.position_setpoint_m)


def test_a_setpoint_preempts_a_running_grasp_and_a_request_preempts_a_setpoint_move():
    sup = GraspSupervisor(P, S)
    sup.step(0, 0.0, 0.0, 0.005)
    sup.request_grasp(validate_request(GraspRequest(0.05, 1.0), P, S), 1.0, after_ns=0)
    d = sup.step(10 * MS, 0.01, 0.0, 0.005, speed_mps=0.01)
    assert d.running and sup.kind == 'grasp'
    ended = sup.request_servo(_setpoint(0.02), after_ns=10 * MS, message='preempted: setpoint')
    assert ended.answer is Outcome.STOPPED and ended.message == 'preempted: setpoint'
    d = sup.step(20 * MS, 0.011, 0.0, 0.005, speed_mps=0.01)
    assert d.running and sup.kind == 'move' and sup.servo and d.phase is Phase.MOVING
    assert d.grasp_id == 2 and d.position_setpoint_m == pytest.approx(0.02)
    # a service request ends the setpoint's move, which nobody waits for, and runs
    sup.request_move(_targets(0.1), after_ns=20 * MS)
    ended = sup.take_preempted()
    assert ended.answer is Outcome.STOPPED and 'preempted by a move request' in ended.message
    assert sup.take_preempted() is None
    d = sup.step(30 * MS, 0.012, 0.0, 0.005)
    assert d.running and not sup.servo and d.grasp_id == 3
    with pytest.raises(RequestError, match='move is running'):   # services: one at a time
        sup.request_move(_targets(0.1))


# ====================================================================== headless moves
@pytest.mark.parametrize('speed_mps', [0.005, 0.02, 0.05])
def test_a_move_reaches_its_width_never_faster_than_the_limit(speed_mps):
    run = simulate_moves(CONFIG, [MoveRequest(0.05, speed_mps)])
    (answer,) = run.answers
    assert answer.outcome is Outcome.MOVED and answer.reached_goal and not answer.stalled
    goal_m = TRAVEL_M - 0.05
    assert abs(answer.position_m - goal_m) <= S.move_tolerance_m
    assert abs(run.series.ticks['velocity_mps'][-1]) <= S.move_rest_speed_mps
    top = np.max(np.abs(run.series.ticks['velocity_mps']))
    assert top <= speed_mps * (1 + SPEED_SLACK)
    # 0.1 m is long enough to reach the limit: the speed rises to it (within 1 %)
    assert top >= 0.99 * speed_mps
    # and the move takes what the travel at that speed takes, not much more
    travel_s = goal_m / speed_mps
    assert travel_s < (answer.answer_ns - answer.start_ns) * 1e-9 < 1.5 * travel_s + 1.0


def _preempted_move(stop_s: float, delay_s: float, goal_m: float):
    """Close at 0.01 m/s from open, stop it after ``stop_s``, move to ``goal_m`` ``delay_s`` on.

    A gripper_cmd goal preempting a running one does this: the running move is stopped, the new
    goal's move starts once that one has ended. Returns (position and speed as the second move
    starts, its answer, its positions until then).
    """
    plant_side = PlantSide(make_plant(CONFIG))
    plant_side.set_object(GraspObject(0.0, 0.0, 0.0), open_fingers=True)
    sup = GraspSupervisor(P, S, load_law(CONFIG))
    decide = SupervisorSide(sup).decide
    stage = StageSide(PositionStageController(CONFIG))
    tick = plant_side.tick()
    decision, ref = decide(tick)
    sup.request_move(_targets(0.005, 0.01), after_ns=tick.stamp_ns)
    start_ns = tick.stamp_ns
    stop_ns = start_ns + round(stop_s * 1e9)
    move_ns = stop_ns + round(delay_s * 1e9)
    second, positions = None, []
    while True:
        if tick.stamp_ns >= stop_ns and sup.grasp_id == 1 and sup.running:
            sup.stop('preempted by a newer goal')
        if tick.stamp_ns >= move_ns and sup.grasp_id == 1 and not sup.pending:
            sup.request_move(_targets(TRAVEL_M - goal_m), after_ns=tick.stamp_ns)
        tick = plant_side.step(stage.answer(ref))
        decision, ref = decide(tick)
        if sup.grasp_id == 2:
            if second is None:                    # the tick it starts at
                second = (tick.position_m, tick.velocity_mps)
            positions.append(tick.position_m)
            if decision.answer is not None:
                return second, decision, np.array(positions)


@pytest.mark.parametrize('stop_s, delay_s', [(0.3, 0.0), (0.45, 0.0), (0.55, 0.0),
                                             (0.55, 0.02), (0.45, 0.05), (0.8, 0.0)])
def test_a_move_started_while_the_finger_moves_overshoots_no_more_than_braking_allows(
        stop_s, delay_s):
    """The second move starts at up to 10 mm/s, towards its goal or away from it.

    Its position stage plans from that motion: past the goal by no more than the braking
    governor's voltage (``mpc_pd_braking_voltage_v``, 20 V) stops the finger from that speed in,
    less the way left, plus one 10 ms sample at that speed (it decides once a sample); the
    least 24 V allows is printed beside. It comes to rest within the tolerance: MOVED.
    """
    goal_m = 0.005
    (x0, v0), decision, positions = _preempted_move(stop_s, delay_s, goal_m)
    toward = math.copysign(1.0, v0) == math.copysign(1.0, goal_m - x0)
    way_m = abs(goal_m - x0)
    least_m = max(0.0, stopping_m(P, v0) - way_m) if toward else 0.0
    bound_m = max(0.0, stopping_m(P, v0, CONFIG.position.mpc_pd_braking_voltage_v) - way_m) + \
        abs(v0) * CONFIG.position.sample_time_s if toward else 0.0
    past_m = max(0.0, float(np.max(math.copysign(1.0, v0) * (positions - goal_m)))) \
        if toward else 0.0
    print(f'from {x0 * 1e3:.3f} mm at {v0 * 1e3:.2f} mm/s to {goal_m * 1e3:g} mm: past it '
          f'{past_m * 1e3:.3f} mm (24 V: {least_m * 1e3:.3f} at least, bound '
          f'{bound_m * 1e3:.3f}), {decision.answer.name} at {positions[-1] * 1e3:.3f} mm')
    assert abs(v0) >= 0.005                       # it was moving
    assert past_m <= bound_m
    assert decision.answer is Outcome.MOVED
    assert abs(positions[-1] - goal_m) <= S.move_tolerance_m


@pytest.mark.parametrize('effort_n', [2.0, 5.0, 20.0])
def test_a_move_onto_a_rigid_object_stalls_pressing_with_the_effort_limit(effort_n):
    run = simulate_moves(CONFIG, [MoveRequest(0.02, 0.02, effort_n)], object_width_m=0.05)
    (answer,) = run.answers
    assert answer.outcome is Outcome.STALLED and answer.stalled and not answer.reached_goal
    assert answer.position_m == pytest.approx(TRAVEL_M - 0.05, abs=1e-12)   # at the face
    # rigid contact: the force follows the current towards the stall force of the capped
    # voltage, the effort limit, and never passes it
    assert S.move_stall_force_fraction * effort_n <= answer.effort_n <= effort_n * (1 + 1e-9)
    assert np.max(run.series.ticks['peak_force_n']) <= effort_n * (1 + 1e-9)
    # stalled as soon as the force sensor tells it: no waiting out move_stall_timeout_s
    touch_ns = run.series.ticks['stamp_ns'][np.argmax(run.series.ticks['force_n'] > 0.0)]
    assert (answer.answer_ns - touch_ns) * 1e-9 < S.move_stall_timeout_s / 10
    assert np.max(np.abs(run.series.ticks['velocity_mps'])) <= 0.02 * (1 + SPEED_SLACK)


def test_after_a_stall_the_finger_keeps_pressing_with_the_effort_limit():
    run = simulate_moves(CONFIG, [MoveRequest(0.02, 0.02, 5.0)], object_width_m=0.05,
                         hold_s=1.0)
    (stalled,) = run.answers
    after = run.series.ticks['stamp_ns'] > stalled.answer_ns
    assert (run.series.ticks['stamp_ns'][-1] - stalled.answer_ns) * 1e-9 >= 1.0
    assert np.allclose(run.series.ticks['force_n'][after], 5.0, rtol=1e-9)  # the last command
    assert np.all(run.series.tick_states['phase'][after] == Phase.DONE)


def test_a_move_opens_the_fingers_after_a_stall():
    run = simulate_moves(CONFIG, [MoveRequest(0.02, 0.02, 5.0), MoveRequest(0.12, 0.04)],
                         object_width_m=0.05)
    stalled, opened = run.answers
    assert stalled.outcome is Outcome.STALLED and opened.outcome is Outcome.MOVED
    assert abs(opened.position_m - (TRAVEL_M - 0.12)) <= S.move_tolerance_m
    assert opened.effort_n == 0.0
    after = run.series.ticks['stamp_ns'] >= opened.start_ns
    assert np.max(np.abs(run.series.ticks['velocity_mps'][after])) <= 0.04 * (1 + SPEED_SLACK)


def test_a_move_that_cannot_move_stalls_after_the_rest_timeout():
    """An effort limit whose stall voltage drives the free finger slower than "at rest"."""
    effort_n = 0.5 * S.move_rest_speed_mps / P.free_speed_per_volt_mps * \
        P.stall_force_per_volt_n
    run = simulate_moves(CONFIG, [MoveRequest(0.05, 0.02, effort_n)])
    (answer,) = run.answers
    assert answer.outcome is Outcome.STALLED and 'at rest for' in answer.message
    assert (answer.answer_ns - answer.start_ns) * 1e-9 == pytest.approx(
        S.move_stall_timeout_s, abs=0.011)
    assert answer.effort_n == 0.0                            # nothing was touched


def test_a_move_out_of_time_is_a_timeout():
    run = simulate_moves(CONFIG, [MoveRequest(0.0, 0.01, 0.0, 0.5)])
    (answer,) = run.answers
    assert answer.outcome is Outcome.TIMEOUT and 'not done within 0.5 s' in answer.message


def test_the_same_moves_twice_are_bit_identical():
    moves = [MoveRequest(0.02, 0.03, 7.0), MoveRequest(0.1, 0.05)]
    a = simulate_moves(CONFIG, moves, object_width_m=0.06)
    b = simulate_moves(CONFIG, moves, object_width_m=0.06)
    for name in a.series.ticks.dtype.names:
        assert np.array_equal(a.series.ticks[name], b.series.ticks[name]), name


def test_every_position_controller_keeps_the_speed_limit():
    for kind in ('pd', 'pid'):
        run = simulate_moves(CONFIG, [MoveRequest(0.05, 0.02, 10.0)], object_width_m=0.08,
                             position_controller=kind)
        assert np.max(np.abs(run.series.ticks['velocity_mps'])) <= 0.02 * (1 + SPEED_SLACK), kind
        assert np.max(run.series.ticks['peak_force_n']) <= 10.0 * (1 + 1e-9), kind


@pytest.mark.parametrize('field', ['speed_limit_mps', 'voltage_limit_v'])
@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_the_position_stage_never_acts_on_a_non_finite_limit(field, bad):
    from gripper_ros.core.control.stages import (LockstepAnswerer, PositionStageController,
                                                 Reference)

    answerer = LockstepAnswerer(PositionStageController(CONFIG))
    ref = Reference(10 * MS, 1, 1, 0, int(Phase.MOVING), 0, int(Controller.POSITION), True,
                    False, 0.1, 0.1, 5.0, 0.05, 0.0, 0.0, 0.0, **{field: bad})
    answer = answerer.answer(ref)
    assert not answer.finite and answer.voltage_v == 0.0 and field in answer.reason
    good = ref._replace(stamp_ns=20 * MS, **{field: 0.02})
    assert answerer.answer(good).finite


def test_the_voltage_limit_caps_only_the_push_towards_the_setpoint():
    from gripper_ros.core.control.stages import PositionStageController, Reference

    stage = PositionStageController(CONFIG, 'pd')
    cap_v = 5.0 / P.stall_force_per_volt_n
    closing = Reference(0, 1, 1, 0, int(Phase.MOVING), 0, int(Controller.POSITION), True,
                        False, 0.1, 0.1, 5.0, 0.05, 0.0, 0.0, 0.0, 0.0, cap_v)
    stage.activate(closing, 0.05)
    assert stage.compute(closing, 0.05)[0] == pytest.approx(cap_v)      # 50 mm short: capped
    # closing towards the setpoint: the closing push is capped, braking (opening) is not
    assert stage.controller.output_limits == (-P.voltage_limit_v, pytest.approx(cap_v))
    opening = closing._replace(position_m=0.15)                        # the setpoint behind
    stage.activate(opening, 0.15)
    assert stage.compute(opening, 0.15)[0] == pytest.approx(-cap_v)
    assert stage.controller.output_limits == (pytest.approx(-cap_v), P.voltage_limit_v)


# ====================================================================== ParallelGripperCommand
def _command(position=(), name=(), velocity=(), effort=()):
    """Return a stand-in for sensor_msgs/JointState with the four sequences."""
    return SimpleNamespace(name=list(name), position=list(position), velocity=list(velocity),
                           effort=list(effort))


def test_moveits_goal_maps_to_a_move_with_the_default_speed_and_the_motors_effort():
    # MoveIt's parallel-gripper handle: one position, no names, effort 0 unless the trajectory
    # gave one, no velocity
    move = move_request_of(_command(position=[0.1], effort=[0.0]), TRAVEL_M)
    assert move == MoveRequest(TRAVEL_M - 0.1, 0.0, 0.0)
    t = validate_move(move, P, S)
    assert t.speed_mps == S.move_default_speed_mps and t.voltage_limit_v == 0.0
    assert t.position_setpoint_m == pytest.approx(0.1)


def test_a_named_command_with_velocity_and_effort_gives_them_as_limits():
    move = move_request_of(_command(name=[FINGER_JOINT], position=[0.04], velocity=[0.03],
                                    effort=[8.0]), TRAVEL_M)
    assert move == MoveRequest(TRAVEL_M - 0.04, 0.03, 8.0)


@pytest.mark.parametrize('command, words', [
    (_command(position=[]), 'one position'),
    (_command(position=[0.1, 0.1]), 'one position'),
    (_command(name=['left', FINGER_JOINT], position=[0.1, 0.1]), "joints \\['left'\\]"),
    (_command(name=[FINGER_JOINT], position=[]), 'gives 0 positions'),
    (_command(position=[math.nan]), 'must be in'),
    (_command(position=[-0.001]), 'must be in'),
    (_command(position=[TRAVEL_M + 0.001]), 'must be in'),
])
def test_a_malformed_command_is_refused_with_the_reason(command, words):
    with pytest.raises(RequestError, match=words):
        move_request_of(command, TRAVEL_M)


def test_a_negative_velocity_or_effort_is_refused_by_the_move():
    for command in (_command(position=[0.1], velocity=[-0.01]),
                    _command(position=[0.1], effort=[-1.0])):
        with pytest.raises(RequestError, match='must be in'):
            validate_move(move_request_of(command, TRAVEL_M), P, S)


def _answer(outcome, position_m=0.1, effort_n=5.0):
    return SimpleNamespace(outcome=int(outcome), position_m=position_m, effort_n=effort_n,
                           stalled=outcome is Outcome.STALLED,
                           reached_goal=outcome is Outcome.MOVED)


def test_the_result_state_carries_a_velocity_only_when_one_is_known():
    """Follow JointState's convention: an empty velocity means "not measured"."""
    assert joint_state_fields(0.02, 0.0)['velocity'] == []
    assert joint_state_fields(0.02, 0.0, -0.0)['velocity'] == [0.0]
    assert result_fields(_answer(Outcome.MOVED), 0.004)['state']['velocity'] == [0.004]


@pytest.mark.parametrize('outcome, allow_stalling, cancel, end', [
    (Outcome.MOVED, False, False, GoalEnd.SUCCEEDED),
    (Outcome.STALLED, False, False, GoalEnd.ABORTED),
    (Outcome.STALLED, True, False, GoalEnd.SUCCEEDED),
    (Outcome.STOPPED, False, True, GoalEnd.CANCELED),
    (Outcome.STOPPED, False, False, GoalEnd.ABORTED),
    (Outcome.REFUSED, True, False, GoalEnd.ABORTED),
    (Outcome.TIMEOUT, True, False, GoalEnd.ABORTED),
    (Outcome.FAULT, True, True, GoalEnd.ABORTED),
])
def test_how_the_goal_ends(outcome, allow_stalling, cancel, end):
    assert goal_end(_answer(outcome), allow_stalling, cancel) is end


# ====================================================================== the live graph
@pytest.fixture(scope='module')
def graph():
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState

    from gripper_interfaces.action import Move as MoveAction
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.nodes.qos import GRAPH_QOS
    from gripper_ros.wire import ACTION_MOVE, TOPIC_JOINT_STATES

    with GripperGraph.in_own_context(GraphOptions(namespace='move_test')) as g:
        g.joint_states = []
        g.run_in_executor(lambda: g.client_node.create_subscription(
            JointState, TOPIC_JOINT_STATES, g.joint_states.append, GRAPH_QOS))
        g.action_client = ActionClient(g.client_node, MoveAction, ACTION_MOVE)
        assert g.action_client.wait_for_server(timeout_sec=10.0)
        assert g.set_object(0.0).success             # a first tick, nothing between the fingers
        yield g
        g.action_client.destroy()


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _joint_states_delivered(graph) -> None:
    """Wait until time stands still and the plant's last joint state has reached the test."""
    from gripper_ros.nodes.services import wait_until
    assert graph.wait_still()
    last_ns = graph.plant.last_state_ns
    assert wait_until(lambda: graph.joint_states and
                      _stamp_ns(graph.joint_states[-1]) >= last_ns, 30.0)


def _speeds_since(graph, t0_ns):
    _joint_states_delivered(graph)
    stamp = [_stamp_ns(m) for m in graph.joint_states]
    return np.array([m.velocity[0] for m, t in zip(graph.joint_states, stamp) if t >= t0_ns])


def test_the_move_service_reaches_the_width_within_the_speed_limit(graph):
    assert graph.set_object(0.0, open_fingers=True).success
    t0 = graph.sim_time_ns
    answer = graph.move(0.04, 0.03)
    assert answer.success and answer.reached_goal and not answer.stalled
    assert answer.outcome == Outcome.MOVED
    assert abs(answer.width_m - 0.04) <= S.move_tolerance_m
    assert answer.width_m == pytest.approx(TRAVEL_M - answer.position_m, abs=1e-12)
    speeds = _speeds_since(graph, t0)
    assert speeds.size > 100
    assert np.max(np.abs(speeds)) <= 0.03 * (1 + SPEED_SLACK)
    assert np.max(np.abs(speeds)) >= 0.99 * 0.03


def test_the_move_service_stalls_on_an_object_at_the_effort_limit(graph):
    assert graph.set_object(0.08, open_fingers=True).success
    answer = graph.move(0.0, 0.04, 6.0)
    assert answer.stalled and not answer.reached_goal and not answer.success
    assert answer.outcome == Outcome.STALLED
    assert answer.width_m == pytest.approx(0.08, abs=1e-9)
    assert S.move_stall_force_fraction * 6.0 <= answer.effort_n <= 6.0 * (1 + 1e-9)
    assert 'at the effort limit' in answer.message
    pressed = result_fields(answer, 0.0)              # gripper_cmd's result of this answer
    assert pressed['stalled'] and not pressed['reached_goal']
    assert pressed['state']['position'] == [answer.position_m]
    assert pressed['state']['effort'] == [answer.effort_n]
    opened = graph.move(TRAVEL_M)                    # opening ends the press
    assert opened.reached_goal and opened.effort_n == 0.0
    assert result_fields(opened, 0.0)['reached_goal'] and not result_fields(opened)['stalled']


def test_the_graphs_move_is_the_headless_move_tick_for_tick(graph):
    """The nodes run the core's lockstep code: the same move gives the same series."""
    assert graph.set_object(0.07, open_fingers=True).success
    graph.wait_still()
    t0 = graph.sim_time_ns
    graph.joint_states.clear()
    answer = graph.move(0.03, 0.04, 8.0)
    _joint_states_delivered(graph)
    run = simulate_moves(CONFIG, [MoveRequest(0.03, 0.04, 8.0)], object_width_m=0.07,
                         start_ns=t0)
    (headless,) = run.answers
    assert (answer.outcome, answer.position_m, answer.effort_n) == \
        (int(headless.outcome), headless.position_m, headless.effort_n)
    ticks = run.series.ticks
    position_at = dict(zip(ticks['stamp_ns'].tolist(), ticks['position_m'].tolist()))
    graph_series = {_stamp_ns(m): m.position[0] for m in graph.joint_states}
    common = sorted(set(graph_series) & set(position_at))
    assert len(common) > 0.9 * len(position_at)
    assert all(graph_series[t] == position_at[t] for t in common)


@pytest.mark.parametrize('width_m, speed_mps, effort_n, why', [
    (math.nan, 0.02, 0.0, 'width_m'),
    (-0.01, 0.02, 0.0, 'width_m'),
    (0.05, 1.0, 0.0, 'speed_mps'),
    (0.05, 0.02, 1e3, 'max_effort_n'),
])
def test_a_bad_move_is_refused_and_nothing_moves(graph, width_m, speed_mps, effort_n, why):
    ticks = graph.plant.ticks_published
    answer = graph.move(width_m, speed_mps, effort_n)
    assert answer.outcome == Outcome.REFUSED and not answer.success
    assert not answer.stalled and not answer.reached_goal
    assert why in answer.message
    graph.wait_still()
    assert graph.plant.ticks_published == ticks


def test_a_move_while_a_grasp_waits_to_start_is_refused(graph):
    assert graph.set_object(0.06, open_fingers=True).success
    assert graph.pause().success                     # the grasp cannot start while paused
    future = graph.grasp_async(0.06, 0.5)
    deadline = time.monotonic() + 10.0
    while not graph.supervisor.logic.pending and time.monotonic() < deadline:
        time.sleep(0.005)
    assert graph.supervisor.logic.pending
    answer = graph.move(0.1)
    assert answer.outcome == Outcome.REFUSED and 'waiting' in answer.message
    assert graph.resume().success
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(60.0) and future.result().outcome == Outcome.HOLDING
    # a move may follow the hold: it ends the hold and opens the fingers
    answer = graph.move(TRAVEL_M, 0.05)
    assert answer.reached_goal and not graph.supervisor.logic.holding


def _wait(future, timeout_s=120.0):
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(timeout_s), 'no answer in time'
    return future.result()


def test_the_move_action_gives_feedback_and_the_service_result(graph):
    from action_msgs.msg import GoalStatus

    from gripper_interfaces.action import Move as MoveAction

    assert graph.set_object(0.07, open_fingers=True).success
    feedback = []
    handle = _wait(graph.action_client.send_goal_async(
        MoveAction.Goal(width_m=0.03, speed_mps=0.03, max_effort_n=4.0),
        feedback_callback=lambda m: feedback.append(m.feedback)))
    assert handle.accepted
    wrapped = _wait(handle.get_result_async())
    result = wrapped.result
    assert wrapped.status == GoalStatus.STATUS_ABORTED            # stalled: not reached
    assert result.stalled and result.outcome == Outcome.STALLED
    assert result.width_m == pytest.approx(0.07, abs=1e-9)
    assert S.move_stall_force_fraction * 4.0 <= result.effort_n <= 4.0 * (1 + 1e-9)
    assert feedback and all(f.grasp_id == result.grasp_id for f in feedback)
    assert feedback[0].phase == Phase.MOVING
    widths = [f.width_m for f in feedback]
    assert widths == sorted(widths, reverse=True)                 # closing, never back
    assert all(f.width_m == pytest.approx(TRAVEL_M - f.position_m, abs=1e-12) for f in feedback)
    handle = _wait(graph.action_client.send_goal_async(MoveAction.Goal(width_m=0.1)))
    wrapped = _wait(handle.get_result_async())
    assert wrapped.status == GoalStatus.STATUS_SUCCEEDED and wrapped.result.reached_goal


def test_cancelling_the_move_action_stops_the_move(graph):
    from action_msgs.msg import GoalStatus

    from gripper_interfaces.action import Move as MoveAction

    assert graph.set_object(0.0, open_fingers=True).success
    feedback = []
    handle = _wait(graph.action_client.send_goal_async(
        MoveAction.Goal(width_m=0.0, speed_mps=0.002),     # 75 s of simulated travel
        feedback_callback=lambda m: feedback.append(m.feedback)))
    deadline = time.monotonic() + 30.0
    while not feedback and time.monotonic() < deadline:
        time.sleep(0.005)
    assert feedback, 'no feedback before cancel'
    assert len(_wait(handle.cancel_goal_async()).goals_canceling) == 1
    wrapped = _wait(handle.get_result_async())
    assert wrapped.status == GoalStatus.STATUS_CANCELED
    assert wrapped.result.outcome == Outcome.STOPPED
    assert wrapped.result.width_m > 0.01


def test_parallel_gripper_command_on_gripper_cmd_drives_the_move(graph):
    """Drive the move with MoveIt's parallel-gripper action, where control_msgs is installed."""
    try:
        from control_msgs.action import ParallelGripperCommand
    except ImportError:
        pytest.skip('control_msgs is not installable from the ros-jazzy wheels; run on a '
                    'system ROS 2 Jazzy')
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from gripper_ros.wire import ACTION_GRIPPER_CMD

    assert graph.move_action_server.gripper_command_served
    client = graph.run_in_executor(lambda: ActionClient(
        graph.client_node, ParallelGripperCommand, ACTION_GRIPPER_CMD))
    assert client.wait_for_server(timeout_sec=10.0)

    def send(command, allow_stalling=False):
        graph.move_action_server.set_parameters(
            [Parameter('allow_stalling', value=allow_stalling)])
        feedback = []
        handle = _wait(client.send_goal_async(ParallelGripperCommand.Goal(command=command),
                                              feedback_callback=feedback.append))
        if not handle.accepted:
            return None, None, feedback
        wrapped = _wait(handle.get_result_async())
        return wrapped.status, wrapped.result, feedback

    try:
        assert graph.set_object(0.06, open_fingers=True).success
        # as MoveIt's handle sends it: a position, no names, the effort given
        close = JointState(position=[TRAVEL_M], effort=[5.0])
        status, result, feedback = send(close)
        assert status == GoalStatus.STATUS_ABORTED                  # stalled, not allowed
        assert result.stalled and not result.reached_goal
        assert list(result.state.name) == [graph.move_action_server.joint_name]   # its prefix
        assert result.state.position[0] == pytest.approx(TRAVEL_M - 0.06, abs=1e-9)
        assert S.move_stall_force_fraction * 5.0 <= result.state.effort[0] <= 5.0 * (1 + 1e-9)
        assert feedback and list(feedback[-1].feedback.state.name) == [
            graph.move_action_server.joint_name]
        # stamped in simulated time, at or after the last feedback, with the measured velocity
        stamp = result.state.header.stamp
        last = feedback[-1].feedback.state.header.stamp
        assert (stamp.sec, stamp.nanosec) >= (last.sec, last.nanosec) > (0, 0)
        assert len(result.state.velocity) == 1 and abs(result.state.velocity[0]) < 0.001
        assert len(feedback[-1].feedback.state.velocity) == 1
        status, result, _ = send(close, allow_stalling=True)         # still pressing there
        assert status == GoalStatus.STATUS_SUCCEEDED and result.stalled
        opened = JointState(name=[graph.move_action_server.joint_name], position=[0.02],
                            velocity=[0.04])
        status, result, _ = send(opened)
        assert status == GoalStatus.STATUS_SUCCEEDED and result.reached_goal
        assert abs(result.state.position[0] - 0.02) <= S.move_tolerance_m
        for bad in (JointState(position=[0.05, 0.05]),
                    JointState(name=['other_joint'], position=[0.05]),
                    JointState(position=[TRAVEL_M + 0.01])):
            ticks = graph.plant.ticks_published
            assert send(bad)[0] is None                              # rejected at the goal
            assert graph.plant.ticks_published == ticks
    finally:
        graph.run_in_executor(client.destroy)


def test_a_gripper_cmd_goal_preempts_the_running_one_which_ends_canceled(graph):
    """A new ``gripper_cmd`` goal ends the running one canceled, and its own move runs.

    As ros2_controllers' parallel gripper controller does
    (parallel_gripper_controller/include/parallel_gripper_controller/
    parallel_gripper_action_controller_impl.hpp): ``accepted_callback`` calls
    ``preempt_active_goal``, which sets the active goal canceled, and the new command is in force.
    """
    try:
        from control_msgs.action import ParallelGripperCommand
    except ImportError:
        pytest.skip('control_msgs is not installable from the ros-jazzy wheels; run on a '
                    'system ROS 2 Jazzy')
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState

    from gripper_ros.wire import ACTION_GRIPPER_CMD

    client = graph.run_in_executor(lambda: ActionClient(
        graph.client_node, ParallelGripperCommand, ACTION_GRIPPER_CMD))
    assert client.wait_for_server(timeout_sec=10.0)
    try:
        assert graph.set_object(0.0, open_fingers=True).success
        moving = threading.Event()
        slow_close = JointState(position=[TRAVEL_M - 0.005], velocity=[0.01])   # some 9 s
        first = _wait(client.send_goal_async(ParallelGripperCommand.Goal(command=slow_close),
                                             feedback_callback=lambda _f: moving.set()))
        assert first.accepted
        assert moving.wait(60.0), 'the first goal gave no feedback'
        second = _wait(client.send_goal_async(ParallelGripperCommand.Goal(
            command=JointState(position=[0.005]))))
        assert second.accepted                                 # accepted, not refused
        first_end = _wait(first.get_result_async())
        second_end = _wait(second.get_result_async())
        assert first_end.status == GoalStatus.STATUS_CANCELED
        assert not first_end.result.reached_goal
        assert first_end.result.state.position[0] < TRAVEL_M - 0.05     # stopped on its way
        assert second_end.status == GoalStatus.STATUS_SUCCEEDED
        assert second_end.result.reached_goal
        assert abs(second_end.result.state.position[0] - 0.005) <= S.move_tolerance_m
    finally:
        graph.run_in_executor(client.destroy)


def test_serve_mode_records_a_move_in_a_bag_of_its_own(tmp_path):
    from gripper_ros.bags.series import load_grasp_series
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.nodes.recording import ServeRecorder
    from gripper_ros.nodes.services import wait_until
    with GripperGraph.in_own_context(GraphOptions(namespace='move_serve',
                                                  time_mode='fast')) as g:
        serve = ServeRecorder(g, tmp_path)
        assert g.set_object(0.0, open_fingers=True).success
        answer = g.move(0.04, 0.03)
        assert answer.success and answer.reached_goal
        assert wait_until(lambda: serve.bags and not serve.recording, 10.0)
    assert serve.errors == []
    [bag] = serve.bags
    assert bag.name.startswith('move_')
    series = load_grasp_series(bag)
    phases = set(series.decisions['phase'].tolist())
    assert int(Phase.MOVING) in phases and int(Phase.POSITION) not in phases
    assert TRAVEL_M - series.ticks['position_m'][-1] == pytest.approx(answer.width_m, abs=1e-9)
    # whole ticks: one command and one measurement per tick
    assert series.ticks['stamp_ns'].size == series.commands['stamp_ns'].size > 100
