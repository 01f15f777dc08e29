"""Grasp supervisor state machine and request validation (no rclpy).

Stages (paper sec. IV): POSITION (MPC-PD drives the finger to ``L_ls - width``) until either
switching criterion holds - the position is within +-2 % of its setpoint, or the force-sensor
voltage has risen by more than its threshold - then FORCE (PI to ``mu_s m (g + a)``, eq. 23)
until the force has stayed within its band for a hold time: HOLDING. Exactly one controller is
active at any tick; the decision for each tick is a :class:`Decision`.

Loss watch: once the force has reached ``lost_force_fraction`` of its setpoint after contact, a
force below that fraction for ``lost_force_hold_s``, or (after settling) the finger moving on
past the held position by more than ``no_object_margin_m``, ends the grasp as OBJECT_LOST.
After settling, the force loop keeps holding and watching for ``hold_watch_s`` (phase HOLDING,
force controller still active) before the grasp ends with outcome HOLDING.

Release: :meth:`GraspSupervisor.start_release` runs the position stage to the open position
(phase RELEASING) until the finger has stayed within ``release_tolerance_m`` of it for
``release_settle_s``: phase DONE, outcome RELEASED.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from gripper_ros.core.config import PlantParams, SupervisorParams
from gripper_ros.wire import Controller
from gripper_ros.wire import Outcome, Phase, SwitchCriterion

MAX_TIMEOUT_S = 600.0  # simulated seconds; a longer grasp is a mistake, not a request


class RequestError(ValueError):
    """A grasp request that must be refused; the message says why, with the numbers."""


@dataclass(frozen=True)
class GraspRequest:
    width_m: float
    mass_kg: float
    friction_coefficient: float = 0.0   # 0 = default
    acceleration_mps2: float = 0.0
    timeout_s: float = 0.0              # 0 = default
    width_tolerance_m: float = 0.0      # 0 = default


@dataclass(frozen=True)
class GraspTargets:
    """What a valid request resolves to."""

    position_setpoint_m: float          # expected face, L_ls - width
    force_setpoint_n: float
    friction_coefficient: float
    timeout_s: float
    width_tolerance_m: float = 0.0

    @property
    def approach_setpoint_m(self) -> float:
        """The position stage's target: the face of the widest object the request allows."""
        return self.position_setpoint_m - self.width_tolerance_m


def force_setpoint_n(mass_kg: float, friction_coefficient: float, gravity_mps2: float,
                     acceleration_mps2: float) -> float:
    """Eq. 23: F_sp = mu_s m (g + a)."""
    return friction_coefficient * mass_kg * (gravity_mps2 + acceleration_mps2)


def validate_request(req: GraspRequest, plant: PlantParams,
                     sup: SupervisorParams) -> GraspTargets:
    """Resolve defaults and refuse anything non-finite, out of range or beyond 24 V."""
    for name in ('width_m', 'mass_kg', 'friction_coefficient', 'acceleration_mps2', 'timeout_s',
                 'width_tolerance_m'):
        value = getattr(req, name)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or \
                not math.isfinite(value):
            raise RequestError(f'{name} must be a finite number, got {value!r}')
    if not 0.0 < req.width_m < plant.max_travel_m:
        raise RequestError(f'width_m must be in (0, {plant.max_travel_m:g}) m (the finger '
                           f'travel), got {req.width_m!r}')
    if req.mass_kg <= 0.0:
        raise RequestError(f'mass_kg must be > 0, got {req.mass_kg!r}')
    if req.friction_coefficient < 0.0:
        raise RequestError(f'friction_coefficient must be >= 0 (0 = default '
                           f'{sup.friction_coefficient:g}), got {req.friction_coefficient!r}')
    if req.acceleration_mps2 < 0.0:
        raise RequestError(f'acceleration_mps2 must be >= 0, got {req.acceleration_mps2!r}')
    if not 0.0 <= req.timeout_s <= MAX_TIMEOUT_S:
        raise RequestError(f'timeout_s must be in [0, {MAX_TIMEOUT_S:g}] s (0 = default '
                           f'{sup.timeout_s:g}), got {req.timeout_s!r}')
    if req.width_tolerance_m < 0.0:
        raise RequestError(f'width_tolerance_m must be >= 0 (0 = default '
                           f'{sup.width_tolerance_m:g}), got {req.width_tolerance_m!r}')
    tolerance = req.width_tolerance_m or sup.width_tolerance_m
    if not req.width_m + tolerance < plant.max_travel_m:
        raise RequestError(f'width_m + width_tolerance_m must be < {plant.max_travel_m:g} m (the '
                           f'finger travel), got {req.width_m:g} + {tolerance:g} m')
    mu = req.friction_coefficient or sup.friction_coefficient
    accel = req.acceleration_mps2 or sup.acceleration_mps2
    force = force_setpoint_n(req.mass_kg, mu, plant.gravity_mps2, accel)
    if force > plant.max_force_n:
        raise RequestError(
            f'force setpoint {force:.2f} N (mu_s={mu:g} x m={req.mass_kg:g} kg x '
            f'(g+a)={plant.gravity_mps2 + accel:g} m/s^2) exceeds the {plant.max_force_n:.2f} N '
            f'the motor can hold at {plant.voltage_limit_v:g} V')
    if force <= 0.0:
        raise RequestError(f'force setpoint must be > 0 N, got {force!r}')
    return GraspTargets(plant.max_travel_m - req.width_m, force, mu,
                        req.timeout_s or sup.timeout_s, tolerance)


@dataclass(frozen=True)
class Decision:
    """The supervisor's verdict for one tick."""

    phase: Phase
    active: Controller
    switch_criterion: SwitchCriterion
    outcome: Outcome
    position_setpoint_m: float
    force_setpoint_n: float
    message: str = ''
    approach_setpoint_m: float = 0.0    # the position stage's target (see GraspTargets)

    @property
    def finished(self) -> bool:
        return self.outcome is not Outcome.UNKNOWN


class GraspSupervisor:
    """One grasp at a time; :meth:`step` once per plant tick with that tick's measurements."""

    def __init__(self, plant: PlantParams, params: SupervisorParams):
        self.plant = plant
        self.params = params
        self.targets: GraspTargets | None = None
        self.phase = Phase.IDLE
        self.switch_criterion = SwitchCriterion.NONE
        self.outcome = Outcome.UNKNOWN
        self.start_ns = 0
        self.switch_ns: int | None = None
        self.contact_ns: int | None = None
        self.settled_ns: int | None = None      # force first settled (phase HOLDING from here)
        self.hold_position_m: float | None = None
        self.end_ns: int | None = None
        self._baseline_voltage_v = 0.0
        self._in_band_since_ns: int | None = None
        self._prev_force_t_ns: int | None = None    # previous FORCE-phase tick (settle rate)
        self._prev_force_n = 0.0
        self._gripped = False                   # force reached lost_force_fraction x F_sp
        self._low_since_ns: int | None = None
        self._t_ns = 0
        self.message = ''

    @property
    def busy(self) -> bool:
        """A grasp or release is running (a controller drives the motor)."""
        return self.phase is not Phase.IDLE and self.outcome is Outcome.UNKNOWN

    @property
    def releasing(self) -> bool:
        return self.busy and self.phase is Phase.RELEASING

    def start(self, targets: GraspTargets, t_ns: int, sensor_voltage_v: float) -> Decision:
        """Begin a grasp at tick ``t_ns``; the sensor voltage now is the no-contact baseline."""
        if self.busy:
            raise RequestError('a release is running' if self.releasing
                               else 'a grasp is already running')
        self.targets = targets
        self.phase = Phase.POSITION
        self.switch_criterion = SwitchCriterion.NONE
        self.outcome = Outcome.UNKNOWN
        self._reset(t_ns)
        self._baseline_voltage_v = sensor_voltage_v
        return self._decision()

    def start_release(self, t_ns: int, open_position_m: float = 0.0,
                      timeout_s: float | None = None) -> Decision:
        """Open the fingers under position control: the position stage to ``open_position_m``."""
        if self.busy:
            raise RequestError(f'a {"release" if self.releasing else "grasp"} is running '
                               f'(phase {self.phase.name})')
        if not (math.isfinite(open_position_m)
                and 0.0 <= open_position_m < self.plant.max_travel_m):
            raise RequestError(f'open position must be in [0, {self.plant.max_travel_m:g}) m, '
                               f'got {open_position_m!r}')
        timeout = self.params.timeout_s if timeout_s is None else timeout_s
        self.targets = GraspTargets(open_position_m, 0.0, 0.0, timeout)
        self.phase = Phase.RELEASING
        self.switch_criterion = SwitchCriterion.NONE
        self._reset(t_ns)
        return self._decision()

    def _reset(self, t_ns: int) -> None:
        self.outcome = Outcome.UNKNOWN
        self.start_ns = self._t_ns = t_ns
        self.switch_ns = None
        self.contact_ns = None
        self.settled_ns = None
        self.hold_position_m = None
        self.end_ns = None
        self._in_band_since_ns = None
        self._prev_force_t_ns: int | None = None
        self._prev_force_n = 0.0
        self._gripped = False
        self._low_since_ns = None
        self.message = ''

    def stop(self, message: str = 'stopped on request') -> Decision:
        """End the running grasp now (STOPPED); the plant is left without a commanding loop."""
        if self.busy:
            self._finish(Phase.DONE, Outcome.STOPPED, message)
        return self._decision()

    def fault(self, message: str) -> Decision:
        if self.busy:
            self._finish(Phase.FAILED, Outcome.FAULT, message)
        return self._decision()

    def step(self, t_ns: int, position_m: float, force_n: float,
             sensor_voltage_v: float, speed_mps: float = 0.0) -> Decision:
        """Advance the state machine with the measurements of tick ``t_ns`` (``speed_mps``:
        the finger's speed, for the position switch's speed condition)."""
        if not self.busy:
            return self._decision()
        self._t_ns = t_ns
        bad = []
        if not math.isfinite(position_m):
            bad.append(f'finger position sensor (joint state) reads {position_m!r} m')
        if self.phase is not Phase.RELEASING and not (
                math.isfinite(force_n) and math.isfinite(sensor_voltage_v)):
            bad.append(f'force sensor reads force {force_n!r} N, voltage '
                       f'{sensor_voltage_v!r} V (sensor dropout)')
        if bad:
            self._finish(Phase.FAILED, Outcome.FAULT,
                         f'fault at t={t_ns * 1e-9:.4f} s ({(t_ns - self.start_ns) * 1e-9:.4f} s '
                         f'into the {"release" if self.phase is Phase.RELEASING else "grasp"}): '
                         + '; '.join(bad) + '; no controller drives the motor from here on')
            return self._decision()
        if self.phase is Phase.RELEASING:
            return self._step_release(t_ns, position_m)
        p, tg = self.params, self.targets
        sensor_rise = sensor_voltage_v - self._baseline_voltage_v > p.sensor_voltage_threshold_v
        if sensor_rise and self.contact_ns is None:
            self.contact_ns = t_ns
        farthest_face_m = tg.position_setpoint_m + tg.width_tolerance_m   # narrowest object
        if self.contact_ns is None and position_m > farthest_face_m + p.no_object_margin_m:
            self._finish(Phase.FAILED, Outcome.NO_OBJECT,
                         f'no object: the finger passed the expected face '
                         f'({tg.position_setpoint_m:.4f} m'
                         + (f' + {tg.width_tolerance_m * 1e3:g} mm tolerance'
                            if tg.width_tolerance_m else '') +
                         f') by {(position_m - farthest_face_m) * 1e3:.2f} mm without contact')
            return self._decision()
        if self.contact_ns is not None and self._object_lost(t_ns, position_m, force_n):
            return self._decision()
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
            self._finish(Phase.HOLDING, Outcome.HOLDING,
                         f'holding {force_n:.3f} N (setpoint '
                         f'{tg.force_setpoint_n:.3f} N) at {position_m:.5f} m')
            return self._decision()
        if (t_ns - self.start_ns) * 1e-9 > tg.timeout_s:
            self._finish(Phase.FAILED, Outcome.TIMEOUT,
                         f'not settled within {tg.timeout_s:g} s of simulated time '
                         f'(phase {self.phase.name}, position {position_m:.5f} m, '
                         f'force {force_n:.3f} N)')
        return self._decision()

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

    def _object_lost(self, t_ns: int, position_m: float, force_n: float) -> bool:
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
                self._finish(Phase.FAILED, Outcome.OBJECT_LOST,
                             f'object lost at t={t_s:.4f} s: force {force_n:.3f} N has been '
                             f'below {p.lost_force_fraction:g} x the setpoint '
                             f'{tg.force_setpoint_n:.3f} N = {floor:.3f} N for '
                             f'{low_s * 1e3:.2f} ms (since t={self._low_since_ns * 1e-9:.4f} s);'
                             f' finger at {position_m:.5f} m')
                return True
        if self.hold_position_m is not None and \
                position_m > self.hold_position_m + p.no_object_margin_m:
            self._finish(Phase.FAILED, Outcome.OBJECT_LOST,
                         f'object lost at t={t_s:.4f} s: the finger moved on '
                         f'{(position_m - self.hold_position_m) * 1e3:.2f} mm past the held '
                         f'position {self.hold_position_m:.5f} m (margin '
                         f'{p.no_object_margin_m * 1e3:g} mm); force {force_n:.3f} N')
            return True
        return False

    def _step_release(self, t_ns: int, position_m: float) -> Decision:
        p, tg = self.params, self.targets
        if abs(position_m - tg.position_setpoint_m) <= p.release_tolerance_m:
            if self._in_band_since_ns is None:
                self._in_band_since_ns = t_ns
            if (t_ns - self._in_band_since_ns) * 1e-9 >= p.release_settle_s:
                self._finish(Phase.DONE, Outcome.RELEASED,
                             f'released: finger at {position_m:.5f} m (open position '
                             f'{tg.position_setpoint_m:.5f} m, opening '
                             f'{self.plant.max_travel_m - position_m:.5f} m) after '
                             f'{(t_ns - self.start_ns) * 1e-9:.3f} s')
                return self._decision()
        else:
            self._in_band_since_ns = None
        if (t_ns - self.start_ns) * 1e-9 > tg.timeout_s:
            self._finish(Phase.FAILED, Outcome.TIMEOUT,
                         f'release not done within {tg.timeout_s:g} s of simulated time '
                         f'(finger at {position_m:.5f} m)')
        return self._decision()

    def _switch(self, criterion: SwitchCriterion, t_ns: int) -> None:
        self._prev_force_t_ns = None          # the settle criterion's force rate starts here
        self.phase = Phase.FORCE
        self.switch_criterion = criterion
        self.switch_ns = t_ns

    def _finish(self, phase: Phase, outcome: Outcome, message: str) -> None:
        self.phase = phase
        self.outcome = outcome
        self.message = message
        self.end_ns = self._t_ns

    def _decision(self) -> Decision:
        active = Controller.NONE
        if self.busy:
            active = {Phase.POSITION: Controller.POSITION,
                      Phase.RELEASING: Controller.POSITION,
                      Phase.FORCE: Controller.FORCE,
                      Phase.HOLDING: Controller.FORCE}.get(self.phase,
                                                                Controller.NONE)
        tg = self.targets
        return Decision(self.phase, active, self.switch_criterion, self.outcome,
                        tg.position_setpoint_m if tg else 0.0,
                        tg.force_setpoint_n if tg else 0.0, self.message,
                        tg.approach_setpoint_m if tg else 0.0)
