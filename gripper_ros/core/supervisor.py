"""Grasp supervisor: the state machine of grasp, hold, release and move requests (no rclpy).

Stages (paper sec. IV): POSITION (MPC-PD drives the finger to ``L_ls - width``) until either
switching criterion holds - the position is within +-2 % of its setpoint, or the force-sensor
voltage has risen by more than its threshold - then FORCE (to the request's setpoint,
:func:`gripper_ros.core.requests.force_setpoint_n`) until the force has settled: HOLDING.
Settled means ``|F - F_sp| + T |dF/dt|`` within the band and the finger slower than
``force_settle_speed_mps`` on every tick for ``force_settle_hold_s``, ``T`` being the slowest
contact mode's time scale (``force_settle_horizon_s``), so that no swing through the band is
taken for settled. Exactly one
controller is active at any tick; the decision for each tick is a :class:`Decision`.

Loss watch: once the force has reached ``lost_force_fraction`` of its setpoint after contact, a
force below that fraction for ``lost_force_hold_s``, or (after settling) the finger moving on
past the held position by more than ``no_object_margin_m``, ends the grasp as OBJECT_LOST.
After settling, the force loop keeps holding and watching for ``hold_watch_s`` (phase HOLDING,
force controller still active) before the grasp ends with outcome HOLDING.

Release: :meth:`GraspSupervisor.request_release` runs the position stage to the open position
(phase RELEASING) until the finger has stayed within ``release_tolerance_m`` of it for
``release_settle_s``: phase DONE, outcome RELEASED.

Move (:meth:`GraspSupervisor.request_move`, Franka's move, control_msgs GripperCommand's
result): the position stage drives the finger to ``L_ls - width`` with the request's speed and
effort as its limits (phase MOVING; :class:`gripper_ros.core.stages.PositionStageController`
keeps the speed below the limit and the push below the stall voltage of the effort). MOVED
(``reached_goal``) once the finger is at rest within ``move_tolerance_m`` of the goal; STALLED
once it is at rest short of the goal and, closing, presses with ``move_stall_force_fraction`` x
the effort limit (the force sensor tells contact), or has been at rest short of it for
``move_stall_timeout_s``. Either way the position stage then keeps the move's last command (the
goal, the limits): a stalled move goes on pressing with at most its effort, as a
position-controlled gripper keeps its command.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import PlantParams, SupervisorParams
from gripper_ros.core.requests import GraspTargets, MoveTargets, RequestError
from gripper_ros.wire import Controller, Outcome, PendingRequest, Phase, SwitchCriterion


class Decision:
    """The supervisor's verdict for one tick; the same object, updated in place, every tick.

    ``answer`` is the outcome this tick produced for the request (the grasp service answers
    now, the outcome is latched), or None.
    """

    __slots__ = ('t_ns', 'phase', 'active', 'switch_criterion', 'outcome', 'grasp_id',
                 'stage_id', 'running', 'contact', 'position_setpoint_m', 'approach_setpoint_m',
                 'force_setpoint_n', 'speed_limit_mps', 'voltage_limit_v', 'message', 'answer')

    def __init__(self):
        self.t_ns = 0
        self.phase = Phase.IDLE
        self.active = Controller.NONE
        self.switch_criterion = SwitchCriterion.NONE
        self.outcome = Outcome.UNKNOWN
        self.grasp_id = 0
        self.stage_id = 0
        self.running = False
        self.contact = False
        self.position_setpoint_m = 0.0
        self.approach_setpoint_m = 0.0
        self.force_setpoint_n = 0.0
        self.speed_limit_mps = 0.0          # the position stage's limits (a move's): speed,
        self.voltage_limit_v = 0.0          # 0 = none; voltage towards the setpoint, 0 = 24 V
        self.message = ''
        self.answer: Outcome | None = None

    @property
    def finished(self) -> bool:
        """The request has been answered (it may go on holding, phase HOLDING)."""
        return self.outcome is not Outcome.UNKNOWN


class RequestKind:
    """The kinds of request the supervisor runs (also the words its log and refusals use)."""

    GRASP = 'grasp'
    RELEASE = 'release'
    MOVE = 'move'


PENDING_CODES = {None: PendingRequest.NONE, RequestKind.GRASP: PendingRequest.GRASP,
                 RequestKind.RELEASE: PendingRequest.RELEASE,
                 RequestKind.MOVE: PendingRequest.MOVE}
START_PHASES = {RequestKind.GRASP: Phase.POSITION, RequestKind.RELEASE: Phase.RELEASING,
                RequestKind.MOVE: Phase.MOVING}


class GraspSupervisor:
    """One request at a time; :meth:`step` once per plant tick with that tick's measurements.

    A controller always drives the motor, except after a FAULT: with no request the position
    stage holds the finger where it came to rest (phase IDLE, or DONE/FAILED with the last
    outcome); a grasp runs POSITION -> FORCE -> HOLDING and, once answered, goes on holding
    (phase HOLDING, outcome HOLDING, force stage active) until a release, a stop, the next
    grasp or the loss of the object; a move runs MOVING and then keeps its last command. A
    request is accepted at once and starts at the next tick (:meth:`request_grasp`,
    :meth:`request_release`, :meth:`request_move`). ``running`` says whether the
    request still needs simulated time; ``stage_id`` grows whenever a controller is
    (re)assigned, so that it restarts from the measured state.
    """

    def __init__(self, plant: PlantParams, params: SupervisorParams):
        self.plant = plant
        self.params = params
        self.targets: GraspTargets | None = None
        self.kind: str | None = None            # the current request's kind, None before any
        self.phase = Phase.IDLE
        self.switch_criterion = SwitchCriterion.NONE
        self.outcome = Outcome.UNKNOWN
        self.grasp_id = 0
        self.stage_id = 0
        self.mass_kg = 0.0                      # the current grasp request's object mass
        self.start_ns = 0
        self.switch_ns: int | None = None
        self.contact_ns: int | None = None
        self.settled_ns: int | None = None      # force first settled (phase HOLDING from here)
        self.hold_position_m: float | None = None
        self.end_ns: int | None = None          # when the request was answered or ended
        self.answer = Outcome.UNKNOWN            # what the current request was answered
        self.answer_ns: int | None = None        # ... and when (the grasp service's answer)
        self.message = ''
        self._pending: tuple | None = None      # (kind, targets, mass_kg) starting next tick
        self._active = Controller.NONE
        self._idle_hold_m = 0.0                 # where the position stage holds without a request
        self._idle_limit_v = 0.0                # ... and its voltage cap (0: the plant's limit)
        self._position_m: float | None = None   # the last position measured in a request
        self._idle_speed_limit_mps = 0.0        # ... and its speed limit (0: none)
        self._move_timeout_s = 0.0
        self._rest_since_ns: int | None = None  # a move: the finger at rest since
        self._revision: int | None = None       # the plant's world revision last seen
        self._baseline_voltage_v = 0.0
        self._in_band_since_ns: int | None = None
        self._prev_force_t_ns: int | None = None    # previous FORCE-phase tick (settle rate)
        self._prev_force_n = 0.0
        self._gripped = False                   # force reached lost_force_fraction x F_sp
        self._low_since_ns: int | None = None
        self._t_ns = 0
        self._decision = Decision()

    # ------------------------------------------------------------------ state
    @property
    def running(self) -> bool:
        """A grasp or release is in progress (it needs simulated time until it is answered)."""
        return self.kind is not None and self.outcome is Outcome.UNKNOWN

    busy = running

    @property
    def releasing(self) -> bool:
        return self.running and self.phase is Phase.RELEASING

    @property
    def holding(self) -> bool:
        """A grasp was answered HOLDING and the force stage goes on holding the object."""
        return self.phase is Phase.HOLDING and self.outcome is Outcome.HOLDING

    @property
    def pressing(self) -> bool:
        """A stalled move's last command is in force: the finger presses at its limits."""
        return self.outcome is Outcome.STALLED and self._idle_speed_limit_mps > 0.0 and \
            self._active is Controller.POSITION

    @property
    def pending(self) -> bool:
        return self._pending is not None

    @property
    def pending_request(self) -> PendingRequest:
        """What request waits to start at the next tick (the status' ``pending_request``)."""
        return PENDING_CODES[self._pending[0] if self._pending is not None else None]

    @property
    def active(self) -> Controller:
        return self._active

    # ------------------------------------------------------------------ requests
    def _refuse_if_busy(self) -> None:
        if self._pending is not None:
            raise RequestError(f'a {self._pending[0]} request is already waiting to start')
        if self.running:
            raise RequestError(f'a {self.kind} is running (phase {self.phase.name})')

    def request_grasp(self, targets: GraspTargets, mass_kg: float = 0.0,
                      after_ns: int | None = None) -> GraspTargets:
        """Accept a grasp and return its targets; it starts at the first tick after ``after_ns``.

        By default that is the next tick decided; its sensor voltage is the no-contact baseline.

        Pass the newest tick received when the request arrived: the start is then the same
        whether or not that tick had been decided yet (deterministic under any timing). A grasp
        may follow a hold; the hold ends when it starts.
        """
        self._refuse_if_busy()
        self._pending = (RequestKind.GRASP, targets, float(mass_kg), after_ns)
        return targets

    def request_release(self, open_position_m: float = 0.0, timeout_s: float | None = None,
                        after_ns: int | None = None) -> GraspTargets:
        """Accept a release (return its targets): the position stage to ``open_position_m``.

        It starts at the first tick later than ``after_ns`` (see :meth:`request_grasp`).
        """
        self._refuse_if_busy()
        if not (math.isfinite(open_position_m)
                and 0.0 <= open_position_m < self.plant.max_travel_m):
            raise RequestError(f'open position must be in [0, {self.plant.max_travel_m:g}) m, '
                               f'got {open_position_m!r}')
        timeout = self.params.timeout_s if timeout_s is None else timeout_s
        targets = GraspTargets(open_position_m, 0.0, 0.0, timeout)
        self._pending = (RequestKind.RELEASE, targets, 0.0, after_ns)
        return targets

    def request_move(self, targets: MoveTargets, after_ns: int | None = None) -> MoveTargets:
        """Accept a move (:func:`validate_move`) and return its targets.

        It starts at the first tick later than ``after_ns`` (see :meth:`request_grasp`). A move
        may follow a hold; the hold ends when it starts.
        """
        self._refuse_if_busy()
        self._pending = (RequestKind.MOVE, targets, 0.0, after_ns)
        return targets

    def stop(self, message: str = 'stopped on request') -> Decision | None:
        """End the running request, the hold, a stalled move's press or a waiting request now.

        The outcome is STOPPED. Returns the ending decision (for the status and the answer),
        or None with nothing to stop. From the next tick the position stage holds the finger
        where it is, without a move's limits.
        """
        if self._pending is not None and not self.running:
            kind, targets, mass, _ = self._pending  # answered at once, it never starts
            self._pending = None
            self.grasp_id += 1
            self.kind, self.targets, self.mass_kg = kind, targets, mass
            self._reset(self._t_ns)
        elif self.pressing:                         # where the move stalled
            self._end(Phase.DONE, Outcome.STOPPED, message, position_m=self._position_m)
            return self._fill(Outcome.STOPPED)
        elif not (self.running or self.holding):
            return None
        self._end(Phase.DONE, Outcome.STOPPED, message)
        return self._fill(Outcome.STOPPED)

    def fault(self, message: str) -> Decision:
        """End the running request or the hold as FAULT: no controller drives the motor."""
        if not (self.running or self.holding):
            return self._fill()
        self._end(Phase.FAILED, Outcome.FAULT, message, hold=False)
        return self._fill(Outcome.FAULT)

    def _start(self, t_ns: int, position_m: float, sensor_voltage_v: float) -> None:
        kind, targets, mass, _ = self._pending
        self._pending = None
        self.grasp_id += 1
        self.kind, self.targets, self.mass_kg = kind, targets, mass
        self.phase = START_PHASES[kind]
        self._reset(t_ns)
        self._baseline_voltage_v = sensor_voltage_v
        if kind == RequestKind.MOVE:
            self._move_timeout_s = targets.timeout_s or (
                self.params.timeout_s
                + abs(targets.position_setpoint_m - position_m) / targets.speed_mps)
        self._assign(Controller.POSITION)

    def _reset(self, t_ns: int) -> None:
        self.outcome = Outcome.UNKNOWN
        self.answer = Outcome.UNKNOWN
        self.answer_ns = None
        self.switch_criterion = SwitchCriterion.NONE
        self.start_ns = self._t_ns = t_ns
        self.switch_ns = None
        self.contact_ns = None
        self.settled_ns = None
        self.hold_position_m = None
        self.end_ns = None
        self._in_band_since_ns = None
        self._prev_force_t_ns = None
        self._prev_force_n = 0.0
        self._gripped = False
        self._low_since_ns = None
        self._rest_since_ns = None
        self.message = ''

    def _assign(self, controller: Controller) -> None:
        """Hand the motor to ``controller`` from this tick on; it restarts (new stage)."""
        self._active = controller
        self.stage_id += 1

    def _hold_here(self, position_m: float, limits: MoveTargets | None = None) -> None:
        """Let the position stage hold the finger at ``position_m`` (no request running).

        With a move's speed and voltage ``limits`` (None: none but the plant's).
        """
        self._idle_hold_m = position_m if math.isfinite(position_m) else self._idle_hold_m
        self._idle_limit_v = limits.voltage_limit_v if limits is not None else 0.0
        self._idle_speed_limit_mps = limits.speed_mps if limits is not None else 0.0
        self._assign(Controller.POSITION)

    # ------------------------------------------------------------------ the tick
    def step(self, t_ns: int, position_m: float, force_n: float, sensor_voltage_v: float,
             speed_mps: float = 0.0, revision: int = 0) -> Decision:
        """Advance the state machine with the measurements of tick ``t_ns``.

        ``speed_mps`` is the finger's speed (the position switch's speed condition);
        ``revision`` counts changes of the simulated world (a new object, fingers reset): the
        position stage then holds the finger where it now is.
        """
        self._t_ns = t_ns
        answer = None
        if self._revision != revision:
            first = self._revision is None
            self._revision = revision
            if not (self.running or self.holding) and \
                    (first or self._active is Controller.POSITION):
                self._hold_here(position_m)       # after a FAULT nothing drives until a request
        pending = self._pending
        if pending is not None and (pending[3] is None or t_ns > pending[3]) and \
                math.isfinite(position_m):
            self._start(t_ns, position_m, sensor_voltage_v)
        if self.running or self.holding:
            answer = self._step_request(t_ns, position_m, force_n, sensor_voltage_v, speed_mps)
        return self._fill(answer)

    def _step_request(self, t_ns, position_m, force_n, sensor_voltage_v, speed_mps):
        phase = self.phase
        position_only = phase is Phase.RELEASING or phase is Phase.MOVING   # no force needed
        bad = []
        if not math.isfinite(position_m):
            bad.append(f'finger position sensor (joint state) reads {position_m!r} m')
        if not position_only and not (math.isfinite(force_n)
                                      and math.isfinite(sensor_voltage_v)):
            bad.append(f'force sensor reads force {force_n!r} N, voltage '
                       f'{sensor_voltage_v!r} V (sensor dropout)')
        if bad:
            what = 'hold' if self.holding else self.kind
            return self._end(Phase.FAILED, Outcome.FAULT,
                             f'fault at t={t_ns * 1e-9:.4f} s ({(t_ns - self.start_ns) * 1e-9:.4f}'
                             f' s into the {what}): ' + '; '.join(bad) +
                             '; no controller drives the motor from here on', hold=False)
        self._position_m = position_m                   # finite: where a stop holds
        if position_only:
            if phase is Phase.RELEASING:
                return self._step_release(t_ns, position_m)
            return self._step_move(t_ns, position_m, force_n, sensor_voltage_v, speed_mps)
        p, tg = self.params, self.targets
        sensor_rise = sensor_voltage_v - self._baseline_voltage_v > p.sensor_voltage_threshold_v
        if sensor_rise and self.contact_ns is None:
            self.contact_ns = t_ns
        farthest_face_m = tg.position_setpoint_m + tg.width_tolerance_m   # narrowest object
        if self.contact_ns is None and position_m > farthest_face_m + p.no_object_margin_m:
            return self._end(
                Phase.FAILED, Outcome.NO_OBJECT,
                f'no object: the finger passed the expected face ({tg.position_setpoint_m:.4f} m'
                + (f' + {tg.width_tolerance_m * 1e3:g} mm tolerance'
                   if tg.width_tolerance_m else '') +
                f') by {(position_m - farthest_face_m) * 1e3:.2f} mm without contact',
                position_m=position_m)
        if self.contact_ns is not None:
            lost = self._object_lost(t_ns, position_m, force_n)
            if lost is not None:
                return lost
        if self.holding:
            return None
        if self.phase is Phase.POSITION:
            tol = p.position_tolerance_fraction * tg.position_setpoint_m
            slow = (p.position_switch_speed_mps <= 0.0
                    or abs(speed_mps) <= p.position_switch_speed_mps)
            if abs(position_m - tg.approach_setpoint_m) <= tol and slow:
                self._switch(SwitchCriterion.POSITION_TOLERANCE, t_ns)
            elif sensor_rise:
                self._switch(SwitchCriterion.SENSOR_VOLTAGE, t_ns)
        elif self.phase is Phase.FORCE:
            if self._force_settled(t_ns, force_n, speed_mps):
                self.settled_ns = t_ns
                self.hold_position_m = position_m
                self.phase = Phase.HOLDING
        if self.phase is Phase.HOLDING and \
                (t_ns - self.settled_ns) * 1e-9 >= p.hold_watch_s:
            self.outcome = Outcome.HOLDING
            self.end_ns = t_ns
            self.message = (f'holding {force_n:.3f} N (setpoint {tg.force_setpoint_n:.3f} N) '
                            f'at {position_m:.5f} m')
            return Outcome.HOLDING
        if (t_ns - self.start_ns) * 1e-9 > tg.timeout_s:
            return self._end(Phase.FAILED, Outcome.TIMEOUT,
                             f'not settled within {tg.timeout_s:g} s of simulated time '
                             f'(phase {self.phase.name}, position {position_m:.5f} m, '
                             f'force {force_n:.3f} N)', position_m=position_m)
        return None

    def _force_settled(self, t_ns: int, force_n: float, speed_mps: float) -> bool:
        """Apply the force stage's settle criterion, once per FORCE-phase tick.

        Settled once, for ``force_settle_hold_s`` on end, every tick has had
        ``|F - F_sp| + T |dF/dt| <= band`` (``T`` = ``force_settle_horizon_s``, ``dF/dt`` from the
        previous tick) and the finger slower than ``force_settle_speed_mps``. A force
        oscillation ``A sin(w t)`` with ``w >= 1 / T`` gives ``|e| + T |de/dt| >= A`` at every
        instant, so none larger than the band is ever taken for settled; ``T`` is the period over
        2 pi of the slowest contact mode of the envelope. The speed bound keeps the creep of a
        damped object after HOLDING (at most ``speed x c / k``) inside the loss watch's margin.
        """
        p, tg = self.params, self.targets
        prev_t_ns, prev_force_n = self._prev_force_t_ns, self._prev_force_n
        self._prev_force_t_ns, self._prev_force_n = t_ns, force_n
        if prev_t_ns is None or t_ns <= prev_t_ns:
            self._in_band_since_ns = None
            return False
        rate = (force_n - prev_force_n) / ((t_ns - prev_t_ns) * 1e-9)
        band = p.force_settle_band_fraction * tg.force_setpoint_n
        steady = (abs(force_n - tg.force_setpoint_n) + p.force_settle_horizon_s * abs(rate)
                  <= band and (p.force_settle_speed_mps <= 0.0
                               or abs(speed_mps) <= p.force_settle_speed_mps))
        if not steady:
            self._in_band_since_ns = None
            return False
        if self._in_band_since_ns is None:
            self._in_band_since_ns = t_ns
        return (t_ns - self._in_band_since_ns) * 1e-9 >= p.force_settle_hold_s

    def _object_lost(self, t_ns: int, position_m: float, force_n: float) -> Outcome | None:
        """After contact: a force collapse, or the finger moving on past the held position."""
        p, tg = self.params, self.targets
        floor = p.lost_force_fraction * tg.force_setpoint_n
        t_s = t_ns * 1e-9
        if force_n >= floor:
            self._gripped = True
            self._low_since_ns = None
        elif self._gripped:
            if self._low_since_ns is None:
                self._low_since_ns = t_ns
            low_s = (t_ns - self._low_since_ns) * 1e-9
            if low_s >= p.lost_force_hold_s:
                return self._end(
                    Phase.FAILED, Outcome.OBJECT_LOST,
                    f'object lost at t={t_s:.4f} s{self._into()}: force {force_n:.3f} N has '
                    f'been below {p.lost_force_fraction:g} x the setpoint '
                    f'{tg.force_setpoint_n:.3f} N = {floor:.3f} N for {low_s * 1e3:.2f} ms '
                    f'(since t={self._low_since_ns * 1e-9:.4f} s); finger at {position_m:.5f} m',
                    position_m=position_m)
        if self.hold_position_m is not None and \
                position_m > self.hold_position_m + p.no_object_margin_m:
            return self._end(
                Phase.FAILED, Outcome.OBJECT_LOST,
                f'object lost at t={t_s:.4f} s{self._into()}: the finger moved on '
                f'{(position_m - self.hold_position_m) * 1e3:.2f} mm past the held position '
                f'{self.hold_position_m:.5f} m (margin {p.no_object_margin_m * 1e3:g} mm); '
                f'force {force_n:.3f} N', position_m=position_m)
        return None

    def _into(self) -> str:
        """Where in the grasp an event happened, for its message."""
        if self.holding and self.end_ns is not None:
            return f', {(self._t_ns - self.end_ns) * 1e-9:.4f} s after HOLDING'
        return f', {(self._t_ns - self.start_ns) * 1e-9:.4f} s into the grasp'

    def _step_release(self, t_ns: int, position_m: float) -> Outcome | None:
        p, tg = self.params, self.targets
        if abs(position_m - tg.position_setpoint_m) <= p.release_tolerance_m:
            if self._in_band_since_ns is None:
                self._in_band_since_ns = t_ns
            if (t_ns - self._in_band_since_ns) * 1e-9 >= p.release_settle_s:
                return self._end(
                    Phase.DONE, Outcome.RELEASED,
                    f'released: finger at {position_m:.5f} m (open position '
                    f'{tg.position_setpoint_m:.5f} m, opening '
                    f'{self.plant.max_travel_m - position_m:.5f} m) after '
                    f'{(t_ns - self.start_ns) * 1e-9:.3f} s', position_m=position_m)
        else:
            self._in_band_since_ns = None
        if (t_ns - self.start_ns) * 1e-9 > tg.timeout_s:
            return self._end(Phase.FAILED, Outcome.TIMEOUT,
                             f'release not done within {tg.timeout_s:g} s of simulated time '
                             f'(finger at {position_m:.5f} m)', position_m=position_m)
        return None

    def _step_move(self, t_ns: int, position_m: float, force_n: float, sensor_voltage_v: float,
                   speed_mps: float) -> Outcome | None:
        """End a move MOVED, STALLED or TIMEOUT; the position stage drives it meanwhile."""
        p, tg = self.params, self.targets
        goal = tg.position_setpoint_m
        elapsed_s = (t_ns - self.start_ns) * 1e-9
        if self.contact_ns is None and \
                sensor_voltage_v - self._baseline_voltage_v > p.sensor_voltage_threshold_v:
            self.contact_ns = t_ns
        error_m = goal - position_m                   # > 0: still to close
        at_rest = abs(speed_mps) <= p.move_rest_speed_mps
        where = (f'finger at {position_m:.5f} m (opening '
                 f'{self.plant.max_travel_m - position_m:.5f} m, goal '
                 f'{self.plant.max_travel_m - goal:.5f} m), force {force_n:.3f} N, after '
                 f'{elapsed_s:.3f} s')
        if not at_rest:
            self._rest_since_ns = None
        elif abs(error_m) <= tg.tolerance_m:
            return self._end(Phase.DONE, Outcome.MOVED, f'moved: {where}', position_m=goal,
                             limits=tg)
        else:
            if self._rest_since_ns is None:
                self._rest_since_ns = t_ns
            rest_s = (t_ns - self._rest_since_ns) * 1e-9
            fraction = p.move_stall_force_fraction
            # closing onto an obstacle, pressing at the effort limit (False for a NaN force)
            pressing = error_m > 0.0 and \
                fraction * tg.max_effort_n <= force_n <= tg.max_effort_n / fraction
            if pressing or rest_s >= p.move_stall_timeout_s:
                why = (f'pressing with {force_n:.3f} N at the effort limit '
                       f'{tg.max_effort_n:.3f} N' if pressing else f'at rest for {rest_s:.3f} s')
                return self._end(Phase.DONE, Outcome.STALLED,
                                 f'stalled {abs(error_m) * 1e3:.2f} mm short of the goal, '
                                 f'{why}: {where}', position_m=goal, limits=tg)
        if elapsed_s > self._move_timeout_s:
            return self._end(Phase.FAILED, Outcome.TIMEOUT,
                             f'move not done within {self._move_timeout_s:g} s of simulated '
                             f'time: {where}', position_m=position_m)
        return None

    def _switch(self, criterion: SwitchCriterion, t_ns: int) -> None:
        self._prev_force_t_ns = None          # the settle criterion's force rate starts here
        self.phase = Phase.FORCE
        self.switch_criterion = criterion
        self.switch_ns = t_ns
        self._assign(Controller.FORCE)

    def _end(self, phase: Phase, outcome: Outcome, message: str, *, hold: bool = True,
             position_m: float | None = None, limits: MoveTargets | None = None) -> Outcome:
        """End the request (or the hold).

        The position stage holds the finger from this tick on (``hold``; at ``position_m``,
        default where it is; with a move's ``limits``), or nothing drives the motor (a FAULT).
        """
        if hold and position_m is None:
            position_m = self._last_position()      # (while the request still runs)
        self.phase = phase
        self.outcome = outcome
        self.message = message
        self.end_ns = self._t_ns
        if hold:
            self._hold_here(position_m, limits)
        else:
            self._active = Controller.NONE
            self.stage_id += 1
        return outcome

    def _last_position(self) -> float:
        """Return where to hold when a request or hold ends.

        The held position of a hold, else where the finger was last measured in the running
        request, else the idle hold.
        """
        if self.hold_position_m is not None:
            return self.hold_position_m
        if self.running and self._position_m is not None:
            return self._position_m
        return self._idle_hold_m

    def _fill(self, answer: Outcome | None = None) -> Decision:
        d = self._decision
        d.t_ns = self._t_ns
        d.phase = self.phase
        d.active = self._active
        d.switch_criterion = self.switch_criterion
        d.outcome = self.outcome
        d.grasp_id = self.grasp_id
        d.stage_id = self.stage_id
        d.running = self.running
        d.contact = self.contact_ns is not None
        d.message = self.message
        d.answer = answer
        if answer is not None and self.answer_ns is None:
            self.answer, self.answer_ns = answer, self._t_ns
        tg = self.targets
        if self._active is Controller.POSITION and not self.running:
            d.position_setpoint_m = d.approach_setpoint_m = self._idle_hold_m
            d.force_setpoint_n = tg.force_setpoint_n if tg is not None else 0.0
            d.voltage_limit_v = self._idle_limit_v
            d.speed_limit_mps = self._idle_speed_limit_mps
        elif tg is not None:
            d.position_setpoint_m = tg.position_setpoint_m
            d.approach_setpoint_m = tg.approach_setpoint_m
            d.force_setpoint_n = tg.force_setpoint_n
            if self.phase is Phase.MOVING:
                d.voltage_limit_v = tg.voltage_limit_v
                d.speed_limit_mps = tg.speed_mps
            else:
                d.voltage_limit_v = d.speed_limit_mps = 0.0
        else:
            d.position_setpoint_m = d.approach_setpoint_m = d.force_setpoint_n = 0.0
            d.voltage_limit_v = d.speed_limit_mps = 0.0
        return d
