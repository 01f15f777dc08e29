"""Grasp supervisor: the state machine of grasp, hold, release and move requests (no rclpy).

Stages (paper sec. IV): POSITION (MPC-PD drives the finger to ``L_ls - width``) until either
switching criterion holds - the position is within +-2 % of its setpoint, or the force-sensor
voltage has risen by more than its threshold - then FORCE (to the request's setpoint,
:func:`gripper_ros.core.supervision.requests.force_setpoint_n`) until the force has settled:
HOLDING. Settled means ``|F - F_sp| + T |dF/dt|`` within the band and the finger slower than
``force_settle_speed_mps`` on every tick for ``force_settle_hold_s``, ``T`` being the slowest
contact mode's time scale (``force_settle_horizon_s``), so that no swing through the band is
taken for settled. Exactly one
controller is active at any tick; the decision for each tick is a :class:`Decision`.

Loss watch: once the force has reached ``lost_force_fraction`` of its setpoint after contact, a
force below that fraction for ``lost_force_hold_s``, or (after settling) the finger moving on
past the held position by more than ``no_object_margin_m``, ends the grasp as OBJECT_LOST.
After settling, the force loop keeps holding and watching for the configured hold watch (phase
HOLDING, force controller still active) before the grasp ends with outcome HOLDING.

Release: :meth:`GraspSupervisor.request_release` runs the position stage to the open position
(phase RELEASING) until the finger has stayed within ``release_tolerance_m`` of it for
``release_settle_s``: phase DONE, outcome RELEASED.

Move (:meth:`GraspSupervisor.request_move`, Franka's move, control_msgs GripperCommand's
result): the position stage drives the finger to ``L_ls - width`` with the request's speed and
effort as its limits (phase MOVING;
:class:`gripper_ros.core.control.stages.PositionStageController` keeps the speed below the limit
and the push below the stall voltage of the effort). MOVED (``reached_goal``) once the finger is at
rest within ``move_tolerance_m`` of the goal; STALLED once it is at rest short of the goal and,
closing, presses with ``move_stall_force_fraction`` x the effort limit (the force sensor tells
contact), or has been at rest short of it for ``move_stall_timeout_s``. Either way the position
stage then keeps the move's last command (the goal, the limits): a stalled move goes on pressing
with at most its effort, as a position-controlled gripper keeps its command.

Setpoint (:meth:`GraspSupervisor.request_servo`, ``joint_commands``): a position servo. The
newest setpoint is a move in force at once: while the previous setpoint's move runs, its goal
and limits change in place (same request, the position stage not restarted); otherwise what
runs ends STOPPED and the setpoint's move starts at the next tick. A stream that keeps changing
moves its reference on between setpoints with its velocity and acceleration, given or estimated
(:mod:`gripper_ros.core.control.servo_feedforward`), which the position stage also turns into
feed-forward. A grasp, release or move request ends a running
setpoint's move (STOPPED) and runs; requests among themselves go one at a time.

The state machine is compiled (numba): :func:`supervisor_step` and :func:`supervisor_decide`
run on the state record :data:`SUPERVISOR_STATE`, called tick by tick by the supervisor node
and by the compiled headless loop alike. :class:`GraspSupervisor` is the Python face of that
record: it takes requests, reads the state and writes the outcome messages, whose numbers the
kernel keeps.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import (GripperConfig, numbers_of, PlantParams, shipped_config,
                                     SupervisorParams)
from gripper_ros.core.control.load_grip import (GRIP_DTYPE, HISTORY_ROWS, law_step, make_law,
                                                MU_GRID, plan_announce, PLAN_DTYPE, PLAN_ROWS)
from gripper_ros.core.control.servo_feedforward import (NO_STREAM, SERVO_DTYPE, servo_changing,
                                                        servo_reference, servo_sample,
                                                        servo_setup)
from gripper_ros.core.records import (copy_fields, face_kernel, FLOATS_2D, RecordField,
                                      RecordParams, set_fields)
from gripper_ros.core.supervision.requests import GraspTargets, MoveTargets, RequestError
from gripper_ros.wire import (Controller, Outcome, PendingRequest, Phase, REFERENCE_LAYOUT,
                              SwitchCriterion, TICK_LAYOUT)
import numba
import numpy as np

NO_NS = -1
"""An ``*_ns`` field that holds no time (every simulated time is >= 0)."""
NO_ANSWER = -1
"""A decision that answers nothing this tick."""


class RequestKind:
    """The kinds of request the supervisor runs (also the words its log and refusals use)."""

    GRASP = 'grasp'
    RELEASE = 'release'
    MOVE = 'move'


KIND_CODES = {RequestKind.GRASP: PendingRequest.GRASP, RequestKind.RELEASE: PendingRequest.RELEASE,
              RequestKind.MOVE: PendingRequest.MOVE}
"""Each request kind's code in the state record (``kind``, ``pend_kind``; 0 = none)."""
KIND_NAMES = {int(code): kind for kind, code in KIND_CODES.items()}

_TARGET_FIELDS = ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                  'friction_coefficient', 'timeout_s', 'width_tolerance_m', 'speed_mps',
                  'max_effort_n', 'voltage_limit_v', 'tolerance_m', 'load_tracking')
"""A request's targets as the kernel reads them (a grasp's move fields are 0)."""

SUPERVISOR_STATE = np.dtype(
    [('t_ns', 'i8'), ('kind', 'i4'), ('phase', 'i4'), ('switch_criterion', 'i4'),
     ('outcome', 'i4'), ('active', 'i4'), ('answer', 'i4'), ('grasp_id', 'i8'),
     ('stage_id', 'i8'), ('mass_kg', 'f8'), ('start_ns', 'i8'), ('switch_ns', 'i8'),
     ('contact_ns', 'i8'), ('settled_ns', 'i8'), ('end_ns', 'i8'), ('answer_ns', 'i8'),
     ('hold_position_m', 'f8'),            # NaN: not holding
     ('idle_hold_m', 'f8'),                # where the position stage holds without a request
     ('idle_limit_v', 'f8'),               # ... its voltage cap (0: the plant's limit)
     ('idle_speed_limit_mps', 'f8'),       # ... its speed limit (0: none)
     ('position_m', 'f8'),                 # last position measured in a request (NaN: none)
     ('move_timeout_s', 'f8'), ('rest_since_ns', 'i8'),
     ('revision', 'i8'),                   # the plant's world revision last seen (-1: none)
     ('baseline_voltage_v', 'f8'), ('in_band_since_ns', 'i8'),
     ('prev_force_t_ns', 'i8'), ('prev_force_n', 'f8'),    # previous FORCE tick (settle rate)
     ('gripped', 'b1'),                    # force reached lost_force_fraction x F_sp
     ('low_since_ns', 'i8'),
     ('seed_voltage_v', 'f8'),             # the last finite applied voltage (a stage's seed)
     ('msg_code', 'i4'), ('msg_seq', 'i8'),  # the current message: a code, numbers in msg_*
     ('status_key', 'i8'),                 # phase, active, outcome and stage in one number
     ('overload_ns', 'i8'),                # when the load-tracking grip said overload
     ('tg_kind', 'i4'),                    # the current request's targets (0: none yet)
     ('servo', SERVO_DTYPE),               # the setpoint stream moving a move's goal
     ('travel_m', 'f8')]                   # the finger's travel: where a reference may lie
    + [('tg_' + name, 'f8') for name in _TARGET_FIELDS]
    + [('pend_kind', 'i4'), ('pend_mass_kg', 'f8'), ('pend_after_ns', 'i8')]   # 0: none
    + [('pend_' + name, 'f8') for name in _TARGET_FIELDS]
    + [('d_answer', 'i4'), ('d_running', 'b1'), ('d_contact', 'b1'),   # the tick's decision
       ('d_position_setpoint_m', 'f8'), ('d_approach_setpoint_m', 'f8'),
       ('d_force_setpoint_n', 'f8'), ('d_speed_limit_mps', 'f8'), ('d_voltage_limit_v', 'f8'),
       ('d_holding', 'b1'), ('d_pressing', 'b1'),
       ('d_approach_velocity_mps', 'f8'), ('d_approach_acceleration_mps2', 'f8')],
    align=True)
"""Everything the state machine remembers between ticks, and the decision of the last one."""

_PARAM_FIELDS = numbers_of(SupervisorParams)
SUPERVISOR_PARAMS = np.dtype([(name, 'f8') for name in _PARAM_FIELDS], align=True)
"""The numbers of :class:`SupervisorParams`, which the tick reads."""

# Messages: a code (``msg_code``) and the numbers the text needs (a SUPERVISOR_MESSAGE record),
# written by the kernel at the instant the outcome happens and formatted by
# GraspSupervisor.message.
MSG_NONE = 0
MSG_TEXT = 1                  # a text given from Python (stop, fault)
MSG_SENSOR_FAULT = 2
MSG_NO_OBJECT = 3
MSG_LOST_FORCE = 4
MSG_LOST_MOVED_ON = 5
MSG_HOLDING = 6
MSG_GRASP_TIMEOUT = 7
MSG_RELEASED = 8
MSG_RELEASE_TIMEOUT = 9
MSG_MOVED = 10
MSG_STALLED_PRESSING = 11
MSG_STALLED_AT_REST = 12
MSG_MOVE_TIMEOUT = 13
MSG_OVERLOADED = 14           # the load needs more grip than the most the motor holds
MSG_OVERLOADED_SLIDING = 15   # the object slides on at the most grip

SUPERVISOR_MESSAGE = np.dtype(
    [('t_ns', 'i8'), ('start_ns', 'i8'),
     ('since_ns', 'i8'),                   # the force low (LOST_FORCE) or at rest (STALLED) since
     ('into_ns', 'i8'),                    # how long after HOLDING (after_holding) or the start
     ('after_holding', 'b1'), ('bad_position', 'b1'), ('bad_force', 'b1'),
     ('request_kind', 'i4'),               # SENSOR_FAULT: the request's code, 0: the hold
     ('phase', 'i4'),                      # GRASP_TIMEOUT: the phase it was in
     ('position_m', 'f8'), ('force_n', 'f8'), ('sensor_voltage_v', 'f8'),
     ('position_setpoint_m', 'f8'),        # the expected face, the open position, the goal
     ('width_tolerance_m', 'f8'), ('farthest_face_m', 'f8'),
     ('lost_force_fraction', 'f8'), ('force_setpoint_n', 'f8'), ('floor_n', 'f8'),
     ('hold_position_m', 'f8'), ('margin_m', 'f8'), ('timeout_s', 'f8'),
     ('short_of_goal_m', 'f8'), ('max_effort_n', 'f8'),
     ('need_n', 'f8'), ('max_force_n', 'f8'), ('load_n', 'f8'), ('friction_coefficient', 'f8')],
    align=True)
"""The numbers of the current message, by name; each code writes the fields its text reads."""

_MOST_GRIP = ('the most {voltage_limit_v:g} V holds is {max_force_n:.2f} N; gripping with '
              '{force_n:.2f} N, at most that, while the object stays')
_WHERE = ('finger at {position_m:.5f} m (opening {opening_m:.5f} m, goal {goal_opening_m:.5f} m),'
          ' force {force_n:.3f} N, after {elapsed_s:.3f} s')
_STALLED = 'stalled {short_of_goal_mm:.2f} mm short of the goal, '

MESSAGES = {
    MSG_NONE: '',
    MSG_TEXT: '{text}',
    MSG_SENSOR_FAULT: ('fault at t={t_s:.4f} s ({elapsed_s:.4f} s into the {what}): {bad}; '
                       'no controller drives the motor from here on'),
    MSG_NO_OBJECT: ('no object: the finger passed the expected face ({position_setpoint_m:.4f} m'
                    '{tolerance}) by {past_face_mm:.2f} mm without contact'),
    MSG_LOST_FORCE: ('object lost at {at}, {into}: force {force_n:.3f} N has been below '
                     '{lost_force_fraction:g} x the setpoint {force_setpoint_n:.3f} N = '
                     '{floor_n:.3f} N for {low_ms:.2f} ms (since t={since_s:.4f} s); finger at '
                     '{position_m:.5f} m'),
    MSG_LOST_MOVED_ON: ('object lost at {at}, {into}: the finger moved on {moved_on_mm:.2f} mm '
                        'past the held position {hold_position_m:.5f} m (margin {margin_mm:g} '
                        'mm); force {force_n:.3f} N'),
    MSG_OVERLOADED: ('overloaded at {at} ({into}): the load {load_n:.2f} N needs {need_n:.2f} N '
                     'of grip at the measured friction {friction_coefficient:.3f}, '
                     + _MOST_GRIP),
    MSG_OVERLOADED_SLIDING: ('overloaded at {at} ({into}): the object slides on, no slower, with'
                             ' the grip at its most: kinetic friction ({friction_coefficient:.3f}'
                             ' measured) is short of the load; ' + _MOST_GRIP),
    MSG_HOLDING: ('holding {force_n:.3f} N (setpoint {force_setpoint_n:.3f} N) at '
                  '{position_m:.5f} m'),
    MSG_GRASP_TIMEOUT: ('not settled within {timeout_s:g} s of simulated time (phase '
                        '{phase_name}, position {position_m:.5f} m, force {force_n:.3f} N)'),
    MSG_RELEASED: ('released: finger at {position_m:.5f} m (open position '
                   '{position_setpoint_m:.5f} m, opening {opening_m:.5f} m) after '
                   '{elapsed_s:.3f} s'),
    MSG_RELEASE_TIMEOUT: ('release not done within {timeout_s:g} s of simulated time (finger at '
                          '{position_m:.5f} m)'),
    MSG_MOVED: 'moved: ' + _WHERE,
    MSG_STALLED_PRESSING: (_STALLED + 'pressing with {force_n:.3f} N at the effort limit '
                           '{max_effort_n:.3f} N: ' + _WHERE),
    MSG_STALLED_AT_REST: _STALLED + 'at rest for {rest_s:.3f} s: ' + _WHERE,
    MSG_MOVE_TIMEOUT: 'move not done within {timeout_s:g} s of simulated time: ' + _WHERE,
}
"""Each message code's text: :data:`SUPERVISOR_MESSAGE` fields and :data:`MESSAGE_VALUES` by
name (:func:`format_message`)."""

# The entries of the tuple ``GraspSupervisor.kernel`` (the headless loop reads 0 and 4).
K_STATE = 0
K_PARAMS = 1
K_MESSAGE = 2
K_LAW_BUFFERS = 3
K_LAW = 4
K_PLAN = 5
_KERNEL_ARRAYS = (SUPERVISOR_STATE, SUPERVISOR_PARAMS, SUPERVISOR_MESSAGE, FLOATS_2D, GRIP_DTYPE,
                  PLAN_DTYPE)
"""The types of ``GraspSupervisor.kernel``, entry by entry."""

_kernel = numba.njit(cache=True)


# ------------------------------------------------------------------ the compiled state machine
@_kernel
def supervisor_record(k):
    """Return the state record of the supervisor kernel ``k``, for compiled readers."""
    return k[K_STATE][0]


@_kernel
def supervisor_law_arrays(k):
    """Return the load-tracking grip's record and its copy as a grasp starts (``K_LAW``)."""
    return k[K_LAW]


@_kernel
def _running(s) -> bool:
    """Tell whether a request is in progress (it needs simulated time until answered)."""
    return s.kind != 0 and s.outcome == Outcome.UNKNOWN


@_kernel
def status_key(s) -> int:
    """Return a number that changes with the phase, driver, outcome, stage or waiting request.

    The status goes out at once when it does.
    """
    return s.status_key * 4 + s.pend_kind


@_kernel
def _holding(s) -> bool:
    """Tell whether a grasp was answered HOLDING (or OVERLOADED) and the force stage holds on."""
    return s.phase == Phase.HOLDING and (s.outcome == Outcome.HOLDING or
                                         s.outcome == Outcome.OVERLOADED)


@_kernel
def _pressing(s) -> bool:
    """Tell whether a stalled move's last command is in force (the finger presses)."""
    return s.outcome == Outcome.STALLED and s.idle_speed_limit_mps > 0.0 and \
        s.active == Controller.POSITION


@_kernel
def _assign(s, controller) -> None:
    """Hand the motor to ``controller`` from this tick on; it restarts (new stage)."""
    s.active = controller
    s.stage_id += 1


@_kernel
def _hold_here(s, position_m, limit_v, speed_limit_mps) -> None:
    """Let the position stage hold the finger at ``position_m`` (no request running)."""
    if math.isfinite(position_m):
        s.idle_hold_m = position_m
    s.idle_limit_v = limit_v
    s.idle_speed_limit_mps = speed_limit_mps
    _assign(s, Controller.POSITION)


@_kernel
def _last_position(s) -> float:
    """Where to hold when a request or hold ends: the held, last measured or idle position."""
    if not math.isnan(s.hold_position_m):
        return s.hold_position_m
    if _running(s) and not math.isnan(s.position_m):
        return s.position_m
    return s.idle_hold_m


@_kernel
def _end(s, phase, outcome, msg_code, hold, position_m, move_limits) -> int:
    """End the request (or the hold) with ``outcome``; the position stage holds, or nothing.

    ``position_m`` NaN: where the finger is (:func:`_last_position`). ``move_limits``: hold
    with the move's speed and voltage limits.
    """
    if hold and math.isnan(position_m):
        position_m = _last_position(s)
    s.phase = phase
    s.outcome = outcome
    s.msg_code = msg_code
    s.msg_seq += 1
    s.end_ns = s.t_ns
    if hold:
        if move_limits:
            _hold_here(s, position_m, s.tg_voltage_limit_v, s.tg_speed_mps)
        else:
            _hold_here(s, position_m, 0.0, 0.0)
    else:
        s.active = Controller.NONE
        s.stage_id += 1
    return s.outcome


_REQUEST_TIMES = ('answer_ns', 'switch_ns', 'contact_ns', 'settled_ns', 'end_ns',
                  'in_band_since_ns', 'prev_force_t_ns', 'low_since_ns', 'rest_since_ns',
                  'overload_ns')
"""The instants of a request (``NO_NS`` as it starts)."""


@_kernel
def _reset(s, t_ns) -> None:
    s.outcome = Outcome.UNKNOWN
    s.answer = Outcome.UNKNOWN
    s.switch_criterion = SwitchCriterion.NONE
    s.start_ns = t_ns
    s.t_ns = t_ns
    set_fields(s, _REQUEST_TIMES, NO_NS)
    s.hold_position_m = math.nan
    s.prev_force_n = 0.0
    s.gripped = False
    s.msg_code = MSG_NONE
    s.msg_seq += 1


@_kernel
def _take_pending(s) -> None:
    """Make the waiting request the current one (its targets, mass and a new id)."""
    s.kind = s.pend_kind
    s.tg_kind = s.pend_kind
    s.mass_kg = s.pend_mass_kg
    copy_fields(s, s, _TARGET_FIELDS, 'tg_', 'pend_')
    s.pend_kind = 0
    s.grasp_id += 1


@_kernel
def _start(s, p, t_ns, position_m, sensor_voltage_v) -> None:
    _take_pending(s)
    if s.kind == PendingRequest.GRASP:
        s.phase = Phase.POSITION
    elif s.kind == PendingRequest.RELEASE:
        s.phase = Phase.RELEASING
    else:
        s.phase = Phase.MOVING
    _reset(s, t_ns)
    s.baseline_voltage_v = sensor_voltage_v
    if s.kind == PendingRequest.MOVE:
        timeout_s = s.tg_timeout_s
        s.move_timeout_s = timeout_s if timeout_s != 0.0 else (
            p.timeout_s + abs(s.tg_position_setpoint_m - position_m) / s.tg_speed_mps)
    _assign(s, Controller.POSITION)


@_kernel
def _switch(s, criterion, t_ns) -> None:
    s.prev_force_t_ns = NO_NS          # the settle criterion's force rate starts here
    s.phase = Phase.FORCE
    s.switch_criterion = criterion
    s.switch_ns = t_ns
    _assign(s, Controller.FORCE)


@_kernel
def _note(s, m, position_m, force_n) -> None:
    """Write what every message may read: when, how long in, the position and the force.

    How long into the request, or into the hold after HOLDING; each message code then writes
    its own numbers.
    """
    m.t_ns = s.t_ns
    m.start_ns = s.start_ns
    if _holding(s) and s.end_ns != NO_NS:
        m.after_holding = True
        m.into_ns = s.t_ns - s.end_ns
    else:
        m.after_holding = False
        m.into_ns = s.t_ns - s.start_ns
    m.position_m = position_m
    m.force_n = force_n


@_kernel
def _force_settled(s, p, t_ns, force_n, speed_mps) -> bool:
    """Apply the force stage's settle criterion, once per FORCE-phase tick.

    Settled once, for ``force_settle_hold_s`` on end, every tick has had ``|F - F_sp| + T
    |dF/dt| <= band`` (``T`` = ``force_settle_horizon_s``, ``dF/dt`` from the previous tick)
    and the finger slower than ``force_settle_speed_mps``. A force oscillation ``A sin(w t)``
    with ``w >= 1 / T`` gives ``|e| + T |de/dt| >= A`` at every instant, so none larger than
    the band is ever taken for settled; the speed bound keeps the creep of a damped object
    after HOLDING inside the loss watch's margin.
    """
    prev_t_ns = s.prev_force_t_ns
    prev_force_n = s.prev_force_n
    s.prev_force_t_ns = t_ns
    s.prev_force_n = force_n
    if prev_t_ns == NO_NS or t_ns <= prev_t_ns:
        s.in_band_since_ns = NO_NS
        return False
    rate = (force_n - prev_force_n) / ((t_ns - prev_t_ns) * 1e-9)
    band = p.force_settle_band_fraction * s.tg_force_setpoint_n
    steady = (abs(force_n - s.tg_force_setpoint_n) + p.force_settle_horizon_s * abs(rate)
              <= band and (p.force_settle_speed_mps <= 0.0
                           or abs(speed_mps) <= p.force_settle_speed_mps))
    if not steady:
        s.in_band_since_ns = NO_NS
        return False
    if s.in_band_since_ns == NO_NS:
        s.in_band_since_ns = t_ns
    return (t_ns - s.in_band_since_ns) * 1e-9 >= p.force_settle_hold_s


@_kernel
def _object_lost(s, p, m, t_ns, position_m, force_n) -> int:
    """After contact: a force collapse, or the finger moving on past the held position."""
    floor = p.lost_force_fraction * s.tg_force_setpoint_n
    if force_n >= floor:
        s.gripped = True
        s.low_since_ns = NO_NS
    elif s.gripped:
        if s.low_since_ns == NO_NS:
            s.low_since_ns = t_ns
        low_s = (t_ns - s.low_since_ns) * 1e-9
        if low_s >= p.lost_force_hold_s:
            _note(s, m, position_m, force_n)
            m.since_ns = s.low_since_ns
            m.lost_force_fraction = p.lost_force_fraction
            m.force_setpoint_n = s.tg_force_setpoint_n
            m.floor_n = floor
            return _end(s, Phase.FAILED, Outcome.OBJECT_LOST, MSG_LOST_FORCE, True,
                        position_m, False)
    if not math.isnan(s.hold_position_m) and \
            position_m > s.hold_position_m + p.no_object_margin_m:
        _note(s, m, position_m, force_n)
        m.hold_position_m = s.hold_position_m
        m.margin_m = p.no_object_margin_m
        return _end(s, Phase.FAILED, Outcome.OBJECT_LOST, MSG_LOST_MOVED_ON, True, position_m,
                    False)
    return NO_ANSWER


@_kernel
def _step_release(s, p, m, t_ns, position_m, force_n) -> int:
    if abs(position_m - s.tg_position_setpoint_m) <= p.release_tolerance_m:
        if s.in_band_since_ns == NO_NS:
            s.in_band_since_ns = t_ns
        if (t_ns - s.in_band_since_ns) * 1e-9 >= p.release_settle_s:
            _note(s, m, position_m, force_n)
            m.position_setpoint_m = s.tg_position_setpoint_m
            return _end(s, Phase.DONE, Outcome.RELEASED, MSG_RELEASED, True, position_m, False)
    else:
        s.in_band_since_ns = NO_NS
    if (t_ns - s.start_ns) * 1e-9 > s.tg_timeout_s:
        _note(s, m, position_m, force_n)
        m.timeout_s = s.tg_timeout_s
        return _end(s, Phase.FAILED, Outcome.TIMEOUT, MSG_RELEASE_TIMEOUT, True, position_m,
                    False)
    return NO_ANSWER


@_kernel
def _step_move(s, p, m, t_ns, position_m, force_n, sensor_voltage_v,
               speed_mps) -> int:
    """End a move MOVED, STALLED or TIMEOUT; the position stage drives it meanwhile."""
    goal = s.tg_position_setpoint_m
    elapsed_s = (t_ns - s.start_ns) * 1e-9
    if s.contact_ns == NO_NS and \
            sensor_voltage_v - s.baseline_voltage_v > p.sensor_voltage_threshold_v:
        s.contact_ns = t_ns
    error_m = goal - position_m                   # > 0: still to close
    at_rest = abs(speed_mps) <= p.move_rest_speed_mps
    _note(s, m, position_m, force_n)              # where: position, goal, force, elapsed
    m.position_setpoint_m = goal
    if not at_rest:
        s.rest_since_ns = NO_NS
    elif abs(error_m) <= s.tg_tolerance_m:
        if not servo_changing(s.servo, t_ns, p.servo_rate_window_s):   # no stream moves it
            return _end(s, Phase.DONE, Outcome.MOVED, MSG_MOVED, True, goal, True)
    else:
        if s.rest_since_ns == NO_NS:
            s.rest_since_ns = t_ns
        rest_s = (t_ns - s.rest_since_ns) * 1e-9
        fraction = p.move_stall_force_fraction
        # closing onto an obstacle, pressing at the effort limit (False for a NaN force)
        pressing = error_m > 0.0 and fraction * s.tg_max_effort_n <= force_n and \
            force_n <= s.tg_max_effort_n / fraction
        if pressing or rest_s >= p.move_stall_timeout_s:
            m.short_of_goal_m = error_m
            m.max_effort_n = s.tg_max_effort_n
            m.since_ns = s.rest_since_ns
            return _end(s, Phase.DONE, Outcome.STALLED,
                        MSG_STALLED_PRESSING if pressing else MSG_STALLED_AT_REST, True, goal,
                        True)
    if elapsed_s > s.move_timeout_s:
        m.timeout_s = s.move_timeout_s
        return _end(s, Phase.FAILED, Outcome.TIMEOUT, MSG_MOVE_TIMEOUT, True, position_m, False)
    return NO_ANSWER


@_kernel
def _step_request(s, p, m, t_ns, position_m, force_n, sensor_voltage_v,
                  speed_mps) -> int:
    phase = s.phase
    position_only = phase == Phase.RELEASING or phase == Phase.MOVING   # no force needed
    bad_position = not math.isfinite(position_m)
    bad_force = not position_only and not (math.isfinite(force_n)
                                           and math.isfinite(sensor_voltage_v))
    if bad_position or bad_force:
        _note(s, m, position_m, force_n)
        m.bad_position = bad_position
        m.bad_force = bad_force
        m.request_kind = 0 if _holding(s) else s.kind   # 0: the hold
        m.sensor_voltage_v = sensor_voltage_v
        return _end(s, Phase.FAILED, Outcome.FAULT, MSG_SENSOR_FAULT, False, math.nan, False)
    s.position_m = position_m                          # finite: where a stop holds
    if position_only:
        if phase == Phase.RELEASING:
            return _step_release(s, p, m, t_ns, position_m, force_n)
        return _step_move(s, p, m, t_ns, position_m, force_n, sensor_voltage_v,
                          speed_mps)
    sensor_rise = sensor_voltage_v - s.baseline_voltage_v > p.sensor_voltage_threshold_v
    if sensor_rise and s.contact_ns == NO_NS:
        s.contact_ns = t_ns
    farthest_face_m = s.tg_position_setpoint_m + s.tg_width_tolerance_m   # narrowest object
    if s.contact_ns == NO_NS and position_m > farthest_face_m + p.no_object_margin_m:
        _note(s, m, position_m, force_n)
        m.position_setpoint_m = s.tg_position_setpoint_m
        m.width_tolerance_m = s.tg_width_tolerance_m
        m.farthest_face_m = farthest_face_m
        return _end(s, Phase.FAILED, Outcome.NO_OBJECT, MSG_NO_OBJECT, True, position_m, False)
    if s.contact_ns != NO_NS:
        lost = _object_lost(s, p, m, t_ns, position_m, force_n)
        if lost != NO_ANSWER:
            return lost
    if _holding(s):
        return NO_ANSWER
    if s.phase == Phase.POSITION:
        tol = p.position_tolerance_fraction * s.tg_position_setpoint_m
        slow = p.position_switch_speed_mps <= 0.0 or abs(speed_mps) <= p.position_switch_speed_mps
        if abs(position_m - s.tg_approach_setpoint_m) <= tol and slow:
            _switch(s, SwitchCriterion.POSITION_TOLERANCE, t_ns)
        elif sensor_rise:
            _switch(s, SwitchCriterion.SENSOR_VOLTAGE, t_ns)
    elif s.phase == Phase.FORCE:
        if _force_settled(s, p, t_ns, force_n, speed_mps):
            s.settled_ns = t_ns
            s.hold_position_m = position_m
            s.phase = Phase.HOLDING
    if s.phase == Phase.HOLDING and (t_ns - s.settled_ns) * 1e-9 >= p.hold_watch_s:
        s.outcome = Outcome.HOLDING
        s.end_ns = t_ns
        _note(s, m, position_m, force_n)
        m.force_setpoint_n = s.tg_force_setpoint_n
        s.msg_code = MSG_HOLDING
        s.msg_seq += 1
        return s.outcome
    if (t_ns - s.start_ns) * 1e-9 > s.tg_timeout_s:
        _note(s, m, position_m, force_n)
        m.timeout_s = s.tg_timeout_s
        m.phase = s.phase
        return _end(s, Phase.FAILED, Outcome.TIMEOUT, MSG_GRASP_TIMEOUT, True, position_m, False)
    return NO_ANSWER


@_kernel
def _tracking(s) -> bool:
    """Tell whether the load-tracking grip sets the force now: a mass-0 grasp from FORCE on."""
    return s.tg_load_tracking != 0.0 and s.tg_kind == PendingRequest.GRASP and \
        (s.phase == Phase.FORCE or s.phase == Phase.HOLDING) and (_running(s) or _holding(s))


@_kernel
def _law_reset(law, law_buffers) -> None:
    """Start a new grasp's law (``law[0]``) as make_law made it (``law[1]``), buffers at 0."""
    law[0] = law[1]
    law_buffers[:, :] = 0.0


@_kernel
def _track_load(s, m, law, law_buffers, plan, t_ns, force_n, shear_n, displacement_m,
                may_answer) -> int:
    """Run the law on this tick's pads: its setpoint becomes the grasp's; OVERLOADED once.

    The answer OVERLOADED comes the first tick the law has found the load beyond the most 24 V
    holds (the next one when this tick already answered); the force stage goes on holding at
    the law's setpoint (at most that force), the loss watch too.
    """
    g = law[0]
    history = law_buffers[:HISTORY_ROWS, :g.window + 1]
    sums = law_buffers[HISTORY_ROWS:, :MU_GRID.size]
    s.tg_force_setpoint_n = law_step(g, history, sums, MU_GRID, t_ns, shear_n, displacement_m,
                                     force_n, plan)
    if g.overload_ns == -1 or s.overload_ns != NO_NS or not may_answer:
        return NO_ANSWER
    s.overload_ns = t_ns
    _note(s, m, s.position_m, force_n)
    m.need_n = g.overload_need_n
    m.max_force_n = g.max_force_n
    m.load_n = 2.0 * shear_n
    m.friction_coefficient = g.overload_mu
    s.phase = Phase.HOLDING
    s.outcome = Outcome.OVERLOADED
    if s.end_ns == NO_NS:                  # not answered before: answered now
        s.end_ns = t_ns
    s.msg_code = MSG_OVERLOADED if m.need_n > m.max_force_n else MSG_OVERLOADED_SLIDING
    s.msg_seq += 1
    return s.outcome


@_kernel
def _fill(s, answer) -> None:
    """Write the tick's decision: who drives, with which setpoints and limits, what answers."""
    s.d_answer = answer
    s.status_key = ((s.stage_id * 16 + s.outcome) * 16 + s.active) * 16 + s.phase
    s.d_running = _running(s)
    s.d_holding = _holding(s)
    s.d_pressing = _pressing(s)
    s.d_contact = s.contact_ns != NO_NS
    s.d_approach_velocity_mps = 0.0
    s.d_approach_acceleration_mps2 = 0.0
    if answer != NO_ANSWER and s.answer_ns == NO_NS:
        s.answer = answer
        s.answer_ns = s.t_ns
    if s.active == Controller.POSITION and not s.d_running:
        s.d_position_setpoint_m = s.idle_hold_m
        s.d_approach_setpoint_m = s.idle_hold_m
        s.d_force_setpoint_n = s.tg_force_setpoint_n if s.tg_kind != 0 else 0.0
        s.d_voltage_limit_v = s.idle_limit_v
        s.d_speed_limit_mps = s.idle_speed_limit_mps
    elif s.tg_kind != 0:
        s.d_position_setpoint_m = s.tg_position_setpoint_m
        s.d_approach_setpoint_m = s.tg_approach_setpoint_m
        s.d_force_setpoint_n = s.tg_force_setpoint_n
        if s.phase == Phase.MOVING:
            s.d_voltage_limit_v = s.tg_voltage_limit_v
            s.d_speed_limit_mps = s.tg_speed_mps
        else:
            s.d_voltage_limit_v = 0.0
            s.d_speed_limit_mps = 0.0
    else:
        s.d_position_setpoint_m = 0.0
        s.d_approach_setpoint_m = 0.0
        s.d_force_setpoint_n = 0.0
        s.d_voltage_limit_v = 0.0
        s.d_speed_limit_mps = 0.0


@face_kernel(_KERNEL_ARRAYS, int, float, float, float, float, int, float, float)
@_kernel
def supervisor_step(k, t_ns, position_m, force_n, sensor_voltage_v, speed_mps,
                    revision, shear_n, displacement_m) -> None:
    """Advance the state machine with the measurements of tick ``t_ns``; the decision in ``k``.

    ``speed_mps`` is the finger's speed (the position switch's speed condition);
    ``revision`` counts changes of the simulated world (a new object, fingers reset): the
    position stage then holds the finger where it now is. ``shear_n`` and ``displacement_m``
    (a pad's mean) feed the load-tracking grip of a mass-0 grasp.
    """
    state, params, message, law_buffers, law, plan = k
    s = state[0]
    p = params[0]
    m = message[0]
    s.t_ns = t_ns
    answer = NO_ANSWER
    if s.revision != revision:
        first = s.revision == NO_NS
        s.revision = revision
        if not (_running(s) or _holding(s)) and (first or s.active == Controller.POSITION):
            _hold_here(s, position_m, 0.0, 0.0)   # after a FAULT nothing drives until a request
    if s.pend_kind != 0 and (s.pend_after_ns == NO_NS or t_ns > s.pend_after_ns) and \
            math.isfinite(position_m):
        _start(s, p, t_ns, position_m, sensor_voltage_v)
        if s.kind == PendingRequest.GRASP:
            _law_reset(law, law_buffers)
    if _running(s) or _holding(s):
        answer = _step_request(s, p, m, t_ns, position_m, force_n, sensor_voltage_v,
                               speed_mps)
    if _tracking(s) and math.isfinite(force_n):
        overloaded = _track_load(s, m, law, law_buffers, plan, t_ns, force_n,
                                 shear_n, displacement_m, answer == NO_ANSWER)
        if overloaded != NO_ANSWER:
            answer = overloaded
    _fill(s, answer)
    _follow(s, p)


@_kernel
def _follow(s, p) -> None:
    """Move the reference on with a setpoint stream that keeps changing (servo_feedforward)."""
    if s.d_running and s.phase == Phase.MOVING and s.servo.t_ns != NO_STREAM:
        (s.d_approach_setpoint_m, s.d_approach_velocity_mps,
         s.d_approach_acceleration_mps2) = servo_reference(
            s.servo, s.t_ns, p.servo_rate_window_s, p.servo_lead_s, s.tg_speed_mps, s.travel_m)


@face_kernel(_KERNEL_ARRAYS, int, float, float, float)
@_kernel
def supervisor_servo_sample(k, t_ns, position_m, velocity_mps, acceleration_mps2) -> None:
    """Take a setpoint of the stream, of instant ``t_ns`` (velocity, acceleration: NaN if not
    given)."""
    s = k[K_STATE][0]
    p = k[K_PARAMS][0]
    servo_sample(s.servo, t_ns, position_m, velocity_mps, acceleration_mps2,
                 p.servo_fit_memory_s, p.servo_rate_window_s)


_RELAYED_FIELDS = ('stamp_ns', 'revision', 'position_m', 'velocity_mps', 'force_n')
"""What a StageReference relays of its PlantTick, as read."""
_DECIDED_FIELDS = ('running', 'contact', 'position_setpoint_m', 'approach_setpoint_m',
                   'force_setpoint_n', 'speed_limit_mps', 'voltage_limit_v',
                   'approach_velocity_mps', 'approach_acceleration_mps2')
"""What it carries of the tick's decision (the state's ``d_*`` fields)."""


@face_kernel(_KERNEL_ARRAYS, TICK_LAYOUT.dtype, REFERENCE_LAYOUT.dtype)
@_kernel
def supervisor_decide(k, tick, ref) -> bool:
    """Decide ``tick`` (a PlantTick record) and address ``ref`` (a StageReference record).

    Returns False when no stage is named (after a FAULT). The reference relays the tick's
    measurement as read, a non-finite one included (the stage then holds 0 V); the seed voltage
    is the last finite applied one, since no measurement of the stage depends on it.
    """
    t = tick[0]
    supervisor_step(k, t.stamp_ns, t.position_m, t.force_n, t.sensor_voltage_v, t.velocity_mps,
                    t.revision, 0.5 * (t.pad1_shear_n + t.pad2_shear_n),
                    0.5 * (t.pad1_displacement_m + t.pad2_displacement_m))
    s = k[K_STATE][0]
    if math.isfinite(t.motor_voltage_v):
        s.seed_voltage_v = t.motor_voltage_v
    if s.active == Controller.NONE:
        return False
    r = ref[0]
    copy_fields(r, t, _RELAYED_FIELDS)
    copy_fields(r, s, ('grasp_id', 'stage_id', 'phase', 'outcome', 'seed_voltage_v'))
    r.controller = s.active
    copy_fields(r, s, _DECIDED_FIELDS, '', 'd_')
    return True


@face_kernel(_KERNEL_ARRAYS)
@_kernel
def supervisor_stop(k) -> bool:
    """End the running request, the hold, a stalled move's press or a waiting request: STOPPED.

    False with nothing to stop. The message is the text the caller gives (MSG_TEXT).
    """
    s = k[K_STATE][0]
    if s.pend_kind != 0 and not _running(s):
        _take_pending(s)                     # answered at once, it never starts
        _reset(s, s.t_ns)
    elif _pressing(s):                       # where the move stalled
        _end(s, Phase.DONE, Outcome.STOPPED, MSG_TEXT, True, s.position_m, False)
        _fill(s, Outcome.STOPPED)
        return True
    elif not (_running(s) or _holding(s)):
        return False
    _end(s, Phase.DONE, Outcome.STOPPED, MSG_TEXT, True, math.nan, False)
    _fill(s, Outcome.STOPPED)
    return True


@face_kernel(_KERNEL_ARRAYS)
@_kernel
def supervisor_fault(k) -> bool:
    """End the running request or the hold as FAULT: no controller drives the motor."""
    s = k[K_STATE][0]
    if not (_running(s) or _holding(s)):
        _fill(s, NO_ANSWER)
        return False
    _end(s, Phase.FAILED, Outcome.FAULT, MSG_TEXT, False, math.nan, False)
    _fill(s, Outcome.FAULT)
    return True


# ------------------------------------------------------------------ the Python face
MESSAGE_VALUES = {
    't_s': lambda m: m['t_ns'] * 1e-9,
    'elapsed_s': lambda m: (m['t_ns'] - m['start_ns']) * 1e-9,
    'at': lambda m: f"t={m['t_s']:.4f} s",
    'into': lambda m: (f"{m['into_ns'] * 1e-9:.4f} s after HOLDING" if m['after_holding'] else
                       f"{m['into_ns'] * 1e-9:.4f} s into the grasp"),
    'since_s': lambda m: m['since_ns'] * 1e-9,
    'low_ms': lambda m: (m['t_ns'] - m['since_ns']) * 1e-9 * 1e3,
    'rest_s': lambda m: (m['t_ns'] - m['since_ns']) * 1e-9,
    'what': lambda m: KIND_NAMES[m['request_kind']] if m['request_kind'] else 'hold',
    'bad': lambda m: '; '.join(
        ([f"finger position sensor (joint state) reads {m['position_m']!r} m"]
         if m['bad_position'] else [])
        + ([f"force sensor reads force {m['force_n']!r} N, voltage {m['sensor_voltage_v']!r} V "
            '(sensor dropout)'] if m['bad_force'] else [])),
    'tolerance': lambda m: (f" + {m['width_tolerance_m'] * 1e3:g} mm tolerance"
                            if m['width_tolerance_m'] else ''),
    'past_face_mm': lambda m: (m['position_m'] - m['farthest_face_m']) * 1e3,
    'moved_on_mm': lambda m: (m['position_m'] - m['hold_position_m']) * 1e3,
    'margin_mm': lambda m: m['margin_m'] * 1e3,
    'phase_name': lambda m: Phase(m['phase']).name,
    'opening_m': lambda m: m['travel_m'] - m['position_m'],
    'goal_opening_m': lambda m: m['travel_m'] - m['position_setpoint_m'],
    'short_of_goal_mm': lambda m: abs(m['short_of_goal_m']) * 1e3,
}
"""What the message texts derive from the record's numbers (and the plant's ``travel_m`` and
``voltage_limit_v``), by name."""


class _MessageNumbers(dict):
    """A message record's numbers by name; a derived value is computed when a text reads it."""

    def __missing__(self, name: str):
        value = self[name] = MESSAGE_VALUES[name](self)
        return value


def format_message(code: int, record, plant: PlantParams, text: str = '') -> str:
    """Return message ``code``'s text from its record's numbers (``text``: a given one)."""
    try:
        template = MESSAGES[code]
    except KeyError:
        raise ValueError(f'unknown message code {code}') from None
    numbers = _MessageNumbers({name: record[name].item() for name in SUPERVISOR_MESSAGE.names},
                              text=text, travel_m=plant.max_travel_m,
                              voltage_limit_v=plant.voltage_limit_v)
    return template.format_map(numbers)


def load_law(config: GripperConfig) -> tuple:
    """Return the load-tracking grip of ``config`` for a supervisor (``make_law``'s arrays).

    Sampled at the force stage's period, the pads' tangential stiffness and displacement
    sensing as configured, at most the force 24 V holds.
    """
    pads = config.pad_sensor
    return make_law(config.load_grip, config.plant.max_force_n,
                    config.contact.pad_tangential_stiffness_n_per_m,
                    config.force.sample_time_s, pads.displacement_noise_m,
                    pads.displacement_resolution_m, pads.shear.latency_s,
                    pads.shear.bandwidth_hz, config.plant.gravity_mps2)


def _ns_or_none(value) -> int | None:
    return None if value == NO_NS else int(value)


def _state(read, field: str = '', doc: str | None = None) -> RecordField:
    """Return a read-only field of the supervisor's state record (the face's ``_s``)."""
    return RecordField(read, False, field=field, at='_s', doc=doc)


class _StateView:
    """What a supervisor and its decision both read of the state record ``_s``."""

    __slots__ = ()

    phase = _state(Phase)
    active = _state(Controller)
    switch_criterion = _state(SwitchCriterion)
    outcome = _state(Outcome)
    grasp_id = _state(int)
    stage_id = _state(int)
    running = _state(bool, 'd_running',
                     'A request is in progress (it needs simulated time until answered).')


class Decision(_StateView):
    """The supervisor's verdict for the last tick: a view of its state, current at any time.

    ``answer`` is the outcome this tick produced for the request (the grasp service answers
    now, the outcome is latched), or None.
    """

    __slots__ = ('_owner', '_s')

    def __init__(self, owner: GraspSupervisor):
        self._owner = owner
        self._s = owner._s

    t_ns = _state(int)
    contact = _state(bool, 'd_contact')
    position_setpoint_m = _state(float, 'd_position_setpoint_m')
    approach_setpoint_m = _state(float, 'd_approach_setpoint_m')
    force_setpoint_n = _state(float, 'd_force_setpoint_n')
    speed_limit_mps = _state(float, 'd_speed_limit_mps')
    voltage_limit_v = _state(float, 'd_voltage_limit_v')
    message = property(lambda self: self._owner.message)
    answer = _state(lambda answer: None if answer == NO_ANSWER else Outcome(answer), 'd_answer')

    @property
    def finished(self) -> bool:
        """The request has been answered (it may go on holding, phase HOLDING)."""
        return self.outcome is not Outcome.UNKNOWN


class GraspSupervisor(_StateView):
    """One request at a time; :meth:`step` once per plant tick with that tick's measurements.

    A controller always drives the motor, except after a FAULT: with no request the position
    stage holds the finger where it came to rest (phase IDLE, or DONE/FAILED with the last
    outcome); a grasp runs POSITION -> FORCE -> HOLDING and, once answered, goes on holding
    (phase HOLDING, outcome HOLDING, force stage active) until a release, a stop, the next
    grasp or the loss of the object; a move runs MOVING and then keeps its last command. A
    request is accepted at once and starts at the next tick (:meth:`request_grasp`,
    :meth:`request_release`, :meth:`request_move`); a setpoint (:meth:`request_servo`) is in
    force at once. ``running`` says whether the
    request still needs simulated time; ``stage_id`` grows whenever a controller is
    (re)assigned, so that it restarts from the measured state.

    ``kernel`` is the tuple of arrays the compiled functions take (entries ``K_*``): the state
    record, the parameters, the numbers of the current message, the load-tracking grip's
    history and residual sums in one array, and its record and a copy as it starts
    (:func:`load_law`).

    A grasp of mass 0 (unknown) needs ``law``; without it such a request is refused.
    """

    def __init__(self, plant: PlantParams, params: SupervisorParams, law: tuple | None = None):
        self.plant = plant
        self.tracks_load = law is not None
        if law is None:                          # inert arrays of the kernel's types
            law = make_law(shipped_config().load_grip, plant.max_force_n, 0.0, 1.0, 0.0, 0.0)
        record, history, sums = law
        state = np.zeros(1, SUPERVISOR_STATE)
        self._s = state[0]                      # a view: reads and writes go to the record
        for name in SUPERVISOR_STATE.names:
            if name.endswith('_ns'):
                self._s[name] = NO_NS
        for name in ('hold_position_m', 'position_m'):
            self._s[name] = math.nan
        self._s['revision'] = NO_NS
        self._s['travel_m'] = plant.max_travel_m
        servo_setup(state['servo'], plant)
        self._s['d_answer'] = NO_ANSWER
        self._s['t_ns'] = 0
        self._params = np.zeros(1, SUPERVISOR_PARAMS)
        # few arrays: the kernel's tuple is copied on every call the compiler does not inline
        law_buffers = np.zeros((history.shape[0] + sums.shape[0],
                                max(history.shape[1], sums.shape[1])))
        kernel = [None] * 6
        kernel[K_STATE] = state
        kernel[K_PARAMS] = self._params
        kernel[K_MESSAGE] = np.zeros(1, SUPERVISOR_MESSAGE)
        kernel[K_LAW_BUFFERS] = law_buffers
        kernel[K_LAW] = np.concatenate([record, record])
        kernel[K_PLAN] = np.zeros(PLAN_ROWS, PLAN_DTYPE)
        self.kernel = tuple(kernel)
        self.params = params
        self._targets: GraspTargets | MoveTargets | None = None
        self._pending_targets: GraspTargets | MoveTargets | None = None
        self._servo_id = NO_NS                   # the id of the last setpoint's move
        self._preempted: Decision | None = None  # the end of one, by the last request
        self._text = ''                          # a message given by stop() or fault()
        self._message = (-1, '')                 # (msg_seq, text) formatted last
        self._decision = Decision(self)

    # ------------------------------------------------------------------ parameters
    params = RecordParams(_PARAM_FIELDS, at='_params',
                          doc='The thresholds; new ones take effect from the next tick.')

    # ------------------------------------------------------------------ state
    kind = property(lambda self: KIND_NAMES.get(int(self._s['kind'])),
                    doc="The current request's kind, None before any.")
    mass_kg = _state(float, doc="The current grasp request's object mass.")
    start_ns = _state(int)
    switch_ns = _state(_ns_or_none)
    contact_ns = _state(_ns_or_none)
    settled_ns = _state(_ns_or_none, doc='Force first settled (phase HOLDING from here).')
    end_ns = _state(_ns_or_none, doc='When the request was answered or ended.')
    answer = _state(Outcome, doc='What the current request was answered.')
    answer_ns = _state(_ns_or_none, doc="... and when (the grasp service's answer).")
    overload_ns = _state(_ns_or_none,
                         doc='When the load-tracking grip said the load is beyond 24 V.')
    force_setpoint_n = _state(float, 'tg_force_setpoint_n',
                              "The grasp's force setpoint now (the law's, tracking).")

    @property
    def record(self):
        """Return the state record, a view: what the compiled loop reads and writes."""
        return self._s

    @property
    def law(self) -> np.ndarray:
        """The load-tracking grip's record now (``[0]``) and as each grasp starts it (``[1]``)."""
        return self.kernel[K_LAW]

    @property
    def overload_need_n(self) -> float:
        """The grip the load needed when the law said overload (NaN: never)."""
        g = self.law[0]
        return float(g['overload_need_n']) if g['overload_ns'] != -1 else math.nan

    @property
    def hold_position_m(self) -> float | None:
        value = float(self._s['hold_position_m'])
        return None if math.isnan(value) else value

    @property
    def targets(self) -> GraspTargets | MoveTargets | None:
        """Return what the current request aims at; a waiting one's once it has started."""
        self._promote_started()
        return self._targets

    def _promote_started(self) -> None:
        """Make a waiting request's targets current once the kernel has started it."""
        if self._pending_targets is not None and self._s['pend_kind'] == 0:
            self._targets, self._pending_targets = self._pending_targets, None

    holding = _state(bool, 'd_holding',
                     'A grasp was answered HOLDING (or OVERLOADED); the force stage holds.')
    pressing = _state(bool, 'd_pressing',
                      "A stalled move's last command is in force: the finger presses.")

    @property
    def releasing(self) -> bool:
        return self.running and bool(self._s['phase'] == Phase.RELEASING)

    @property
    def pending(self) -> bool:
        return bool(self._s['pend_kind'] != 0)

    @property
    def pending_request(self) -> PendingRequest:
        """What request waits to start at the next tick (the status' ``pending_request``)."""
        return PendingRequest(self._s['pend_kind'])

    @property
    def decision(self) -> Decision:
        """The decision of the last tick (the same object, always current)."""
        return self._decision

    @property
    def message(self) -> str:
        """The current request's outcome, in words with its numbers ('' while none)."""
        seq = int(self._s['msg_seq'])
        if self._message[0] != seq:
            self._message = (seq, format_message(int(self._s['msg_code']),
                                                 self.kernel[K_MESSAGE][0], self.plant,
                                                 self._text))
        return self._message[1]

    # ------------------------------------------------------------------ requests
    def _refuse_if_busy(self, kind: str) -> None:
        """Refuse a request while another runs or waits; a setpoint's move ends (preempted)."""
        if self.servo and (self.pending or self.running):
            self._preempted = self.stop(f'preempted by a {kind} request')
        elif self.pending:
            raise RequestError(f'a {KIND_NAMES[int(self._s["pend_kind"])]} request is already '
                               'waiting to start')
        elif self.running:
            raise RequestError(f'a {self.kind} is running (phase {self.phase.name})')
        self._s['servo']['t_ns'] = NO_STREAM    # no setpoint stream moves this request's goal

    def _wait(self, kind: str, targets, mass_kg: float, after_ns: int | None):
        """Write a request that starts at the first tick after ``after_ns`` (None: the next)."""
        self._promote_started()                 # the one that started before becomes current
        s = self._s
        for name in _TARGET_FIELDS:
            s['pend_' + name] = getattr(targets, name, 0.0)
        s['pend_mass_kg'] = mass_kg
        s['pend_after_ns'] = NO_NS if after_ns is None else after_ns
        s['pend_kind'] = KIND_CODES[kind]
        self._pending_targets = targets
        return targets

    def take_preempted(self) -> Decision | None:
        """Return the decision that ended a setpoint's move for the last request, once."""
        ended, self._preempted = self._preempted, None
        return ended

    def continue_ids_after(self, last_id: int) -> None:
        """Make the next request ``last_id + 1`` (ids go on across restarts); before any."""
        if self.kind is not None or self._s['pend_kind'] != 0:
            raise RuntimeError('request ids can only be set before the first request')
        self._s['grasp_id'] = int(last_id)

    def request_grasp(self, targets: GraspTargets, mass_kg: float = 0.0,
                      after_ns: int | None = None) -> GraspTargets:
        """Accept a grasp and return its targets; it starts at the first tick after ``after_ns``.

        By default that is the next tick decided; its sensor voltage is the no-contact baseline.

        Pass the newest tick received when the request arrived: the start is then the same
        whether or not that tick had been decided yet (deterministic under any timing). A grasp
        may follow a hold; the hold ends when it starts.
        """
        if getattr(targets, 'load_tracking', False) and not self.tracks_load:
            raise RequestError('mass_kg 0 (load-tracking grip) needs the load_grip settings, '
                               'which this supervisor was not given')
        self._refuse_if_busy(RequestKind.GRASP)
        return self._wait(RequestKind.GRASP, targets, float(mass_kg), after_ns)

    def request_release(self, open_position_m: float = 0.0, timeout_s: float | None = None,
                        after_ns: int | None = None) -> GraspTargets:
        """Accept a release (return its targets): the position stage to ``open_position_m``.

        It starts at the first tick later than ``after_ns`` (see :meth:`request_grasp`).
        """
        if not (math.isfinite(open_position_m)
                and 0.0 <= open_position_m < self.plant.max_travel_m):
            raise RequestError(f'open position must be in [0, {self.plant.max_travel_m:g}) m, '
                               f'got {open_position_m!r}')
        self._refuse_if_busy(RequestKind.RELEASE)
        timeout = self.params.timeout_s if timeout_s is None else timeout_s
        targets = GraspTargets(open_position_m, 0.0, 0.0, timeout)
        return self._wait(RequestKind.RELEASE, targets, 0.0, after_ns)

    def request_move(self, targets: MoveTargets, after_ns: int | None = None) -> MoveTargets:
        """Accept a move (:func:`validate_move`) and return its targets.

        It starts at the first tick later than ``after_ns`` (see :meth:`request_grasp`). A move
        may follow a hold; the hold ends when it starts.
        """
        self._refuse_if_busy(RequestKind.MOVE)
        return self._wait(RequestKind.MOVE, targets, 0.0, after_ns)

    @property
    def servo(self) -> bool:
        """Tell whether the current or waiting request is a position setpoint's move."""
        return self._servo_id == self.grasp_id + (1 if self.pending else 0)

    def request_servo(self, targets: MoveTargets, after_ns: int | None = None,
                      message: str = 'preempted by a new setpoint', *,
                      velocity_mps: float = math.nan, acceleration_mps2: float = math.nan,
                      sample_ns: int | None = None) -> Decision | None:
        """Put a position setpoint in force (a move, :func:`validate_move`) at once.

        The setpoint is the one command in force, as a position command interface is to the
        hardware: while the previous setpoint's move runs, its goal and limits change in place
        (the position stage follows the new reference without restarting, the request keeps
        its id); otherwise a running or waiting request ends STOPPED with ``message`` and the
        setpoint's move starts at the first tick after ``after_ns`` (a hold or a stalled press
        ends as it starts, as before any move).
        ``velocity_mps`` and ``acceleration_mps2`` are the setpoint's own (NaN: estimated from
        the stream), ``sample_ns`` the simulated instant it was sampled at (:meth:`_instant`);
        the reference moves on with them (:mod:`~gripper_ros.core.control.servo_feedforward`).
        The same targets again while their move runs are no new request (:meth:`servo_repeated`).
        Returns the decision that ended a preempted request (to be answered), else None.
        """
        s = self._s
        t_ns = self._instant(sample_ns)
        moving = self.servo and self.running and self.phase is Phase.MOVING
        if moving:
            self._promote_started()             # else the started move's targets come back
        if self.servo and self.pending:          # not started yet: it starts with these
            self._wait(RequestKind.MOVE, targets, 0.0, after_ns)
        elif moving and targets != self._targets:     # else the same again: it stands
            for name in _TARGET_FIELDS:
                s['tg_' + name] = getattr(targets, name, 0.0)
            position_m = float(s['position_m'])
            if targets.timeout_s == 0.0 and math.isfinite(position_m):
                s['move_timeout_s'] = (int(s['t_ns']) - int(s['start_ns'])) * 1e-9 + \
                    self.params.timeout_s + abs(targets.position_setpoint_m - position_m) / \
                    targets.speed_mps
            elif targets.timeout_s != 0.0:
                s['move_timeout_s'] = (int(s['t_ns']) - int(s['start_ns'])) * 1e-9 + \
                    targets.timeout_s
            s['rest_since_ns'] = NO_NS
            self._targets = targets
        elif not moving:
            ended = None
            if self.pending or self.running:    # a hold or a press ends as the move starts
                ended = self.stop(message)
            self._wait(RequestKind.MOVE, targets, 0.0, after_ns)
            self._servo_id = self.grasp_id + 1
            s['servo']['t_ns'] = NO_STREAM      # a new stream (its first setpoint: not done)
            supervisor_servo_sample(self.kernel, t_ns, targets.position_setpoint_m,
                                    float(velocity_mps), float(acceleration_mps2))
            return ended
        supervisor_servo_sample(self.kernel, t_ns, targets.position_setpoint_m,
                                float(velocity_mps), float(acceleration_mps2))
        return None

    def servo_repeated(self, sample_ns: int | None = None) -> None:
        """Note the setpoint in force sent again (a topic-based hardware's repeat): no request;
        the stream lives and stands there (velocity and acceleration 0)."""
        if self.servo and self.running and self.phase is Phase.MOVING:
            supervisor_servo_sample(self.kernel, self._instant(sample_ns),
                                    float(self._s['tg_position_setpoint_m']), 0.0, 0.0)

    def _instant(self, sample_ns: int | None) -> int:
        """Return when a setpoint was sampled: its stamp when that is on this clock (within
        ``servo_rate_window_s`` of the newest tick), else the newest tick's instant."""
        t_ns = int(self._s['t_ns'])
        if sample_ns is not None and \
                abs(int(sample_ns) - t_ns) <= self.params.servo_rate_window_s * 1e9:
            return int(sample_ns)
        return t_ns

    def stop(self, message: str = 'stopped on request') -> Decision | None:
        """End the running request, the hold, a stalled move's press or a waiting request now.

        The outcome is STOPPED. Returns the ending decision (for the status and the answer),
        or None with nothing to stop. From the next tick the position stage holds the finger
        where it is, without a move's limits.
        """
        if not supervisor_stop(self.kernel):
            return None
        self._text = message
        return self._decision

    def fault(self, message: str) -> Decision:
        """End the running request or the hold as FAULT: no controller drives the motor."""
        if supervisor_fault(self.kernel):
            self._text = message
        return self._decision

    def announce(self, t_ns: int, accel_mps2: float) -> None:
        """Take the arm's plan: from simulated time ``t_ns`` on, upward ``accel_mps2``.

        A breakpoint replaces what was announced from its instant on; the plan is the grasp's
        (a new grasp starts without one). The load-tracking grip raises the grip with the load
        the motion will bring. ValueError (nothing changes) for a non-finite value.
        """
        if isinstance(accel_mps2, bool) or not isinstance(accel_mps2, (int, float)) or \
                not math.isfinite(accel_mps2) or int(t_ns) < 0:
            raise ValueError(f'a planned acceleration must be finite and stamped at a time >= 0,'
                             f' got {accel_mps2!r} m/s^2 at {t_ns!r} ns')
        plan_announce(self.kernel[K_LAW][0:1], self.kernel[K_PLAN], int(t_ns),
                      float(accel_mps2))

    @property
    def plan(self) -> np.ndarray:
        """The arm's announced breakpoints now (``t_ns``, ``accel_mps2``), a copy."""
        return self.kernel[K_PLAN][:int(self.kernel[K_LAW][0]['plan_count'])].copy()

    # ------------------------------------------------------------------ the tick
    def step(self, t_ns: int, position_m: float, force_n: float, sensor_voltage_v: float,
             speed_mps: float = 0.0, revision: int = 0, shear_n: float = 0.0,
             displacement_m: float = 0.0) -> Decision:
        """Advance the state machine with the measurements of tick ``t_ns``.

        ``speed_mps`` is the finger's speed (the position switch's speed condition);
        ``revision`` counts changes of the simulated world (a new object, fingers reset): the
        position stage then holds the finger where it now is. ``shear_n`` and
        ``displacement_m`` are a pad's (the two pads' mean) readings.
        """
        supervisor_step(self.kernel, t_ns, float(position_m), float(force_n),
                        float(sensor_voltage_v), float(speed_mps), revision, float(shear_n),
                        float(displacement_m))
        return self._decision
