"""FollowJointTrajectory's numerics as joint_trajectory_controller runs them, without ROS.

Follows ros-controls/ros2_controllers (Jazzy) joint_trajectory_controller: ``src/trajectory.cpp``
(``sample``, ``interpolate_between_points``, ``set_point_before_trajectory_msg``),
``include/joint_trajectory_controller/tolerances.hpp`` and ``src/joint_trajectory_controller.cpp``
(``validate_trajectory_msg``, the tolerance checks of ``update``). Known answers: the boundary
conditions a spline of each degree meets, scipy's Hermite splines of the same data
(``CubicHermiteSpline``, ``BPoly.from_derivatives``), the minimum-jerk closed form, and the
messages and codes of JTC's source.
"""
from __future__ import annotations

from types import SimpleNamespace

from gripper_ros.core.supervision.joint_trajectory import (check_trajectory, default_tolerances,
                                                           interpolate, Point,
                                                           resolve_tolerance,
                                                           resolve_tolerances, State,
                                                           StateTolerance, Tolerances,
                                                           Trajectory, TrajectoryError,
                                                           TrajectoryRun, Verdict, within)
import numpy as np
import pytest
from scipy.interpolate import BPoly, CubicHermiteSpline

S = 1_000_000_000
MS = 1_000_000
JOINT = 'finger_joint'
TRAVEL_M = 0.15


def msg_point(t_s, positions=(), velocities=(), accelerations=(), effort=()):
    """Return a JointTrajectoryPoint's fields, the time in ns."""
    return SimpleNamespace(time_from_start_ns=round(t_s * S), positions=list(positions),
                           velocities=list(velocities), accelerations=list(accelerations),
                           effort=list(effort))


# ====================================================================== interpolation
def test_positions_only_are_linear():
    a, b = Point(0, 0.02), Point(2 * S, 0.10)
    for t_s in (0.0, 0.5, 1.0, 1.99):
        s = interpolate(0, a, 2 * S, b, round(t_s * S))
        assert s.position == pytest.approx(0.02 + 0.04 * t_s, abs=1e-15)
        assert s.velocity == pytest.approx(0.04)
        assert s.acceleration == 0.0


def test_velocities_make_a_cubic_meeting_both_ends():
    a, b = Point(0, 0.02, 0.01), Point(S, 0.08, -0.02)
    ref = CubicHermiteSpline([0.0, 1.0], [0.02, 0.08], [0.01, -0.02])
    for t_s in np.linspace(0.0, 1.0, 11):
        s = interpolate(0, a, S, b, round(t_s * S))
        assert s.position == pytest.approx(float(ref(t_s)), abs=1e-15)
        assert s.velocity == pytest.approx(float(ref(t_s, 1)), abs=1e-14)
        assert s.acceleration == pytest.approx(float(ref(t_s, 2)), abs=1e-13)
    end = interpolate(0, a, S, b, S - 1)
    assert (end.position, end.velocity) == pytest.approx((0.08, -0.02), abs=1e-9)


def test_accelerations_make_a_quintic_meeting_both_ends():
    a, b = Point(0, 0.01, 0.02, 0.1), Point(S // 2, 0.03, 0.0, -0.05)
    ref = BPoly.from_derivatives([0.0, 0.5], [[0.01, 0.02, 0.1], [0.03, 0.0, -0.05]])
    for t_s in np.linspace(0.0, 0.5, 11):
        s = interpolate(0, a, S // 2, b, round(t_s * S))
        assert s.position == pytest.approx(float(ref(t_s)), abs=1e-15)
        assert s.velocity == pytest.approx(float(ref(t_s, 1)), abs=1e-13)
        assert s.acceleration == pytest.approx(float(ref(t_s, 2)), abs=1e-11)


def test_rest_to_rest_quintic_is_the_minimum_jerk_profile():
    """p0 + d (10 u^3 - 15 u^4 + 6 u^5), u = t / T: the closed form from rest to rest."""
    a, b = Point(0, 0.0, 0.0, 0.0), Point(3 * S, 0.12, 0.0, 0.0)
    for u in np.linspace(0.0, 1.0, 13)[:-1]:
        s = interpolate(0, a, 3 * S, b, round(u * 3 * S))
        u = round(u * 3 * S) / (3 * S)
        assert s.position == pytest.approx(0.12 * (10 * u**3 - 15 * u**4 + 6 * u**5), abs=1e-15)
        assert s.velocity == pytest.approx(0.12 / 3 * (30 * u**2 - 60 * u**3 + 30 * u**4),
                                           abs=1e-15)


def test_outside_its_segment_the_time_is_clamped_and_linear():
    """JTC drops to linear when the time is outside the segment (duration clamped)."""
    a, b = Point(0, 0.02, 0.05), Point(S, 0.06, 0.0)
    after = interpolate(0, a, S, b, 2 * S)
    assert (after.position, after.velocity, after.acceleration) == (0.06, pytest.approx(0.04),
                                                                    0.0)
    before = interpolate(0, a, S, b, -S)
    assert before.position == 0.02


# ====================================================================== sampling
def test_the_first_segment_starts_from_the_measured_state():
    """set_point_before_trajectory_msg: the first update's measurement, velocity included."""
    traj = Trajectory([Point(S, 0.10, 0.0), Point(2 * S, 0.12, 0.0)])
    traj.set_state_before(5 * S, State(0.04, 0.01))           # no header stamp: starts now
    assert traj.start_ns == 5 * S
    ref = CubicHermiteSpline([5.0, 6.0], [0.04, 0.10], [0.01, 0.0])
    for t_s in (5.0, 5.3, 5.9):
        sample = traj.sample(round(t_s * S))
        assert sample.segment == -1 and sample.before_last_point
        assert sample.state.position == pytest.approx(float(ref(t_s)), abs=1e-15)
    mid = traj.sample(round(6.5 * S))
    assert mid.segment == 0 and mid.before_last_point
    end = traj.sample(7 * S)
    assert end.segment == 1 and not end.before_last_point
    assert end.state == State(0.12, 0.0, 0.0)


def test_a_first_point_without_velocities_makes_a_linear_first_segment():
    traj = Trajectory([Point(S, 0.10)])
    traj.set_state_before(0, State(0.04, 0.02))
    s = traj.sample(S // 2)
    assert s.state.position == pytest.approx(0.07) and s.state.velocity == pytest.approx(0.06)


def test_accelerations_of_the_first_point_start_from_zero_acceleration():
    """The state has no acceleration: 0, so the first segment is a quintic too."""
    traj = Trajectory([Point(S, 0.10, 0.0, 0.0)])
    traj.set_state_before(0, State(0.04, 0.0))
    assert traj.state_before == State(0.04, 0.0, 0.0)
    ref = BPoly.from_derivatives([0.0, 1.0], [[0.04, 0.0, 0.0], [0.10, 0.0, 0.0]])
    assert traj.sample(S // 4).state.position == pytest.approx(float(ref(0.25)), abs=1e-15)


def test_a_header_stamp_sets_the_start():
    traj = Trajectory([Point(S, 0.10)], start_ns=20 * S)
    traj.set_state_before(19 * S, State(0.0, 0.0))
    assert traj.start_ns == 20 * S and traj.end_ns == 21 * S
    assert traj.sample(20 * S).state.position == pytest.approx(0.05)   # from 19 s to 21 s


def test_past_the_last_point_the_last_point_with_zero_derivatives():
    traj = Trajectory([Point(0, 0.05), Point(S, 0.07)])
    traj.set_state_before(0, State(0.05, 0.0))
    s = traj.sample(3 * S)
    assert s.state == State(0.07, 0.0, 0.0) and not s.before_last_point


# ====================================================================== validation
def _check(points, names=(JOINT,), **kw):
    return check_trajectory(list(names), points, JOINT, TRAVEL_M, **kw)


def test_a_valid_goal_keeps_what_it_gives():
    points = _check([msg_point(0.5, [0.02]), msg_point(1.0, [0.05], [0.0], [0.0])])
    assert points == [Point(S // 2, 0.02), Point(S, 0.05, 0.0, 0.0)]


@pytest.mark.parametrize('names, points, words', [
    ((), [msg_point(1, [0.1])], "Joints on incoming trajectory don't match"),
    ((JOINT, 'other'), [msg_point(1, [0.1, 0.1])], "Joints on incoming trajectory don't match"),
    (('other_joint',), [msg_point(1, [0.1])],
     "Incoming joint other_joint doesn't match the controller's joints."),
    ((JOINT,), [], 'Empty trajectory received.'),
    ((JOINT,), [msg_point(1, [0.1], [0.01])],
     'Velocity of last trajectory point of joint finger_joint is not zero: 0.010000000000000'),
    ((JOINT,), [msg_point(1, [0.1]), msg_point(1, [0.12])],
     'Time between points 0 and 1 is not strictly increasing, it is 1.000000 and 1.000000'),
    ((JOINT,), [msg_point(1, [])], 'Mismatch between joint_names size (1) and positions (0) at '
                                   'point #0.'),
    ((JOINT,), [msg_point(1, [0.1], [0.0, 0.0])], 'Mismatch between joint_names size (1) and '
                                                  'velocities (2) at point #0.'),
    ((JOINT,), [msg_point(1, [0.1], effort=[5.0])],
     "Trajectories with effort fields are only supported for controllers using the 'effort'"),
    ((JOINT,), [msg_point(1, [float('nan')])], 'the position of finger_joint is nan'),
    ((JOINT,), [msg_point(1, [0.1]), msg_point(2, [0.16])],
     "point #1: position 0.16 of finger_joint is out of the joint's limits [0, 0.15] m"),
    ((JOINT,), [msg_point(1, [-0.001])], "out of the joint's limits"),
    ((JOINT,), [msg_point(1, [0.1], [], [0.0])], 'accelerations without velocities'),
])
def test_a_goal_jtc_or_the_travel_refuses_is_rejected_saying_why(names, points, words):
    with pytest.raises(TrajectoryError) as raised:
        _check(points, names)
    assert words in str(raised.value)


def test_a_goal_that_ends_in_the_past_is_rejected():
    points = [msg_point(1, [0.1])]
    with pytest.raises(TrajectoryError, match='ends in the past'):
        _check(points, start_ns=10 * S, now_ns=12 * S)
    assert _check(points, start_ns=10 * S, now_ns=10 * S)          # ends in the future
    assert _check(points, start_ns=0, now_ns=12 * S)                # no stamp: now


def test_a_nonzero_final_velocity_is_allowed_when_asked():
    assert _check([msg_point(1, [0.1], [0.01])], allow_nonzero_velocity_at_end=True)


# ====================================================================== tolerances
def test_a_goals_tolerance_overrides_erases_or_keeps_the_default():
    assert resolve_tolerance(0.02, 0.05) == 0.05
    assert resolve_tolerance(0.02, 0.0) == 0.02
    assert resolve_tolerance(0.02, -1.0) == 0.0
    with pytest.raises(ValueError):
        resolve_tolerance(0.02, -0.5)


def _tol(name=JOINT, position=0.0, velocity=0.0, acceleration=0.0):
    return SimpleNamespace(name=name, position=position, velocity=velocity,
                           acceleration=acceleration)


def test_goal_tolerances_resolve_per_field_as_jtc():
    defaults = default_tolerances(trajectory_m=0.005, goal_m=0.001, goal_time_s=0.5)
    assert defaults == Tolerances(StateTolerance(0.005), StateTolerance(0.001, 0.01), 0.5)
    got, why = resolve_tolerances(defaults, JOINT, [_tol(position=0.002)],
                                  [_tol(position=-1.0, velocity=0.05)], 1.5)
    assert why == ''
    assert got == Tolerances(StateTolerance(0.002), StateTolerance(0.0, 0.05), 1.5)


@pytest.mark.parametrize('path, goal, goal_time_s, words', [
    ([_tol('other', 0.1)], [], 0.0,
     "joint 'other' specified in goal.path_tolerance does not exist. Using default tolerances."),
    ([], [_tol(position=-0.3)], 0.0, "joint 'finger_joint' specified in goal.goal_tolerance has "
                                     'a invalid position tolerance. Using default tolerances.'),
    ([], [], -2.0, 'Specified illegal goal_time_tolerance: -2.000000. Using default tolerances'),
])
def test_an_illegal_goal_tolerance_keeps_every_default(path, goal, goal_time_s, words):
    defaults = default_tolerances(goal_m=0.001)
    got, why = resolve_tolerances(defaults, JOINT, path, goal, goal_time_s)
    assert got == defaults and why == words


def test_within_checks_only_set_bounds():
    assert within(State(0.5, 0.5, None), StateTolerance())
    assert not within(State(0.002, 0.0), StateTolerance(position=0.001))
    assert within(State(-0.001, 0.0), StateTolerance(position=0.001))
    assert not within(State(0.0, -0.02), StateTolerance(velocity=0.01))


# ====================================================================== a goal's updates
def _run(points, tolerances=None, start_ns=0):
    return TrajectoryRun(Trajectory(points, start_ns), tolerances or default_tolerances())


def test_each_update_commands_the_next_updates_sample():
    run = _run([Point(S, 0.10)])
    u = run.update(0, 0.0, 0.0, 10 * MS)
    assert u.command_ns == 10 * MS and u.verdict is None
    assert u.desired.position == 0.0
    assert u.command.position == pytest.approx(0.10 * 0.01)
    u = run.update(500 * MS, 0.04, 0.1, 10 * MS)
    assert u.desired.position == pytest.approx(0.05) and u.error.position == pytest.approx(0.01)
    assert u.command.position == pytest.approx(0.051)


def test_the_goal_succeeds_at_its_end_within_the_goal_tolerance():
    run = _run([Point(S, 0.10, 0.0)], default_tolerances(goal_m=0.001))
    run.update(0, 0.0, 0.0, 10 * MS)
    u = run.update(S, 0.0995, 0.005, 10 * MS)
    assert u.verdict is Verdict.SUCCESSFUL and u.message == 'Goal successfully reached!'
    assert u.hold == State(0.10, 0.0, 0.0)
    assert run.update(S + 10 * MS, 0.1, 0.0, 10 * MS).command is None     # ended: nothing new


def test_with_default_constraints_a_stalled_finger_succeeds_once_stopped():
    """Default goal 0 (unchecked), stopped_velocity_tolerance 0.01: at rest short of it."""
    run = _run([Point(S, 0.14, 0.0)])
    run.update(0, 0.05, 0.0, 10 * MS)
    assert run.update(S, 0.10, 0.02, 10 * MS).verdict is None        # still moving: waits
    assert run.update(S + 50 * MS, 0.10, 0.0, 10 * MS).verdict is Verdict.SUCCESSFUL


def test_outside_the_goal_tolerance_it_waits_with_no_goal_time():
    run = _run([Point(S, 0.10, 0.0)], default_tolerances(goal_m=0.001))
    run.update(0, 0.0, 0.0, 10 * MS)
    for t in (S, 5 * S, 60 * S):
        assert run.update(t, 0.09, 0.0, 10 * MS).verdict is None
    assert run.update(61 * S, 0.1, 0.0, 10 * MS).verdict is Verdict.SUCCESSFUL


def test_outside_the_goal_tolerance_past_goal_time_it_aborts():
    run = _run([Point(S, 0.10, 0.0)], default_tolerances(goal_m=0.001, goal_time_s=0.5))
    run.update(0, 0.0, 0.0, 10 * MS)
    assert run.update(1500 * MS, 0.09, 0.0, 10 * MS).verdict is None      # 0.5 s late: not yet
    u = run.update(1510 * MS, 0.09, 0.0, 10 * MS)
    assert u.verdict is Verdict.GOAL_TOLERANCE_VIOLATED
    assert u.message.startswith('Aborted due to goal_time_tolerance exceeding by 0.510000 '
                                'seconds: Position Error: 0.010000, Position Tolerance: 0.001000')
    assert u.hold == State(0.09, 0.0, 0.0)                               # where it is


def test_the_path_tolerance_aborts_on_the_way_and_holds_where_it_is():
    run = _run([Point(S, 0.10)], default_tolerances(trajectory_m=0.005))
    run.update(0, 0.0, 0.0, 10 * MS)
    assert run.update(500 * MS, 0.046, 0.1, 10 * MS).verdict is None      # 4 mm behind
    u = run.update(510 * MS, 0.045, 0.1, 10 * MS)                          # 6 mm behind
    assert u.verdict is Verdict.PATH_TOLERANCE_VIOLATED and u.command is None
    assert u.message == ('Aborted due to path tolerance violation: Position Error: 0.006000, '
                         'Position Tolerance: 0.005000')
    assert u.hold == State(0.045, 0.0, 0.0)


def test_a_single_point_is_checked_against_the_path_on_the_first_update():
    """JTC checks the state tolerance on the first sample even when it is the last point."""
    run = _run([Point(0, 0.10)], default_tolerances(trajectory_m=0.005))
    u = run.update(0, 0.0, 0.0, 10 * MS)
    assert u.verdict is Verdict.PATH_TOLERANCE_VIOLATED
