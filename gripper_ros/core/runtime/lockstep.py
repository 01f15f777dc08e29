"""The three sides of one lockstep tick, shared by the nodes and the headless loop (no rclpy).

Each tick ``t_k``: the plant measures (:class:`Tick`), the supervisor decides and sends a
:class:`Reference` to the stage it names, that stage answers with a :class:`Command`, and the
plant holds the command's voltage for its ``hold_s``. The nodes move these messages as bytes
(:mod:`gripper_ros.wire` layouts) and take each with one call of a face below
(``side_take_command``, ``supervisor_take_tick``, ``stage_take_reference``);
:mod:`gripper_ros.core.runtime.headless` hands them over inside one compiled loop. Both call
exactly the compiled functions below (numba), on the messages as records (``TICK_LAYOUT.dtype``
and so on), so a headless grasp equals the graph's tick for tick.
"""
from __future__ import annotations

import math

from gripper_ros.core.control.stages import (LockstepAnswerer, Reference, stage_answer,
                                             STAGE_KERNEL, TickAnswer)
from gripper_ros.core.physics.plant import (GraspObject, GripperPlant, HoldState,
                                            plant_begin_hold, plant_cancel_fault, PLANT_DTYPE,
                                            plant_fault_scheduled, plant_hold_record,
                                            plant_read_tick, plant_scenario_in_progress,
                                            plant_schedule_fault, plant_step)
from gripper_ros.core.records import BYTES, face_kernel, FLOATS_2D, RecordField, UINT8S
from gripper_ros.core.series import STATUS_ROW
from gripper_ros.core.supervision.machine import (NO_NS, status_changed, status_note,
                                                  supervisor_decide, SUPERVISOR_DTYPE)
from gripper_ros.core.supervision.supervisor import Decision, GraspSupervisor
from gripper_ros.wire import (COMMAND_LAYOUT, Controller, FaultKind, Outcome, Phase,
                              REFERENCE_LAYOUT, TICK_LAYOUT)
import numba
import numpy as np

Tick = TICK_LAYOUT.tuple
"""One PlantTick's fields, in message order."""
Command = COMMAND_LAYOUT.tuple
"""One MotorCommand's fields, in message order."""

MAX_HOLD_S = 1.0
"""A command held longer than this is refused as malformed."""

PLANT_SIDE_STATE = np.dtype(
    [('revision', 'i8'),               # +1 on every change of the simulated world
     ('applied_source', 'i4'),
     ('grasp_mass_kg', 'f8'),          # the requested mass of the grasp (from its status)
     ('fault_kind', 'i4'),             # a fault to arm at the next grasp's start (NONE: none)
     ('fault_at_s', 'f8'), ('fault_time_constant_s', 'f8'),
     ('fault_grasp', 'i8'),            # the grasp it was armed for (-1: none)
     ('echo_grasp', 'i8'),             # grasp id of the last accepted command
     ('hold_begun_for', 'i8'),         # the grasp whose hold clock was started (-1: none)
     ('next_state_ns', 'i8'),          # the state topics are due at this tick or later
     ('state_hold', 'i4')],            # the hold state they last carried
    align=True)
"""The plant side's bookkeeping between ticks (beside the plant's own state)."""

_kernel = numba.njit(cache=True)


def new_record(layout, count: int = 1) -> np.ndarray:
    """Return ``count`` zeroed records of a loop message (a 1-element array by default)."""
    return np.zeros(count, layout.dtype)


def command_problem(cmd: Command) -> str:
    """Why the plant must refuse ``cmd`` ('' when it is usable)."""
    if not math.isfinite(cmd.voltage_v):
        return f'voltage {cmd.voltage_v!r} V is not finite'
    if not (math.isfinite(cmd.hold_s) and 0.0 < cmd.hold_s <= MAX_HOLD_S):
        return f'hold {cmd.hold_s!r} s is not in (0, {MAX_HOLD_S:g}] s'
    if cmd.source not in (Controller.POSITION, Controller.FORCE):
        return f'source {cmd.source!r} is no stage controller'
    return ''


# ------------------------------------------------------------------ the plant side, compiled
@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, COMMAND_LAYOUT.dtype)
@_kernel
def side_accept(side, plant_k, cmd) -> None:
    """React to the decision ``cmd`` echoes, at the tick it answers.

    A scheduled fault is armed when a grasp starts (its first command) and dropped when the
    grasp ends before it fired; the hold clock of a lift starts when the grasp is answered
    HOLDING.
    """
    s = side[0]
    c = cmd[0]
    if c.grasp_id != s.echo_grasp:
        s.echo_grasp = c.grasp_id
        if s.fault_kind != FaultKind.NONE and c.phase == Phase.POSITION:
            plant_schedule_fault(plant_k, s.fault_kind,
                                 c.stamp_ns + round(s.fault_at_s * 1e9), s.fault_time_constant_s)
            s.fault_kind = FaultKind.NONE
            s.fault_grasp = c.grasp_id
    if c.outcome != Outcome.UNKNOWN and plant_fault_scheduled(plant_k) and \
            c.grasp_id == s.fault_grasp:
        plant_cancel_fault(plant_k)            # the grasp ended before its fault fired
    if c.phase == Phase.HOLDING and c.outcome == Outcome.HOLDING and \
            s.hold_begun_for != c.grasp_id:
        s.hold_begun_for = c.grasp_id
        plant_begin_hold(plant_k, c.stamp_ns, s.grasp_mass_kg)   # 1: left its support before


@face_kernel(PLANT_DTYPE, COMMAND_LAYOUT.dtype)
@_kernel
def side_needs_time(plant_k, cmd) -> bool:
    """Tell whether simulated time must go on after ``cmd`` in fast mode.

    It must for a request in progress, or a hold scenario (a lift) still to be played out.
    """
    return cmd[0].running != 0 or plant_scenario_in_progress(plant_k)


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, COMMAND_LAYOUT.dtype, TICK_LAYOUT.dtype)
@_kernel
def side_step(side, plant_k, cmd, tick) -> None:
    """Hold the command's voltage for its ``hold_s``; ``tick`` becomes the next tick."""
    c = cmd[0]
    s = side[0]
    s.applied_source = c.source
    plant_step(plant_k, c.voltage_v, round(c.hold_s * 1e9))
    plant_read_tick(plant_k, tick, s.revision, c.source)


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, int, TICK_LAYOUT.dtype)
@_kernel
def side_step_unpowered(side, plant_k, duration_ns, tick) -> None:
    """No command came: the motor is held at 0 V (a driver's command timeout)."""
    s = side[0]
    s.applied_source = Controller.NONE
    plant_step(plant_k, 0.0, duration_ns)
    plant_read_tick(plant_k, tick, s.revision, Controller.NONE)


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, TICK_LAYOUT.dtype)
@_kernel
def side_read_tick(side, plant_k, tick) -> None:
    """``tick``: the plant's measurement now."""
    s = side[0]
    plant_read_tick(plant_k, tick, s.revision, s.applied_source)


# ------------------------------------------------------------------ the nodes' faces, compiled
# A node takes a loop message as bytes and answers with one call: the message is copied into its
# record, checked, and acted on, and the reply is left in a record whose bytes are the reply's
# CDR body. What the Python side then does is publish, count and, rarely, log.

TAKEN = 0
"""The message was acted on."""
REPEATED = 1
"""Seen before (a repeat of a tick or a reference), or not for the current tick."""
FOREIGN = 2
"""Not little-endian plain CDR of the layout's size: the caller deserialises it, then retries."""
REFUSED = 3
"""A command the plant must not apply (:func:`command_problem` says why)."""


@_kernel
def load_message(data, record_bytes) -> bool:
    """Copy serialised ``data`` into a record (its bytes); False when not in the layout's form.

    The form is little-endian plain CDR with this layout's size (``wire.LoopLayout``).
    """
    n = record_bytes.size
    if len(data) != n + 4 or data[0] != 0 or data[1] != 1 or data[2] != 0 or data[3] != 0:
        return False
    for i in range(n):
        record_bytes[i] = data[i + 4]
    return True


@_kernel
def _command_usable(c) -> bool:
    return math.isfinite(c.voltage_v) and math.isfinite(c.hold_s) and \
        0.0 < c.hold_s <= MAX_HOLD_S and \
        (c.source == Controller.POSITION or c.source == Controller.FORCE)


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, BYTES, COMMAND_LAYOUT.dtype, UINT8S,
             COMMAND_LAYOUT.dtype, UINT8S, TICK_LAYOUT.dtype, bool)
@_kernel
def side_take_command(side, plant_k, data, offered, offered_bytes, cmd, cmd_bytes, tick,
                      pending) -> int:
    """Take the command ``data`` for the current ``tick``: TAKEN, REPEATED, FOREIGN or REFUSED.

    Only the command of this tick's stamp and world revision counts, and of a later stage than
    an accepted one still ``pending``; it is accepted into ``cmd`` (:func:`side_accept`).
    ``offered`` holds it as read, whatever became of it.
    """
    if not load_message(data, offered_bytes):
        return FOREIGN
    o = offered[0]
    s = side[0]
    if o.stamp_ns != tick[0].stamp_ns or o.revision != s.revision or \
            (pending and o.stage_id <= cmd[0].stage_id):
        return REPEATED
    if not _command_usable(o):
        return REFUSED
    cmd_bytes[:] = offered_bytes
    side_accept(side, plant_k, cmd)
    return TAKEN


@_kernel
def _state_due(side, plant_k, tick) -> bool:
    """Tell whether the state topics are due: their period came, or the hold state changed."""
    s = side[0]
    h = plant_hold_record(plant_k)
    hold = h.state if h.has_hold else HoldState.NONE
    return tick[0].stamp_ns >= s.next_state_ns or hold != s.state_hold


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, TICK_LAYOUT.dtype, int)
@_kernel
def side_state_published(side, plant_k, tick, period_ns) -> None:
    """Note the state topics of ``tick``: next due one period on, or on a hold change."""
    s = side[0]
    h = plant_hold_record(plant_k)
    s.state_hold = h.state if h.has_hold else HoldState.NONE
    s.next_state_ns = (tick[0].stamp_ns // period_ns + 1) * period_ns


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, COMMAND_LAYOUT.dtype, TICK_LAYOUT.dtype)
@_kernel
def side_step_due(side, plant_k, cmd, tick):
    """:func:`side_step`; the new tick's stamp, and whether the state topics are due for it."""
    side_step(side, plant_k, cmd, tick)
    return tick[0].stamp_ns, _state_due(side, plant_k, tick)


@face_kernel(PLANT_SIDE_STATE, PLANT_DTYPE, int, TICK_LAYOUT.dtype)
@_kernel
def side_step_unpowered_due(side, plant_k, duration_ns, tick):
    """:func:`side_step_unpowered`; the new tick's stamp, and whether the state topics are due."""
    side_step_unpowered(side, plant_k, duration_ns, tick)
    return tick[0].stamp_ns, _state_due(side, plant_k, tick)


SUPERVISOR_SIDE_STATE = np.dtype(
    [('decided_stamp_ns', 'i8'), ('decided_revision', 'i8'),   # the tick last decided
     ('expected_source', 'i4'),        # who should command the next tick
     ('good_position_m', 'f8'), ('good_force_n', 'f8'),        # the last finite readings
     ('status', STATUS_ROW),           # what the last status said (status_changed compares)
     ('next_status_ns', 'i8'), ('status_period_ns', 'i8')],
    align=True)
"""The supervisor node's bookkeeping between ticks (beside the supervisor's own state)."""

NAMED = 1
"""``supervisor_take_tick``: a reference was addressed to a stage (``flags >> ACTIVE_SHIFT``)."""
STATUS_DUE = 2
"""... the status is due (its period, or the phase, stage, outcome or request changed)."""
ANSWERED = 4
"""... the request was answered at this tick."""
PROGRESS = 8
"""... the named stage's command moved the plant (or nothing runs): no silence."""
ACTIVE_SHIFT = 4
"""... and above these flags, the stage named (a ``Controller``)."""


@face_kernel(SUPERVISOR_DTYPE, FLOATS_2D, SUPERVISOR_SIDE_STATE, BYTES, TICK_LAYOUT.dtype, UINT8S,
             REFERENCE_LAYOUT.dtype)
@_kernel
def supervisor_take_tick(sup, law_buffers, side, data, tick, tick_bytes, ref) -> int:
    """Decide the tick ``data``; FOREIGN, REPEATED, or the flags of what the node must do.

    A tick already decided is REPEATED (its reference goes out again). Otherwise ``ref`` holds
    the reference (flag NAMED), and the flags say whether the status is due, the request was
    answered, and the plant moved by the named stage's command.
    """
    if not load_message(data, tick_bytes):
        return -FOREIGN
    t = tick[0]
    n = side[0]
    if t.stamp_ns == n.decided_stamp_ns and t.revision == n.decided_revision:
        return -REPEATED
    n.decided_stamp_ns = t.stamp_ns
    n.decided_revision = t.revision
    if math.isfinite(t.position_m):
        n.good_position_m = t.position_m
    if math.isfinite(t.force_n):
        n.good_force_n = t.force_n
    record = sup[0]
    s = record.machine
    flags = 0
    if t.applied_source == n.expected_source or not s.running:
        flags |= PROGRESS
    if supervisor_decide(record, law_buffers, t, ref[0]):
        flags |= NAMED
    n.expected_source = s.active
    flags |= s.active << ACTIVE_SHIFT
    if status_changed(record, n.status) or t.stamp_ns >= n.next_status_ns:
        flags |= STATUS_DUE
    if s.tick_answer != Outcome.UNKNOWN:
        flags |= ANSWERED
    return flags


@face_kernel(SUPERVISOR_DTYPE, SUPERVISOR_SIDE_STATE, int)
@_kernel
def supervisor_status_published(sup, side, t_ns) -> None:
    """Note the status of ``t_ns``: the next is due one period on, or on a change."""
    n = side[0]
    status_note(sup[0], n.status)
    n.next_status_ns = (t_ns // n.status_period_ns + 1) * n.status_period_ns


@face_kernel(STAGE_KERNEL, BYTES, REFERENCE_LAYOUT.dtype, UINT8S, COMMAND_LAYOUT.dtype)
@_kernel
def stage_take_reference(k, data, ref, ref_bytes, cmd) -> int:
    """Answer the reference ``data`` into ``cmd``: TAKEN, REPEATED (answered before) or FOREIGN."""
    if not load_message(data, ref_bytes):
        return FOREIGN
    return TAKEN if stage_answer(k, ref, cmd) else REPEATED


_ENTRY_POINTS: dict = {}


def entry_point(kernel, *args):
    """Return ``kernel`` compiled for arguments of the types of ``args``, to call directly.

    numba types every argument on every call to pick the machine code (0.2-0.5 us an array or
    record, more for a tuple of them); a node calls its kernels every tick with the same
    records, so it types them once here. Call the result only with arguments of these types.
    Each (kernel, types) is typed and looked up once a process (typing a record array costs
    about 0.15 ms, the plant's tuple of them 1 ms, and the headless loop builds sides by the
    thousand).
    """
    key = (kernel, _type_key(args))
    found = _ENTRY_POINTS.get(key)
    if found is None:
        found = _ENTRY_POINTS[key] = kernel.compile(tuple(numba.typeof(a) for a in args))
    return found


def _type_key(value):
    """Return what decides numba's type of ``value``, cheaply: arrays by dtype and shape."""
    if isinstance(value, np.ndarray):
        return (value.dtype, value.ndim, value.flags.c_contiguous, value.flags.writeable)
    if isinstance(value, tuple):
        return tuple(_type_key(v) for v in value)
    return type(value)


class PlantSide:
    """The plant's share of a tick: the measurement, the command's echo, the step.

    ``state`` is its bookkeeping record; the tick, command and reference records it fills are
    ``tick_record`` and ``command_record``.
    """

    def __init__(self, plant: GripperPlant):
        self.plant = plant
        self.state = np.zeros(1, PLANT_SIDE_STATE)
        self._s = self.state[0]
        self._forget_grasps()
        self.tick_record = new_record(TICK_LAYOUT)
        self.command_record = new_record(COMMAND_LAYOUT)
        self.offered = new_record(COMMAND_LAYOUT)
        """The last command offered to :meth:`take_command`, as read."""
        self._bind_faces()

    def _bind_faces(self) -> None:
        """Bind the node's calls of a tick, typed once (:func:`entry_point`)."""
        state, k, tick, cmd, offered = (self.state, self.plant.kernel, self.tick_record,
                                        self.command_record, self.offered)
        cmd_bytes, offered_bytes = cmd.view(np.uint8), offered.view(np.uint8)
        take = entry_point(side_take_command, state, k, b'', offered, offered_bytes, cmd,
                           cmd_bytes, tick, False)
        step = entry_point(side_step_due, state, k, cmd, tick)
        unpowered = entry_point(side_step_unpowered_due, state, k, 0, tick)
        self.take_command = lambda data, pending: take(state, k, data, offered, offered_bytes,
                                                       cmd, cmd_bytes, tick, pending)
        """Take a serialised command (:func:`side_take_command`); ``pending``: one is accepted."""
        self.step_due = lambda: step(state, k, cmd, tick)
        """Step with the accepted command: (the new tick's stamp, state topics due)."""
        self.step_unpowered_due = lambda duration_ns: unpowered(state, k, duration_ns, tick)
        """Step ``duration_ns`` at 0 V: (the new tick's stamp, state topics due)."""
        needs_time = entry_point(side_needs_time, k, cmd)
        self.command_needs_time = lambda: needs_time(k, cmd)
        """Whether simulated time must go on after the accepted command (fast mode)."""

    revision = RecordField(int, writable=False, at='_s',
                           doc='+1 on every change of the simulated world.')
    applied_source = RecordField(Controller, writable=False, at='_s')
    grasp_mass_kg = RecordField(at='_s', doc="The requested mass of the grasp (the plant's mass "
                                'of an object that gives none).')

    def _tick(self) -> Tick:
        return Tick._make(self.tick_record[0].item())

    def tick(self) -> Tick:
        side_read_tick(self.state, self.plant.kernel, self.tick_record)
        return self._tick()

    def set_object(self, obj: GraspObject, open_fingers: bool = False,
                   fault: tuple[FaultKind, float, float] | None = None, **hold) -> None:
        """Place ``obj`` (ValueError and nothing changes when refused).

        ``fault`` (kind, seconds after the next grasp's start, time constant) is armed when
        that grasp starts.
        """
        saved = self.plant.snapshot()
        try:
            if open_fingers:
                self.plant.reset(open_fingers=True)
            self.plant.set_object(obj, **hold)
        except ValueError:
            self.plant.restore(saved)           # refused: the plant is as it was
            raise
        s = self._s
        if fault is None or fault[0] is FaultKind.NONE:
            s['fault_kind'] = FaultKind.NONE
        else:
            s['fault_kind'], s['fault_at_s'], s['fault_time_constant_s'] = fault
        self._forget_grasps()
        s['revision'] += 1

    def _forget_grasps(self) -> None:
        """No command applied yet, no fault armed for a grasp, no hold clock started."""
        s = self._s
        s['applied_source'] = Controller.NONE
        s['fault_grasp'] = s['hold_begun_for'] = NO_NS

    def _command(self, cmd) -> np.ndarray:
        record = self.command_record
        if cmd is not record:
            record[0] = tuple(cmd)
        return record

    def accept(self, cmd: Command) -> None:
        """React to the decision ``cmd`` echoes, at the tick it answers."""
        side_accept(self.state, self.plant.kernel, self._command(cmd))

    def needs_time(self, cmd: Command) -> bool:
        """Tell whether simulated time must go on after ``cmd`` in fast mode."""
        return bool(side_needs_time(self.plant.kernel, self._command(cmd)))

    def step(self, cmd: Command) -> Tick:
        """Hold the command's voltage for its ``hold_s``; the next tick."""
        side_step(self.state, self.plant.kernel, self._command(cmd), self.tick_record)
        return self._tick()

    def step_unpowered(self, duration_s: float) -> Tick:
        """No command came: the motor is held at 0 V (a driver's command timeout)."""
        side_step_unpowered(self.state, self.plant.kernel, round(duration_s * 1e9),
                            self.tick_record)
        return self._tick()


class SupervisorSide:
    """The supervisor's share of a tick: decide, and address the reference to one stage."""

    def __init__(self, supervisor: GraspSupervisor):
        self.supervisor = supervisor
        self.tick_record = new_record(TICK_LAYOUT)
        self.reference_record = new_record(REFERENCE_LAYOUT)
        self.state = np.zeros(1, SUPERVISOR_SIDE_STATE)
        """The node's bookkeeping: the tick last decided, the last finite readings, the status."""
        n = self.state[0]
        n['decided_stamp_ns'] = n['decided_revision'] = NO_NS
        n['status']['stage_id'] = NO_NS           # no status yet: the first is a change
        n['expected_source'] = Controller.NONE
        (sup, buffers), state, tick, ref = self.supervisor.kernel, self.state, \
            self.tick_record, self.reference_record
        tick_bytes = tick.view(np.uint8)
        take = entry_point(supervisor_take_tick, sup, buffers, state, b'', tick, tick_bytes,
                           ref)
        self.take_tick = lambda data: take(sup, buffers, state, data, tick, tick_bytes, ref)
        """Decide a serialised tick (:func:`supervisor_take_tick`): its flags."""

    def status_published(self, t_ns: int, period_ns: int) -> None:
        """Note the status of ``t_ns``; the next is due ``period_ns`` on, or on a change."""
        self.state[0]['status_period_ns'] = period_ns
        supervisor_status_published(self.supervisor.record, self.state, t_ns)

    @property
    def good_readings(self) -> tuple[float, float]:
        """The last finite position (m) and force (N) read."""
        n = self.state[0]
        return float(n['good_position_m']), float(n['good_force_n'])

    def expect_nobody(self) -> None:
        """No stage drives the next tick (a FAULT): none is waited for."""
        self.state[0]['expected_source'] = Controller.NONE

    def decide_record(self, tick: np.ndarray) -> bool:
        """Decide the tick record ``tick``; True when ``reference_record`` names a stage."""
        return bool(supervisor_decide(*self.supervisor.kernel, tick, self.reference_record))

    def decide(self, tick: Tick) -> tuple[Decision, Reference | None]:
        """Return the decision for ``tick`` and the reference to the stage it names (or None).

        The reference relays the tick's measurement as read, a non-finite one included (the
        stage then holds 0 V); the seed voltage is the last finite applied one.
        """
        record = self.tick_record
        record[0] = tuple(tick)
        named = self.decide_record(record)
        decision = self.supervisor.decision
        if not named:
            return decision, None
        return decision, Reference._make(self.reference_record[0].item())


class StageSide:
    """A stage controller's share of a tick: answer each reference once."""

    def __init__(self, stage):
        self.stage = stage
        self.answerer = LockstepAnswerer(stage)
        self.reference_record = new_record(REFERENCE_LAYOUT)
        self.command_record = new_record(COMMAND_LAYOUT)
        kernel, ref, cmd = stage.kernel, self.reference_record, self.command_record
        ref_bytes = ref.view(np.uint8)
        take = entry_point(stage_take_reference, kernel, b'', ref, ref_bytes, cmd)
        self.take_reference = lambda data: take(kernel, data, ref, ref_bytes, cmd)
        """Answer a serialised reference (:func:`stage_take_reference`)."""
        self.finite = cmd['finite']
        """Whether the last command's voltage is the controller's (a view, read every tick)."""

    @property
    def last_answer(self) -> TickAnswer:
        """The answer of the last command (with the reason when 0 V was held)."""
        c = self.command_record[0]
        if c['finite']:
            return TickAnswer(float(c['voltage_v']), float(c['inner_setpoint']))
        return TickAnswer(0.0, 0.0, finite=False, reason=self.answerer.reason)

    def answer_record(self, ref: np.ndarray) -> bool:
        """Answer the reference record ``ref`` into ``command_record``; False: answered before."""
        return bool(stage_answer(self.stage.kernel, ref, self.command_record))

    def answer(self, ref: Reference) -> Command | None:
        """Return the command for ``ref``, or None when that (stage, stamp) was answered."""
        record = self.reference_record
        record[0] = tuple(ref)
        if not self.answer_record(record):
            return None
        return Command._make(self.command_record[0].item())
