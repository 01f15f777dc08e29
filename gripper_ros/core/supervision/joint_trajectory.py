"""FollowJointTrajectory for the one joint, as joint_trajectory_controller runs it (no rclpy).

Follows ros-controls/ros2_controllers, joint_trajectory_controller (Jazzy) for a controller of
one joint with the command interfaces position, velocity and acceleration and the state
interfaces position and velocity, default parameters otherwise:

- :func:`check_trajectory`: ``validate_trajectory_msg`` (a goal it refuses is rejected), and
  what this gripper cannot do beside it: a point outside the travel, a number that is not finite,
  accelerations without velocities (there ``interpolate_between_points`` takes no branch and
  commands position 0).
- :class:`Trajectory`: ``trajectory.cpp``'s ``sample``: from the state the first update finds
  to the first point, then point to point; linear between two points where one has no
  velocities, cubic where both have velocities, quintic where both also have accelerations;
  the last point once the time has passed it.
- :func:`resolve_tolerances` and :func:`within`: ``tolerances.hpp`` (0 = the default, -1 = not
  checked, another negative value: the goal's tolerances are all ignored for the defaults).
- :class:`TrajectoryRun`: ``update()``'s share for one goal: at each update the desired state
  now and the command for the next update, the path tolerance until the last point's time,
  then the goal tolerance, within ``goal_time`` when that is not 0 (0: it waits for good).

Times are integer nanoseconds of the gripper's clock (its ``joint_states`` stamps).
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
import math

from gripper_ros.core.supervision.requests import RequestError

FLOAT_EPSILON = 1.1920928955078125e-07
"""``std::numeric_limits<float>::epsilon()``: JTC's zero for a final velocity and an erased
tolerance."""
ERASE_TOLERANCE = -1.0
"""JointTolerance's "erased": not checked, whatever the default."""


class TrajectoryError(RequestError):
    """A trajectory goal that is rejected; the message says why, with the numbers."""


class Verdict(enum.IntEnum):
    """How a goal ends: control_msgs FollowJointTrajectory.Result's error codes."""

    SUCCESSFUL = 0
    INVALID_GOAL = -1
    INVALID_JOINTS = -2
    OLD_HEADER_TIMESTAMP = -3
    PATH_TOLERANCE_VIOLATED = -4
    GOAL_TOLERANCE_VIOLATED = -5


@dataclass(frozen=True)
class Point:
    """A trajectory point of the joint: velocity and acceleration None where not given."""

    time_from_start_ns: int
    position: float
    velocity: float | None = None
    acceleration: float | None = None


@dataclass(frozen=True)
class State:
    """A sampled or measured state; velocity or acceleration None: not known."""

    position: float
    velocity: float | None = None
    acceleration: float | None = None


@dataclass(frozen=True)
class StateTolerance:
    """Bounds on |desired - actual|; 0 = not checked."""

    position: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass(frozen=True)
class Tolerances:
    """JTC's SegmentTolerances for one joint."""

    path: StateTolerance = StateTolerance()
    goal: StateTolerance = StateTolerance()
    goal_time_s: float = 0.0


def default_tolerances(trajectory_m: float = 0.0, goal_m: float = 0.0,
                       stopped_velocity_mps: float = 0.01, goal_time_s: float = 0.0) -> Tolerances:
    """Return the tolerances of JTC's ``constraints`` parameters (its defaults by default).

    ``constraints.<joint>.trajectory`` bounds the position on the way, ``.goal`` at the end,
    where ``stopped_velocity_tolerance`` bounds the velocity; ``goal_time`` the lateness.
    """
    return Tolerances(StateTolerance(position=trajectory_m),
                      StateTolerance(position=goal_m, velocity=stopped_velocity_mps),
                      goal_time_s)


def _entry(values, index: int, what: str, point: int, count: int, optional: bool):
    """Return ``values[index]`` (None when optional and empty) or raise JTC's size refusal."""
    values = list(values)
    if optional and not values:
        return None
    if len(values) != count:
        raise TrajectoryError(f'Mismatch between joint_names size ({count}) and {what} '
                              f'({len(values)}) at point #{point}.')
    return float(values[index])


def check_trajectory(joint_names, points, joint: str, travel_m: float, start_ns: int = 0,
                     now_ns: int = 0, allow_nonzero_velocity_at_end: bool = False
                     ) -> list[Point]:
    """Return the points of a trajectory goal for ``joint``, or raise TrajectoryError.

    ``points``: objects with ``time_from_start_ns``, ``positions``, ``velocities``,
    ``accelerations`` and ``effort`` (JointTrajectoryPoint's fields, the time in ns).
    ``start_ns``: the header's stamp (0: start at the first update), judged against
    ``now_ns`` on the same clock. The checks and messages are ``validate_trajectory_msg``'s
    with ``allow_partial_joints_goal`` false, then this joint's travel ``[0, travel_m]``.
    """
    names = list(joint_names)
    if len(names) != 1:
        raise TrajectoryError("Joints on incoming trajectory don't match the controller joints.")
    if not points:
        raise TrajectoryError('Empty trajectory received.')
    if names[0] != joint:
        raise TrajectoryError(f"Incoming joint {names[0]} doesn't match the controller's "
                              'joints.')
    last_velocities = list(points[-1].velocities)
    if not allow_nonzero_velocity_at_end:
        for velocity in last_velocities:
            if abs(velocity) > FLOAT_EPSILON:
                raise TrajectoryError(f'Velocity of last trajectory point of joint {joint} is '
                                      f'not zero: {velocity:.15f}')
    if start_ns != 0 and start_ns + points[-1].time_from_start_ns < now_ns:
        raise TrajectoryError(
            f'Received trajectory with non-zero start time ({start_ns * 1e-9:f}) that ends in '
            f'the past ({(start_ns + points[-1].time_from_start_ns) * 1e-9:f})')
    checked = []
    for i, p in enumerate(points):
        if i > 0 and p.time_from_start_ns <= points[i - 1].time_from_start_ns:
            raise TrajectoryError(
                f'Time between points {i - 1} and {i} is not strictly increasing, it is '
                f'{points[i - 1].time_from_start_ns * 1e-9:f} and '
                f'{p.time_from_start_ns * 1e-9:f} respectively')
        position = _entry(p.positions, 0, 'positions', i, 1, False)
        velocity = _entry(p.velocities, 0, 'velocities', i, 1, True)
        acceleration = _entry(p.accelerations, 0, 'accelerations', i, 1, True)
        if list(p.effort):
            raise TrajectoryError('Trajectories with effort fields are only supported for '
                                  "controllers using the 'effort' command interface.")
        for what, value in (('position', position), ('velocity', velocity),
                            ('acceleration', acceleration)):
            if value is not None and not math.isfinite(value):
                raise TrajectoryError(f'point #{i}: the {what} of {joint} is {value!r}, not a '
                                      'finite number')
        if not 0.0 <= position <= travel_m:
            raise TrajectoryError(f'point #{i}: position {position!r} of {joint} is out of the '
                                  f"joint's limits [0, {travel_m:g}] m (the travel of the finger "
                                  'from fully open)')
        if acceleration is not None and velocity is None:
            raise TrajectoryError(f'point #{i}: accelerations without velocities (a spline needs '
                                  'the velocities too)')
        checked.append(Point(p.time_from_start_ns, position, velocity, acceleration))
    return checked


def interpolate(t0_ns: int, a: State | Point, t1_ns: int, b: State | Point,
                t_ns: int) -> State:
    """Return the state at ``t_ns`` between ``a`` at ``t0_ns`` and ``b`` at ``t1_ns``.

    ``interpolate_between_points``: linear in position unless both ends have velocities (cubic)
    and accelerations too (quintic). Outside ``[t0, t1]`` the time is clamped to the nearer end
    and the interpolation is linear (its velocity the segment's mean).
    """
    span_s = (t1_ns - t0_ns) * 1e-9
    dt_s = (t_ns - t0_ns) * 1e-9
    has_velocity = a.velocity is not None and b.velocity is not None
    has_acceleration = a.acceleration is not None and b.acceleration is not None
    if dt_s < 0.0:
        dt_s, has_velocity, has_acceleration = 0.0, False, False
    if dt_s > span_s:
        dt_s, has_velocity, has_acceleration = span_s, False, False
    p0, p1 = a.position, b.position
    if not has_velocity:
        rate = (p1 - p0) / span_s if span_s != 0.0 else 0.0
        return State(p0 + rate * dt_s, rate, 0.0)
    v0, v1 = a.velocity, b.velocity
    t, T = dt_s, span_s
    if not has_acceleration:
        c2 = c3 = 0.0
        if T != 0.0:
            c2 = (-3.0 * p0 + 3.0 * p1 - 2.0 * v0 * T - v1 * T) / T ** 2
            c3 = (2.0 * p0 - 2.0 * p1 + v0 * T + v1 * T) / T ** 3
        return State(p0 + v0 * t + c2 * t ** 2 + c3 * t ** 3,
                     v0 + 2.0 * c2 * t + 3.0 * c3 * t ** 2, 2.0 * c2 + 6.0 * c3 * t)
    a0, a1 = a.acceleration, b.acceleration
    c2 = 0.5 * a0
    c3 = c4 = c5 = 0.0
    if T != 0.0:
        c3 = (-20.0 * p0 + 20.0 * p1 - 3.0 * a0 * T ** 2 + a1 * T ** 2 - 12.0 * v0 * T
              - 8.0 * v1 * T) / (2.0 * T ** 3)
        c4 = (30.0 * p0 - 30.0 * p1 + 3.0 * a0 * T ** 2 - 2.0 * a1 * T ** 2 + 16.0 * v0 * T
              + 14.0 * v1 * T) / (2.0 * T ** 4)
        c5 = (-12.0 * p0 + 12.0 * p1 - a0 * T ** 2 + a1 * T ** 2 - 6.0 * v0 * T
              - 6.0 * v1 * T) / (2.0 * T ** 5)
    return State(p0 + v0 * t + c2 * t ** 2 + c3 * t ** 3 + c4 * t ** 4 + c5 * t ** 5,
                 v0 + 2.0 * c2 * t + 3.0 * c3 * t ** 2 + 4.0 * c4 * t ** 3 + 5.0 * c5 * t ** 4,
                 2.0 * c2 + 6.0 * c3 * t + 12.0 * c4 * t ** 2 + 20.0 * c5 * t ** 3)


@dataclass(frozen=True)
class Sample:
    """A sampled state, where it is and whether the last point's time is still ahead.

    ``segment``: the index of the point its segment starts at (-1: before the first point).
    """

    state: State
    segment: int
    before_last_point: bool


class Trajectory:
    """A goal's points from a start time, sampled as ``Trajectory::sample`` does.

    ``start_ns``: the header's stamp, or 0 for the time of the first sample. The state before
    the trajectory is set by the first update (:meth:`set_state_before`).
    """

    def __init__(self, points: list[Point], start_ns: int = 0):
        if not points:
            raise TrajectoryError('Empty trajectory received.')
        self.points = points
        self.start_ns = start_ns
        self.time_before_ns: int | None = None
        self.state_before: State | None = None

    def set_state_before(self, t_ns: int, state: State) -> None:
        """Start from ``state`` at ``t_ns`` (the first update's measurement).

        ``set_point_before_trajectory_msg``: a velocity or acceleration the state lacks but the
        first point has is 0 (so that the first segment is of the same degree as the rest).
        """
        first = self.points[0]
        velocity = state.velocity
        if velocity is None and first.velocity is not None:
            velocity = 0.0
        acceleration = state.acceleration
        if acceleration is None and first.acceleration is not None:
            acceleration = 0.0
        self.time_before_ns = t_ns
        self.state_before = State(state.position, velocity, acceleration)
        if self.start_ns == 0:
            self.start_ns = t_ns

    def point_ns(self, index: int) -> int:
        """Return the time (ns) of point ``index``."""
        return self.start_ns + self.points[index].time_from_start_ns

    @property
    def end_ns(self) -> int:
        return self.point_ns(len(self.points) - 1)

    def sample(self, t_ns: int) -> Sample:
        """Return the state at ``t_ns`` (after :meth:`set_state_before`)."""
        first_ns = self.point_ns(0)
        if t_ns < first_ns:
            return Sample(interpolate(self.time_before_ns, self.state_before, first_ns,
                                      self.points[0], t_ns), -1, True)
        last = len(self.points) - 1
        for i in range(last):
            t0_ns, t1_ns = self.point_ns(i), self.point_ns(i + 1)
            if t0_ns <= t_ns < t1_ns:
                return Sample(interpolate(t0_ns, self.points[i], t1_ns, self.points[i + 1],
                                          t_ns), i, True)
        end = self.points[last]
        return Sample(State(end.position, end.velocity or 0.0, end.acceleration or 0.0), last,
                      False)


def resolve_tolerance(default: float, given: float) -> float:
    """Return the tolerance in force: ``given`` > 0, 0 for -1 (erased), ``default`` for 0.

    ``resolve_tolerance_source``; ValueError for another negative value.
    """
    if given > 0.0:
        return given
    if abs(given - ERASE_TOLERANCE) < FLOAT_EPSILON:
        return 0.0
    if given < 0.0:
        raise ValueError(f'Illegal tolerance value {given!r}')
    return default


def resolve_tolerances(defaults: Tolerances, joint: str, path_tolerance=(),
                       goal_tolerance=(), goal_time_tolerance_s: float = 0.0
                       ) -> tuple[Tolerances, str]:
    """Return the tolerances of a goal and why the defaults were kept ('' if they were not).

    ``get_segment_tolerances``: ``path_tolerance`` and ``goal_tolerance`` are JointTolerance
    entries (``name``, ``position``, ``velocity``, ``acceleration``); an entry for another joint
    or an illegal value keeps all the defaults, as JTC does (it logs why).
    """
    try:
        goal_time_s = resolve_tolerance(defaults.goal_time_s, goal_time_tolerance_s)
    except ValueError:
        return defaults, f'Specified illegal goal_time_tolerance: {goal_time_tolerance_s:f}. ' \
                         'Using default tolerances'
    resolved = {'path': defaults.path, 'goal': defaults.goal}
    for kind, entries in (('path', path_tolerance), ('goal', goal_tolerance)):
        for entry in entries:
            if entry.name != joint:
                return defaults, (f"joint '{entry.name}' specified in goal.{kind}_tolerance does "
                                  'not exist. Using default tolerances.')
            fields = {}
            for what in ('position', 'velocity', 'acceleration'):
                try:
                    fields[what] = resolve_tolerance(getattr(defaults, kind).__dict__[what],
                                                     float(getattr(entry, what)))
                except ValueError:
                    return defaults, (f"joint '{joint}' specified in goal.{kind}_tolerance has "
                                      f'a invalid {what} tolerance. Using default tolerances.')
            resolved[kind] = StateTolerance(**fields)
    return Tolerances(resolved['path'], resolved['goal'], goal_time_s), ''


def within(error: State, tolerance: StateTolerance) -> bool:
    """Tell whether ``error`` (desired - actual) is within ``tolerance`` (0: unchecked).

    ``check_state_tolerance_per_joint``: an error left unknown (None) counts as 0.
    """
    for what in ('position', 'velocity', 'acceleration'):
        bound = getattr(tolerance, what)
        value = getattr(error, what)
        if bound > 0.0 and value is not None and abs(value) > bound:
            return False
    return True


def violation_text(error: State, tolerance: StateTolerance) -> str:
    """Name what ``error`` violates, as JTC logs it (``Position Error: e, ... Tolerance: t``)."""
    parts = []
    for what in ('position', 'velocity', 'acceleration'):
        bound = getattr(tolerance, what)
        value = getattr(error, what)
        if bound > 0.0 and value is not None and abs(value) > bound:
            parts.append(f'{what.capitalize()} Error: {value:f}, {what.capitalize()} Tolerance: '
                         f'{bound:f}')
    return '; '.join(parts)


@dataclass(frozen=True)
class Update:
    """One update of a running goal.

    ``command``: the state to command for the next update, at ``command_ns``; None when
    nothing new is to be commanded (the goal has ended: see ``verdict``).
    ``verdict``: None while the goal runs; its code once it has ended, with ``message``
    (the result's ``error_string``) and ``hold`` (the state to hold from now).
    """

    t_ns: int
    desired: State
    actual: State
    error: State
    command: State | None
    command_ns: int
    verdict: Verdict | None = None
    message: str = ''
    hold: State | None = None


class TrajectoryRun:
    """One goal's trajectory, updated at each measurement as JTC's ``update()`` does.

    The first update sets the state before the trajectory (the measurement) and, with no
    header stamp, its start. Each update samples the desired state now and the command for
    ``now + period``. Until the last point's time, a path tolerance violated aborts the goal
    (PATH_TOLERANCE_VIOLATED); from it on, the goal succeeds once within the goal tolerance,
    and is aborted (GOAL_TOLERANCE_VIOLATED) when still outside it ``goal_time_s`` after the
    last point (``goal_time_s`` 0: it waits). An ended goal holds: the measured position after
    an abort, the last point after success.
    """

    def __init__(self, trajectory: Trajectory, tolerances: Tolerances):
        self.trajectory = trajectory
        self.tolerances = tolerances
        self.updates = 0
        self.ended: Verdict | None = None

    def update(self, t_ns: int, position: float, velocity: float | None,
               period_ns: int) -> Update:
        """Return the update of the measurement (``position``, ``velocity``) at ``t_ns``."""
        traj = self.trajectory
        actual = State(position, velocity, None)
        first = self.updates == 0
        if first:
            traj.set_state_before(t_ns, actual)
        self.updates += 1
        now = traj.sample(t_ns)
        desired = now.state
        command_ns = t_ns + period_ns
        command = traj.sample(command_ns).state
        error = State(desired.position - position,
                      None if velocity is None else desired.velocity - velocity, None)
        if self.ended is not None:
            return Update(t_ns, desired, actual, error, None, command_ns, self.ended)
        tol = self.tolerances
        path_violated = (now.before_last_point or first) and not within(error, tol.path)
        outside_goal = not now.before_last_point and not within(error, tol.goal)
        late_s = (t_ns - traj.point_ns(max(now.segment, 0))) * 1e-9
        within_goal_time = not (outside_goal and tol.goal_time_s != 0.0
                                and late_s > tol.goal_time_s)
        hold = State(position, 0.0, 0.0)
        if path_violated:
            self.ended = Verdict.PATH_TOLERANCE_VIOLATED
            return Update(t_ns, desired, actual, error, None, command_ns, self.ended,
                          'Aborted due to path tolerance violation: '
                          + violation_text(error, tol.path), hold)
        if not now.before_last_point and not outside_goal:
            self.ended = Verdict.SUCCESSFUL
            end = traj.points[-1]
            return Update(t_ns, desired, actual, error, None, command_ns, self.ended,
                          'Goal successfully reached!',
                          State(end.position, end.velocity or 0.0, end.acceleration or 0.0))
        if not within_goal_time:
            self.ended = Verdict.GOAL_TOLERANCE_VIOLATED
            return Update(t_ns, desired, actual, error, None, command_ns, self.ended,
                          f'Aborted due to goal_time_tolerance exceeding by {late_s:f} seconds: '
                          + violation_text(error, tol.goal), hold)
        return Update(t_ns, desired, actual, error, command, command_ns)
