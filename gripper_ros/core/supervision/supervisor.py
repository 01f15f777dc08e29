"""The supervisor's Python face: requests in, the state machine's decision and messages out.

:class:`GraspSupervisor` holds the compiled machine's record (:mod:`.machine`): it checks a
request, hands it to the machine as a :data:`~.requests.TARGETS_DTYPE` record and reads the
record back (phase, outcome, the decision, the message in words). Every change of the record is
a kernel's (``supervisor_*``): the face reads and asks. The supervisor node and the compiled
headless loop step the same record tick by tick.

A request is accepted at once and starts at the next tick (:meth:`GraspSupervisor.request_grasp`,
:meth:`~GraspSupervisor.request_release`, :meth:`~GraspSupervisor.request_move`); requests go one
at a time. A position setpoint (:meth:`~GraspSupervisor.request_servo`, ``joint_commands``) is in
force at once: while the previous setpoint's move runs, its goal and limits change in place
(same request, the position stage not restarted); otherwise what runs ends STOPPED and the
setpoint's move starts at the next tick. A stream that keeps changing moves its reference on
between setpoints with its velocity and acceleration, given or estimated
(:mod:`gripper_ros.core.control.servo_feedforward`), which the position stage also turns into
feed-forward. A grasp, release or move request ends a running setpoint's move (STOPPED).
"""
from __future__ import annotations

import math

from gripper_ros.core.config import GripperConfig, PlantParams, shipped_config, SupervisorParams
from gripper_ros.core.control.load_grip import law_for, make_law, plan_announce
from gripper_ros.core.control.servo_feedforward import stream_bounds
from gripper_ros.core.records import copy_fields, RecordField
from gripper_ros.core.supervision.machine import (Event, NO_NS, PARAMS_DTYPE, PARAMS_FIELDS,
                                                  State, STREAM_BEGIN, STREAM_CLEAR,
                                                  STREAM_KEEP, supervisor_configure,
                                                  supervisor_continue_ids, SUPERVISOR_DTYPE,
                                                  supervisor_fault, supervisor_reset,
                                                  supervisor_retarget, supervisor_servo_sample,
                                                  supervisor_step, supervisor_stop,
                                                  supervisor_wait)
from gripper_ros.core.supervision.messages import format_message
from gripper_ros.core.supervision.requests import (GraspTargets, MoveTargets, RequestError,
                                                   targets_of, targets_record)
from gripper_ros.wire import Controller, Outcome, PendingRequest, Phase, SwitchCriterion
import numpy as np


class RequestKind:
    """The kinds of request the supervisor runs (also the words its log and refusals use)."""

    GRASP = 'grasp'
    RELEASE = 'release'
    MOVE = 'move'


KIND_CODES = {RequestKind.GRASP: PendingRequest.GRASP, RequestKind.RELEASE: PendingRequest.RELEASE,
              RequestKind.MOVE: PendingRequest.MOVE}
"""Each request kind's code in the record (``current.kind``, ``waiting.kind``; 0 = none)."""
KIND_NAMES = {int(code): kind for kind, code in KIND_CODES.items()}


def load_law(config: GripperConfig) -> tuple:
    """Return the load-tracking grip of ``config`` for a supervisor (``law_for``'s arrays)."""
    return law_for(config)


def _ns_or_none(value) -> int | None:
    return None if value == NO_NS else int(value)


def _machine(read, field: str = '', doc: str | None = None) -> RecordField:
    """Return a read-only field of the machine's record (the face's ``_s``)."""
    return RecordField(read, False, field=field, at='_s', doc=doc)


def _decided(read, field: str = '', doc: str | None = None) -> RecordField:
    """Return a read-only field of the last tick's decided setpoints (the face's ``_d``)."""
    return RecordField(read, False, field=field, at='_d', doc=doc)


class _MachineView:
    """What a supervisor and its decision both read of the machine's record ``_s``."""

    __slots__ = ()

    state = _machine(State, doc='Where the machine stands (:class:`~.machine.State`).')
    phase = _machine(Phase)
    active = _machine(Controller)
    switch_criterion = _machine(SwitchCriterion)
    outcome = _machine(Outcome)
    grasp_id = _machine(int)
    stage_id = _machine(int)
    running = _machine(bool, doc='A request is in progress (it needs simulated time until '
                                 'answered).')


class Decision(_MachineView):
    """The supervisor's verdict for the last tick: a view of its record, current at any time.

    ``answer`` is the outcome this tick produced for the request (the grasp service answers
    now, the outcome is latched), or None.
    """

    __slots__ = ('_owner', '_s', '_d')

    def __init__(self, owner: GraspSupervisor):
        self._owner = owner
        self._s = owner._s
        self._d = owner._d

    t_ns = _machine(int)
    contact = _machine(bool)
    position_setpoint_m = _decided(float)
    approach_setpoint_m = _decided(float)
    force_setpoint_n = _decided(float)
    speed_limit_mps = _decided(float, 'speed_mps')
    voltage_limit_v = _decided(float)
    approach_velocity_mps = property(
        lambda self: float(self._owner.record[0]['servo']['velocity_mps']),
        doc="The approach setpoint's velocity (a setpoint stream's; 0 while it stands).")
    approach_acceleration_mps2 = property(
        lambda self: float(self._owner.record[0]['servo']['acceleration_mps2']),
        doc='... and its acceleration.')
    message = property(lambda self: self._owner.message)
    answer = _machine(lambda answer: None if answer == Outcome.UNKNOWN else Outcome(answer),
                      'tick_answer')

    @property
    def finished(self) -> bool:
        """The request has been answered (it may go on holding, phase HOLDING)."""
        return self.outcome is not Outcome.UNKNOWN


class GraspSupervisor(_MachineView):
    """One request at a time; :meth:`step` once per plant tick with that tick's measurements.

    A controller always drives the motor, except after a FAULT: with no request the position
    stage holds the finger where it came to rest (phase IDLE, or DONE/FAILED with the last
    outcome); a grasp runs POSITION -> FORCE -> HOLDING and, once answered, goes on holding
    (phase HOLDING, outcome HOLDING, force stage active) until a release, a stop, the next
    grasp or the loss of the object; a move runs MOVING and then keeps its last command.
    ``running`` says whether the request still needs simulated time; ``stage_id`` grows
    whenever a controller is (re)assigned, so that it restarts from the measured state.

    ``kernel`` is what the compiled functions take: the record (a 1-element
    :data:`~.machine.SUPERVISOR_DTYPE` array) and the load-tracking grip's history and residual
    sums in one float array (:func:`load_law`).

    A grasp of mass 0 (unknown) needs ``law``; without it such a request is refused.
    """

    def __init__(self, plant: PlantParams, params: SupervisorParams, law: tuple | None = None):
        self.plant = plant
        self.tracks_load = law is not None
        if law is None:                          # inert arrays of the kernel's types
            law = make_law(shipped_config().load_grip, plant.max_force_n, 0.0, 1.0, 0.0, 0.0)
        record, history, sums = law
        buffers = np.zeros((history.shape[0] + sums.shape[0],
                            max(history.shape[1], sums.shape[1])))
        self.record = np.zeros(1, SUPERVISOR_DTYPE)
        """The supervisor's record, a 1-element array: what the compiled loop reads and writes."""
        self.kernel = (self.record, buffers)
        self._s = self.record[0]['machine']      # views: what the kernels write shows here
        self._d = self.record[0]['decided']
        supervisor_reset(*self.kernel, float(plant.max_travel_m), record, *stream_bounds(plant))
        self.params = params
        self._preempted: Decision | None = None  # the end of one, by the last request
        self._text = ''                          # a message given by stop() or fault()
        self._message = (-1, '')                 # (message_seq, text) formatted last
        self._decision = Decision(self)

    # ------------------------------------------------------------------ parameters
    @property
    def params(self) -> SupervisorParams:
        """The thresholds; new ones take effect from the next tick."""
        return self._params

    @params.setter
    def params(self, params: SupervisorParams) -> None:
        self._params = params
        numbers = np.zeros(1, PARAMS_DTYPE)
        copy_fields(numbers[0], params, PARAMS_FIELDS)
        supervisor_configure(*self.kernel, numbers)

    # ------------------------------------------------------------------ state
    kind = property(lambda self: KIND_NAMES.get(int(self.record[0]['current']['kind'])),
                    doc="The current request's kind, None before any.")
    mass_kg = property(lambda self: float(self.record[0]['current']['mass_kg']),
                       doc="The current grasp request's object mass.")
    start_ns = _machine(int)
    switch_ns = _machine(_ns_or_none)
    contact_ns = _machine(_ns_or_none)
    settled_ns = _machine(_ns_or_none, doc='Force first settled (phase HOLDING from here).')
    end_ns = _machine(_ns_or_none, doc='When the request was answered or ended.')
    answer = _machine(Outcome, doc='What the current request was answered.')
    answer_ns = _machine(_ns_or_none, doc="... and when (the grasp service's answer).")
    overload_ns = _machine(_ns_or_none,
                           doc='When the load-tracking grip said the load is beyond 24 V.')
    force_setpoint_n = _machine(float, doc="The grasp's force setpoint now (the law's, "
                                           'tracking).')
    holding = _machine(bool, doc='A grasp was answered HOLDING (or OVERLOADED); the force '
                                 'stage holds.')
    pressing = _machine(bool, doc="A stalled move's last command is in force: the finger "
                                  'presses.')

    @property
    def law(self) -> np.ndarray:
        """The load-tracking grip's record now (``[0]``) and as each grasp starts it (``[1]``)."""
        return self.record[0]['law']

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
        """Return what the current request aims at (None before any)."""
        return targets_of(self.record[0]['current'])

    @property
    def releasing(self) -> bool:
        return self.state is State.RELEASE

    @property
    def pending(self) -> bool:
        return self.pending_request is not PendingRequest.NONE

    @property
    def pending_request(self) -> PendingRequest:
        """What request waits to start at the next tick (the status' ``pending_request``)."""
        return PendingRequest(int(self.record[0]['waiting']['kind']))

    @property
    def decision(self) -> Decision:
        """The decision of the last tick (the same object, always current)."""
        return self._decision

    @property
    def message(self) -> str:
        """The current request's outcome, in words with its numbers ('' while none)."""
        seq = int(self._s['message_seq'])
        if self._message[0] != seq:
            event = Event(int(self._s['message']))
            self._message = (seq, format_message(event.name if event else '',
                                                 self.record[0]['message'], self.plant,
                                                 self._text))
        return self._message[1]

    # ------------------------------------------------------------------ requests
    def _refuse_if_busy(self, kind: str) -> None:
        """Refuse a request while another runs or waits; a setpoint's move ends (preempted)."""
        if self.servo and (self.pending or self.running):
            self._preempted = self.stop(f'preempted by a {kind} request')
        elif self.pending:
            raise RequestError(f'a {KIND_NAMES[int(self.pending_request)]} request is already '
                               'waiting to start')
        elif self.running:
            raise RequestError(f'a {self.kind} is running (phase {self.phase.name})')

    def _wait(self, kind: str, targets, mass_kg: float, after_ns: int | None, stream: int):
        """Hand the machine a request that starts at the first tick after ``after_ns``."""
        record = targets_record(KIND_CODES[kind], targets, mass_kg,
                                NO_NS if after_ns is None else after_ns)
        supervisor_wait(*self.kernel, record, stream)
        return targets

    def take_preempted(self) -> Decision | None:
        """Return the decision that ended a setpoint's move for the last request, once."""
        ended, self._preempted = self._preempted, None
        return ended

    def continue_ids_after(self, last_id: int) -> None:
        """Make the next request ``last_id + 1`` (ids go on across restarts); before any."""
        if not supervisor_continue_ids(*self.kernel, int(last_id)):
            raise RuntimeError('request ids can only be set before the first request')

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
        return self._wait(RequestKind.GRASP, targets, float(mass_kg), after_ns, STREAM_CLEAR)

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
        return self._wait(RequestKind.RELEASE, targets, 0.0, after_ns, STREAM_CLEAR)

    def request_move(self, targets: MoveTargets, after_ns: int | None = None) -> MoveTargets:
        """Accept a move (:func:`validate_move`) and return its targets.

        It starts at the first tick later than ``after_ns`` (see :meth:`request_grasp`). A move
        may follow a hold; the hold ends when it starts.
        """
        self._refuse_if_busy(RequestKind.MOVE)
        return self._wait(RequestKind.MOVE, targets, 0.0, after_ns, STREAM_CLEAR)

    @property
    def servo(self) -> bool:
        """Tell whether the current or waiting request is a position setpoint's move."""
        return int(self.record[0]['servo']['request_id']) == \
            self.grasp_id + (1 if self.pending else 0)

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
        the stream), ``sample_ns`` the simulated instant it was sampled at (None: the newest
        tick's); the reference moves on with them
        (:mod:`~gripper_ros.core.control.servo_feedforward`). The same targets again while
        their move runs are no new request (:meth:`servo_repeated`).
        Returns the decision that ended a preempted request (to be answered), else None.
        """
        ended = None
        if self.servo and self.pending:          # not started yet: it starts with these
            self._wait(RequestKind.MOVE, targets, 0.0, after_ns, STREAM_KEEP)
        elif self.servo and self.running and self.phase is Phase.MOVING:
            if targets != self.targets:          # else the same again: it stands
                supervisor_retarget(*self.kernel, targets_record(PendingRequest.MOVE, targets))
        else:
            if self.pending or self.running:    # a hold or a press ends as the move starts
                ended = self.stop(message)
            self._wait(RequestKind.MOVE, targets, 0.0, after_ns, STREAM_BEGIN)
        self._sample(targets.position_setpoint_m, velocity_mps, acceleration_mps2, sample_ns)
        return ended

    def servo_repeated(self, sample_ns: int | None = None) -> None:
        """Note the setpoint in force sent again (a topic-based hardware's repeat).

        No request: the stream lives and stands there (velocity and acceleration 0).
        """
        if self.servo and self.running and self.phase is Phase.MOVING:
            self._sample(float(self.record[0]['current']['position_setpoint_m']), 0.0, 0.0,
                         sample_ns)

    def _sample(self, position_m: float, velocity_mps: float, acceleration_mps2: float,
                sample_ns: int | None) -> None:
        supervisor_servo_sample(*self.kernel, NO_NS if sample_ns is None else int(sample_ns),
                                float(position_m), float(velocity_mps), float(acceleration_mps2))

    def stop(self, message: str = 'stopped on request') -> Decision | None:
        """End the running request, the hold, a stalled move's press or a waiting request now.

        The outcome is STOPPED. Returns the ending decision (for the status and the answer),
        or None with nothing to stop. From the next tick the position stage holds the finger
        where it is, without a move's limits.
        """
        if not supervisor_stop(*self.kernel):
            return None
        self._text = message
        return self._decision

    def fault(self, message: str) -> Decision:
        """End the running request or the hold as FAULT: no controller drives the motor."""
        if supervisor_fault(*self.kernel):
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
        plan_announce(self.law[0:1], self.record[0]['plan'], int(t_ns), float(accel_mps2))

    @property
    def plan(self) -> np.ndarray:
        """The arm's announced breakpoints now (``t_ns``, ``accel_mps2``), a copy."""
        return self.record[0]['plan'][:int(self.law[0]['plan_count'])].copy()

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
        supervisor_step(*self.kernel, t_ns, float(position_m), float(force_n),
                        float(sensor_voltage_v), float(speed_mps), revision, float(shear_n),
                        float(displacement_m))
        return self._decision
