"""The supervisor's state machine, compiled: its states, its events and the one table between.

Stages (paper sec. IV): a grasp runs the position stage (APPROACH, MPC-PD to ``L_ls - width``)
until either switching criterion holds - the position is within +-2 % of its setpoint, or the
force-sensor voltage has risen by more than its threshold - then the force stage (SQUEEZE, to
the request's setpoint) until the force has settled (SETTLED, phase HOLDING): ``|F - F_sp| + T
|dF/dt|`` within the band and the finger slower than ``force_settle_speed_mps`` on every tick for
``force_settle_hold_s``, ``T`` being the slowest contact mode's time scale. After the hold watch
(``hold_watch_s``) the grasp is answered HOLDING and the force stage holds on (HOLD) until a
release, a stop, a move, the next grasp or the loss of the object. A release runs the position
stage to the open position (RELEASE), a move to its goal under its speed and effort limits
(MOVE); a move that stalls keeps pressing with its last command (PRESSING). Without a request
the position stage holds the finger where it came to rest (IDLE); after a FAULT nothing drives
the motor (UNDRIVEN) until the next request.

:data:`TRANSITIONS` is the machine: for each state and event, the next state, the phase and
outcome it reports, and what drives the motor from then on. The code reads it (the compiled
table :data:`TABLE`); each state's tick function (``_tick_*``) only detects which event happened
and writes the numbers of its message; :func:`_take` applies the row. docs/ARCHITECTURE.md
shows the same table (``test_supervisor_machine`` holds the two equal).

Everything the machine keeps is one record (:data:`SUPERVISOR_DTYPE`): its state, the
thresholds, the current message's numbers, the current, the waiting and the decided request
(:data:`~gripper_ros.core.supervision.requests.TARGETS_DTYPE`), a setpoint stream (its fit
and the motion it gives the reference), and the load-tracking grip's record and the arm's
plan; the grip's history is one float array beside it. A kernel takes ``(record,
law_buffers)``: a record passes as one pointer. The Python face (:mod:`.supervisor`) reads
the record and asks through the kernels named ``supervisor_*``; it writes no field itself.
"""
from __future__ import annotations

import enum
import math

from gripper_ros.core.config import numbers_of, SupervisorParams
from gripper_ros.core.control.load_grip import (GRIP_DTYPE, HISTORY_ROWS, law_step, MU_GRID,
                                                PLAN_DTYPE, PLAN_ROWS)
from gripper_ros.core.control.servo_feedforward import (NO_STREAM, stream_changing,
                                                        STREAM_DTYPE, stream_reference,
                                                        stream_sample)
from gripper_ros.core.records import as_record, copy_fields, face_kernel, FLOATS_2D, set_fields
from gripper_ros.core.supervision.messages import MESSAGE_DTYPE, MESSAGES
from gripper_ros.core.supervision.requests import TARGETS_DTYPE
from gripper_ros.wire import (Controller, MSG_TICK, Outcome, PendingRequest, Phase,
                              REFERENCE_LAYOUT, SwitchCriterion, TICK_LAYOUT)
import numba
import numpy as np

NO_NS = -1
"""An ``*_ns`` field that holds no time (every simulated time is >= 0)."""


class State(enum.IntEnum):
    """Where the machine stands (the status reports its phase, which several states share)."""

    UNDRIVEN = 0        # nothing drives the motor: before the first tick, after a FAULT
    IDLE = 1            # the position stage holds where the finger came to rest
    PRESSING = 2        # a stalled move's last command: the position stage presses on
    APPROACH = 3        # a grasp's position stage
    SQUEEZE = 4         # a grasp's force stage, until the force settles
    SETTLED = 5         # settled, the hold watched before the answer
    HOLD = 6            # answered HOLDING (or OVERLOADED): the force stage holds on
    RELEASE = 7         # the position stage opens the fingers
    MOVE = 8            # the position stage drives the finger to a move's goal


class Event(enum.IntEnum):
    """What can happen to the machine: at a tick, or asked from outside (stop, fault)."""

    NONE = 0
    FIRST_TICK = 1          # the plant's first tick: the position stage holds the finger
    NEW_WORLD = 2           # the plant's world changed (an object placed): hold where it is now
    START_GRASP = 3         # the waiting request starts
    START_RELEASE = 4
    START_MOVE = 5
    SENSOR_FAULT = 6        # a measurement the request needs is not finite
    NO_OBJECT = 7           # past the farthest face without contact
    LOST_FORCE = 8          # gripped, then the force below its floor for lost_force_hold_s
    LOST_MOVED_ON = 9       # settled, then the finger moved on past the held position
    AT_TOLERANCE = 10       # within the position tolerance and slow: the force stage
    SENSOR_RISE = 11        # the sensor voltage rose past its threshold: the force stage
    SETTLED = 12            # the force settled
    HELD = 13               # the hold watch passed: answered HOLDING
    OVERLOADED = 14         # the load needs more grip than the most the motor holds
    OVERLOADED_SLIDING = 15  # the object slides on at the most grip
    GRASP_TIMEOUT = 16
    RELEASED = 17
    RELEASE_TIMEOUT = 18
    MOVED = 19
    STALLED_PRESSING = 20   # at rest short of the goal, closing with the effort limit
    STALLED_AT_REST = 21    # at rest short of the goal for move_stall_timeout_s
    MOVE_TIMEOUT = 22
    STOP = 23               # asked: the running request, the hold or the press ends
    CANCEL = 24             # asked to stop while a request only waits: it ends unstarted
    FAULT = 25              # asked (a node went silent): nothing drives from here on


class Drive(enum.IntEnum):
    """What drives the motor after a transition."""

    KEEP = 0            # the stage that drives goes on
    REQUEST = 1         # the position stage, for the request that starts (a new stage)
    FORCE = 2           # the force stage (a new stage)
    HOLD_HERE = 3       # the position stage holds the finger where it is, within 24 V
    HOLD_GOAL = 4       # the position stage holds a move's goal under the move's limits
    NOTHING = 5         # no stage: the motor is left unpowered


KEEP = -1
"""A phase or outcome a transition leaves as it is."""

_ACTIVE = (State.APPROACH, State.SQUEEZE, State.SETTLED, State.HOLD, State.RELEASE, State.MOVE)
"""The states a stop or a fault ends: a request runs, or a grasp holds."""
_GRASP = (State.APPROACH, State.SQUEEZE, State.SETTLED, State.HOLD)
_TIMED = (State.APPROACH, State.SQUEEZE, State.SETTLED)
_ANY = tuple(State)

S, E, P, O, D = State, Event, Phase, Outcome, Drive
TRANSITIONS = (
    # (from states, event, next state, phase, outcome, drive)
    ((S.UNDRIVEN, S.IDLE, S.PRESSING), E.FIRST_TICK, S.IDLE, KEEP, KEEP, D.HOLD_HERE),
    ((S.IDLE, S.PRESSING), E.NEW_WORLD, S.IDLE, KEEP, KEEP, D.HOLD_HERE),
    (_ANY, E.START_GRASP, S.APPROACH, P.POSITION, O.UNKNOWN, D.REQUEST),
    (_ANY, E.START_RELEASE, S.RELEASE, P.RELEASING, O.UNKNOWN, D.REQUEST),
    (_ANY, E.START_MOVE, S.MOVE, P.MOVING, O.UNKNOWN, D.REQUEST),
    (_ACTIVE, E.SENSOR_FAULT, S.UNDRIVEN, P.FAILED, O.FAULT, D.NOTHING),
    (_GRASP, E.NO_OBJECT, S.IDLE, P.FAILED, O.NO_OBJECT, D.HOLD_HERE),
    (_GRASP, E.LOST_FORCE, S.IDLE, P.FAILED, O.OBJECT_LOST, D.HOLD_HERE),
    (_GRASP, E.LOST_MOVED_ON, S.IDLE, P.FAILED, O.OBJECT_LOST, D.HOLD_HERE),
    ((S.APPROACH,), E.AT_TOLERANCE, S.SQUEEZE, P.FORCE, KEEP, D.FORCE),
    ((S.APPROACH,), E.SENSOR_RISE, S.SQUEEZE, P.FORCE, KEEP, D.FORCE),
    ((S.SQUEEZE,), E.SETTLED, S.SETTLED, P.HOLDING, KEEP, D.KEEP),
    ((S.SETTLED,), E.HELD, S.HOLD, KEEP, O.HOLDING, D.KEEP),
    ((S.SQUEEZE, S.SETTLED, S.HOLD), E.OVERLOADED, S.HOLD, P.HOLDING, O.OVERLOADED, D.KEEP),
    ((S.SQUEEZE, S.SETTLED, S.HOLD), E.OVERLOADED_SLIDING, S.HOLD, P.HOLDING, O.OVERLOADED,
     D.KEEP),
    (_TIMED, E.GRASP_TIMEOUT, S.IDLE, P.FAILED, O.TIMEOUT, D.HOLD_HERE),
    ((S.RELEASE,), E.RELEASED, S.IDLE, P.DONE, O.RELEASED, D.HOLD_HERE),
    ((S.RELEASE,), E.RELEASE_TIMEOUT, S.IDLE, P.FAILED, O.TIMEOUT, D.HOLD_HERE),
    ((S.MOVE,), E.MOVED, S.IDLE, P.DONE, O.MOVED, D.HOLD_GOAL),
    ((S.MOVE,), E.STALLED_PRESSING, S.PRESSING, P.DONE, O.STALLED, D.HOLD_GOAL),
    ((S.MOVE,), E.STALLED_AT_REST, S.PRESSING, P.DONE, O.STALLED, D.HOLD_GOAL),
    ((S.MOVE,), E.MOVE_TIMEOUT, S.IDLE, P.FAILED, O.TIMEOUT, D.HOLD_HERE),
    (_ACTIVE + (S.PRESSING,), E.STOP, S.IDLE, P.DONE, O.STOPPED, D.HOLD_HERE),
    ((S.UNDRIVEN, S.IDLE, S.PRESSING, S.HOLD), E.CANCEL, S.IDLE, P.DONE, O.STOPPED,
     D.HOLD_HERE),
    (_ACTIVE, E.FAULT, S.UNDRIVEN, P.FAILED, O.FAULT, D.NOTHING),
)
"""The state machine, row by row: (states, event, next state, phase, outcome, drive). An event
no row names for the state it comes in is ignored. A transition whose outcome is an answer
(neither UNKNOWN nor KEEP) gives the message of its event (:data:`.messages.MESSAGES`)."""
del S, E, P, O, D

T_NEXT, T_PHASE, T_OUTCOME, T_DRIVE = range(4)


def _table() -> np.ndarray:
    """Return :data:`TRANSITIONS` as ``table[state, event] = (next, phase, outcome, drive)``."""
    table = np.full((len(State), len(Event), 4), KEEP, np.int64)
    for states, event, after, phase, outcome, drive in TRANSITIONS:
        for state in states:
            if table[state, event, T_NEXT] != KEEP:
                raise ValueError(f'two transitions for {state.name} on {event.name}')
            table[state, event] = (after, phase, outcome, drive)
    return table


def transitions_table() -> str:
    """Return :data:`TRANSITIONS` as the Markdown table docs/ARCHITECTURE.md shows."""
    lines = ['| in state | on event | to state | phase | outcome | then the motor |',
             '|---|---|---|---|---|---|']
    for states, event, after, phase, outcome, drive in TRANSITIONS:
        where = 'any' if tuple(states) == _ANY else ', '.join(s.name for s in states)
        lines.append(f'| {where} | {event.name} | {after.name} | '
                     f'{"=" if phase == KEEP else phase.name} | '
                     f'{"=" if outcome == KEEP else outcome.name} | {_DRIVE_WORDS[drive]} |')
    return '\n'.join(lines)


_DRIVE_WORDS = {Drive.KEEP: 'as it was', Drive.REQUEST: 'position stage, the request',
                Drive.FORCE: 'force stage', Drive.HOLD_HERE: 'position stage holds here',
                Drive.HOLD_GOAL: "position stage holds the goal, the move's limits",
                Drive.NOTHING: 'unpowered'}

TABLE = _table()
"""The compiled machine reads this: ``TABLE[state, event]``, KEEP (-1) everywhere for none."""

ANSWERS = tuple(sorted({event for _, event, _, _, outcome, _ in TRANSITIONS
                        if outcome not in (KEEP, Outcome.UNKNOWN)}))
"""The events that answer a request, each with its message template."""
if {event.name for event in ANSWERS} != set(MESSAGES):
    raise ImportError('each answering event needs exactly one message template')

MACHINE_DTYPE = np.dtype(
    [('state', 'i4'),                      # State
     ('t_ns', 'i8'), ('phase', 'i4'), ('switch_criterion', 'i4'), ('outcome', 'i4'),
     ('active', 'i4'),                     # the stage that drives (Controller)
     ('answer', 'i4'),                     # what the current request was answered first
     ('tick_answer', 'i4'),                # what the last tick answered (Outcome.UNKNOWN: none)
     ('running', 'b1'), ('holding', 'b1'), ('pressing', 'b1'), ('contact', 'b1'),
     ('grasp_id', 'i8'), ('stage_id', 'i8'), ('start_ns', 'i8'), ('switch_ns', 'i8'),
     ('contact_ns', 'i8'), ('settled_ns', 'i8'), ('end_ns', 'i8'), ('answer_ns', 'i8'),
     ('force_setpoint_n', 'f8'),           # the grasp's force setpoint now (the law's, tracking)
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
     ('message', 'i4'), ('message_seq', 'i8'),   # the current message: its Event, a count
     ('overload_ns', 'i8'),                # when the load-tracking grip said overload
     ('travel_m', 'f8')],                  # the finger's travel: where a reference may lie
    align=True)
"""Where the machine stands and what it remembers between ticks."""

SERVO_DTYPE = np.dtype(
    [('request_id', 'i8'),                 # the id of the last setpoint's move (-1: none)
     ('stream', STREAM_DTYPE),             # its setpoints' fit (servo_feedforward)
     ('velocity_mps', 'f8'),               # the decided reference's velocity (0: it stands)
     ('acceleration_mps2', 'f8')],         # ... and acceleration
    align=True)
"""A stream of position setpoints (``joint_commands``, a trajectory's samples): its move, the
stream (:mod:`~gripper_ros.core.control.servo_feedforward`), and the motion it gives the tick's
reference (the position stage's feed-forward)."""

PARAMS_FIELDS = numbers_of(SupervisorParams)
PARAMS_DTYPE = np.dtype([(name, 'f8') for name in PARAMS_FIELDS], align=True)
"""The numbers of :class:`SupervisorParams`, which the tick reads."""

SUPERVISOR_DTYPE = np.dtype(
    [('machine', MACHINE_DTYPE), ('params', PARAMS_DTYPE), ('message', MESSAGE_DTYPE),
     ('current', TARGETS_DTYPE), ('waiting', TARGETS_DTYPE), ('decided', TARGETS_DTYPE),
     ('servo', SERVO_DTYPE),
     ('law', GRIP_DTYPE, (2,)),            # the load-tracking grip now, and as a grasp starts it
     ('plan', PLAN_DTYPE, (PLAN_ROWS,))],  # the arm's announced breakpoints
    align=True)
"""Everything the supervisor keeps: ``current`` is the request that runs (or ran last),
``waiting`` the one accepted that starts at the next tick (kind 0: none), ``decided`` the
setpoints and limits of the last tick's reference."""

_kernel = numba.njit(cache=True)
_ARRAYS = (SUPERVISOR_DTYPE, FLOATS_2D)
"""What a supervisor kernel called from Python takes: the record (a 1-element array) and the
load-tracking grip's buffers."""


# ------------------------------------------------------------------ applying the table
@_kernel
def _assign(s, controller) -> None:
    """Hand the motor to ``controller`` from this tick on; it restarts (new stage)."""
    s.active = controller
    s.stage_id += 1


@_kernel
def _hold_here(s, position_m, limit_v, speed_limit_mps) -> None:
    """Let the position stage hold the finger at ``position_m`` (NaN: where it held)."""
    if math.isfinite(position_m):
        s.idle_hold_m = position_m
    s.idle_limit_v = limit_v
    s.idle_speed_limit_mps = speed_limit_mps
    _assign(s, Controller.POSITION)


@_kernel
def _take(sup, event, position_m) -> int:
    """Apply ``event``'s transition; return the outcome it answers (UNKNOWN: none).

    ``position_m``: where the position stage holds after a HOLD_HERE (NaN: where it held).
    """
    s = sup.machine
    row = TABLE[s.state, event]
    if row[T_NEXT] == KEEP:
        return Outcome.UNKNOWN
    s.state = row[T_NEXT]
    if row[T_PHASE] != KEEP:
        s.phase = row[T_PHASE]
    outcome = row[T_OUTCOME]
    drive = row[T_DRIVE]
    answer = outcome != KEEP and outcome != Outcome.UNKNOWN
    if outcome != KEEP:
        s.outcome = outcome
    if answer:
        s.message = event
        s.message_seq += 1
        if drive != Drive.KEEP or s.end_ns == NO_NS:
            s.end_ns = s.t_ns
    if drive == Drive.REQUEST:
        _assign(s, Controller.POSITION)
    elif drive == Drive.FORCE:
        _assign(s, Controller.FORCE)
    elif drive == Drive.HOLD_HERE:
        _hold_here(s, position_m, 0.0, 0.0)
    elif drive == Drive.HOLD_GOAL:
        c = sup.current
        _hold_here(s, c.position_setpoint_m, c.voltage_limit_v, c.speed_mps)
    elif drive == Drive.NOTHING:
        s.active = Controller.NONE
        s.stage_id += 1
    return outcome if answer else Outcome.UNKNOWN


@_kernel
def _running(s) -> bool:
    """Tell whether a request is in progress (it needs simulated time until answered)."""
    return s.state == State.APPROACH or s.state == State.SQUEEZE or \
        s.state == State.SETTLED or s.state == State.RELEASE or s.state == State.MOVE


@_kernel
def _last_position(s) -> float:
    """Where to hold when a request or hold ends: the held, last measured or idle position."""
    if not math.isnan(s.hold_position_m):
        return s.hold_position_m
    if _running(s) and not math.isnan(s.position_m):
        return s.position_m
    return s.idle_hold_m


# ------------------------------------------------------------------ a request starts
_REQUEST_TIMES = ('answer_ns', 'switch_ns', 'contact_ns', 'settled_ns', 'end_ns',
                  'in_band_since_ns', 'prev_force_t_ns', 'low_since_ns', 'rest_since_ns',
                  'overload_ns')
"""The instants of a request (``NO_NS`` as it starts)."""
_FIRST_NO_NS = _REQUEST_TIMES + ('start_ns', 'revision')
"""What a new supervisor holds no time (or revision) of yet."""
_START = {PendingRequest.GRASP: Event.START_GRASP, PendingRequest.RELEASE: Event.START_RELEASE,
          PendingRequest.MOVE: Event.START_MOVE}


@_kernel
def _take_waiting(sup) -> None:
    """Make the waiting request the current one (a new id), with fresh instants."""
    s = sup.machine
    sup.current = sup.waiting
    sup.waiting.kind = PendingRequest.NONE
    s.force_setpoint_n = sup.current.force_setpoint_n
    s.grasp_id += 1
    s.outcome = Outcome.UNKNOWN
    s.answer = Outcome.UNKNOWN
    s.switch_criterion = SwitchCriterion.NONE
    s.start_ns = s.t_ns
    set_fields(s, _REQUEST_TIMES, NO_NS)
    s.hold_position_m = math.nan
    s.prev_force_n = 0.0
    s.gripped = False
    s.message = Event.NONE
    s.message_seq += 1


@_kernel
def _move_timeout_s(p, c, position_m, elapsed_s) -> float:
    """Return when a move times out, counted from its start (NaN: no position to count from).

    Its own timeout, or the default one plus the travel at its speed.
    """
    if c.timeout_s != 0.0:
        return elapsed_s + c.timeout_s
    return elapsed_s + p.timeout_s + abs(c.position_setpoint_m - position_m) / c.speed_mps


@_kernel
def _start(sup, law_buffers, position_m, sensor_voltage_v) -> None:
    """Start the waiting request at this tick."""
    s = sup.machine
    kind = sup.waiting.kind
    _take_waiting(sup)
    s.baseline_voltage_v = sensor_voltage_v
    if kind == PendingRequest.MOVE:
        s.move_timeout_s = _move_timeout_s(sup.params, sup.current, position_m, 0.0)
    elif kind == PendingRequest.GRASP:
        sup.law[0] = sup.law[1]            # a new grasp's law, as make_law made it
        law_buffers[:, :] = 0.0
    if kind == PendingRequest.GRASP:
        _take(sup, Event.START_GRASP, position_m)
    elif kind == PendingRequest.RELEASE:
        _take(sup, Event.START_RELEASE, position_m)
    else:
        _take(sup, Event.START_MOVE, position_m)


# ------------------------------------------------------------------ each state's tick
@_kernel
def _note(sup, position_m, force_n) -> None:
    """Write what every message may read: when, how long in, the position and the force.

    How long into the request, or into the hold after HOLDING; each event then writes its own
    numbers.
    """
    s = sup.machine
    m = sup.message
    m.t_ns = s.t_ns
    m.start_ns = s.start_ns
    if s.state == State.HOLD and s.end_ns != NO_NS:
        m.after_holding = True
        m.into_ns = s.t_ns - s.end_ns
    else:
        m.after_holding = False
        m.into_ns = s.t_ns - s.start_ns
    m.position_m = position_m
    m.force_n = force_n


@_kernel
def _force_settled(s, p, t_ns, force_n, speed_mps) -> bool:
    """Apply the force stage's settle criterion, once per SQUEEZE tick.

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
    band = p.force_settle_band_fraction * s.force_setpoint_n
    steady = (abs(force_n - s.force_setpoint_n) + p.force_settle_horizon_s * abs(rate)
              <= band and (p.force_settle_speed_mps <= 0.0
                           or abs(speed_mps) <= p.force_settle_speed_mps))
    if not steady:
        s.in_band_since_ns = NO_NS
        return False
    if s.in_band_since_ns == NO_NS:
        s.in_band_since_ns = t_ns
    return (t_ns - s.in_band_since_ns) * 1e-9 >= p.force_settle_hold_s


@_kernel
def _object_lost(sup, t_ns, position_m, force_n) -> int:
    """After contact: a force collapse, or the finger moving on past the held position."""
    s = sup.machine
    p = sup.params
    m = sup.message
    floor = p.lost_force_fraction * s.force_setpoint_n
    if force_n >= floor:
        s.gripped = True
        s.low_since_ns = NO_NS
    elif s.gripped:
        if s.low_since_ns == NO_NS:
            s.low_since_ns = t_ns
        low_s = (t_ns - s.low_since_ns) * 1e-9
        if low_s >= p.lost_force_hold_s:
            _note(sup, position_m, force_n)
            m.since_ns = s.low_since_ns
            m.lost_force_fraction = p.lost_force_fraction
            m.force_setpoint_n = s.force_setpoint_n
            m.floor_n = floor
            return Event.LOST_FORCE
    if not math.isnan(s.hold_position_m) and \
            position_m > s.hold_position_m + p.no_object_margin_m:
        _note(sup, position_m, force_n)
        m.hold_position_m = s.hold_position_m
        m.margin_m = p.no_object_margin_m
        return Event.LOST_MOVED_ON
    return Event.NONE


@_kernel
def _tick_grasp(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps) -> int:
    """APPROACH, SQUEEZE, SETTLED and HOLD: the watches they share, then each state's own.

    Contact (the sensor voltage's rise), no object (past the farthest face without contact),
    the loss after contact; then APPROACH switches to the force stage, SQUEEZE settles, SETTLED
    is answered HELD after the hold watch, and a grasp not answered in time times out. The
    switch and the settling take effect at once: the same tick may go on to be answered.
    """
    s = sup.machine
    p = sup.params
    m = sup.message
    c = sup.current
    sensor_rise = sensor_voltage_v - s.baseline_voltage_v > p.sensor_voltage_threshold_v
    if sensor_rise and s.contact_ns == NO_NS:
        s.contact_ns = t_ns
    farthest_face_m = c.position_setpoint_m + c.width_tolerance_m   # narrowest object
    if s.contact_ns == NO_NS and position_m > farthest_face_m + p.no_object_margin_m:
        _note(sup, position_m, force_n)
        m.position_setpoint_m = c.position_setpoint_m
        m.width_tolerance_m = c.width_tolerance_m
        m.farthest_face_m = farthest_face_m
        return Event.NO_OBJECT
    if s.contact_ns != NO_NS:
        lost = _object_lost(sup, t_ns, position_m, force_n)
        if lost != Event.NONE:
            return lost
    if s.state == State.HOLD:
        return Event.NONE
    if s.state == State.APPROACH:
        tol = p.position_tolerance_fraction * c.position_setpoint_m
        slow = p.position_switch_speed_mps <= 0.0 or abs(speed_mps) <= p.position_switch_speed_mps
        if abs(position_m - c.approach_setpoint_m) <= tol and slow:
            _switch(sup, SwitchCriterion.POSITION_TOLERANCE, Event.AT_TOLERANCE)
        elif sensor_rise:
            _switch(sup, SwitchCriterion.SENSOR_VOLTAGE, Event.SENSOR_RISE)
    elif s.state == State.SQUEEZE:
        if _force_settled(s, p, t_ns, force_n, speed_mps):
            s.settled_ns = t_ns
            s.hold_position_m = position_m
            _take(sup, Event.SETTLED, position_m)
    if s.state == State.SETTLED and (t_ns - s.settled_ns) * 1e-9 >= p.hold_watch_s:
        _note(sup, position_m, force_n)
        m.force_setpoint_n = s.force_setpoint_n
        return Event.HELD
    if (t_ns - s.start_ns) * 1e-9 > c.timeout_s:
        _note(sup, position_m, force_n)
        m.timeout_s = c.timeout_s
        m.phase = s.phase
        return Event.GRASP_TIMEOUT
    return Event.NONE


@_kernel
def _switch(sup, criterion, event) -> None:
    """APPROACH -> SQUEEZE: note the criterion; the settle rate starts at the next tick."""
    s = sup.machine
    s.prev_force_t_ns = NO_NS
    s.switch_criterion = criterion
    s.switch_ns = s.t_ns
    _take(sup, event, math.nan)


@_kernel
def _tick_release(sup, t_ns, position_m, force_n) -> int:
    """RELEASE: open once within ``release_tolerance_m`` for ``release_settle_s``."""
    s = sup.machine
    p = sup.params
    m = sup.message
    c = sup.current
    if abs(position_m - c.position_setpoint_m) <= p.release_tolerance_m:
        if s.in_band_since_ns == NO_NS:
            s.in_band_since_ns = t_ns
        if (t_ns - s.in_band_since_ns) * 1e-9 >= p.release_settle_s:
            _note(sup, position_m, force_n)
            m.position_setpoint_m = c.position_setpoint_m
            return Event.RELEASED
    else:
        s.in_band_since_ns = NO_NS
    if (t_ns - s.start_ns) * 1e-9 > c.timeout_s:
        _note(sup, position_m, force_n)
        m.timeout_s = c.timeout_s
        return Event.RELEASE_TIMEOUT
    return Event.NONE


@_kernel
def _tick_move(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps) -> int:
    """MOVE: MOVED at rest within the tolerance, STALLED at rest short of it, or TIMEOUT."""
    s = sup.machine
    p = sup.params
    m = sup.message
    c = sup.current
    goal = c.position_setpoint_m
    elapsed_s = (t_ns - s.start_ns) * 1e-9
    if s.contact_ns == NO_NS and \
            sensor_voltage_v - s.baseline_voltage_v > p.sensor_voltage_threshold_v:
        s.contact_ns = t_ns
    error_m = goal - position_m                   # > 0: still to close
    at_rest = abs(speed_mps) <= p.move_rest_speed_mps
    _note(sup, position_m, force_n)               # where: position, goal, force, elapsed
    m.position_setpoint_m = goal
    if not at_rest:
        s.rest_since_ns = NO_NS
    elif abs(error_m) <= c.tolerance_m:
        if not stream_changing(sup.servo.stream, t_ns, p.servo_rate_window_s):
            return Event.MOVED                    # no setpoint stream moves it
    else:
        if s.rest_since_ns == NO_NS:
            s.rest_since_ns = t_ns
        rest_s = (t_ns - s.rest_since_ns) * 1e-9
        fraction = p.move_stall_force_fraction
        # closing onto an obstacle, pressing at the effort limit (False for a NaN force)
        pressing = error_m > 0.0 and fraction * c.max_effort_n <= force_n and \
            force_n <= c.max_effort_n / fraction
        if pressing or rest_s >= p.move_stall_timeout_s:
            m.short_of_goal_m = error_m
            m.max_effort_n = c.max_effort_n
            m.since_ns = s.rest_since_ns
            return Event.STALLED_PRESSING if pressing else Event.STALLED_AT_REST
    if elapsed_s > s.move_timeout_s:
        m.timeout_s = s.move_timeout_s
        return Event.MOVE_TIMEOUT
    return Event.NONE


@_kernel
def _tick_request(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps) -> int:
    """Return the event a tick of a running request or a hold brings (NONE: none)."""
    s = sup.machine
    m = sup.message
    state = s.state
    position_only = state == State.RELEASE or state == State.MOVE   # no force needed
    bad_position = not math.isfinite(position_m)
    bad_force = not position_only and not (math.isfinite(force_n)
                                           and math.isfinite(sensor_voltage_v))
    if bad_position or bad_force:
        _note(sup, position_m, force_n)
        m.bad_position = bad_position
        m.bad_force = bad_force
        m.request_kind = 0 if state == State.HOLD else sup.current.kind   # 0: the hold
        m.sensor_voltage_v = sensor_voltage_v
        return Event.SENSOR_FAULT
    s.position_m = position_m                          # finite: where a stop holds
    if state == State.RELEASE:
        return _tick_release(sup, t_ns, position_m, force_n)
    if state == State.MOVE:
        return _tick_move(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps)
    return _tick_grasp(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps)


@_kernel
def _track_load(sup, law_buffers, t_ns, force_n, shear_n, displacement_m, may_answer) -> int:
    """Run the load-tracking grip on this tick's pads: its setpoint becomes the grasp's.

    Returns OVERLOADED (or OVERLOADED_SLIDING) the first tick the law has found the load beyond
    the most 24 V holds (the next one when this tick already answered), else NONE; the force
    stage goes on holding at the law's setpoint (at most that force), the loss watch too.
    """
    s = sup.machine
    m = sup.message
    g = sup.law[0]
    history = law_buffers[:HISTORY_ROWS, :g.window + 1]
    sums = law_buffers[HISTORY_ROWS:, :MU_GRID.size]
    s.force_setpoint_n = law_step(g, history, sums, MU_GRID, t_ns, shear_n, displacement_m,
                                  force_n, sup.plan, s.position_m)
    if g.overload_ns == -1 or s.overload_ns != NO_NS or not may_answer:
        return Event.NONE
    s.overload_ns = t_ns
    _note(sup, s.position_m, force_n)
    m.need_n = g.overload_need_n
    m.max_force_n = g.max_force_n
    m.load_n = 2.0 * shear_n
    m.friction_coefficient = g.overload_mu
    return Event.OVERLOADED if m.need_n > m.max_force_n else Event.OVERLOADED_SLIDING


@_kernel
def _decide(sup, answer) -> None:
    """Write the tick's decision: who drives, with which setpoints and limits, what answers."""
    s = sup.machine
    c = sup.current
    d = sup.decided
    s.tick_answer = answer
    s.running = _running(s)
    s.holding = s.state == State.HOLD
    s.pressing = s.state == State.PRESSING
    s.contact = s.contact_ns != NO_NS
    if answer != Outcome.UNKNOWN and s.answer_ns == NO_NS:
        s.answer = answer
        s.answer_ns = s.t_ns
    if s.state == State.IDLE or s.state == State.PRESSING:
        d.position_setpoint_m = s.idle_hold_m
        d.approach_setpoint_m = s.idle_hold_m
        d.force_setpoint_n = s.force_setpoint_n if c.kind != PendingRequest.NONE else 0.0
        d.voltage_limit_v = s.idle_limit_v
        d.speed_mps = s.idle_speed_limit_mps
    elif c.kind != PendingRequest.NONE:
        copy_fields(d, c, ('position_setpoint_m', 'approach_setpoint_m'))
        d.force_setpoint_n = s.force_setpoint_n
        if s.state == State.MOVE:
            d.voltage_limit_v = c.voltage_limit_v
            d.speed_mps = c.speed_mps
        else:
            d.voltage_limit_v = 0.0
            d.speed_mps = 0.0
    else:
        set_fields(d, ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                       'voltage_limit_v', 'speed_mps'), 0.0)
    _lead(sup)


@_kernel
def _lead(sup) -> None:
    """Move a setpoint stream's reference on with its velocity and acceleration (0: none)."""
    s = sup.machine
    p = sup.params
    v = sup.servo
    if s.state == State.MOVE and v.stream.t_ns != NO_STREAM:
        d = sup.decided
        d.approach_setpoint_m, v.velocity_mps, v.acceleration_mps2 = stream_reference(
            v.stream, s.t_ns, p.servo_rate_window_s, p.servo_lead_s, sup.current.speed_mps,
            s.travel_m)
    else:
        v.velocity_mps = 0.0
        v.acceleration_mps2 = 0.0


# ------------------------------------------------------------------ the entry points
@face_kernel(*_ARRAYS, int, float, float, float, float, int, float, float)
@_kernel
def supervisor_step(sup, law_buffers, t_ns, position_m, force_n, sensor_voltage_v, speed_mps,
                    revision, shear_n, displacement_m) -> None:
    """Advance the machine with the measurements of tick ``t_ns``; the decision in the record.

    ``speed_mps`` is the finger's speed (the position switch's speed condition);
    ``revision`` counts changes of the simulated world (a new object, fingers reset): the
    position stage then holds the finger where it now is. ``shear_n`` and ``displacement_m``
    (a pad's mean) feed the load-tracking grip of a mass-0 grasp.
    """
    sup = as_record(sup)
    s = sup.machine
    s.t_ns = t_ns
    if s.revision != revision:
        first = s.revision == NO_NS
        s.revision = revision
        _take(sup, Event.FIRST_TICK if first else Event.NEW_WORLD, position_m)
    w = sup.waiting
    if w.kind != PendingRequest.NONE and (w.after_ns == NO_NS or t_ns > w.after_ns) and \
            math.isfinite(position_m):
        _start(sup, law_buffers, position_m, sensor_voltage_v)
    answer = Outcome.UNKNOWN
    if _running(s) or s.state == State.HOLD:
        event = _tick_request(sup, t_ns, position_m, force_n, sensor_voltage_v, speed_mps)
        if event != Event.NONE:
            answer = _take(sup, event, position_m)
    if sup.current.load_tracking and math.isfinite(force_n) and (
            s.state == State.SQUEEZE or s.state == State.SETTLED or s.state == State.HOLD):
        event = _track_load(sup, law_buffers, t_ns, force_n, shear_n, displacement_m,
                            answer == Outcome.UNKNOWN)
        if event != Event.NONE:
            answer = _take(sup, event, position_m)
    _decide(sup, answer)


_RELAYED_FIELDS = REFERENCE_LAYOUT.copied_from(MSG_TICK)
"""What a StageReference relays of its PlantTick, as read."""


@face_kernel(*_ARRAYS, TICK_LAYOUT.dtype, REFERENCE_LAYOUT.dtype)
@_kernel
def supervisor_decide(sup, law_buffers, tick, ref) -> bool:
    """Decide ``tick`` (a PlantTick record) and address ``ref`` (a StageReference record).

    Returns False when no stage is named (after a FAULT). The reference relays the tick's
    measurement as read, a non-finite one included (the stage then holds 0 V); the seed voltage
    is the last finite applied one, since no measurement of the stage depends on it.
    """
    sup = as_record(sup)
    t = as_record(tick)
    supervisor_step(sup, law_buffers, t.stamp_ns, t.position_m, t.force_n, t.sensor_voltage_v,
                    t.velocity_mps, t.revision, 0.5 * (t.pad1_shear_n + t.pad2_shear_n),
                    0.5 * (t.pad1_displacement_m + t.pad2_displacement_m))
    s = sup.machine
    if math.isfinite(t.motor_voltage_v):
        s.seed_voltage_v = t.motor_voltage_v
    if s.active == Controller.NONE:
        return False
    r = as_record(ref)
    d = sup.decided
    copy_fields(r, t, _RELAYED_FIELDS)
    copy_fields(r, s, ('grasp_id', 'stage_id', 'phase', 'outcome', 'seed_voltage_v',
                       'running', 'contact'))
    r.controller = s.active
    copy_fields(r, d, ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                       'voltage_limit_v'))
    r.speed_limit_mps = d.speed_mps
    r.approach_velocity_mps = sup.servo.velocity_mps
    r.approach_acceleration_mps2 = sup.servo.acceleration_mps2
    return True


@face_kernel(*_ARRAYS)
@_kernel
def supervisor_stop(sup, law_buffers) -> bool:
    """End the running request, the hold, a stalled move's press or a waiting request: STOPPED.

    False with nothing to stop. The message is the text the caller gives.
    """
    sup = as_record(sup)
    s = sup.machine
    if sup.waiting.kind != PendingRequest.NONE and not _running(s):
        _take_waiting(sup)                # answered at once, it never starts: the finger
        where_m = s.position_m if not math.isnan(s.position_m) else s.idle_hold_m
        answer = _take(sup, Event.CANCEL, where_m)   # stays where it was last measured
    elif s.state == State.PRESSING:       # where the move stalled
        answer = _take(sup, Event.STOP, s.position_m)
    else:
        answer = _take(sup, Event.STOP, _last_position(s))
    if answer == Outcome.UNKNOWN:
        return False
    _decide(sup, answer)
    return True


@face_kernel(*_ARRAYS)
@_kernel
def supervisor_fault(sup, law_buffers) -> bool:
    """End the running request or the hold as FAULT: no controller drives the motor."""
    sup = as_record(sup)
    answer = _take(sup, Event.FAULT, math.nan)
    _decide(sup, answer)
    return answer != Outcome.UNKNOWN


STREAM_CLEAR = 0
"""``supervisor_wait``: no setpoint stream moves the waiting request (a service's request)."""
STREAM_BEGIN = 1
"""... the waiting request is a setpoint stream's first move."""
STREAM_KEEP = 2
"""... the stream's waiting move takes a newer setpoint before it starts."""


@face_kernel(*_ARRAYS, TARGETS_DTYPE, int)
@_kernel
def supervisor_wait(sup, law_buffers, targets, stream) -> None:
    """Accept ``targets`` (a request's record, its kind, mass and start) as the waiting one."""
    sup = as_record(sup)
    sup.waiting = as_record(targets)
    v = sup.servo
    if stream == STREAM_CLEAR or stream == STREAM_BEGIN:
        v.stream.t_ns = NO_STREAM            # no stream moves it (yet: supervisor_servo_sample)
    if stream == STREAM_BEGIN:
        v.request_id = sup.machine.grasp_id + 1


@face_kernel(*_ARRAYS, int, float, float, float)
@_kernel
def supervisor_servo_sample(sup, law_buffers, sample_ns, position_m, velocity_mps,
                            acceleration_mps2) -> None:
    """Take the stream's setpoint ``position_m`` sampled at ``sample_ns``.

    Its velocity and acceleration are NaN when not given. Its instant is ``sample_ns`` when
    that is on the ticks' clock (within ``servo_rate_window_s`` of the newest tick; NO_NS: not
    known), else the newest tick's.
    """
    sup = as_record(sup)
    p = sup.params
    t_ns = sup.machine.t_ns
    if sample_ns != NO_NS and abs(sample_ns - t_ns) <= p.servo_rate_window_s * 1e9:
        t_ns = sample_ns
    stream_sample(sup.servo.stream, t_ns, position_m, velocity_mps, acceleration_mps2,
                  p.servo_fit_memory_s, p.servo_rate_window_s)


@face_kernel(*_ARRAYS, TARGETS_DTYPE)
@_kernel
def supervisor_retarget(sup, law_buffers, targets) -> None:
    """Give the running setpoint move new targets in place (same request, same stage).

    The move's timeout counts on from its start; the stream's motion is the setpoint's
    (:func:`supervisor_servo_sample`).
    """
    sup = as_record(sup)
    s = sup.machine
    p = sup.params
    t = as_record(targets)
    t_ns = s.t_ns
    sup.current = t
    sup.current.kind = PendingRequest.MOVE
    s.force_setpoint_n = t.force_setpoint_n
    if t.timeout_s != 0.0 or math.isfinite(s.position_m):
        s.move_timeout_s = _move_timeout_s(p, t, s.position_m, (t_ns - s.start_ns) * 1e-9)
    s.rest_since_ns = NO_NS


@face_kernel(*_ARRAYS, int)
@_kernel
def supervisor_continue_ids(sup, law_buffers, last_id) -> bool:
    """Make the next request ``last_id + 1``; False (nothing changed) after the first request."""
    sup = as_record(sup)
    if sup.current.kind != PendingRequest.NONE or sup.waiting.kind != PendingRequest.NONE:
        return False
    sup.machine.grasp_id = last_id
    return True


@face_kernel(*_ARRAYS, PARAMS_DTYPE)
@_kernel
def supervisor_configure(sup, law_buffers, params) -> None:
    """Take new thresholds, in effect from the next tick."""
    sup = as_record(sup)
    sup.params = as_record(params)


@face_kernel(*_ARRAYS, float, GRIP_DTYPE, float, float)
@_kernel
def supervisor_reset(sup, law_buffers, travel_m, law, jump_speed_mps,
                     servo_acceleration_mps2) -> None:
    """Put a new supervisor's record in its first state: nothing drives, nothing asked.

    ``law`` is the load-tracking grip as each grasp starts it (``make_law``'s record); a
    setpoint stream's bounds are the plant's (``servo_feedforward.stream_bounds``).
    """
    sup = as_record(sup)
    s = sup.machine
    s.state = State.UNDRIVEN
    set_fields(s, ('t_ns', 'grasp_id', 'stage_id'), 0)
    set_fields(s, _FIRST_NO_NS, NO_NS)
    set_fields(s, ('hold_position_m', 'position_m'), math.nan)
    s.travel_m = travel_m
    s.tick_answer = Outcome.UNKNOWN
    v = sup.servo
    v.request_id = NO_NS
    v.stream.t_ns = NO_STREAM
    v.stream.jump_speed_mps = jump_speed_mps
    v.stream.max_acceleration_mps2 = servo_acceleration_mps2
    sup.law[1] = as_record(law)
    sup.law[0] = sup.law[1]


# ------------------------------------------------------------------ the status
@_kernel
def status_changed(sup, row) -> bool:
    """Tell whether the status differs from ``row`` (a :data:`.series.STATUS_ROW`).

    The status goes out at once when it does: phase, stage, outcome, switch, request, contact
    or the waiting request. The node and the headless trace both ask this.
    """
    s = sup.machine
    return row.phase != s.phase or row.active_controller != s.active or \
        row.switch_criterion != s.switch_criterion or row.grasp_id != s.grasp_id or \
        row.outcome != s.outcome or row.stage_id != s.stage_id or row.contact != s.contact or \
        row.pending_request != sup.waiting.kind


@_kernel
def status_note(sup, row) -> None:
    """Write into ``row`` what :func:`status_changed` compares."""
    s = sup.machine
    copy_fields(row, s, ('phase', 'switch_criterion', 'grasp_id', 'outcome', 'stage_id',
                         'contact'))
    row.active_controller = s.active
    row.pending_request = sup.waiting.kind
