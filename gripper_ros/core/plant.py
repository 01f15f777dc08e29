"""Two-finger parallel gripper plant: brushed DC motor driving a lead screw (paper eqs. 1-13).

State ``[i_a (A), omega (rad/s), x (m)]`` where ``x`` is the moving finger's travel from fully
open (eq. 10: ``x = p/(2 pi) theta``). Free motion is linear and is discretised exactly (zero-order
hold, matrix exponential) at whatever hold time a controller asks for. Contact with the object at
``x_c = L_ls - width`` uses one of two documented models:

* rigid (the paper's): the finger stops on arrival (perfectly inelastic; the kinetic energy it
  loses is reported), and the gripping force follows the motor torque, ``F = k_t i_a / (eta p
  N1/N2)`` (eq. 12), so force obeys eq. 13 exactly. The finger leaves the object when the motor
  torque turns negative.
* compliant (Kelvin-Voigt): ``F = k d + c d'`` for penetration ``d = x - x_c > 0``; the force
  loads the motor through the same lever ``eta p N1/N2``.

The fully-open end stop (``x = 0``) is rigid and senses no force; with no object the fingers meet
at ``x = L_ls`` (a rigid object of width 0).

Integration: an interval in which no contact event can happen is one exact ZOH step. Free motion
is one step when a rigorous bound on the finger's reach (its speed grows by at most the
acceleration the current can give) keeps it clear of both stops; compliant contact is one step
when the step is short against the object's spring mode and the finger is still in contact at
its end. Otherwise the interval is sub-stepped at ``contact_substep_s`` and contact or
separation is located on that grid.

Holding (:mod:`gripper_ros.core.hold`): a lifted object is held by Coulomb friction on both pads
at the plant's contact force, and may slide and be lost; :meth:`GripperPlant.begin_hold` starts
the lift's clock, :attr:`GripperPlant.object_state` reports it. A step is split at the lift's
start and end and at the loss, and the grip force is taken at the start of each piece (at most
one ``contact_substep_s`` long while the object slides). At the loss the object is gone, as for
``OBJECT_REMOVED``.

Fault injection (tests and demos; :meth:`GripperPlant.schedule_fault`, one fault fires at an exact
simulated instant, the step is split there):

* ``OBJECT_REMOVED``: the object vanishes; the finger is free to move on (to the other finger).
* ``OBJECT_SLIPPING`` (rigid objects): the object slides out of the grip. The most force it can
  resist decays as ``C(t) = F_0 exp(-(t - t_f)/tau)`` from the force ``F_0`` at the fault
  instant ``t_f``. While the motor pushes harder than ``C`` the finger advances against the
  constant load ``C`` (the face recedes with it) and the measured force is ``C``; once
  ``C < 1 %`` of ``F_0`` the object is out and gone. Fired while nothing is gripped
  (``F_0 = 0``) it acts as a removal.
* ``SENSOR_DROPOUT``: the force sensor reports NaN force and voltage from then on
  (:class:`gripper_ros.core.force_sensor.FsrVoltageDivider`); the mechanics are unaffected.

Effects last until the next :meth:`GripperPlant.set_object` (a new object, a repaired sensor).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import enum
import math
from typing import NamedTuple

from gripper_ros.core.config import ContactParams, PlantParams
from gripper_ros.core.force_sensor import FsrVoltageDivider
from gripper_ros.core.hold import (check_finite_nonnegative, HoldModel, HoldState, Lift,
                                   ObjectState)
from gripper_ros.wire import FaultKind
import numpy as np
from scipy.linalg import expm


DEFAULT_SLIP_TIME_CONSTANT_S = 0.01   # e-folding time of the slipping object's force capacity
SLIP_GONE_FRACTION = 0.01             # the object is out once its capacity is below 1 % of F_0
MAX_FAULT_DELAY_S = 600.0
MAX_CACHED_DISCRETISATIONS = 256
FREE_REACH_MARGIN_MPS = 1e-9          # added to the speed bound of a free step (rounding)
# A compliant contact is stepped in one piece while its spring mode turns through at most this
# phase: far too little for the finger to leave the face and come back within the step.
COMPLIANT_ONE_STEP_PHASE_RAD = 0.1
# An interior force maximum this much above both ends of a one-piece compliant step is located
# on the sub-step grid (the reported peak); a smaller one is rounding.
PEAK_RESOLUTION_N = 1e-9

__all__ = ['ContactState', 'DEFAULT_SLIP_TIME_CONSTANT_S', 'FaultKind', 'GraspObject',
           'GripperPlant', 'HoldState', 'Lift', 'ObjectState', 'PlantSample', 'ScheduledFault',
           'check_fault']


@dataclass(frozen=True)
class ScheduledFault:
    """A fault to fire at an absolute simulated instant."""

    kind: FaultKind
    at_ns: int                        # absolute simulated time at which it fires
    time_constant_s: float = DEFAULT_SLIP_TIME_CONSTANT_S


def check_fault(kind, delay_s: float, time_constant_s: float = 0.0,
                rigid_object: bool = True) -> tuple[FaultKind, float]:
    """Validate a fault request; returns (kind, time constant with 0 = default). ValueError."""
    try:
        kind = FaultKind(kind)
    except ValueError:
        raise ValueError(f'unknown fault {kind!r}; known: '
                         f'{", ".join(f"{k.value}={k.name}" for k in FaultKind)}') from None
    if not (math.isfinite(delay_s) and 0.0 <= delay_s <= MAX_FAULT_DELAY_S):
        raise ValueError(f'fault_at_s must be in [0, {MAX_FAULT_DELAY_S:g}] s, got {delay_s!r}')
    if not (math.isfinite(time_constant_s) and time_constant_s >= 0.0):
        raise ValueError(f'fault_time_constant_s must be finite and >= 0, '
                         f'got {time_constant_s!r}')
    if kind is FaultKind.OBJECT_SLIPPING and not rigid_object:
        raise ValueError('OBJECT_SLIPPING is modelled for rigid objects only (stiffness 0)')
    return kind, time_constant_s or DEFAULT_SLIP_TIME_CONSTANT_S


class ContactState(enum.Enum):
    """Which mechanical regime the finger is in."""

    FREE = 'free'
    SLIPPING = 'slipping'              # a slipping object gives way: finger advances against C(t)
    RIGID_OBJECT = 'rigid_object'      # pressing a rigid object (or the other finger)
    COMPLIANT_OBJECT = 'compliant'     # compressing a compliant object
    OPEN_STOP = 'open_stop'            # resting on the fully-open end stop


_FREE = ContactState.FREE
_SLIPPING = ContactState.SLIPPING
_RIGID = ContactState.RIGID_OBJECT
_COMPLIANT = ContactState.COMPLIANT_OBJECT
_OPEN_STOP = ContactState.OPEN_STOP


@dataclass(frozen=True)
class GraspObject:
    """What lies between the fingers. width 0 = nothing (the fingers meet at full travel).

    ``mass_kg`` 0 = the grasp's mass (given to :meth:`GripperPlant.begin_hold`); the pad friction
    and pad length 0 = the configured ``contact`` defaults.
    """

    width_m: float = 0.0
    stiffness_n_per_m: float = 0.0     # 0 = rigid
    damping_n_s_per_m: float = 0.0
    mass_kg: float = 0.0
    static_friction: float = 0.0
    kinetic_friction: float = 0.0
    pad_length_m: float = 0.0

    @property
    def rigid(self) -> bool:
        return self.stiffness_n_per_m == 0.0


_NOTHING = GraspObject(0.0)


class PlantSample(NamedTuple):
    """What the plant's sensors and motor report at one instant."""

    t_ns: int                   # simulated time, integer nanoseconds
    position_m: float           # finger travel from fully open
    velocity_mps: float
    force_n: float              # gripping (contact) force
    peak_force_n: float         # largest force since the previous sample
    current_a: float
    speed_rad_s: float
    voltage_v: float            # armature voltage applied over the interval that ended now
    sensor_voltage_v: float     # FSR divider output
    contact: bool

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9


_new_tuple = tuple.__new__

# Discretisations shared by all plants with the same parameters (a sweep builds many plants):
# params -> {kind key -> {dt_s -> flat coefficients}}.
_SHARED_CACHES: dict[PlantParams, dict] = {}


def _bounded_entry(store: dict, key) -> dict:
    """``store[key]``, a dict made on first use; a store grown past the bound starts afresh."""
    entry = store.get(key)
    if entry is None:
        if len(store) > MAX_CACHED_DISCRETISATIONS:
            store.clear()
        entry = store[key] = {}
    return entry


class GripperPlant:
    """Exact-discretised motor + lead screw + contact. Call :meth:`step` with a held voltage."""

    def __init__(self, params: PlantParams, sensor: FsrVoltageDivider,
                 contact: ContactParams | None = None):
        self.params = params
        self.sensor = sensor
        p = params
        self._rho = p.travel_per_rad_m
        self._lever = p.force_lever_m
        self._tau_e = p.inductance_h / p.resistance_ohm
        self._kt = p.torque_constant_n_m_per_a
        self._h = p.contact_substep_s
        self._h_ns = max(1, round(p.contact_substep_s * 1e9))
        self._limit_v = p.voltage_limit_v
        # Free-reach bound (see _free_step_is_safe): |omega'| <= (k_t I + b W) / J.
        self._reach_feedback = (p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad
                                / p.resistance_ohm + p.damping_n_m_s_per_rad)
        self._a_free = np.array([
            [-p.resistance_ohm / p.inductance_h, -p.back_emf_v_s_per_rad / p.inductance_h, 0.0],
            [p.torque_constant_n_m_per_a / p.inertia_kg_m2,
             -p.damping_n_m_s_per_rad / p.inertia_kg_m2, 0.0],
            [0.0, self._rho, 0.0]])
        self._b = np.array([1.0 / p.inductance_h, 0.0, 0.0])
        self._caches = _bounded_entry(_SHARED_CACHES, params)
        self._free_cache = _bounded_entry(self._caches, 'free')
        self._loaded_cache = _bounded_entry(self._caches, 'loaded')
        self.contact_defaults = contact or ContactParams(0.0, 0.0)
        default = self.contact_defaults
        self.impact_energy_lost_j = 0.0
        self.t_ns = 0  # simulated time in integer nanoseconds: exact, the lockstep's tick key
        self.scheduled_fault: ScheduledFault | None = None
        self.fired_faults: list[tuple[FaultKind, int]] = []   # (kind, t_ns) since set_object
        self._slip: tuple[float, float, float] | None = None   # (t_f s, F_0 N, tau s)
        self._t_now_s = 0.0
        self._x = 0.0
        self._lift: Lift | None = None
        self._hold: HoldModel | None = None          # the object's tangential hold, if any
        self._hold_live: HoldModel | None = None     # the same while it must be stepped
        self._use_object(GraspObject(0.0, default.stiffness_n_per_m, default.damping_n_s_per_m))
        self.reset()

    # ----------------------------------------------------------------- set-up
    def reset(self, open_fingers: bool = True) -> None:
        """Motor at rest; optionally the finger back at the fully-open stop. Time keeps running."""
        self._i = 0.0
        self._w = 0.0
        if open_fingers:
            self._x = 0.0
        self._voltage = 0.0
        self._state = _OPEN_STOP if self._x <= 0.0 else _FREE
        self._peak = 0.0
        self.impact_energy_lost_j = 0.0
        self._refresh_contact_state()

    def touch_object(self) -> None:
        """Put the finger at rest just touching the object, motor off (force-loop studies)."""
        self._i = 0.0
        self._w = 0.0
        self._x = self._x_c
        self._voltage = 0.0
        self._peak = 0.0
        self._state = _RIGID if self.object.rigid else _COMPLIANT

    def set_object(self, obj: GraspObject, lift: Lift | None = None) -> None:
        """Place an object (its fixed-finger face is the fixed finger; the other face at x_c).

        ``lift``: how the arm will lift it once the grasp holds (None = it stays on its support).
        Bad values raise ValueError naming the field, and change nothing.
        """
        if not (math.isfinite(obj.width_m) and 0.0 <= obj.width_m < self.params.max_travel_m):
            raise ValueError(f'object width must be in [0, {self.params.max_travel_m}) m, '
                             f'got {obj.width_m!r}')
        for name in ('stiffness_n_per_m', 'damping_n_s_per_m', 'mass_kg', 'static_friction',
                     'kinetic_friction', 'pad_length_m'):
            check_finite_nonnegative('object', name, getattr(obj, name))
        if lift is not None and not isinstance(lift, Lift):
            raise ValueError(f'lift must be a Lift or None, got {lift!r}')
        hold = self._hold_model_for(obj, lift)
        if self._x > self.params.max_travel_m - obj.width_m:
            raise ValueError('the finger is already past the new object surface; open first')
        self._use_object(obj)
        self._lift = lift
        self._hold = hold
        self._hold_live = None
        self.clear_faults()
        self._refresh_contact_state()

    def _hold_model_for(self, obj: GraspObject, lift: Lift | None) -> HoldModel | None:
        """Build the hold of ``obj``, its friction resolved against the defaults (ValueError)."""
        if obj.width_m == 0.0:
            return None
        d = self.contact_defaults
        mu_s = obj.static_friction or d.static_friction
        mu_k = obj.kinetic_friction or d.kinetic_friction
        if mu_k > mu_s:
            raise ValueError(f'object kinetic_friction {mu_k!r} must be <= its static_friction '
                             f'{mu_s!r} (0 = the contact defaults {d.kinetic_friction!r} / '
                             f'{d.static_friction!r})')
        pad_m = obj.pad_length_m or d.pad_length_m
        if not pad_m > 0.0:
            raise ValueError(f'object pad_length_m must be > 0 (0 = the contact default '
                             f'{d.pad_length_m!r}), got {pad_m!r}')
        return HoldModel(obj.mass_kg, mu_s, mu_k, pad_m, self.params.gravity_mps2, lift)

    def _use_object(self, obj: GraspObject) -> None:
        """Make ``obj`` the object between the fingers (geometry and discretisations)."""
        self.object = obj
        self._x_c = self.params.max_travel_m - obj.width_m
        if obj.rigid:
            self._compliant_cache = None
            self._compliant_one_step_s = 0.0
        else:
            self._compliant_cache = _bounded_entry(
                self._caches, ('compliant', obj.stiffness_n_per_m, obj.damping_n_s_per_m,
                               self._x_c))
            p = self.params
            spring_rad_s = math.sqrt(self._lever * obj.stiffness_n_per_m * self._rho
                                     / p.inertia_kg_m2)
            self._compliant_one_step_s = COMPLIANT_ONE_STEP_PHASE_RAD / spring_rad_s

    # ----------------------------------------------------------------- holding a lifted object
    def begin_hold(self, t_ns: int, grasp_mass_kg: float = 0.0) -> None:
        """Start the lift's clock: the grasp was declared HOLDING at simulated time ``t_ns``.

        ``grasp_mass_kg`` is the object's mass if the object did not give one. A lift instant
        already past when this is called takes effect at the plant's present time. Nothing
        between the fingers: no effect. ValueError (nothing changes) for a bad value or when
        the object has already left its support.
        """
        if isinstance(t_ns, bool) or not isinstance(t_ns, int) or t_ns < 0:
            raise ValueError(f'hold t_ns must be an integer >= 0, got {t_ns!r}')
        mass = check_finite_nonnegative('hold', 'grasp_mass_kg', grasp_mass_kg)
        hold = self._hold
        if hold is None or hold.state is HoldState.NONE:
            return
        hold.begin(t_ns, hold.mass_kg or mass)
        self._hold_live = hold if hold.live else None

    @property
    def lift(self) -> Lift | None:
        """The lift given with the object (None: it stays on its support)."""
        return self._lift

    @property
    def hold_state(self) -> HoldState:
        """What the held object does now (cheap: for a per-step check)."""
        hold = self._hold
        return HoldState.NONE if hold is None else hold.state

    @property
    def object_state(self) -> ObjectState:
        """The grasped object's hold: state, slip, load against the static capacity, loss time."""
        hold = self._hold
        if hold is None:
            return ObjectState(HoldState.NONE)
        if hold.state is HoldState.NONE:
            return ObjectState(HoldState.NONE, hold.slip_m, 0.0, 0.0, 0.0, None)
        return ObjectState(hold.state, hold.slip_m, hold.slip_speed_mps, hold.load_n,
                           hold.capacity_n(self._force()), hold.lost_ns, hold.acceleration_mps2)

    def scenario_in_progress(self) -> bool:
        """A hold scenario (a lift) is still to be played out, so that simulated time must go
        on in fast mode after the grasp was answered."""
        hold = self._hold
        return hold is not None and hold.scenario_in_progress(
            self.t_ns, round(self.contact_defaults.after_lift_s * 1e9))

    # ----------------------------------------------------------------- fault injection
    def schedule_fault(self, kind, at_ns: int,
                       time_constant_s: float = DEFAULT_SLIP_TIME_CONSTANT_S) -> ScheduledFault:
        """Fire ``kind`` at simulated time ``at_ns`` (>= now; replaces a scheduled one)."""
        kind, tau = check_fault(kind, 0.0, time_constant_s, self.object.rigid)
        at_ns = max(int(at_ns), self.t_ns)
        self.scheduled_fault = None if kind is FaultKind.NONE else \
            ScheduledFault(kind, at_ns, tau)
        return self.scheduled_fault

    def cancel_fault(self) -> None:
        """Drop a scheduled fault that has not fired (its effects, once fired, stay)."""
        self.scheduled_fault = None

    def clear_faults(self) -> None:
        """No scheduled fault, a working sensor, no slip."""
        self.scheduled_fault = None
        self.fired_faults = []
        self.sensor.dropped_out = False
        self._slip = None
        if self._state is _SLIPPING:
            self._w = 0.0
            self._state = _RIGID

    @property
    def sensor_dropped_out(self) -> bool:
        return self.sensor.dropped_out

    def slip_capacity_n(self, t_s: float | None = None) -> float:
        """Force the slipping object can still resist at ``t_s`` (inf when not slipping)."""
        if self._slip is None:
            return math.inf
        t_f, f_0, tau = self._slip
        t = self._t_now_s if t_s is None else t_s
        return f_0 * math.exp(-max(0.0, t - t_f) / tau)

    def _fire_fault(self, fault: ScheduledFault) -> None:
        self.scheduled_fault = None
        self.fired_faults.append((fault.kind, fault.at_ns))
        if fault.kind is FaultKind.SENSOR_DROPOUT:
            self.sensor.dropped_out = True
        elif fault.kind is FaultKind.OBJECT_REMOVED:
            self._remove_object()
        elif fault.kind is FaultKind.OBJECT_SLIPPING:
            f_0 = self._force()
            if f_0 <= 0.0:
                self._remove_object()
            else:
                self._slip = (fault.at_ns * 1e-9, f_0, fault.time_constant_s)

    def _remove_object(self, lost: bool = False) -> None:
        """Nothing between the fingers from now on (slid out of the pads if ``lost``)."""
        self._slip = None
        self._use_object(_NOTHING)              # nothing: the fingers would meet at L_ls
        if not lost:
            self._end_hold()
        if self._state in (_RIGID, _COMPLIANT, _SLIPPING) and self._x < self.params.max_travel_m:
            self._state = _FREE
        self._refresh_contact_state()

    def _end_hold(self) -> None:
        if self._hold is not None and self._hold.state is not HoldState.LOST:
            self._hold.remove()
        self._hold_live = None

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    @property
    def contact_position_m(self) -> float:
        """Finger travel at which it touches the object."""
        return self._x_c

    # ----------------------------------------------------------------- model facts
    def position_transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 11, X(s)/E_a(s), as (numerator, denominator) polynomial coefficients in s."""
        p = self.params
        num = np.array([p.torque_constant_n_m_per_a * p.pitch_m / (2.0 * math.pi)])
        mech = np.polymul([p.inertia_kg_m2, p.damping_n_m_s_per_rad],
                          [p.inductance_h, p.resistance_ohm])
        den = np.polymul(np.polyadd(mech, [p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad]),
                         [1.0, 0.0])
        return num, den

    def force_transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 13, F_gr(s)/E_a(s) with the finger stalled, as (numerator, denominator)."""
        p = self.params
        return (np.array([p.torque_constant_n_m_per_a / self._lever]),
                np.array([p.inductance_h, p.resistance_ohm]))

    def stall_force_n(self, voltage_v: float) -> float:
        """Steady gripping force for a held voltage on a rigid object (DC gain of eq. 13)."""
        return self.params.stall_force_per_volt_n * voltage_v

    def free_speed_mps(self, voltage_v: float) -> float:
        """Steady finger speed for a held voltage in free motion (DC gain of eq. 9 times p/2pi)."""
        p = self.params
        w = p.torque_constant_n_m_per_a * voltage_v / (
            p.damping_n_m_s_per_rad * p.resistance_ohm
            + p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad)
        return w * self._rho

    def discrete_free_model(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact ZOH model of free motion: ``s[k+1] = Ad s[k] + Bd e[k]``, s = [i, omega, x]."""
        c = self._free(dt_s)
        return np.array([c[0:3], c[4:7], c[8:11]]), np.array(c[12:15])

    def discrete_force_model(self, dt_s: float) -> tuple[float, float]:
        """Exact ZOH of eq. 13: ``F[k+1] = a F[k] + b e[k]`` on a rigid object."""
        a = math.exp(-dt_s / self._tau_e)
        return a, self.params.stall_force_per_volt_n * (1.0 - a)

    # ----------------------------------------------------------------- simulation
    @property
    def contact_state(self) -> ContactState:
        return self._state

    def sample(self) -> PlantSample:
        return self._sample(self._force())

    def _sample(self, force: float) -> PlantSample:
        sensor = self.sensor
        if sensor.dropped_out:
            measured = sensor_v = peak = math.nan
        else:
            measured = force
            sensor_v = sensor.voltage_v(force)
            peak = force if force > self._peak else self._peak
        w = self._w
        # Only the contact states give a force, so "in contact" is "force > 0".
        return _new_tuple(PlantSample, (self.t_ns, self._x, w * self._rho, measured, peak,
                                        self._i, w, self._voltage, sensor_v, force > 0.0))

    def step(self, voltage_v: float, duration_s: float) -> PlantSample:
        """Hold ``voltage_v`` (clipped to the supply, the H-bridge limit) for ``duration_s``."""
        if not 0.0 < duration_s < math.inf:
            raise ValueError(f'duration must be finite and > 0, got {duration_s!r}')
        duration_ns = round(duration_s * 1e9)
        if duration_ns <= 0:
            raise ValueError(f'duration must be at least 1 ns, got {duration_s!r}')
        if not -math.inf < voltage_v < math.inf:
            raise ValueError(f'voltage must be finite, got {voltage_v!r}')
        limit = self._limit_v
        e = limit if voltage_v > limit else (-limit if voltage_v < -limit else voltage_v)
        self._voltage = e
        self._peak = self._force()
        start_ns = self.t_ns
        end_ns = start_ns + duration_ns
        hold = self._hold_live
        if self.scheduled_fault is None and (
                hold is None or hold.stays_stuck(self._peak, end_ns)):
            force = self._integrate(e, duration_ns * 1e-9, start_ns * 1e-9)
        else:
            self._step_in_pieces(e, start_ns, end_ns)
            force = None
        self.t_ns = end_ns
        self._t_now_s = end_ns * 1e-9
        if force is None or self._slip is not None:   # a slip capacity is read at the end time
            force = self._force()
        return self._sample(force)

    def _step_in_pieces(self, e: float, t_ns: int, end_ns: int) -> None:
        """Integrate ``[t_ns, end_ns]`` split at the fault, the lift's start and end, the loss.

        An event at ``end_ns`` itself takes effect in the next step (after this sample).
        """
        while t_ns < end_ns:
            fault = self.scheduled_fault
            if fault is not None and fault.at_ns <= t_ns:
                self._fire_fault(fault)
                fault = self.scheduled_fault
            hold = self._hold_live
            if hold is not None:
                hold.fire_events(t_ns)
                if not hold.live:
                    hold = self._hold_live = None
            piece_end_ns = end_ns
            if fault is not None and fault.at_ns < piece_end_ns:
                piece_end_ns = fault.at_ns
            if hold is not None:
                event_ns = hold.next_event_ns
                if event_ns is not None and event_ns < piece_end_ns:
                    piece_end_ns = event_ns
                if hold.state is HoldState.SLIDING and t_ns + self._h_ns < piece_end_ns:
                    piece_end_ns = t_ns + self._h_ns      # refresh the grip force while sliding
                loss_s = hold.advance(self._force(), (piece_end_ns - t_ns) * 1e-9)
                if loss_s is not None:
                    loss_ns = min(piece_end_ns, t_ns + round(loss_s * 1e9))
                    if loss_ns > t_ns:
                        self._integrate(e, (loss_ns - t_ns) * 1e-9, t_ns * 1e-9)
                    hold.lost_ns = loss_ns
                    self._remove_object(lost=True)
                    self._hold_live = None
                    t_ns = loss_ns
                    continue
            self._integrate(e, (piece_end_ns - t_ns) * 1e-9, t_ns * 1e-9)
            t_ns = piece_end_ns

    def _integrate(self, e: float, duration_s: float, start_s: float) -> float:
        """Advance ``duration_s`` at voltage ``e``; returns the contact force at its end."""
        remaining = duration_s
        h = self._h
        one_step = True       # a compliant interval may be one exact step until it is not
        force = self._peak
        while remaining > 1e-15:
            self._t_now_s = start_s + (duration_s - remaining)
            state = self._state
            if self._slip is not None and (state is _RIGID or state is _SLIPPING):
                remaining = self._advance_slipping(e, min(h, remaining), remaining)
            elif state is _FREE:
                if self._free_step_is_safe(e, remaining):
                    self._advance_free(e, remaining)
                    remaining = 0.0
                else:
                    dt = min(h, remaining)
                    self._advance_free(e, dt)
                    remaining -= dt
                    self._detect_contact()
            elif state is _RIGID or state is _OPEN_STOP:
                remaining = self._advance_stalled(e, remaining)
            else:
                if one_step and remaining <= self._compliant_one_step_s and \
                        self._advance_compliant_in_one_step(e, remaining):
                    remaining = 0.0
                else:
                    one_step = False   # the rest of this interval on the sub-step grid
                    dt = min(h, remaining)
                    self._advance_compliant(e, dt)
                    remaining -= dt
                    self._detect_separation()
            force = self._force()
            if force > self._peak:
                self._peak = force
        return force

    # ----------------------------------------------------------------- internals
    def _motor_force_n(self) -> float:
        """Return the force the motor torque pushes with through the lead screw (eq. 12)."""
        return self._kt * self._i / self._lever

    def _force(self) -> float:
        state = self._state
        if state is _RIGID:
            motor = self._kt * self._i / self._lever
            if not motor > 0.0:
                motor = 0.0
            return motor if self._slip is None else min(motor, self.slip_capacity_n())
        if state is _COMPLIANT:
            obj = self.object
            force = obj.stiffness_n_per_m * (self._x - self._x_c) \
                + obj.damping_n_s_per_m * self._w * self._rho
            return force if force > 0.0 else 0.0
        if state is _SLIPPING:
            return self.slip_capacity_n()
        return 0.0

    def _refresh_contact_state(self) -> None:
        """Re-derive the contact state after a reset or a new object."""
        x_c = self._x_c
        if self._x <= 0.0:
            self._x = 0.0
            self._state = _OPEN_STOP
        elif self._x >= x_c:
            self._state = _RIGID if self.object.rigid else _COMPLIANT
            if self.object.rigid:
                self._x = x_c
        else:
            self._state = _FREE

    def _discretise(self, compliant: bool, dt_s: float) -> tuple:
        """Exact ZOH over ``dt_s``: flat ``(Ad row 0 (4), row 1 (4), row 2 (4), Bd (3))``."""
        # Augmented state [i, omega, x, 1] so the contact's affine term discretises exactly.
        a = np.zeros((4, 4))
        a[:3, :3] = self._a_free
        if compliant:
            p, obj = self.params, self.object
            k, c = obj.stiffness_n_per_m, obj.damping_n_s_per_m
            a[1, 1] -= self._lever * c * self._rho / p.inertia_kg_m2
            a[1, 2] -= self._lever * k / p.inertia_kg_m2
            a[1, 3] += self._lever * k * self._x_c / p.inertia_kg_m2
        m = np.zeros((5, 5))
        m[:4, :4] = a * dt_s
        m[0, 4] = self._b[0] * dt_s
        phi = expm(m)
        return tuple(phi[:3, :4].ravel().tolist()) + tuple(phi[:3, 4].tolist())

    def _free(self, dt_s: float) -> tuple:
        cache = self._free_cache
        c = cache.get(dt_s)
        if c is None:
            c = self._store(cache, dt_s, self._discretise(False, dt_s))
        return c

    @staticmethod
    def _store(cache: dict, key, discretisation):
        """Cache a discretisation (bounded: a long run with many hold times stays small)."""
        if len(cache) > MAX_CACHED_DISCRETISATIONS:
            cache.clear()
        cache[key] = discretisation
        return discretisation

    def _advance_free(self, e: float, dt_s: float) -> None:
        c = self._free_cache.get(dt_s)
        if c is None:
            c = self._free(dt_s)
        i, w, x = self._i, self._w, self._x
        self._i = c[0] * i + c[1] * w + c[2] * x + c[3] + c[12] * e
        self._w = c[4] * i + c[5] * w + c[6] * x + c[7] + c[13] * e
        self._x = c[8] * i + c[9] * w + c[10] * x + c[11] + c[14] * e

    def _advance_compliant(self, e: float, dt_s: float) -> None:
        cache = self._compliant_cache
        c = cache.get(dt_s)
        if c is None:
            c = self._store(cache, dt_s, self._discretise(True, dt_s))
        i, w, x = self._i, self._w, self._x
        self._i = c[0] * i + c[1] * w + c[2] * x + c[3] + c[12] * e
        self._w = c[4] * i + c[5] * w + c[6] * x + c[7] + c[13] * e
        self._x = c[8] * i + c[9] * w + c[10] * x + c[11] + c[14] * e

    def _free_step_is_safe(self, e: float, dt_s: float) -> bool:
        """Tell whether free motion over dt can reach neither stop (rigorous reach bound).

        With ``W = sup |omega|`` over the step, ``|i| <= max(|i0|, (|e| + k_b W) / R)`` and
        ``|omega'| <= (k_t |i| + b W) / J``; with ``W <= |omega0| + alpha dt`` this gives
        ``alpha <= (k_t I0 + b |omega0|) / (J - (k_t k_b / R + b) dt)``, ``I0 = max(|i0|,
        (|e| + k_b |omega0|) / R)``, and the reach ``rho (|omega0| dt + alpha dt^2 / 2)``.
        """
        p = self.params
        slack = p.inertia_kg_m2 - self._reach_feedback * dt_s
        if slack <= 0.0:
            return False
        w0 = abs(self._w)
        i0 = max(abs(self._i), (abs(e) + p.back_emf_v_s_per_rad * w0) / p.resistance_ohm)
        alpha = (self._kt * i0 + p.damping_n_m_s_per_rad * w0) / slack
        reach = (self._rho * (w0 + 0.5 * alpha * dt_s) + FREE_REACH_MARGIN_MPS) * dt_s
        return self._x - reach > 0.0 and self._x + reach < self._x_c

    def _advance_compliant_in_one_step(self, e: float, dt_s: float) -> bool:
        """Step a compliant contact over ``dt_s`` at once; False (state kept) if it may not.

        It may not if the finger has left the face at the end (separation is then located on
        the sub-step grid), or if the force has an interior maximum above both ends (the peak is
        then found on the grid as well).
        """
        i0, w0, x0 = self._i, self._w, self._x
        rate0 = self._compliant_force_rate()
        self._advance_compliant(e, dt_s)
        obj = self.object
        depth = self._x - self._x_c
        if depth > 0.0 and obj.stiffness_n_per_m * depth \
                + obj.damping_n_s_per_m * self._w * self._rho >= 0.0:
            if rate0 <= 0.0:
                return True
            rate1 = self._compliant_force_rate()
            if rate1 >= 0.0 or rate0 * rate0 * dt_s / (2.0 * (rate0 - rate1)) <= \
                    PEAK_RESOLUTION_N:
                return True
        self._i, self._w, self._x = i0, w0, x0
        return False

    def _compliant_force_rate(self) -> float:
        """D/dt of the Kelvin-Voigt force ``k d + c d'`` in the present state (N/s)."""
        p, obj = self.params, self.object
        k, c = obj.stiffness_n_per_m, obj.damping_n_s_per_m
        v = self._w * self._rho
        force = k * (self._x - self._x_c) + c * v
        accel = (self._kt * self._i - p.damping_n_m_s_per_rad * self._w
                 - self._lever * force) / p.inertia_kg_m2 * self._rho
        return k * v + c * accel

    def _detect_contact(self) -> None:
        x_c = self._x_c
        if self._x >= x_c:
            if self.object.rigid:
                mass_equiv = self.params.inertia_kg_m2
                self.impact_energy_lost_j += 0.5 * mass_equiv * self._w ** 2
                self._x = x_c
                self._w = 0.0
                self._state = _RIGID
            else:
                self._state = _COMPLIANT
        elif self._x <= 0.0:
            self.impact_energy_lost_j += 0.5 * self.params.inertia_kg_m2 * self._w ** 2
            self._x = 0.0
            self._w = 0.0
            self._state = _OPEN_STOP

    def _detect_separation(self) -> None:
        obj = self.object
        depth = self._x - self._x_c
        if depth <= 0.0 or obj.stiffness_n_per_m * depth + obj.damping_n_s_per_m * self._w * \
                self._rho < 0.0:
            self._state = _FREE

    def _advance_stalled(self, e: float, dt_s: float) -> float:
        """Finger held by a rigid object or the open stop: only the current moves (first order).

        Returns the time left in the interval after the finger leaves the stop (0 if it stays).
        """
        i_inf = e / self.params.resistance_ohm
        i0 = self._i
        # The stop holds while the motor torque (sign of the current) pushes into it.
        into = 1.0 if self._state is _RIGID else -1.0
        if into * i0 < 0.0:
            t_leave = 0.0
        elif into * i_inf >= 0.0:
            t_leave = math.inf
        else:  # the current decays through zero on its way to i_inf
            t_leave = self._tau_e * math.log((i0 - i_inf) / (0.0 - i_inf))
        if t_leave >= dt_s:
            self._i = i_inf + (i0 - i_inf) * math.exp(-dt_s / self._tau_e)
            return 0.0
        self._i = i_inf + (i0 - i_inf) * math.exp(-t_leave / self._tau_e)
        self._state = _FREE
        return dt_s - t_leave

    # ----------------------------------------------------------------- slipping object
    def _advance_slipping(self, e: float, dt_s: float, remaining_s: float) -> float:
        """One sub-step of a gripped, slipping rigid object; returns the time left after it."""
        p = self.params
        cap = self.slip_capacity_n()
        if cap < SLIP_GONE_FRACTION * self._slip[1]:
            self._remove_object()                       # slid out: nothing left to grip
            return remaining_s
        if self._state is _RIGID:
            if self._motor_force_n() <= cap:             # the object holds: stalled, as usual
                left = self._advance_stalled(e, dt_s)
                return remaining_s - dt_s + left
            self._state = _SLIPPING                     # pushing harder than it can resist
        ad, bd = self._discretise_loaded(dt_s)
        s = (self._i, self._w, self._x)
        u = (e, cap)
        self._i, self._w, self._x = (
            sum(ad[r][c] * s[c] for c in range(3)) + bd[r][0] * u[0] + bd[r][1] * u[1]
            for r in range(3))
        end = p.max_travel_m
        if self._x >= end:                              # the object is gone, the fingers meet
            self._x = end
            self._w = 0.0
            self._slip = None
            self._use_object(_NOTHING)
            self._end_hold()
            self._state = _RIGID
        else:
            self._use_object(replace(self.object, width_m=end - self._x))   # the face recedes
            if self._w <= 0.0:                          # the finger stopped: it grips again
                self._w = 0.0
                self._state = _RIGID
        return remaining_s - dt_s

    def _discretise_loaded(self, dt_s: float):
        """Exact ZOH of free motion with two held inputs: voltage and a load force (N)."""
        cache = self._loaded_cache
        cached = cache.get(dt_s)
        if cached is not None:
            return cached
        m = np.zeros((5, 5))
        m[:3, :3] = self._a_free * dt_s
        m[0, 3] = self._b[0] * dt_s
        m[1, 4] = -self._lever / self.params.inertia_kg_m2 * dt_s
        phi = expm(m)
        return self._store(cache, dt_s, (phi[:3, :3].tolist(), phi[:3, 3:5].tolist()))
