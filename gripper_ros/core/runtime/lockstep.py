"""The three sides of one lockstep tick, shared by the nodes and the headless loop (no rclpy).

Each tick ``t_k``: the plant measures (:class:`Tick`), the supervisor decides and sends a
:class:`Reference` to the stage it names, that stage answers with a :class:`Command`, and the
plant holds the command's voltage for its ``hold_s``. The nodes move these messages over DDS as
bytes (:mod:`gripper_ros.wire` layouts); :mod:`gripper_ros.core.runtime.headless` hands them over
inside one compiled loop. Both call exactly the compiled functions below (numba), on the
messages as records (``TICK_LAYOUT.dtype`` and so on), so a headless grasp equals the graph's
tick for tick.
"""
from __future__ import annotations

from collections import namedtuple
import math

from gripper_ros.core.control.stages import LockstepAnswerer, Reference, stage_answer, TickAnswer
from gripper_ros.core.physics.plant import (GraspObject, GripperPlant, plant_begin_hold,
                                            plant_cancel_fault, plant_fault_scheduled,
                                            plant_read_tick, plant_scenario_in_progress,
                                            plant_schedule_fault, plant_step)
from gripper_ros.core.records import RecordField
from gripper_ros.core.supervision.supervisor import (Decision, GraspSupervisor, NO_NS,
                                                     supervisor_decide)
from gripper_ros.wire import (COMMAND_LAYOUT, Controller, FaultKind, Outcome, Phase,
                              REFERENCE_LAYOUT, TICK_LAYOUT)
import numba
import numpy as np

Tick = namedtuple('Tick', TICK_LAYOUT.fields)
"""One PlantTick's fields, in message order."""
Command = namedtuple('Command', COMMAND_LAYOUT.fields)
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
     ('hold_begun_for', 'i8')],        # the grasp whose hold clock was started (-1: none)
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


@_kernel
def side_needs_time(plant_k, cmd) -> bool:
    """Tell whether simulated time must go on after ``cmd`` in fast mode.

    It must for a request in progress, or a hold scenario (a lift) still to be played out.
    """
    return cmd[0].running != 0 or plant_scenario_in_progress(plant_k)


@_kernel
def side_step(side, plant_k, cmd, tick) -> None:
    """Hold the command's voltage for its ``hold_s``; ``tick`` becomes the next tick."""
    c = cmd[0]
    s = side[0]
    s.applied_source = c.source
    plant_step(plant_k, c.voltage_v, round(c.hold_s * 1e9))
    plant_read_tick(plant_k, tick, s.revision, c.source)


@_kernel
def side_step_unpowered(side, plant_k, duration_ns, tick) -> None:
    """No command came: the motor is held at 0 V (a driver's command timeout)."""
    s = side[0]
    s.applied_source = Controller.NONE
    plant_step(plant_k, 0.0, duration_ns)
    plant_read_tick(plant_k, tick, s.revision, Controller.NONE)


@_kernel
def side_read_tick(side, plant_k, tick) -> None:
    """``tick``: the plant's measurement now."""
    s = side[0]
    plant_read_tick(plant_k, tick, s.revision, s.applied_source)


class PlantSide:
    """The plant's share of a tick: the measurement, the command's echo, the step.

    ``state`` is its bookkeeping record; the tick, command and reference records it fills are
    ``tick_record`` and ``command_record``.
    """

    def __init__(self, plant: GripperPlant):
        self.plant = plant
        self.state = np.zeros(1, PLANT_SIDE_STATE)
        self._s = self.state[0]
        self._s['applied_source'] = Controller.NONE
        for name in ('fault_grasp', 'hold_begun_for'):
            self._s[name] = NO_NS
        self.tick_record = new_record(TICK_LAYOUT)
        self.command_record = new_record(COMMAND_LAYOUT)

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
        s['fault_grasp'] = NO_NS
        s['hold_begun_for'] = NO_NS
        s['applied_source'] = Controller.NONE
        s['revision'] += 1

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

    def decide_record(self, tick: np.ndarray) -> bool:
        """Decide the tick record ``tick``; True when ``reference_record`` names a stage."""
        return bool(supervisor_decide(self.supervisor.kernel, tick, self.reference_record))

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
