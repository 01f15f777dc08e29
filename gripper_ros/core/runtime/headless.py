"""Grasps without ROS: the node graph's lockstep loop, compiled, tick for tick the graph's.

The same plant, supervisor and stage code the nodes call
(:mod:`gripper_ros.core.runtime.lockstep`), wired exactly as the graph wires them in ``time_mode``
fast: the position stage holds the open fingers, the grasp request starts at the next tick, each
tick the supervisor decides, the stage it names answers and the plant holds that answer; simulated
time stops when the request no longer needs it (answered, and no lift left to play out), or
``hold_s`` after the answer. A grasp here gives the same series as the graph, tick for tick, in a
fraction of the time, so sweeps over many objects are practical.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import functools
import math
import sys
import time
from typing import Callable, Sequence

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.load_grip import GRIP_DTYPE, plan_announce
from gripper_ros.core.control.stages import (ForceStageController, PositionStageController,
                                             Reference, stage_answer, STAGE_KERNEL)
from gripper_ros.core.physics.hold import ANNOUNCE_ROWS, hold_load_n, hold_plan
from gripper_ros.core.physics.plant import (_object_state, check_fault, GraspObject, HoldState,
                                            Lift, OBJECT_STATE_DTYPE, PLANT_DTYPE,
                                            plant_hold_record)
from gripper_ros.core.records import (as_record, compile_face_kernels, copy_fields, face_kernel,
                                      FLOATS_2D)
from gripper_ros.core.runtime.engine import map_cases
from gripper_ros.core.runtime.lockstep import (Command, PLANT_SIDE_STATE, PlantSide, side_accept,
                                               side_needs_time, side_step, StageSide,
                                               SupervisorSide, Tick)
from gripper_ros.core.series import (GraspSeries, OBJECT_ROW, rows, STATUS_ROW,
                                     TICK_STATE_ROW)
from gripper_ros.core.supervision.machine import (NO_NS, status_changed, status_note,
                                                  supervisor_decide, SUPERVISOR_DTYPE)
from gripper_ros.core.supervision.requests import (GraspRequest, MoveRequest, RequestError,
                                                   validate_move, validate_request)
from gripper_ros.core.supervision.supervisor import GraspSupervisor, load_law
from gripper_ros.wire import (COMMAND_LAYOUT, Controller, DEFAULT_APPROACH_FORCE_MARGIN,
                              DEFAULT_FORCE_CONTROLLER, DEFAULT_POSITION_CONTROLLER, FaultKind,
                              Outcome, Phase, REFERENCE_LAYOUT, SwitchCriterion, TICK_LAYOUT)
import numba
import numpy as np


TRACE_STATE = np.dtype(
    [('state_period_ns', 'i8'),        # 0: no trace is kept
     ('references', 'i8'), ('statuses', 'i8'), ('objects', 'i8'),    # rows kept so far
     ('next_object_ns', 'i8'), ('hold_state', 'i4')], align=True)
"""The compiled loop's trace bookkeeping (beside its row buffers)."""


@dataclass
class HeadlessGrasp:
    """A headless grasp's answer and result, and its time series."""

    outcome: Outcome                    # the final outcome (after the hold, when it went on)
    message: str
    switch_criterion: SwitchCriterion
    position_setpoint_m: float
    force_setpoint_n: float
    start_ns: int
    switch_ns: int | None
    contact_ns: int | None
    end_ns: int                         # the last tick simulated
    answer: Outcome = Outcome.UNKNOWN   # what the grasp service answered
    answer_ns: int | None = None        # when
    final_ns: int | None = None         # when the final outcome was reached
    slip_m: float = 0.0                 # ground truth: how far the object slid on the pads
    lost_ns: int | None = None          # ground truth: when it left the pads
    overload_ns: int | None = None      # when the load-tracking grip answered OVERLOADED
    overload_need_n: float = math.nan   # ... the grip the load needed then
    overload_limit_n: float = math.nan  # ... the most 24 V holds
    series: GraspSeries | None = field(repr=False, default=None)
    """Every tick and its state; with ``trace_state_period_ns`` every message too."""

    @property
    def peak_contact_force_n(self) -> float:
        """Largest contact force, between samples included, over the grasp and the hold."""
        return float(np.max(self.series.ticks['peak_force_n']))

    @property
    def time_to_answer_s(self) -> float:
        """From the request to the grasp service's answer (inf without one)."""
        if self.answer_ns is None:
            return math.inf
        return (self.answer_ns - self.start_ns) * 1e-9

    @property
    def continued_hold(self) -> slice:
        """The samples after a HOLDING answer (empty without one or without ``hold_s``)."""
        if self.answer is not Outcome.HOLDING:
            return slice(0, 0)
        return slice(int(np.searchsorted(self.series.ticks['stamp_ns'], self.answer_ns,
                                         side='right')), None)

    def hold_force_range_n(self) -> tuple[float, float]:
        """Return (min, max) of the force over the continued hold; (nan, nan) without one.

        The max includes the peaks between samples.
        """
        held = self.series.ticks[self.continued_hold]
        if held.size == 0:
            return math.nan, math.nan
        return float(np.min(held['force_n'])), float(np.max(held['peak_force_n']))

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


LOOP_STATE = np.dtype([('woken', 'b1'), ('named', 'b1'), ('done', 'b1'),
                       ('hold_ns', 'i8'), ('hold_until_ns', 'i8'), ('rows', 'i8'),
                       ('announce', 'b1'),      # the arm announces its lift to the supervisor
                       ('announced', 'b1')], align=True)
"""The compiled loop's own state: resumable when its row buffers fill up."""
_TRACE_BUFFERS = (('references', REFERENCE_LAYOUT.dtype), ('commands', COMMAND_LAYOUT.dtype),
                  ('statuses', STATUS_ROW), ('objects', OBJECT_ROW))
"""The compiled loop's trace buffers, in its arguments' order (a grasp's every message)."""
FIRST_ROWS = 4096
"""Rows a grasp's series buffers start with (they double when full)."""


@face_kernel(TICK_LAYOUT.dtype, TICK_STATE_ROW, int, TICK_LAYOUT.dtype, int,
             REFERENCE_LAYOUT.dtype, PLANT_DTYPE, GRIP_DTYPE)
@numba.njit(cache=True)
def _keep_row(ticks, tick_states, n, tick, phase, ref, plant_k, law) -> None:
    """Keep tick ``n`` and its state (:data:`TICK_STATE_ROW`)."""
    ticks[n] = tick[0]
    h = plant_hold_record(plant_k)
    s = tick_states[n]
    s.phase = phase
    s.force_setpoint_n = ref[0].force_setpoint_n
    s.approach_setpoint_m = ref[0].approach_setpoint_m
    s.load_n = hold_load_n(h) if h.has_hold else 0.0
    s.slip_m = h.slip_m
    s.hold_state = h.state
    s.mu_est = law[0].mu_est


@face_kernel(TRACE_STATE, TICK_LAYOUT.dtype, SUPERVISOR_DTYPE, PLANT_DTYPE, STATUS_ROW, OBJECT_ROW)
@numba.njit(cache=True)
def _trace_tick(trace, tick, sup, plant_k, statuses, objects) -> None:
    """Keep the supervisor's state when it changed and the object's when due."""
    ts = trace[0]
    t = tick[0]
    sup = as_record(sup)
    m = ts.statuses
    if m == 0 or status_changed(sup, statuses[m - 1]):
        r = statuses[m]
        copy_fields(r, t, ('stamp_ns', 'position_m', 'force_n'))
        status_note(sup, r)
        copy_fields(r, sup.decided, ('position_setpoint_m', 'force_setpoint_n',
                                     'approach_setpoint_m'))
        r.seed_voltage_v = sup.machine.seed_voltage_v
        ts.statuses = m + 1
    h = plant_hold_record(plant_k)
    hold_state = h.state if h.has_hold else HoldState.NONE
    j = ts.objects
    if j == 0 or t.stamp_ns >= ts.next_object_ns or hold_state != ts.hold_state:
        now = np.zeros(1, OBJECT_STATE_DTYPE)     # at the state rate, not every tick
        _object_state(plant_k, now)
        s = now[0]
        o = objects[j]
        o.stamp_ns = t.stamp_ns
        copy_fields(o, s, ('state', 'slip_m', 'slip_speed_mps', 'load_n', 'capacity_n'))
        ts.hold_state = s.state
        ts.next_object_ns = (t.stamp_ns // ts.state_period_ns + 1) * ts.state_period_ns
        ts.objects = j + 1


@numba.njit(cache=True)
def _trace_answer(trace, ref, cmd, references, commands) -> None:
    """Keep the tick's reference and the command that answered it."""
    ts = trace[0]
    references[ts.references] = ref[0]
    commands[ts.references] = cmd[0]
    ts.references += 1


@face_kernel(LOOP_STATE, PLANT_DTYPE, SUPERVISOR_DTYPE)
@numba.njit(cache=True)
def announce_lift(state, plant_k, sup) -> None:
    """Once the lift's clock has started, hand its plan to the supervisor, as the arm would.

    The graph's plant node publishes the same breakpoints on ``arm/planned_acceleration`` then;
    the supervisor uses each by its stamp, so the plan acts the same whenever it arrives before
    its first breakpoint's lead.
    """
    state = as_record(state)
    if not state.announce or state.announced:
        return
    h = plant_hold_record(plant_k)
    if h.hold_ns == -1:
        return
    state.announced = True
    times = np.zeros(ANNOUNCE_ROWS, np.int64)
    accels = np.zeros(ANNOUNCE_ROWS)
    n = hold_plan(h, times, accels)
    sup = as_record(sup)
    for i in range(n):
        plan_announce(sup.law[0], sup.plan, times[i], accels[i])


@face_kernel(LOOP_STATE, PLANT_SIDE_STATE, PLANT_DTYPE, SUPERVISOR_DTYPE, FLOATS_2D, STAGE_KERNEL,
             STAGE_KERNEL, TICK_LAYOUT.dtype, REFERENCE_LAYOUT.dtype, COMMAND_LAYOUT.dtype,
             TICK_LAYOUT.dtype, TICK_STATE_ROW, TRACE_STATE, REFERENCE_LAYOUT.dtype,
             COMMAND_LAYOUT.dtype, STATUS_ROW, OBJECT_ROW)
@numba.njit(cache=True)
def run_lockstep(loop, side, plant_k, supervisor, law_buffers, position_k, force_k, tick, ref,
                 cmd, ticks, tick_states, trace, trace_references, trace_commands,
                 trace_statuses, trace_objects) -> bool:
    """Run the graph's loop in fast mode from ``tick`` until simulated time would pause.

    Each tick: keep its row, let the named stage answer, the plant react and hold the command,
    the supervisor decide the next tick. With a state period in ``trace`` it also keeps every
    message (``trace_*``, at most one row a tick each, in buffers as long as ``ticks``).
    Returns False when the row buffers are full (call again with larger ones: everything
    resumes from the records).
    """
    state = loop[0]
    sup = supervisor[0]
    s = sup.machine
    tracing = trace[0].state_period_ns > 0
    n = state.rows
    while True:
        if n == ticks.shape[0]:
            state.rows = n
            return False
        _keep_row(ticks, tick_states, n, tick, s.phase, ref, plant_k, sup.law)
        if tracing:
            _trace_tick(trace, tick, sup, plant_k, trace_statuses, trace_objects)
        n += 1
        if state.hold_until_ns == NO_NS and s.answer_ns != NO_NS:
            state.hold_until_ns = s.answer_ns + state.hold_ns
        if not state.named:
            break                                   # a FAULT: nothing drives the motor
        if ref[0].controller == Controller.POSITION:
            stage_answer(position_k, ref, cmd)
        else:
            stage_answer(force_k, ref, cmd)
        if tracing:
            _trace_answer(trace, ref, cmd, trace_references, trace_commands)
        side_accept(side, plant_k, cmd)
        announce_lift(state, plant_k, sup)
        needed = side_needs_time(plant_k, cmd) or state.woken or (
            state.hold_until_ns != NO_NS and tick[0].stamp_ns < state.hold_until_ns)
        if not needed:
            break                                   # fast mode: simulated time pauses
        state.woken = False
        side_step(side, plant_k, cmd, tick)
        state.named = supervisor_decide(sup, law_buffers, tick, ref)
    state.rows = n
    state.done = True
    return True


_SPARE_ROWS: list = []
"""Row buffers (ticks, tick states) of a summarized batch case that nothing refers to any more:
the process's next grasp writes its rows into them instead of allocating and growing its own."""


class _Loop:
    """One headless grasp's plant, supervisor and stages, wired as the graph wires them."""

    def __init__(self, plant_side, supervisor, position_stage, force_stage,
                 rows: int = FIRST_ROWS):
        self._first_rows = rows
        self.plant_side = plant_side
        self.supervisor = supervisor
        self.sup_side = SupervisorSide(supervisor)
        self.stages = {Controller.POSITION: StageSide(position_stage),
                       Controller.FORCE: StageSide(force_stage)}
        self.tick = plant_side.tick_record
        self.ref = self.sup_side.reference_record
        self.cmd = plant_side.command_record
        self.state = np.zeros(1, LOOP_STATE)
        self.state[0]['hold_until_ns'] = NO_NS
        self.ticks, self.tick_states = _SPARE_ROWS.pop() if _SPARE_ROWS else (
            np.zeros(0, TICK_LAYOUT.dtype), np.zeros(0, TICK_STATE_ROW))
        self.trace = np.zeros(1, TRACE_STATE)
        self.trace_buffers = {name: np.zeros(0, dtype) for name, dtype in _TRACE_BUFFERS}

    def keep_trace(self, state_period_ns: int) -> None:
        """Keep every message from now on, the object's on a grid of ``state_period_ns``.

        The trace buffers take the tick buffers' length (which may be a spare's, not 0): a
        tick keeps at most one row of each, so a room check on the ticks alone covers them.
        """
        self.trace[0]['state_period_ns'] = state_period_ns
        for rows_buffer in self.trace_buffers.values():
            rows_buffer.resize(self.ticks.shape[0], refcheck=False)

    @property
    def tracing(self) -> bool:
        return bool(self.trace[0]['state_period_ns'] > 0)

    def decide(self) -> bool:
        named = self.sup_side.decide_record(self.tick)
        self.state[0]['named'] = named
        return named

    def _grow(self) -> None:
        """Give the row buffers room: the first rows asked for, then twice as many.

        In place (``ndarray.resize``, a realloc: a large buffer's pages are moved, its rows not
        copied); no view of a buffer exists before :meth:`series`. Every row below the count
        kept is written before it is read.
        """
        size = max(self._first_rows, 2 * self.ticks.shape[0])
        buffers = [self.ticks, self.tick_states]
        if self.tracing:
            buffers += self.trace_buffers.values()
        for rows_buffer in buffers:
            rows_buffer.resize(size, refcheck=False)

    def keep_row(self) -> None:
        """Keep the present tick's row (the Python-driven loop)."""
        if self.state[0]['rows'] == self.ticks.shape[0]:
            self._grow()
        n = int(self.state[0]['rows'])
        _keep_row(self.ticks, self.tick_states, n, self.tick,
                  int(self.supervisor.decision.phase), self.ref, self.plant_side.plant.kernel,
                  self.supervisor.law)
        if self.tracing:
            b = self.trace_buffers
            _trace_tick(self.trace, self.tick, self.supervisor.record,
                        self.plant_side.plant.kernel, b['statuses'], b['objects'])
        self.state[0]['rows'] = n + 1

    def run(self) -> None:
        """Run compiled until simulated time pauses."""
        ps = self.plant_side
        while not run_lockstep(self.state, ps.state, ps.plant.kernel, *self.supervisor.kernel,
                               self.stages[Controller.POSITION].stage.kernel,
                               self.stages[Controller.FORCE].stage.kernel, self.tick, self.ref,
                               self.cmd, self.ticks, self.tick_states,
                               self.trace, *self.trace_buffers.values()):
            self._grow()

    def series(self) -> GraspSeries:
        """Return the ticks and their states kept, and the messages when traced.

        The buffers' rows themselves, not copies: the loop is done with them.
        """
        n = int(self.state[0]['rows'])
        messages = {}
        if self.tracing:
            ts = self.trace[0]
            count = {'references': int(ts['references']), 'commands': int(ts['references']),
                     'statuses': int(ts['statuses']), 'objects': int(ts['objects'])}
            messages = {name: rows[:count[name]] for name, rows in self.trace_buffers.items()}
        stamps = self.ticks['stamp_ns'][:n]
        return GraspSeries(self.ticks[:n], tick_states=self.tick_states[:n],
                           start_ns=int(stamps[0]) if n else 0,
                           end_ns=int(stamps[-1]) if n else 0, **messages)

    def run_traced(self, trace: Callable) -> None:
        """Run tick by tick from Python, calling ``trace`` every tick: the same kernels."""
        state = self.state[0]
        while True:
            self.keep_row()
            sup = self.supervisor
            if state['hold_until_ns'] == NO_NS and sup.answer_ns is not None:
                state['hold_until_ns'] = sup.answer_ns + state['hold_ns']
            tick = Tick._make(self.tick[0].item())
            if not state['named']:
                trace(self.plant_side.plant, tick, sup.decision, None, None)
                break
            ref = Reference._make(self.ref[0].item())
            side = self.stages[Controller(ref.controller)]
            side.answer_record(self.ref)
            self.cmd[0] = side.command_record[0]
            trace(self.plant_side.plant, tick, sup.decision, ref,
                  Command._make(self.cmd[0].item()))
            self.plant_side.accept(self.cmd)
            announce_lift(self.state, self.plant_side.plant.kernel, sup.record)
            needed = self.plant_side.needs_time(self.cmd) or state['woken'] or (
                state['hold_until_ns'] != NO_NS and tick.stamp_ns < state['hold_until_ns'])
            if not needed:
                break
            state['woken'] = False
            self.plant_side.step(self.cmd)
            self.decide()


def simulate_grasp(config: GripperConfig, width_m: float, mass_kg: float, *,
                   object_width_m: float | None = None, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, friction_coefficient: float = 0.0,
                   acceleration_mps2: float = 0.0, timeout_s: float = 0.0,
                   width_tolerance_m: float = 0.0,
                   position_controller=DEFAULT_POSITION_CONTROLLER,
                   force_controller=DEFAULT_FORCE_CONTROLLER,
                   approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN,
                   object_mass_kg: float = 0.0, static_friction: float | None = None,
                   kinetic_friction: float | None = None, pad_length_m: float = 0.0,
                   lift: Lift | None = None, hold_s: float = 0.0,
                   start_ns: int = 0,
                   fault: tuple[FaultKind | int, float, float] | None = None,
                   idle_unpowered_s: float = 0.0,
                   trace: Callable | None = None,
                   trace_state_period_ns: int = 0, announce: bool = False) -> HeadlessGrasp:
    """Grasp from fully open, as the graph grasps in fast mode.

    ``object_width_m`` (default ``width_m``; 0 = nothing) is the real
    object, ``width_m`` the expected one. The object's own mass (0 = the grasp's) and pad
    friction (None = the configured one, ``SetObject.default_friction``; 0 = frictionless) hold
    it once ``lift`` lifts it; time runs until the lift has played out, and ``hold_s`` at least
    that long after the answer. Raises RequestError for a request the graph refuses.

    ``fault`` = (kind, seconds after the grasp's start, time constant; 0 = the default) is
    scheduled as ``sim/set_object`` schedules it (ValueError when refused).
    ``idle_unpowered_s`` > 0: the tick before the grasp goes unanswered and the motor is held at
    0 V this long, as in the graph after a FAULT (its supervisor names no stage until the next
    request, and the plant steps unpowered for one state period). ``trace``, when
    given, is called every tick with (plant, tick, decision, reference, command) before the
    plant reacts to the command (reference and command None on the tick no stage is named);
    the decision is the supervisor's reused object, to be read at once. Without ``trace`` the
    loop runs compiled; with it, tick by tick from Python over the same compiled functions.
    ``trace_state_period_ns`` > 0 keeps, in the compiled loop, what ``trace`` sees as a bag
    holds it (in the result's :class:`GraspSeries`; the object state on that period's grid); it
    cannot be combined with ``trace``. ``announce``: the arm announces ``lift`` to the
    supervisor as the hold begins (its plan's breakpoints, ``arm/planned_acceleration`` in the
    graph), so that the load-tracking grip rises with the load the motion brings.
    """
    if trace is not None and trace_state_period_ns > 0:
        raise ValueError('trace and trace_state_period_ns are exclusive')
    targets = validate_request(GraspRequest(width_m, mass_kg, friction_coefficient,
                                            acceleration_mps2, timeout_s, width_tolerance_m),
                               config.plant, config.supervisor, config.load_grip)
    plant = make_plant(config)
    plant.t_ns = start_ns
    plant_side = PlantSide(plant)
    plant_side.grasp_mass_kg = mass_kg
    obj = GraspObject(width_m if object_width_m is None else object_width_m, stiffness_n_per_m,
                      damping_n_s_per_m, object_mass_kg,
                      config.contact.static_friction if static_friction is None
                      else static_friction,
                      config.contact.kinetic_friction if kinetic_friction is None
                      else kinetic_friction, pad_length_m)
    if fault is not None:
        kind, tau = check_fault(fault[0], fault[1], fault[2], obj.rigid)
        fault = (kind, fault[1], tau)
    plant_side.set_object(obj, fault=fault, lift=lift)
    supervisor = GraspSupervisor(config.plant, config.supervisor, load_law(config))
    loop = _Loop(plant_side, supervisor,
                 PositionStageController(config, position_controller),
                 ForceStageController(config, force_controller, approach_force_margin),
                 FIRST_ROWS + round(hold_s / config.force.sample_time_s))
    state = loop.state[0]
    state['hold_ns'] = round(hold_s * 1e9)
    state['announce'] = announce
    if trace_state_period_ns > 0:
        loop.keep_trace(trace_state_period_ns)
    plant_side.tick()
    loop.decide()                                   # the position stage holds the open fingers
    supervisor.request_grasp(targets, mass_kg, after_ns=int(loop.tick[0]['stamp_ns']))
    state['woken'] = True                           # the request wakes the paused simulation
    if idle_unpowered_s > 0.0:
        loop.keep_row()
        if trace is not None:
            trace(plant, Tick._make(loop.tick[0].item()), supervisor.decision, None, None)
        plant_side.step_unpowered(idle_unpowered_s)
        loop.decide()
        state['woken'] = False
    if trace is None:
        loop.run()
    else:
        loop.run_traced(trace)
    s = supervisor
    held = plant.object_state
    return HeadlessGrasp(
        s.outcome, s.message, s.switch_criterion, targets.position_setpoint_m,
        targets.force_setpoint_n, s.start_ns, s.switch_ns, s.contact_ns,
        int(loop.tick[0]['stamp_ns']), s.answer, s.answer_ns, s.end_ns,
        held.slip_m, held.lost_ns, s.overload_ns, s.overload_need_n, config.plant.max_force_n,
        loop.series())


def _grasp_case(config: GripperConfig, summarize: Callable | None, case: dict):
    """One case of :func:`simulate_grasps`: the grasp, or the RequestError that refused it."""
    case = dict(case)
    config = case.pop('config', config)
    try:
        result = simulate_grasp(config, **case)
    except RequestError as exc:
        result = exc
    if summarize is None:
        return result
    summary = summarize(case, result)
    if isinstance(result, HeadlessGrasp):
        ticks, states = result.series.ticks.base, result.series.tick_states.base
        del result
        # no view left (the summary kept none): the buffers are free for the next case
        if ticks is not None and states is not None and \
                sys.getrefcount(ticks) == sys.getrefcount(states) == 2:
            _SPARE_ROWS[:] = [(ticks, states)]
    return summary


def simulate_grasps(config: GripperConfig, cases: Sequence[dict], jobs: int | None = None,
                    summarize: Callable | None = None, *, scheduler=None,
                    progress: Callable[[int], None] | None = None) -> list:
    """Run many grasps (:func:`simulate_grasp` keywords, one dict a case) through the engine.

    Each result is the :class:`HeadlessGrasp`, or the :class:`RequestError` that refused the
    request; a case may carry its own ``config``. ``summarize(case, result)``, when given, runs
    in the worker and its (small, picklable) return value comes back instead: a sweep of
    long grasps then sends no series between processes. ``jobs``, ``scheduler`` and
    ``progress`` are :func:`gripper_ros.core.runtime.engine.map_cases`'s. The results are in the
    cases' order and the same bytes whatever the engine and the worker count.
    """
    return map_cases(functools.partial(_grasp_case, config, summarize), cases, jobs,
                     scheduler=scheduler, progress=progress)


@dataclass
class MoveAnswer:
    """What the move service answered one request (srv/Move's result)."""

    outcome: Outcome
    message: str
    start_ns: int
    answer_ns: int
    position_m: float
    effort_n: float

    @property
    def reached_goal(self) -> bool:
        return self.outcome is Outcome.MOVED

    @property
    def stalled(self) -> bool:
        return self.outcome is Outcome.STALLED


@dataclass
class HeadlessMoves:
    """Each move's answer and the time series of the whole sequence."""

    answers: list
    series: GraspSeries | None = field(repr=False, default=None)
    """Every tick and the supervisor's phase and setpoints on it (``tick_states``; the held
    object's truth and the law's estimate are not kept: NaN)."""


def simulate_moves(config: GripperConfig, moves, *, object_width_m: float = 0.0,
                   stiffness_n_per_m: float = 0.0, damping_n_s_per_m: float = 0.0,
                   position_controller=DEFAULT_POSITION_CONTROLLER, hold_s: float = 0.0,
                   start_ns: int = 0) -> HeadlessMoves:
    """Run moves (:class:`MoveRequest`) and grasps (:class:`GraspRequest`) one after another.

    From fully open. Each is requested when the one before has been answered and simulated time
    has paused (as a client of the graph in fast mode does); ``object_width_m`` 0 = nothing
    between the fingers. Time runs on ``hold_s`` after the last answer (the stage named last
    keeps its command). Raises RequestError for a request the graph refuses (before anything
    runs).
    """
    targets = [validate_request(m, config.plant, config.supervisor, config.load_grip)
               if isinstance(m, GraspRequest) else
               validate_move(m, config.plant, config.supervisor) for m in moves]
    masses = [m.mass_kg if isinstance(m, GraspRequest) else None for m in moves]
    plant = make_plant(config)
    plant.t_ns = start_ns
    plant_side = PlantSide(plant)
    plant_side.set_object(GraspObject(object_width_m, stiffness_n_per_m, damping_n_s_per_m))
    supervisor = GraspSupervisor(config.plant, config.supervisor, load_law(config))
    decide = SupervisorSide(supervisor).decide
    stages = {Controller.POSITION: StageSide(PositionStageController(config,
                                                                     position_controller))}
    if any(m is not None for m in masses):
        stages[Controller.FORCE] = StageSide(ForceStageController(
            config, DEFAULT_FORCE_CONTROLLER, DEFAULT_APPROACH_FORCE_MARGIN))
    tick = plant_side.tick()
    decision, ref = decide(tick)                    # the position stage holds the open fingers
    pending = list(zip(targets, masses))
    answers, ticks, states = [], [], []
    while True:
        ticks.append(tuple(tick))
        states.append((int(decision.phase), decision.force_setpoint_n,
                       decision.approach_setpoint_m, math.nan, math.nan, 0, math.nan))
        if decision.answer is not None:
            answers.append(MoveAnswer(decision.answer, decision.message, supervisor.start_ns,
                                      tick.stamp_ns, tick.position_m, tick.force_n))
        if ref is None:
            break                                   # a FAULT: nothing drives the motor
        cmd = stages[Controller(ref.controller)].answer(ref)
        plant_side.accept(cmd)
        if not plant_side.needs_time(cmd):
            if not pending:
                if answers and tick.stamp_ns < answers[-1].answer_ns + round(hold_s * 1e9):
                    tick = plant_side.step(cmd)
                    decision, ref = decide(tick)
                    continue
                break                               # fast mode: simulated time pauses
            # the next request wakes the paused simulation; it starts at the next tick
            target, mass = pending.pop(0)
            if mass is None:
                supervisor.request_move(target, after_ns=tick.stamp_ns)
            else:
                plant_side.grasp_mass_kg = mass
                supervisor.request_grasp(target, mass, after_ns=tick.stamp_ns)
        tick = plant_side.step(cmd)
        decision, ref = decide(tick)
    ticks = rows(TICK_LAYOUT.dtype, ticks)
    return HeadlessMoves(answers, GraspSeries(ticks, tick_states=rows(TICK_STATE_ROW, states),
                                              start_ns=int(ticks['stamp_ns'][0]),
                                              end_ns=int(ticks['stamp_ns'][-1])))


def warm_up_worker() -> None:
    """Load the kernels a batch of grasps uses (a short grasp; errors are the batch's to see)."""
    from gripper_ros.core.config import load_config
    try:
        simulate_grasp(load_config(), 0.1, 0.5, timeout_s=0.05)
    except Exception:           # noqa: B902 - a bad config file is reported by the batch itself
        pass


def warm_up() -> float:
    """Compile (or load from numba's cache) every kernel the package declares.

    Set-up calls this once after a change, so that no program pays numba's compilation;
    returns the seconds it took.
    """
    start = time.perf_counter()
    compile_face_kernels()
    return time.perf_counter() - start


__all__ = ['GraspSeries', 'HeadlessGrasp', 'HeadlessMoves', 'map_cases', 'MoveAnswer',
           'MoveRequest', 'Phase', 'simulate_grasp', 'simulate_grasps', 'simulate_moves',
           'warm_up']
