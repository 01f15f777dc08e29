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

import enum
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm

from gripper_ros.core.config import ContactParams, PlantParams
from gripper_ros.core.force_sensor import FsrVoltageDivider
from gripper_ros.wire import FaultKind


DEFAULT_SLIP_TIME_CONSTANT_S = 0.01   # e-folding time of the slipping object's force capacity
SLIP_GONE_FRACTION = 0.01             # the object is out once its capacity is below 1 % of F_0
MAX_FAULT_DELAY_S = 600.0
MAX_CACHED_DISCRETISATIONS = 256


@dataclass(frozen=True)
class ScheduledFault:
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
    FREE = 'free'
    SLIPPING = 'slipping'              # a slipping object gives way: finger advances against C(t)
    RIGID_OBJECT = 'rigid_object'      # pressing a rigid object (or the other finger)
    COMPLIANT_OBJECT = 'compliant'     # compressing a compliant object
    OPEN_STOP = 'open_stop'            # resting on the fully-open end stop


@dataclass(frozen=True)
class GraspObject:
    """What lies between the fingers. width 0 = nothing (the fingers meet at full travel)."""

    width_m: float = 0.0
    stiffness_n_per_m: float = 0.0     # 0 = rigid
    damping_n_s_per_m: float = 0.0

    @property
    def rigid(self) -> bool:
        return self.stiffness_n_per_m == 0.0


@dataclass(frozen=True)
class PlantSample:
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
        self._a_free = np.array([
            [-p.resistance_ohm / p.inductance_h, -p.back_emf_v_s_per_rad / p.inductance_h, 0.0],
            [p.torque_constant_n_m_per_a / p.inertia_kg_m2, -p.damping_n_m_s_per_rad / p.inertia_kg_m2,
             0.0],
            [0.0, self._rho, 0.0]])
        self._b = np.array([1.0 / p.inductance_h, 0.0, 0.0])
        self._cache: dict[tuple, tuple[list, list]] = {}
        default = contact or ContactParams(0.0, 0.0)
        self.object = GraspObject(0.0, default.stiffness_n_per_m, default.damping_n_s_per_m)
        self.impact_energy_lost_j = 0.0
        self.t_ns = 0  # simulated time in integer nanoseconds: exact, the lockstep's tick key
        self.scheduled_fault: ScheduledFault | None = None
        self.fired_faults: list[tuple[FaultKind, int]] = []   # (kind, t_ns) since set_object
        self._slip: tuple[float, float, float] | None = None   # (t_f s, F_0 N, tau s)
        self._t_now_s = 0.0
        self.reset()

    # ----------------------------------------------------------------- set-up
    def reset(self, open_fingers: bool = True) -> None:
        """Motor at rest; optionally the finger back at the fully-open stop. Time keeps running."""
        self._i = 0.0
        self._w = 0.0
        if open_fingers:
            self._x = 0.0
        self._voltage = 0.0
        self._state = ContactState.OPEN_STOP if self._x <= 0.0 else ContactState.FREE
        self._peak = 0.0
        self.impact_energy_lost_j = 0.0
        self._refresh_contact_state()

    def touch_object(self) -> None:
        """Put the finger at rest just touching the object, motor off (force-loop studies)."""
        self._i = 0.0
        self._w = 0.0
        self._x = self.contact_position_m
        self._voltage = 0.0
        self._peak = 0.0
        self._state = (ContactState.RIGID_OBJECT if self.object.rigid
                       else ContactState.COMPLIANT_OBJECT)

    def set_object(self, obj: GraspObject) -> None:
        """Place an object (its fixed-finger face is the fixed finger; the other face at x_c)."""
        if not (math.isfinite(obj.width_m) and 0.0 <= obj.width_m < self.params.max_travel_m):
            raise ValueError(f'object width must be in [0, {self.params.max_travel_m}) m, '
                             f'got {obj.width_m!r}')
        for name in ('stiffness_n_per_m', 'damping_n_s_per_m'):
            value = getattr(obj, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'object {name} must be finite and >= 0, got {value!r}')
        if self._x > self.params.max_travel_m - obj.width_m:
            raise ValueError('the finger is already past the new object surface; open first')
        self.object = obj
        self.clear_faults()
        self._refresh_contact_state()

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
        if self._state is ContactState.SLIPPING:
            self._w = 0.0
            self._state = ContactState.RIGID_OBJECT

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

    def _remove_object(self) -> None:
        self._slip = None
        self.object = GraspObject(0.0)          # nothing: the fingers would meet at L_ls
        if self._state in (ContactState.RIGID_OBJECT, ContactState.COMPLIANT_OBJECT,
                           ContactState.SLIPPING) and self._x < self.params.max_travel_m:
            self._state = ContactState.FREE
        self._refresh_contact_state()

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    @property
    def contact_position_m(self) -> float:
        """Finger travel at which it touches the object."""
        return self.params.max_travel_m - self.object.width_m

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
        ad, bd = self._discretise(ContactState.FREE, dt_s)
        return np.array(ad)[:3, :3], np.array(bd)[:3]

    def discrete_force_model(self, dt_s: float) -> tuple[float, float]:
        """Exact ZOH of eq. 13: ``F[k+1] = a F[k] + b e[k]`` on a rigid object."""
        a = math.exp(-dt_s / self._tau_e)
        return a, self.params.stall_force_per_volt_n * (1.0 - a)

    # ----------------------------------------------------------------- simulation
    @property
    def contact_state(self) -> ContactState:
        return self._state

    def sample(self) -> PlantSample:
        force = self._force()
        measured, sensor_v = self.sensor.read(force)
        peak = math.nan if math.isnan(measured) else max(self._peak, force)
        return PlantSample(self.t_ns, self._x, self._w * self._rho, measured, peak,
                           self._i, self._w, self._voltage, sensor_v,
                           self._state in (ContactState.RIGID_OBJECT, ContactState.SLIPPING,
                                           ContactState.COMPLIANT_OBJECT) and force > 0.0)

    def step(self, voltage_v: float, duration_s: float) -> PlantSample:
        """Hold ``voltage_v`` (clipped to the supply, the H-bridge limit) for ``duration_s``."""
        if not math.isfinite(duration_s) or duration_s <= 0.0:
            raise ValueError(f'duration must be finite and > 0, got {duration_s!r}')
        duration_ns = round(duration_s * 1e9)
        if duration_ns <= 0:
            raise ValueError(f'duration must be at least 1 ns, got {duration_s!r}')
        duration_s = duration_ns * 1e-9
        if not math.isfinite(voltage_v):
            raise ValueError(f'voltage must be finite, got {voltage_v!r}')
        limit = self.params.voltage_limit_v
        e = min(limit, max(-limit, voltage_v))
        self._voltage = e
        self._peak = self._force()
        fault = self.scheduled_fault
        end_ns = self.t_ns + duration_ns
        if fault is not None and fault.at_ns < end_ns:
            before_ns = fault.at_ns - self.t_ns
            if before_ns > 0:
                self._integrate(e, before_ns * 1e-9, self.t_ns * 1e-9)
            self._fire_fault(fault)
            self._integrate(e, (duration_ns - before_ns) * 1e-9, fault.at_ns * 1e-9)
        else:
            self._integrate(e, duration_s, self.t_ns * 1e-9)
        self.t_ns = end_ns
        self._t_now_s = end_ns * 1e-9
        return self.sample()

    def _integrate(self, e: float, duration_s: float, start_s: float) -> None:
        remaining = duration_s
        h = self.params.contact_substep_s
        while remaining > 1e-15:
            self._t_now_s = start_s + (duration_s - remaining)
            if self._slip is not None and self._state in (ContactState.RIGID_OBJECT,
                                                          ContactState.SLIPPING):
                remaining = self._advance_slipping(e, min(h, remaining), remaining)
                self._peak = max(self._peak, self._force())
                continue
            if self._state is ContactState.FREE:
                if self._free_step_is_safe(e, remaining):
                    self._advance_linear(ContactState.FREE, e, remaining)
                    remaining = 0.0
                else:
                    dt = min(h, remaining)
                    self._advance_linear(ContactState.FREE, e, dt)
                    remaining -= dt
                    self._detect_contact()
            elif self._state in (ContactState.RIGID_OBJECT, ContactState.OPEN_STOP):
                remaining = self._advance_stalled(e, remaining)
            else:
                dt = min(h, remaining)
                self._advance_linear(ContactState.COMPLIANT_OBJECT, e, dt)
                remaining -= dt
                self._detect_separation()
            self._peak = max(self._peak, self._force())

    # ----------------------------------------------------------------- internals
    def _motor_force_n(self) -> float:
        """The force the motor torque pushes with through the lead screw (eq. 12)."""
        return self.params.torque_constant_n_m_per_a * self._i / self._lever

    def _force(self) -> float:
        if self._state is ContactState.SLIPPING:
            return self.slip_capacity_n()
        if self._state is ContactState.RIGID_OBJECT:
            motor = max(0.0, self._motor_force_n())
            return motor if self._slip is None else min(motor, self.slip_capacity_n())
        if self._state is ContactState.COMPLIANT_OBJECT:
            obj = self.object
            depth = self._x - self.contact_position_m
            return max(0.0, obj.stiffness_n_per_m * depth
                       + obj.damping_n_s_per_m * self._w * self._rho)
        return 0.0

    def _refresh_contact_state(self) -> None:
        """Re-derive the contact state after a reset or a new object."""
        x_c = self.contact_position_m
        if self._x <= 0.0:
            self._x = 0.0
            self._state = ContactState.OPEN_STOP
        elif self._x >= x_c:
            self._state = (ContactState.RIGID_OBJECT if self.object.rigid
                           else ContactState.COMPLIANT_OBJECT)
            if self.object.rigid:
                self._x = x_c
        else:
            self._state = ContactState.FREE

    def _discretise(self, regime: ContactState, dt_s: float):
        key = (regime, dt_s, self.object) if regime is ContactState.COMPLIANT_OBJECT \
            else (regime, dt_s)
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        # Augmented state [i, omega, x, 1] so the contact's affine term discretises exactly.
        a = np.zeros((4, 4))
        a[:3, :3] = self._a_free
        if regime is ContactState.COMPLIANT_OBJECT:
            p, obj = self.params, self.object
            k, c = obj.stiffness_n_per_m, obj.damping_n_s_per_m
            a[1, 1] -= self._lever * c * self._rho / p.inertia_kg_m2
            a[1, 2] -= self._lever * k / p.inertia_kg_m2
            a[1, 3] += self._lever * k * self.contact_position_m / p.inertia_kg_m2
        m = np.zeros((5, 5))
        m[:4, :4] = a * dt_s
        m[0, 4] = self._b[0] * dt_s
        phi = expm(m)
        return self._store(key, (phi[:4, :4].tolist(), phi[:4, 4].tolist()))

    def _store(self, key, discretisation):
        """Cache a discretisation (bounded: a long run with many hold times stays small)."""
        if len(self._cache) > MAX_CACHED_DISCRETISATIONS:
            self._cache.clear()
        self._cache[key] = discretisation
        return discretisation

    def _advance_linear(self, regime: ContactState, e: float, dt_s: float) -> None:
        ad, bd = self._discretise(regime, dt_s)
        s = (self._i, self._w, self._x, 1.0)
        self._i = ad[0][0] * s[0] + ad[0][1] * s[1] + ad[0][2] * s[2] + ad[0][3] + bd[0] * e
        self._w = ad[1][0] * s[0] + ad[1][1] * s[1] + ad[1][2] * s[2] + ad[1][3] + bd[1] * e
        self._x = ad[2][0] * s[0] + ad[2][1] * s[1] + ad[2][2] * s[2] + ad[2][3] + bd[2] * e

    def _free_step_is_safe(self, e: float, dt_s: float) -> bool:
        """True if free motion over dt cannot reach either stop (speed bound, conservative)."""
        # The speed of this overdamped drive moves monotonically towards the free speed of the
        # held voltage, except for the short electrical transient; a 20 % margin covers it.
        v_bound = 1.2 * max(abs(self._w * self._rho), abs(self.free_speed_mps(e))) + 1e-9
        reach = v_bound * dt_s
        return self._x - reach > 0.0 and self._x + reach < self.contact_position_m

    def _detect_contact(self) -> None:
        x_c = self.contact_position_m
        if self._x >= x_c:
            if self.object.rigid:
                mass_equiv = self.params.inertia_kg_m2
                self.impact_energy_lost_j += 0.5 * mass_equiv * self._w ** 2
                self._x = x_c
                self._w = 0.0
                self._state = ContactState.RIGID_OBJECT
            else:
                self._state = ContactState.COMPLIANT_OBJECT
        elif self._x <= 0.0:
            self.impact_energy_lost_j += 0.5 * self.params.inertia_kg_m2 * self._w ** 2
            self._x = 0.0
            self._w = 0.0
            self._state = ContactState.OPEN_STOP

    def _detect_separation(self) -> None:
        obj = self.object
        depth = self._x - self.contact_position_m
        if depth <= 0.0 or obj.stiffness_n_per_m * depth + obj.damping_n_s_per_m * self._w * \
                self._rho < 0.0:
            self._state = ContactState.FREE

    def _advance_stalled(self, e: float, dt_s: float) -> float:
        """Finger held by a rigid object or the open stop: only the current moves (first order).

        Returns the time left in the interval after the finger leaves the stop (0 if it stays).
        """
        i_inf = e / self.params.resistance_ohm
        i0 = self._i
        # The stop holds while the motor torque (sign of the current) pushes into it.
        into = 1.0 if self._state is ContactState.RIGID_OBJECT else -1.0
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
        self._state = ContactState.FREE
        return dt_s - t_leave

    # ----------------------------------------------------------------- slipping object
    def _advance_slipping(self, e: float, dt_s: float, remaining_s: float) -> float:
        """One sub-step of a gripped, slipping rigid object; returns the time left after it."""
        p = self.params
        cap = self.slip_capacity_n()
        if cap < SLIP_GONE_FRACTION * self._slip[1]:
            self._remove_object()                       # slid out: nothing left to grip
            return remaining_s
        if self._state is ContactState.RIGID_OBJECT:
            if self._motor_force_n() <= cap:             # the object holds: stalled, as usual
                left = self._advance_stalled(e, dt_s)
                return remaining_s - dt_s + left
            self._state = ContactState.SLIPPING         # pushing harder than it can resist
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
            self.object = GraspObject(0.0)
            self._state = ContactState.RIGID_OBJECT
        else:
            self.object = replace(self.object, width_m=end - self._x)   # the face recedes
            if self._w <= 0.0:                          # the finger stopped: it grips again
                self._w = 0.0
                self._state = ContactState.RIGID_OBJECT
        return remaining_s - dt_s

    def _discretise_loaded(self, dt_s: float):
        """Exact ZOH of free motion with two held inputs: voltage and a load force (N)."""
        key = ('loaded', dt_s)
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        m = np.zeros((5, 5))
        m[:3, :3] = self._a_free * dt_s
        m[0, 3] = self._b[0] * dt_s
        m[1, 4] = -self._lever / self.params.inertia_kg_m2 * dt_s
        phi = expm(m)
        return self._store(key, (phi[:3, :3].tolist(), phi[:3, 3:5].tolist()))
