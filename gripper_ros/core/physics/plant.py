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

* flexible fingers and nonlinear pads (``contact.finger_stiffness_n_per_m``,
  ``contact.pad_normal_stiffness_n_per_m1_5`` > 0): every contact, rigid or compliant object,
  is the series chain finger - pad - object - pad - finger of
  :mod:`gripper_ros.core.physics.contact_chain`, one force through all, solved each sub-step. With
  both keys 0 the two models above run unchanged.

The fully-open end stop (``x = 0``) is rigid and senses no force; with no object the fingers meet
at ``x = L_ls`` (a rigid object of width 0).

Integration: an interval in which no contact event can happen is one exact ZOH step. Free motion
is one step when a rigorous bound on the finger's reach (its speed grows by at most the
acceleration the current can give) keeps it clear of both stops; compliant contact is one step
when the step is short against the object's spring mode and the finger is still in contact at
its end. Otherwise the interval is sub-stepped at ``contact_substep_s`` and contact or
separation is located on that grid.

Holding (:mod:`gripper_ros.core.physics.hold`): a lifted object is held by Coulomb friction on both
pads at the plant's contact force, and may slide and be lost; :meth:`GripperPlant.begin_hold`
starts the lift's clock, :attr:`GripperPlant.object_state` reports it. A step is split at the
lift's start and end and at the loss, and the grip force is taken at the start of each piece (at
most one ``contact_substep_s`` long while the object slides). At the loss the object is gone, as
for ``OBJECT_REMOVED``.

Fault injection (tests and demos; :meth:`GripperPlant.schedule_fault`, one fault fires at an exact
simulated instant, the step is split there):

* ``OBJECT_REMOVED``: the object vanishes; the finger is free to move on (to the other finger).
* ``OBJECT_SLIPPING`` (rigid objects): the object slides out of the grip. The most force it can
  resist decays as ``C(t) = F_0 exp(-(t - t_f)/tau)`` from the force ``F_0`` at the fault
  instant ``t_f``. While the motor pushes harder than ``C`` the finger advances against the
  constant load ``C`` (the face recedes with it) and the measured force is ``C``; once
  ``C < 1 %`` of ``F_0`` the object is out and gone. Fired while nothing is gripped
  (``F_0 = 0``), or with flexible fingers or pads (the chain below), it acts as a removal.
* ``SENSOR_DROPOUT``: the force sensor reports NaN force and voltage from then on
  (:class:`gripper_ros.core.physics.force_sensor.FsrVoltageDivider`); the mechanics are unaffected.

Effects last until the next :meth:`GripperPlant.set_object` (a new object, a repaired sensor).

Compiled core (numba): the state lives in numpy records, and ``GripperPlant.kernel`` is the
tuple ``k`` of the plant's buffers, indexed by ``K_*``: the state (:data:`STATE_DTYPE`), the
constants (:data:`PARAMS_DTYPE`), the object's hold
(:data:`gripper_ros.core.physics.hold.HOLD_DTYPE`), the sensor
(:data:`gripper_ros.core.physics.force_sensor.SENSOR_DTYPE`, the record the plant's
:class:`FsrVoltageDivider` wraps), the faults fired since ``set_object`` (int64 rows ``(kind,
t_ns)``) and the table of discretisations (keys ``(kind, dt_s, k, c, x_c)``, 15 coefficients
each). The entry points :func:`plant_step`, :func:`plant_read_tick`, :func:`plant_begin_hold`,
:func:`plant_scenario_in_progress`, :func:`plant_schedule_fault`, :func:`plant_cancel_fault` and
:func:`plant_fault_scheduled` take ``k`` and are called by the facade and by compiled loops. The
matrix exponential is computed in Python (:func:`_discretise`, with
:func:`gripper_ros.core.linalg.expm`): a table miss calls it in object mode, so every coefficient
is the one the Python plant used.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
import enum
import math
from typing import NamedTuple

from gripper_ros.core.config import (ChannelSpec, ContactParams, object_contact, PadSensorParams,
                                     PlantParams)
from gripper_ros.core.linalg import expm
from gripper_ros.core.physics.contact_chain import chain_solve, PADS_IN_CHAIN
from gripper_ros.core.physics.force_sensor import (fsr_voltage_v, FsrVoltageDivider,
                                                   NOISE_CHANNEL_FORCE, NOISE_CHANNEL_POSITION,
                                                   noisy_reading)
from gripper_ros.core.physics.hold import (ANNOUNCE_ROWS, check_finite_nonnegative,
                                           hold_advance, hold_begin, hold_capacity_n,
                                           hold_drive, HOLD_DTYPE, hold_fire_events,
                                           hold_live, hold_load_n, hold_plan,
                                           hold_presliding_m, hold_remove,
                                           hold_scenario_in_progress, hold_shear_n,
                                           hold_stays_stuck, HoldModel, HoldState, Lift,
                                           ObjectState)
from gripper_ros.core.physics.pad_sensor import (CHANNEL_DTYPE, channel_step, make_channel,
                                                 MAX_LATENCY_SAMPLES)
from gripper_ros.core.records import copy_fields, RecordField
from gripper_ros.wire import FaultKind, TICK_LAYOUT
import numba
import numpy as np


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
           'GripperPlant', 'HoldState', 'Lift', 'ObjectState', 'PARAMS_DTYPE', 'PlantSample',
           'STATE_DTYPE', 'ScheduledFault', 'check_fault', 'plant_begin_hold',
           'plant_cancel_fault', 'plant_fault_scheduled', 'plant_hold_record', 'plant_place',
           'plant_read_tick', 'plant_sample',
           'plant_scenario_in_progress', 'plant_schedule_fault', 'plant_step']


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

# ----------------------------------------------------------------------------- kernel buffers
# Contact-state codes of the ``contact`` field (ContactState in the facade).
CONTACT_FREE = 0
CONTACT_SLIPPING = 1
CONTACT_RIGID = 2
CONTACT_COMPLIANT = 3
CONTACT_OPEN_STOP = 4
_CONTACT_STATES = (ContactState.FREE, ContactState.SLIPPING, ContactState.RIGID_OBJECT,
                   ContactState.COMPLIANT_OBJECT, ContactState.OPEN_STOP)

# Discretisation kinds (column 0 of the table's keys).
DISC_FREE = 0
DISC_COMPLIANT = 1
DISC_LOADED = 2
DISC_TABLE_SIZE = 64          # entries of the plant's table (a grasp uses about 8)
DISC_COEFFICIENTS = 15        # one entry's coefficients, in one of the two layouts below
# DISC_FREE and DISC_COMPLIANT: rows i, omega, x of the augmented Ad (over [i, omega, x, 1],
# so the contact's affine term is exact), then Bd. AFF_WX is omega's row, x's column.
(AFF_II, AFF_IW, AFF_IX, AFF_I1, AFF_WI, AFF_WW, AFF_WX, AFF_W1, AFF_XI, AFF_XW, AFF_XX,
 AFF_X1, AFF_IE, AFF_WE, AFF_XE) = range(DISC_COEFFICIENTS)
# DISC_LOADED: Ad (3 x 3) row by row, then Bd's rows over the inputs (voltage E, load force F).
(LD_II, LD_IW, LD_IX, LD_WI, LD_WW, LD_WX, LD_XI, LD_XW, LD_XX, LD_IE, LD_IF, LD_WE, LD_WF,
 LD_XE, LD_XF) = range(DISC_COEFFICIENTS)
MAX_FIRED_FAULTS = 16         # fired faults kept since set_object (the oldest are dropped)

# The entries of the tuple ``GripperPlant.kernel``.
# Few arrays: the compiled code copies the tuple on every call it does not inline.
K_STATE, K_PARAMS, K_HOLD, K_SENSOR, K_FIRED, K_DISC_KEYS, K_DISC_COEF, K_PADS = range(8)

# The pad channels (K_PADS rows, core/physics/pad_sensor.py), in PlantTick's order of their
# readings.
PAD_SHEAR_1, PAD_SHEAR_2, PAD_DISPLACEMENT_1, PAD_DISPLACEMENT_2 = range(4)
PAD_CHANNELS = 4
PAD_DTYPE = np.dtype([(name, CHANNEL_DTYPE.fields[name][0]) for name in CHANNEL_DTYPE.names]
                     + [('line', np.float64, (MAX_LATENCY_SAMPLES,))], align=True)
"""A pad channel's record (pad_sensor.CHANNEL_DTYPE) with its delay line."""

PARAMS_DTYPE = np.dtype([
    ('rho', np.float64),                   # p / (2 pi), m per motor rad (eq. 10)
    ('lever', np.float64),                 # eta p N1/N2, N m of torque per N of force (eq. 12)
    ('tau_e', np.float64),                 # L / R (s)
    ('kt', np.float64),
    ('kb', np.float64),
    ('resistance_ohm', np.float64),
    ('inductance_h', np.float64),
    ('inertia_kg_m2', np.float64),
    ('damping_n_m_s_per_rad', np.float64),
    ('max_travel_m', np.float64),
    ('h', np.float64),                     # contact_substep_s
    ('h_ns', np.int64),
    ('limit_v', np.float64),
    ('reach_feedback', np.float64),        # k_t k_b / R + b (free-reach bound)
    ('after_lift_ns', np.int64),           # contact.after_lift_s in ns
    ('two', np.float64),                   # 2.0 read at run time: w ** two is Python's w ** 2
    ('pad_dt_ns', np.int64),               # the pad channels' sample period
    # flexible fingers and Hertz pads in series with the object (core/physics/contact_chain.py)
    ('chain', np.uint8),                   # 1: either is on; every contact is a chain
    ('finger_compliance_m_per_n', np.float64),   # 2 / k_f, both fingers (0: rigid)
    ('pad_stiffness_n_per_m1_5', np.float64),    # k_p of each pad (0: no pad)
], align=True)
"""The plant's constants (Table I and derived), as one record."""

STATE_DTYPE = np.dtype([
    ('t_ns', np.int64),                    # simulated time, integer ns
    ('t_now_s', np.float64),               # time of the piece being integrated (slip capacity)
    ('i', np.float64),                     # armature current (A)
    ('w', np.float64),                     # motor speed (rad/s)
    ('x', np.float64),                     # finger travel from fully open (m)
    ('voltage', np.float64),               # applied (clipped) armature voltage (V)
    ('contact', np.int64),                 # CONTACT_* code (the facade's ContactState)
    ('peak', np.float64),                  # largest force in the step (N)
    ('impact_energy_lost_j', np.float64),
    ('width_m', np.float64),               # the object (GraspObject's fields)
    ('stiffness_n_per_m', np.float64),
    ('damping_n_s_per_m', np.float64),
    ('mass_kg', np.float64),
    ('static_friction', np.float64),
    ('kinetic_friction', np.float64),
    ('pad_length_m', np.float64),
    ('x_c', np.float64),                   # travel at which the finger touches the object
    ('compliant_one_step_s', np.float64),
    ('has_slip', np.uint8),                # an OBJECT_SLIPPING fault is acting
    ('slip_t_f_s', np.float64),
    ('slip_f_0_n', np.float64),
    ('slip_tau_s', np.float64),
    ('fault_kind', np.int64),              # FaultKind scheduled, NONE = none
    ('fault_at_ns', np.int64),
    ('fault_time_constant_s', np.float64),
    ('fired_count', np.int64),             # rows of the fired-faults array in use
    ('disc_count', np.int64),              # entries of the discretisation table in use
    ('disc_next', np.int64),               # the entry a miss overwrites once it is full
    ('disc_last', np.int64),               # the entry last found (looked at first)
    ('pads_resting', np.uint8),            # the pad channels read 0: nothing is held
    ('chain_force_n', np.float64),         # the chain's force (contact_chain.py)
    ('chain_object_m', np.float64),        # the object's own compression d_o in the chain
    ('chain_pad_m', np.float64),           # each pad's compression (Newton's next start)
], align=True)
"""The plant's mutable state: mechanics, object, slip, scheduled fault, table bookkeeping."""


def _plant_params_record(params: PlantParams, contact: ContactParams) -> np.ndarray:
    p = params
    rec = np.zeros(1, PARAMS_DTYPE)
    r = rec[0]
    r['rho'] = p.travel_per_rad_m
    r['lever'] = p.force_lever_m
    r['tau_e'] = p.inductance_h / p.resistance_ohm
    r['kt'] = p.torque_constant_n_m_per_a
    r['kb'] = p.back_emf_v_s_per_rad
    copy_fields(r, p, ('resistance_ohm', 'inductance_h', 'inertia_kg_m2', 'damping_n_m_s_per_rad',
                       'max_travel_m'))
    r['h'] = p.contact_substep_s
    r['h_ns'] = max(1, round(p.contact_substep_s * 1e9))
    r['limit_v'] = p.voltage_limit_v
    # Free-reach bound (see _free_step_is_safe): |omega'| <= (k_t I + b W) / J.
    r['reach_feedback'] = (p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad
                           / p.resistance_ohm + p.damping_n_m_s_per_rad)
    r['after_lift_ns'] = round(contact.after_lift_s * 1e9)
    r['two'] = 2.0
    finger_k = contact.finger_stiffness_n_per_m
    r['finger_compliance_m_per_n'] = PADS_IN_CHAIN / finger_k if finger_k > 0.0 else 0.0
    r['pad_stiffness_n_per_m1_5'] = contact.pad_normal_stiffness_n_per_m1_5
    r['chain'] = 1 if finger_k > 0.0 or contact.pad_normal_stiffness_n_per_m1_5 > 0.0 else 0
    return rec


# ----------------------------------------------------------------------------- discretisation
# Exact ZOH coefficients, shared by all plants (a sweep builds many):
# (constants, kind, dt_s, k, c, x_c) -> DISC_COEFFICIENTS coefficients.
_DISCRETISATIONS: dict[tuple, np.ndarray] = {}


def _discretise(raw: tuple, kind: int, dt_s: float, stiffness: float, damping: float,
                x_c: float) -> np.ndarray:
    """Exact ZOH over ``dt_s`` (:func:`linalg.expm`), flat.

    In the layout ``AFF_*`` (free, compliant) or ``LD_*`` (loaded: a held voltage and load force
    in N). ``raw`` = (R, L, k_b, k_t, J, b, rho, lever).
    """
    key = (raw, kind, dt_s, stiffness, damping, x_c)
    cached = _DISCRETISATIONS.get(key)
    if cached is not None:
        return cached
    r, ind, kb, kt, inertia, b, rho, lever = raw
    a_free = np.array([[-r / ind, -kb / ind, 0.0],
                       [kt / inertia, -b / inertia, 0.0],
                       [0.0, rho, 0.0]])
    b0 = 1.0 / ind
    if kind == DISC_LOADED:
        m = np.zeros((5, 5))
        m[:3, :3] = a_free * dt_s
        m[0, 3] = b0 * dt_s
        m[1, 4] = -lever / inertia * dt_s
        phi = expm(m)
        out = np.concatenate((phi[:3, :3].ravel(), phi[:3, 3:5].ravel()))
    else:
        a = np.zeros((4, 4))
        a[:3, :3] = a_free
        if kind == DISC_COMPLIANT:
            a[1, 1] -= lever * damping * rho / inertia
            a[1, 2] -= lever * stiffness / inertia
            a[1, 3] += lever * stiffness * x_c / inertia
        m = np.zeros((5, 5))
        m[:4, :4] = a * dt_s
        m[0, 4] = b0 * dt_s
        phi = expm(m)
        out = np.concatenate((phi[:3, :4].ravel(), phi[:3, 4]))
    if len(_DISCRETISATIONS) > 4 * MAX_CACHED_DISCRETISATIONS:
        _DISCRETISATIONS.clear()
    _DISCRETISATIONS[key] = out
    return out


def _raw_constants(params: PlantParams) -> tuple:
    p = params
    return (p.resistance_ohm, p.inductance_h, p.back_emf_v_s_per_rad,
            p.torque_constant_n_m_per_a, p.inertia_kg_m2, p.damping_n_m_s_per_rad,
            p.travel_per_rad_m, p.force_lever_m)


def _discretise_from_kernel(r, ind, kb, kt, inertia, b, rho, lever, kind, dt_s, stiffness,
                            damping, x_c):
    """:func:`_discretise` for the kernels' table (called in object mode on a miss)."""
    return _discretise((r, ind, kb, kt, inertia, b, rho, lever), int(kind), dt_s, stiffness,
                       damping, x_c)


@numba.njit(cache=True, inline='always')
def _disc_entry(s, p, keys, coef, kind, dt_s):
    """Row of the discretisation table for ``kind`` over ``dt_s`` (computed on a miss)."""
    if kind == DISC_COMPLIANT:
        stiffness = s.stiffness_n_per_m
        damping = s.damping_n_s_per_m
        x_c = s.x_c
    else:
        stiffness = 0.0
        damping = 0.0
        x_c = 0.0
    j = s.disc_last
    if j < s.disc_count and keys[j, 0] == kind and keys[j, 1] == dt_s and \
            keys[j, 2] == stiffness and keys[j, 3] == damping and keys[j, 4] == x_c:
        return j
    for j in range(s.disc_count):
        if keys[j, 0] == kind and keys[j, 1] == dt_s and keys[j, 2] == stiffness and \
                keys[j, 3] == damping and keys[j, 4] == x_c:
            s.disc_last = j
            return j
    return _disc_miss(s, p, keys, coef, kind, dt_s, stiffness, damping, x_c)


@numba.njit(cache=True)
def _disc_miss(s, p, keys, coef, kind, dt_s, stiffness, damping, x_c):
    """Compute a discretisation in Python (:func:`linalg.expm`) and store it in the table."""
    r = p.resistance_ohm
    ind = p.inductance_h
    kb = p.kb
    kt = p.kt
    inertia = p.inertia_kg_m2
    b = p.damping_n_m_s_per_rad
    rho = p.rho
    lever = p.lever
    fkind = float(kind)
    with numba.objmode(out='float64[:]'):
        out = _discretise_from_kernel(r, ind, kb, kt, inertia, b, rho, lever, fkind, dt_s,
                                      stiffness, damping, x_c)
    j = s.disc_next
    keys[j, 0] = kind
    keys[j, 1] = dt_s
    keys[j, 2] = stiffness
    keys[j, 3] = damping
    keys[j, 4] = x_c
    for n in range(DISC_COEFFICIENTS):
        coef[j, n] = out[n]
    s.disc_next = (j + 1) % DISC_TABLE_SIZE
    if s.disc_count < DISC_TABLE_SIZE:
        s.disc_count += 1
    s.disc_last = j
    return j


# ----------------------------------------------------------------------------- kernels
@numba.njit(cache=True, inline='always')
def _slip_capacity_n(s, t_s):
    """Force the slipping object can still resist at ``t_s`` (inf when not slipping)."""
    if not s.has_slip:
        return math.inf
    d = t_s - s.slip_t_f_s
    return s.slip_f_0_n * math.exp(-(d if d > 0.0 else 0.0) / s.slip_tau_s)


@numba.njit(cache=True, inline='always')
def _force(s, p):
    """Contact force now (N): motor torque on a rigid face, Kelvin-Voigt, a slip's capacity."""
    state = s.contact
    if state == CONTACT_RIGID:
        motor = p.kt * s.i / p.lever
        if not motor > 0.0:
            motor = 0.0
        if not s.has_slip:
            return motor
        cap = _slip_capacity_n(s, s.t_now_s)
        return cap if cap < motor else motor
    if state == CONTACT_COMPLIANT:
        if p.chain:
            return s.chain_force_n
        force = s.stiffness_n_per_m * (s.x - s.x_c) + s.damping_n_s_per_m * s.w * p.rho
        return force if force > 0.0 else 0.0
    if state == CONTACT_SLIPPING:
        return _slip_capacity_n(s, s.t_now_s)
    return 0.0


@numba.njit(cache=True)
def _refresh_contact_state(s, p):
    """Re-derive the contact state after a reset or a new object."""
    x_c = s.x_c
    if s.x <= 0.0:
        s.x = 0.0
        s.contact = CONTACT_OPEN_STOP
    elif s.x >= x_c:
        rigid = s.stiffness_n_per_m == 0.0 and not p.chain
        s.contact = CONTACT_RIGID if rigid else CONTACT_COMPLIANT
        if rigid:
            s.x = x_c
        if p.chain:
            _chain_at_rest(s, p)
    else:
        s.contact = CONTACT_FREE


@numba.njit(cache=True)
def _use_object(s, p, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
                pad_length_m):
    """Make the object between the fingers the given one (geometry; spring mode)."""
    s.width_m = width_m
    s.stiffness_n_per_m = stiffness
    s.damping_n_s_per_m = damping
    s.mass_kg = mass_kg
    s.static_friction = static_friction
    s.kinetic_friction = kinetic_friction
    s.pad_length_m = pad_length_m
    s.x_c = p.max_travel_m - width_m
    if stiffness == 0.0:
        s.compliant_one_step_s = 0.0
    else:
        spring_rad_s = math.sqrt(p.lever * stiffness * p.rho / p.inertia_kg_m2)
        s.compliant_one_step_s = COMPLIANT_ONE_STEP_PHASE_RAD / spring_rad_s


@numba.njit(cache=True)
def _reset(k, open_fingers):
    """Motor at rest; optionally the finger back at the fully-open stop."""
    s = k[K_STATE][0]
    p = k[K_PARAMS][0]
    s.i = 0.0
    s.w = 0.0
    if open_fingers:
        s.x = 0.0
    s.voltage = 0.0
    s.contact = CONTACT_OPEN_STOP if s.x <= 0.0 else CONTACT_FREE
    s.peak = 0.0
    s.impact_energy_lost_j = 0.0
    _refresh_contact_state(s, p)


@numba.njit(cache=True)
def _touch_object(k):
    """Put the finger at rest just touching the object, motor off."""
    s = k[K_STATE][0]
    s.i = 0.0
    s.w = 0.0
    s.x = s.x_c
    s.voltage = 0.0
    s.peak = 0.0
    s.contact = CONTACT_RIGID if s.stiffness_n_per_m == 0.0 and not \
        k[K_PARAMS][0].chain else CONTACT_COMPLIANT
    _chain_untouched(s)


@numba.njit(cache=True)
def _clear_fault_state(s, sensor):
    s.fault_kind = FaultKind.NONE
    s.fired_count = 0
    sensor.dropped_out = 0
    s.has_slip = 0
    if s.contact == CONTACT_SLIPPING:
        s.w = 0.0
        s.contact = CONTACT_RIGID


@numba.njit(cache=True)
def _set_object(k, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
                pad_length_m):
    """Place a validated object (the hold record is already the object's)."""
    s = k[K_STATE][0]
    p = k[K_PARAMS][0]
    _use_object(s, p, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
                pad_length_m)
    k[K_HOLD][0].live = 0
    _clear_fault_state(s, k[K_SENSOR][0])
    _refresh_contact_state(s, p)


@numba.njit(cache=True)
def _use_default_object(k, stiffness, damping):
    """Place a new plant's object: width 0 (nothing), the contact defaults' stiffness."""
    _use_object(k[K_STATE][0], k[K_PARAMS][0], 0.0, stiffness, damping, 0.0, 0.0, 0.0, 0.0)


@numba.njit(cache=True)
def _end_hold(h):
    if h.has_hold and h.state != HoldState.LOST:
        hold_remove(h)
    h.live = 0


@numba.njit(cache=True)
def _remove_object(s, p, h, lost):
    """Nothing between the fingers from now on (slid out of the pads if ``lost``)."""
    s.has_slip = 0
    _use_object(s, p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)   # the fingers would meet at L_ls
    if not lost:
        _end_hold(h)
    state = s.contact
    if (state == CONTACT_RIGID or state == CONTACT_COMPLIANT or state == CONTACT_SLIPPING) \
            and s.x < p.max_travel_m:
        s.contact = CONTACT_FREE
    _refresh_contact_state(s, p)


@numba.njit(cache=True)
def _fire_fault(s, p, h, sensor, fired):
    """Fire the scheduled fault (its instant has come)."""
    kind = s.fault_kind
    at_ns = s.fault_at_ns
    s.fault_kind = FaultKind.NONE
    n = s.fired_count
    if n == fired.shape[0]:                # full: drop the oldest
        for r in range(n - 1):
            fired[r, 0] = fired[r + 1, 0]
            fired[r, 1] = fired[r + 1, 1]
        n -= 1
    fired[n, 0] = kind
    fired[n, 1] = at_ns
    s.fired_count = n + 1
    if kind == FaultKind.SENSOR_DROPOUT:
        sensor.dropped_out = 1
    elif kind == FaultKind.OBJECT_REMOVED:
        _remove_object(s, p, h, False)
    elif kind == FaultKind.OBJECT_SLIPPING:
        f_0 = _force(s, p)
        if f_0 <= 0.0 or p.chain:        # the decaying capacity is the rigid contact's
            _remove_object(s, p, h, False)
        else:
            s.has_slip = 1
            s.slip_t_f_s = at_ns * 1e-9
            s.slip_f_0_n = f_0
            s.slip_tau_s = s.fault_time_constant_s


@numba.njit(cache=True, inline='always')
def _advance_zoh(s, p, keys, coef, kind, e, dt_s):
    """Exact ZOH step of free motion (DISC_FREE) or of compressing a Kelvin-Voigt object."""
    c = coef[_disc_entry(s, p, keys, coef, kind, dt_s)]
    i = s.i
    w = s.w
    x = s.x
    s.i = c[AFF_II] * i + c[AFF_IW] * w + c[AFF_IX] * x + c[AFF_I1] + c[AFF_IE] * e
    s.w = c[AFF_WI] * i + c[AFF_WW] * w + c[AFF_WX] * x + c[AFF_W1] + c[AFF_WE] * e
    s.x = c[AFF_XI] * i + c[AFF_XW] * w + c[AFF_XX] * x + c[AFF_X1] + c[AFF_XE] * e


@numba.njit(cache=True, inline='always')
def _free_step_is_safe(s, p, e, dt_s):
    """Tell whether free motion over dt can reach neither stop (rigorous reach bound).

    With ``W = sup |omega|`` over the step, ``|i| <= max(|i0|, (|e| + k_b W) / R)`` and
    ``|omega'| <= (k_t |i| + b W) / J``; with ``W <= |omega0| + alpha dt`` this gives
    ``alpha <= (k_t I0 + b |omega0|) / (J - (k_t k_b / R + b) dt)``, ``I0 = max(|i0|,
    (|e| + k_b |omega0|) / R)``, and the reach ``rho (|omega0| dt + alpha dt^2 / 2)``.
    """
    slack = p.inertia_kg_m2 - p.reach_feedback * dt_s
    if slack <= 0.0:
        return False
    w0 = abs(s.w)
    i_abs = abs(s.i)
    i_emf = (abs(e) + p.kb * w0) / p.resistance_ohm
    i0 = i_emf if i_emf > i_abs else i_abs
    alpha = (p.kt * i0 + p.damping_n_m_s_per_rad * w0) / slack
    reach = (p.rho * (w0 + 0.5 * alpha * dt_s) + FREE_REACH_MARGIN_MPS) * dt_s
    return s.x - reach > 0.0 and s.x + reach < s.x_c


@numba.njit(cache=True, inline='always')
def _compliant_force_rate(s, p):
    """D/dt of the Kelvin-Voigt force ``k d + c d'`` in the present state (N/s)."""
    stiffness = s.stiffness_n_per_m
    damping = s.damping_n_s_per_m
    v = s.w * p.rho
    force = stiffness * (s.x - s.x_c) + damping * v
    accel = (p.kt * s.i - p.damping_n_m_s_per_rad * s.w
             - p.lever * force) / p.inertia_kg_m2 * p.rho
    return stiffness * v + damping * accel


@numba.njit(cache=True)
def _advance_compliant_in_one_step(s, p, keys, coef, e, dt_s):
    """Step a compliant contact over ``dt_s`` at once; False (state kept) if it may not.

    It may not if the finger has left the face at the end (separation is then located on
    the sub-step grid), or if the force has an interior maximum above both ends (the peak is
    then found on the grid as well).
    """
    i0 = s.i
    w0 = s.w
    x0 = s.x
    rate0 = _compliant_force_rate(s, p)
    _advance_zoh(s, p, keys, coef, DISC_COMPLIANT, e, dt_s)
    depth = s.x - s.x_c
    if depth > 0.0 and s.stiffness_n_per_m * depth \
            + s.damping_n_s_per_m * s.w * p.rho >= 0.0:
        if rate0 <= 0.0:
            return True
        rate1 = _compliant_force_rate(s, p)
        if rate1 >= 0.0 or rate0 * rate0 * dt_s / (2.0 * (rate0 - rate1)) <= \
                PEAK_RESOLUTION_N:
            return True
    s.i = i0
    s.w = w0
    s.x = x0
    return False


@numba.njit(cache=True, inline='always')
def _detect_contact(s, p):
    """After a free sub-step: arrival on the object (or the other finger) or the open stop."""
    x_c = s.x_c
    if s.x >= x_c:
        if p.chain:                  # the pads touch: the chain carries the force from here
            _chain_untouched(s)
            s.contact = CONTACT_COMPLIANT
        elif s.stiffness_n_per_m == 0.0:
            mass_equiv = p.inertia_kg_m2
            s.impact_energy_lost_j += 0.5 * mass_equiv * s.w ** p.two
            s.x = x_c
            s.w = 0.0
            s.contact = CONTACT_RIGID
        else:
            s.contact = CONTACT_COMPLIANT
    elif s.x <= 0.0:
        s.impact_energy_lost_j += 0.5 * p.inertia_kg_m2 * s.w ** p.two
        s.x = 0.0
        s.w = 0.0
        s.contact = CONTACT_OPEN_STOP


@numba.njit(cache=True, inline='always')
def _chain_untouched(s):
    """Zero the chain: the pads just touch the object, nothing is compressed."""
    s.chain_force_n = 0.0
    s.chain_object_m = 0.0
    s.chain_pad_m = 0.0


@numba.njit(cache=True)
def _chain_at_rest(s, p):
    """Set the chain's force for the finger at rest where it is (after a reset, a new object)."""
    rigid = s.stiffness_n_per_m == 0.0
    compliance = p.finger_compliance_m_per_n + (0.0 if rigid else 1.0 / s.stiffness_n_per_m)
    force, pad_m = chain_solve(s.x - s.x_c, compliance, p.pad_stiffness_n_per_m1_5, 0.0)
    s.chain_force_n = force
    s.chain_pad_m = pad_m
    s.chain_object_m = 0.0 if rigid else force / s.stiffness_n_per_m


@numba.njit(cache=True)
def _advance_chain(s, p, keys, coef, e, dt_s):
    """One sub-step of the finger pressing through the chain (core/physics/contact_chain.py).

    The motor is the exact ZOH model with the chain's force as a held load input, taken as the
    mean of its values at the two ends (trapezoidal rule: second order, and on an undamped
    spring it neither adds nor removes energy); the object's damper is backward Euler,
    ``F = k_o d_o + c_o (d_o - d_prev) / dt``. The end force solves the chain for the end
    travel, which depends on it linearly. Free once the finger is back behind the object's
    face.
    """
    c = coef[_disc_entry(s, p, keys, coef, DISC_LOADED, dt_s)]
    i = s.i
    w = s.w
    x = s.x
    half_f0 = 0.5 * s.chain_force_n
    i1 = c[LD_II] * i + c[LD_IW] * w + c[LD_IX] * x + c[LD_IE] * e + c[LD_IF] * half_f0
    w1 = c[LD_WI] * i + c[LD_WW] * w + c[LD_WX] * x + c[LD_WE] * e + c[LD_WF] * half_f0
    x1 = c[LD_XI] * i + c[LD_XW] * w + c[LD_XX] * x + c[LD_XE] * e + c[LD_XF] * half_f0
    if s.stiffness_n_per_m == 0.0:
        object_compliance = 0.0
        object_offset = 0.0
        gamma = 0.0
    else:
        gamma = s.damping_n_s_per_m / dt_s
        object_compliance = 1.0 / (s.stiffness_n_per_m + gamma)
        object_offset = gamma * s.chain_object_m * object_compliance
    # x_end = x1 + 0.5 c[LD_XF] F (c[LD_XF] < 0: the load slows the finger)
    compliance = p.finger_compliance_m_per_n - 0.5 * c[LD_XF] + object_compliance
    force, pad_m = chain_solve(x1 - s.x_c - object_offset, compliance,
                               p.pad_stiffness_n_per_m1_5, s.chain_pad_m)
    half_f1 = 0.5 * force
    s.i = i1 + c[LD_IF] * half_f1
    s.w = w1 + c[LD_WF] * half_f1
    s.x = x1 + c[LD_XF] * half_f1
    s.chain_force_n = force
    s.chain_pad_m = pad_m
    s.chain_object_m = (force + gamma * s.chain_object_m) * object_compliance
    if s.x < s.x_c:
        _chain_untouched(s)
        s.contact = CONTACT_FREE


@numba.njit(cache=True, inline='always')
def _detect_separation(s, p):
    """After a compliant sub-step: free once out of the face or pulling on it."""
    depth = s.x - s.x_c
    if depth <= 0.0 or s.stiffness_n_per_m * depth + s.damping_n_s_per_m * s.w * \
            p.rho < 0.0:
        s.contact = CONTACT_FREE


@numba.njit(cache=True, inline='always')
def _advance_stalled(s, p, e, dt_s):
    """Finger held by a rigid object or the open stop: only the current moves (first order).

    Returns the time left in the interval after the finger leaves the stop (0 if it stays).
    """
    i_inf = e / p.resistance_ohm
    i0 = s.i
    # The stop holds while the motor torque (sign of the current) pushes into it.
    into = 1.0 if s.contact == CONTACT_RIGID else -1.0
    if into * i0 < 0.0:
        t_leave = 0.0
    elif into * i_inf >= 0.0:
        t_leave = math.inf
    else:  # the current decays through zero on its way to i_inf
        t_leave = p.tau_e * math.log((i0 - i_inf) / (0.0 - i_inf))
    if t_leave >= dt_s:
        s.i = i_inf + (i0 - i_inf) * math.exp(-dt_s / p.tau_e)
        return 0.0
    s.i = i_inf + (i0 - i_inf) * math.exp(-t_leave / p.tau_e)
    s.contact = CONTACT_FREE
    return dt_s - t_leave


@numba.njit(cache=True)
def _advance_slipping(s, p, h, keys, coef, e, dt_s, remaining_s):
    """One sub-step of a gripped, slipping rigid object; returns the time left after it."""
    cap = _slip_capacity_n(s, s.t_now_s)
    if cap < SLIP_GONE_FRACTION * s.slip_f_0_n:
        _remove_object(s, p, h, False)             # slid out: nothing left to grip
        return remaining_s
    if s.contact == CONTACT_RIGID:
        if p.kt * s.i / p.lever <= cap:             # the object holds: stalled, as usual
            left = _advance_stalled(s, p, e, dt_s)
            return remaining_s - dt_s + left
        s.contact = CONTACT_SLIPPING               # pushing harder than it can resist
    c = coef[_disc_entry(s, p, keys, coef, DISC_LOADED, dt_s)]
    i = s.i
    w = s.w
    x = s.x
    # the sum starts at 0 as Python's sum() does
    s.i = 0.0 + c[LD_II] * i + c[LD_IW] * w + c[LD_IX] * x + c[LD_IE] * e + c[LD_IF] * cap
    s.w = 0.0 + c[LD_WI] * i + c[LD_WW] * w + c[LD_WX] * x + c[LD_WE] * e + c[LD_WF] * cap
    s.x = 0.0 + c[LD_XI] * i + c[LD_XW] * w + c[LD_XX] * x + c[LD_XE] * e + c[LD_XF] * cap
    end = p.max_travel_m
    if s.x >= end:                                 # the object is gone, the fingers meet
        s.x = end
        s.w = 0.0
        s.has_slip = 0
        _use_object(s, p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        _end_hold(h)
        s.contact = CONTACT_RIGID
    else:                                          # the face recedes
        _use_object(s, p, end - s.x, s.stiffness_n_per_m, s.damping_n_s_per_m, s.mass_kg,
                    s.static_friction, s.kinetic_friction, s.pad_length_m)
        if s.w <= 0.0:                             # the finger stopped: it grips again
            s.w = 0.0
            s.contact = CONTACT_RIGID
    return remaining_s - dt_s


@numba.njit(cache=True)
def _integrate(s, p, h, keys, coef, e, duration_s, start_s):
    """Advance ``duration_s`` at voltage ``e``; returns the contact force at its end."""
    remaining = duration_s
    sub = p.h
    one_step = True       # a compliant interval may be one exact step until it is not
    force = s.peak
    while remaining > 1e-15:
        s.t_now_s = start_s + (duration_s - remaining)
        state = s.contact
        if s.has_slip and (state == CONTACT_RIGID or state == CONTACT_SLIPPING):
            remaining = _advance_slipping(s, p, h, keys, coef, e,
                                          remaining if remaining < sub else sub, remaining)
        elif state == CONTACT_FREE:
            if _free_step_is_safe(s, p, e, remaining):
                _advance_zoh(s, p, keys, coef, DISC_FREE, e, remaining)
                remaining = 0.0
            else:
                dt = remaining if remaining < sub else sub
                _advance_zoh(s, p, keys, coef, DISC_FREE, e, dt)
                remaining -= dt
                _detect_contact(s, p)
        elif state == CONTACT_RIGID or state == CONTACT_OPEN_STOP:
            remaining = _advance_stalled(s, p, e, remaining)
        elif p.chain:
            dt = remaining if remaining < sub else sub
            _advance_chain(s, p, keys, coef, e, dt)
            remaining -= dt
        else:
            if one_step and remaining <= s.compliant_one_step_s and \
                    _advance_compliant_in_one_step(s, p, keys, coef, e, remaining):
                remaining = 0.0
            else:
                one_step = False   # the rest of this interval on the sub-step grid
                dt = remaining if remaining < sub else sub
                _advance_zoh(s, p, keys, coef, DISC_COMPLIANT, e, dt)
                remaining -= dt
                _detect_separation(s, p)
        force = _force(s, p)
        if force > s.peak:
            s.peak = force
    return force


@numba.njit(cache=True)
def _step_in_pieces(s, p, h, sensor, fired, keys, coef, e, t_ns, end_ns):
    """Integrate ``[t_ns, end_ns]`` split at the fault, the lift's start and end, the loss.

    An event at ``end_ns`` itself takes effect in the next step (after this sample).
    """
    while t_ns < end_ns:
        if s.fault_kind != FaultKind.NONE and s.fault_at_ns <= t_ns:
            _fire_fault(s, p, h, sensor, fired)
        live = h.live != 0
        if live:
            hold_fire_events(h, t_ns)
            if not hold_live(h):
                h.live = 0
                live = False
        piece_end_ns = end_ns
        if s.fault_kind != FaultKind.NONE and s.fault_at_ns < piece_end_ns:
            piece_end_ns = s.fault_at_ns
        if live:
            event_ns = h.next_event_ns
            if event_ns != -1 and event_ns < piece_end_ns:
                piece_end_ns = event_ns
            if h.state == HoldState.SLIDING and t_ns + p.h_ns < piece_end_ns:
                piece_end_ns = t_ns + p.h_ns      # refresh the grip force while sliding
            loss_s = hold_advance(h, _force(s, p), (piece_end_ns - t_ns) * 1e-9)
            if not math.isnan(loss_s):
                loss_ns = t_ns + round(loss_s * 1e9)
                if piece_end_ns < loss_ns:
                    loss_ns = piece_end_ns
                if loss_ns > t_ns:
                    _integrate(s, p, h, keys, coef, e, (loss_ns - t_ns) * 1e-9, t_ns * 1e-9)
                h.lost_ns = loss_ns
                _remove_object(s, p, h, True)
                h.live = 0
                t_ns = loss_ns
                continue
        _integrate(s, p, h, keys, coef, e, (piece_end_ns - t_ns) * 1e-9, t_ns * 1e-9)
        t_ns = piece_end_ns


# ----------------------------------------------------------------------------- pad sensing
@numba.njit(cache=True)
def _pads_rest(chans):
    """Nothing is held: every pad channel reads 0 with a history of 0 (no noise is drawn)."""
    for i in range(PAD_CHANNELS):
        c = chans[i]
        line = c.line
        for j in range(line.shape[0]):
            line[j] = 0.0
        c.filtered = 0.0
        c.primed = 1
        c.reading = 0.0


@numba.njit(cache=True)
def _pads_sample(s, p, h, chans, duration_ns):
    """Read each pad's shear and the object's displacement on it at the end of a step.

    While the object is held (stuck or sliding) each channel takes one sample per ``pad_dt_ns``
    of the step (at least one) of the value now; otherwise the channels rest at 0 (plant_step),
    so the readings, and the noise drawn, depend only on the held samples since ``set_object``.
    """
    s.pads_resting = 0
    force = _force(s, p)
    shear = hold_shear_n(h, force)
    displacement = hold_presliding_m(h, force) + h.slip_m
    n = 1
    if p.pad_dt_ns > 0:
        n = (duration_ns + p.pad_dt_ns // 2) // p.pad_dt_ns
        if n < 1:
            n = 1
    shear_1, shear_2 = chans[PAD_SHEAR_1], chans[PAD_SHEAR_2]
    disp_1, disp_2 = chans[PAD_DISPLACEMENT_1], chans[PAD_DISPLACEMENT_2]
    for _ in range(n):
        channel_step(shear_1, shear_1.line, shear)
        channel_step(shear_2, shear_2.line, shear)
        channel_step(disp_1, disp_1.line, displacement)
        channel_step(disp_2, disp_2.line, displacement)


# ----------------------------------------------------------------------------- entry points
@numba.njit(cache=True)
def plant_step(k, voltage_v, duration_ns):
    """Hold ``voltage_v`` (clipped to the supply) for ``duration_ns`` >= 1 (validated)."""
    s = k[K_STATE][0]
    p = k[K_PARAMS][0]
    h = k[K_HOLD][0]
    keys = k[K_DISC_KEYS]
    coef = k[K_DISC_COEF]
    limit = p.limit_v
    e = limit if voltage_v > limit else (-limit if voltage_v < -limit else voltage_v)
    s.voltage = e
    s.peak = _force(s, p)
    start_ns = s.t_ns
    end_ns = start_ns + duration_ns
    if s.fault_kind == FaultKind.NONE and (
            h.live == 0 or hold_stays_stuck(h, s.peak, end_ns)):
        _integrate(s, p, h, keys, coef, e, duration_ns * 1e-9, start_ns * 1e-9)
    else:
        _step_in_pieces(s, p, h, k[K_SENSOR][0], k[K_FIRED], keys, coef, e, start_ns, end_ns)
    s.t_ns = end_ns
    s.t_now_s = end_ns * 1e-9
    # the pads, every tick: given only the arrays they need (a call copies the tuple)
    if h.has_hold != 0 and (h.state == HoldState.STUCK or h.state == HoldState.SLIDING):
        _pads_sample(s, p, h, k[K_PADS], duration_ns)
    elif not s.pads_resting:
        _pads_rest(k[K_PADS])
        s.pads_resting = 1


@numba.njit(cache=True)
def plant_sample(k):
    """Return what the sensors and motor report now, as PlantSample's fields in order."""
    s = k[K_STATE][0]
    p = k[K_PARAMS][0]
    sensor = k[K_SENSOR][0]
    force = _force(s, p)
    x = s.x
    if sensor.dropped_out:
        measured = math.nan
        sensor_v = math.nan
        peak = math.nan
    else:
        measured = force
        if sensor.noisy:
            measured = noisy_reading(sensor, force, NOISE_CHANNEL_FORCE, s.t_ns,
                                     sensor.force_noise_n, sensor.force_quantum_n)
        sensor_v = fsr_voltage_v(sensor, measured)
        peak = force if force > s.peak else s.peak
    if sensor.noisy:
        x = noisy_reading(sensor, x, NOISE_CHANNEL_POSITION, s.t_ns, sensor.position_noise_m,
                          sensor.position_quantum_m)
    w = s.w
    # Only the contact states give a force, so "in contact" is "force > 0".
    return (s.t_ns, x, w * p.rho, measured, peak, s.i, w, s.voltage, sensor_v,
            force > 0.0)


@numba.njit(cache=True)
def plant_hold_record(k):
    """Return the held object's record (``HOLD_DTYPE``) of the plant ``k`` (compiled readers)."""
    return k[K_HOLD][0]


@numba.njit(cache=True)
def plant_place(k, x, w, i):
    """Put the finger at travel ``x`` with motor speed ``w`` and current ``i`` (a run's start)."""
    s = k[K_STATE][0]
    s.x = x
    s.w = w
    s.i = i
    _refresh_contact_state(s, k[K_PARAMS][0])


@numba.njit(cache=True)
def plant_read_tick(k, tick, revision, applied_source):
    """Fill the 1-element TICK record array ``tick`` with the measurement now."""
    (t_ns, x, v, measured, peak, i, w, voltage, sensor_v, _contact) = plant_sample(k)
    r = tick[0]
    r.stamp_ns = t_ns
    r.position_m = x
    r.velocity_mps = v
    r.force_n = measured
    r.peak_force_n = peak
    r.sensor_voltage_v = sensor_v
    r.motor_voltage_v = voltage
    r.current_a = i
    r.speed_rad_s = w
    r.applied_source = applied_source
    r.revision = revision
    pads = k[K_PADS]
    r.pad1_shear_n = pads[PAD_SHEAR_1].reading
    r.pad2_shear_n = pads[PAD_SHEAR_2].reading
    r.pad1_displacement_m = pads[PAD_DISPLACEMENT_1].reading
    r.pad2_displacement_m = pads[PAD_DISPLACEMENT_2].reading


@numba.njit(cache=True)
def plant_begin_hold(k, t_ns, grasp_mass_kg):
    """Start the lift's clock at ``t_ns``; 1 (nothing changed) if the object left its support."""
    h = k[K_HOLD][0]
    if not h.has_hold or h.state == HoldState.NONE:
        return 0
    mass = h.mass_kg if h.mass_kg != 0.0 else grasp_mass_kg
    if hold_begin(h, t_ns, mass):
        return 1
    h.live = 1 if hold_live(h) else 0
    return 0


@numba.njit(cache=True)
def plant_drive_load(k, accel_mps2):
    """Set the arm's acceleration live from now on; 1 (nothing changed) if nothing is held."""
    h = k[K_HOLD][0]
    if not h.has_hold or hold_drive(h, k[K_STATE][0].t_ns, accel_mps2,
                                    k[K_PARAMS][0].after_lift_ns):
        return 1
    h.live = 1
    return 0


@numba.njit(cache=True)
def plant_scenario_in_progress(k):
    """Whether a hold scenario (a lift) is still to be played out."""
    h = k[K_HOLD][0]
    return h.has_hold != 0 and hold_scenario_in_progress(
        h, k[K_STATE][0].t_ns, k[K_PARAMS][0].after_lift_ns)


@numba.njit(cache=True)
def plant_schedule_fault(k, kind, at_ns, time_constant_s):
    """Fire ``kind`` at ``at_ns`` (>= now; replaces a scheduled one; NONE cancels)."""
    s = k[K_STATE][0]
    s.fault_kind = kind
    s.fault_at_ns = at_ns if at_ns > s.t_ns else s.t_ns
    s.fault_time_constant_s = time_constant_s


@numba.njit(cache=True)
def plant_cancel_fault(k):
    """Drop a scheduled fault that has not fired (its effects, once fired, stay)."""
    k[K_STATE][0].fault_kind = FaultKind.NONE


@numba.njit(cache=True)
def plant_fault_scheduled(k):
    """Whether a fault is scheduled and has not fired."""
    return k[K_STATE][0].fault_kind != FaultKind.NONE


OBJECT_STATE_DTYPE = np.dtype([(f.name, np.int64 if f.name in ('state', 'lost_ns') else np.float64)
                               for f in fields(ObjectState)])
""":class:`ObjectState` as a record, field for field (``lost_ns`` -1: not lost), for a kernel."""
_HOLD_NONE = int(HoldState.NONE)


@numba.njit(cache=True)
def _object_state(k, out):
    """Write the held object's :class:`ObjectState` into the record ``out[0]`` (lost_ns -1: not).

    Nothing held: all zeros; an object taken away (state NONE): only how far it had slid.
    """
    o = out[0]
    h = k[K_HOLD][0]
    o.state = _HOLD_NONE
    o.slip_m = o.slip_speed_mps = o.load_n = o.capacity_n = 0.0
    o.lift_acceleration_mps2 = o.shear_n = o.presliding_m = 0.0
    o.lost_ns = -1
    if not h.has_hold:
        return
    o.slip_m = h.slip_m
    if h.state == HoldState.NONE:
        return
    force = _force(k[K_STATE][0], k[K_PARAMS][0])
    o.state = h.state
    o.slip_speed_mps = h.slip_speed_mps
    o.load_n = hold_load_n(h)
    o.capacity_n = hold_capacity_n(h, force)
    o.lost_ns = h.lost_ns
    o.lift_acceleration_mps2 = h.acceleration_mps2
    o.shear_n = hold_shear_n(h, force)
    o.presliding_m = hold_presliding_m(h, force)


@numba.njit(cache=True)
def _step_and_sample(k, voltage_v, duration_ns):
    plant_step(k, voltage_v, duration_ns)
    return plant_sample(k)


_warmed_up = []


def _warm_up(kernel: tuple) -> None:
    """Load (or compile) every kernel the facade calls, once per process, on a scratch copy.

    A kernel's first call loads its machine code from numba's cache (tens of ms; seconds when
    it must compile): done here, a node's first lift or fault does not stall its loop.
    """
    if _warmed_up:
        return
    k = tuple(a.copy() for a in kernel)
    _reset(k, True)
    _set_object(k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    k[K_STATE][0]['x'] = 0.5 * k[K_PARAMS][0]['max_travel_m']
    _reset(k, False)
    _step_and_sample(k, 0.0, 1)             # free motion: a table miss, linalg's expm loaded
    _touch_object(k)
    plant_sample(k)
    plant_read_tick(k, np.zeros(1, TICK_LAYOUT.dtype), 0, 0)
    _object_state(k, np.zeros(1, OBJECT_STATE_DTYPE))
    plant_begin_hold(k, 0, 0.0)
    plant_scenario_in_progress(k)
    plant_schedule_fault(k, 1, 0, DEFAULT_SLIP_TIME_CONSTANT_S)
    plant_fault_scheduled(k)
    plant_cancel_fault(k)
    _warmed_up.append(True)


# ----------------------------------------------------------------------------- the facade
class GripperPlant:
    """Exact-discretised motor + lead screw + contact. Call :meth:`step` with a held voltage.

    The state lives in numpy records (the tuple :attr:`kernel`, see ``K_*``); every step and
    reading runs the compiled kernels above. This class validates and formats.
    """

    def __init__(self, params: PlantParams, sensor: FsrVoltageDivider,
                 contact: ContactParams | None = None, pads: PadSensorParams | None = None,
                 pad_dt_s: float = 0.0, pad_seed: int = 0):
        """Build the plant; ``pads`` sensed every ``pad_dt_s`` (None: exact pad readings).

        ``pad_seed`` seeds the pads' noise, again at each :meth:`set_object`.
        """
        self.params = params
        self.sensor = sensor
        self.pads = pads
        ideal = ChannelSpec(0.0, 0.0, 0.0, 0.0)
        self._pad_specs = (ideal,) * PAD_CHANNELS if pads is None else (
            pads.shear, pads.shear, pads.displacement, pads.displacement)
        self._pad_dt_s = float(pad_dt_s) if pads is not None else 1.0
        self._pad_seed = int(pad_seed)
        self.contact_defaults = contact or object_contact(0.0, 0.0)
        default = self.contact_defaults
        self._raw = _raw_constants(params)
        self._object_record = np.zeros(1, OBJECT_STATE_DTYPE)   # _object_state writes it
        self._lift: Lift | None = None
        state = np.zeros(1, STATE_DTYPE)
        hold = np.zeros(1, HOLD_DTYPE)
        hold[0]['state'] = HoldState.NONE
        self.kernel = (state, _plant_params_record(params, self.contact_defaults), hold,
                       sensor.record, np.zeros((MAX_FIRED_FAULTS, 2), np.int64),
                       np.zeros((DISC_TABLE_SIZE, 5)),
                       np.zeros((DISC_TABLE_SIZE, DISC_COEFFICIENTS)),
                       np.zeros(PAD_CHANNELS, PAD_DTYPE))
        """The kernel buffers: (state, params, hold, sensor, fired faults, table keys, table,
        pad channels with their delay lines)."""
        if pads is not None:
            self.kernel[K_PARAMS][0]['pad_dt_ns'] = round(self._pad_dt_s * 1e9)
        self._seed_pads()
        _use_default_object(self.kernel, float(default.stiffness_n_per_m),
                            float(default.damping_n_s_per_m))
        self.reset()
        _warm_up(self.kernel)

    # ----------------------------------------------------------------- records for callers
    @property
    def _s(self) -> np.void:
        """The state record (looked up each time: a deep copy of the plant has its own)."""
        return self.kernel[K_STATE][0]

    @property
    def _h(self) -> np.void:
        """The hold record."""
        return self.kernel[K_HOLD][0]

    def snapshot(self) -> tuple:
        """Return a copy of the whole state (for :meth:`restore` after a refused change)."""
        return tuple(a.copy() for a in self.kernel), self._lift

    def restore(self, saved: tuple) -> None:
        """Put back a :meth:`snapshot` (the buffers stay the same arrays)."""
        arrays, self._lift = saved
        for a, b in zip(self.kernel, arrays):
            a[...] = b

    # ----------------------------------------------------------------- set-up
    def reset(self, open_fingers: bool = True) -> None:
        """Motor at rest; optionally the finger back at the fully-open stop. Time keeps running."""
        _reset(self.kernel, bool(open_fingers))

    def touch_object(self) -> None:
        """Put the finger at rest just touching the object, motor off (force-loop studies)."""
        _touch_object(self.kernel)

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
        if self._s['x'] > self.params.max_travel_m - obj.width_m:
            raise ValueError('the finger is already past the new object surface; open first')
        if hold is None:
            self._h['has_hold'] = 0
            self._h['state'] = HoldState.NONE
        else:
            self.kernel[K_HOLD][0] = hold.record[0]
            self._h['has_hold'] = 1
        self._lift = lift
        self._seed_pads()
        _set_object(self.kernel, float(obj.width_m), float(obj.stiffness_n_per_m),
                    float(obj.damping_n_s_per_m), float(obj.mass_kg),
                    float(obj.static_friction), float(obj.kinetic_friction),
                    float(obj.pad_length_m))

    def _seed_pads(self) -> None:
        """Fresh pad channels (each its own noise stream from the seed), resting at 0."""
        for i, spec in enumerate(self._pad_specs):
            record, buffer = make_channel(spec, self._pad_dt_s,
                                          (self._pad_seed * PAD_CHANNELS + i) % 2 ** 64)
            pad = self.kernel[K_PADS][i]
            for name in CHANNEL_DTYPE.names:
                pad[name] = record[0][name]
            pad['line'] = buffer
        self._s['pads_resting'] = 0

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
        lift_off_s = lift.lift_off_or(d.lift_off_s) if lift is not None else d.lift_off_s
        return HoldModel(obj.mass_kg, mu_s, mu_k, pad_m, self.params.gravity_mps2, lift,
                         d.pad_tangential_stiffness_n_per_m, lift_off_s)

    @property
    def object(self) -> GraspObject:  # noqa: A003 - the public attribute name
        """What lies between the fingers now (a slipping object's width shrinks)."""
        s = self._s
        return GraspObject(float(s['width_m']), float(s['stiffness_n_per_m']),
                           float(s['damping_n_s_per_m']), float(s['mass_kg']),
                           float(s['static_friction']), float(s['kinetic_friction']),
                           float(s['pad_length_m']))

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
        if plant_begin_hold(self.kernel, t_ns, mass):
            raise ValueError(f'the object is already off its support '
                             f'({HoldState(int(self._h["state"])).name}); '
                             'place an object again before a new hold')

    @property
    def lift(self) -> Lift | None:
        """The lift given with the object (None: it stays on its support)."""
        return self._lift

    @property
    def _hold(self) -> HoldModel | None:
        """The object's tangential hold (a view of the plant's hold record), if any."""
        return HoldModel.view(self.kernel[K_HOLD], self._lift) if self._h['has_hold'] else None

    @property
    def hold_state(self) -> HoldState:
        """What the held object does now (cheap: for a per-step check)."""
        return HoldState(int(self._h['state'])) if self._h['has_hold'] else HoldState.NONE

    def lift_plan(self) -> list[tuple[int, float]]:
        """Return the begun lift's breakpoints (t_ns, upward m/s^2), as its arm announces them.

        Empty without a lift whose clock has started (:func:`hold_plan`).
        """
        times = np.zeros(ANNOUNCE_ROWS, np.int64)
        accels = np.zeros(ANNOUNCE_ROWS)
        n = hold_plan(self.kernel[K_HOLD], times, accels)
        return [(int(times[i]), float(accels[i])) for i in range(n)]

    @property
    def object_state(self) -> ObjectState:
        """The grasped object's hold: state, slip, load against the static capacity, loss time."""
        _object_state(self.kernel, self._object_record)
        values = {name: self._object_record[0][name].item() for name in OBJECT_STATE_DTYPE.names}
        values['state'] = HoldState(values['state'])
        values['lost_ns'] = None if values['lost_ns'] == -1 else values['lost_ns']
        return ObjectState(**values)

    def drive_load(self, accel_mps2: float) -> None:
        """Set the arm's upward acceleration from now on (a live arm: ``sim/load_acceleration``).

        The load on the pads becomes ``m (g + a)``; an object still on its support leaves it; a
        lift profile still running stops. ValueError (nothing changes) for a non-finite value or
        when no grasp holds an object.
        """
        if isinstance(accel_mps2, bool) or not isinstance(accel_mps2, (int, float)) or \
                not math.isfinite(accel_mps2):
            raise ValueError(f'load acceleration must be a finite number, got {accel_mps2!r}')
        if plant_drive_load(self.kernel, float(accel_mps2)):
            raise ValueError('no grasp holds an object: a load acceleration applies only after '
                             'HOLDING, while the object is between the pads')

    # ----------------------------------------------------------------- fault injection
    def schedule_fault(self, kind, at_ns: int,
                       time_constant_s: float = DEFAULT_SLIP_TIME_CONSTANT_S) -> ScheduledFault:
        """Fire ``kind`` at simulated time ``at_ns`` (>= now; replaces a scheduled one)."""
        kind, tau = check_fault(kind, 0.0, time_constant_s, self.object.rigid)
        plant_schedule_fault(self.kernel, int(kind), int(at_ns), float(tau))
        return self.scheduled_fault

    @property
    def scheduled_fault(self) -> ScheduledFault | None:
        """The fault to fire (None: none scheduled, or it has fired)."""
        s = self._s
        if s['fault_kind'] == FaultKind.NONE:
            return None
        return ScheduledFault(FaultKind(int(s['fault_kind'])), int(s['fault_at_ns']),
                              float(s['fault_time_constant_s']))

    @property
    def fired_faults(self) -> list[tuple[FaultKind, int]]:
        """(kind, t_ns) of each fault fired since set_object."""
        rows = self.kernel[K_FIRED][:int(self._s['fired_count'])]
        return [(FaultKind(int(kind)), int(at_ns)) for kind, at_ns in rows]

    def cancel_fault(self) -> None:
        """Drop a scheduled fault that has not fired (its effects, once fired, stay)."""
        plant_cancel_fault(self.kernel)

    @property
    def sensor_dropped_out(self) -> bool:
        return self.sensor.dropped_out

    # ----------------------------------------------------------------- state read-outs
    t_ns = RecordField(int, at='_s', doc='Simulated time in integer nanoseconds: exact, the '
                       "lockstep's tick key.")

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    impact_energy_lost_j = RecordField(at='_s', doc='Kinetic energy lost in arrivals on a rigid '
                                       'face or the open stop since the reset.')
    contact_position_m = RecordField(writable=False, field='x_c', at='_s',
                                     doc='Finger travel at which it touches the object.')

    @property
    def contact_state(self) -> ContactState:
        return _CONTACT_STATES[self._s['contact']]

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
        return (np.array([p.torque_constant_n_m_per_a / p.force_lever_m]),
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
        return w * p.travel_per_rad_m

    def discrete_free_model(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact ZOH model of free motion: ``s[k+1] = Ad s[k] + Bd e[k]``, s = [i, omega, x]."""
        c = _discretise(self._raw, DISC_FREE, dt_s, 0.0, 0.0, 0.0).tolist()
        return (np.array([c[AFF_II:AFF_I1], c[AFF_WI:AFF_W1], c[AFF_XI:AFF_X1]]),
                np.array(c[AFF_IE:AFF_XE + 1]))

    def discrete_force_model(self, dt_s: float) -> tuple[float, float]:
        """Exact ZOH of eq. 13: ``F[k+1] = a F[k] + b e[k]`` on a rigid object."""
        a = math.exp(-dt_s / self.kernel[K_PARAMS][0]['tau_e'])
        return a, self.params.stall_force_per_volt_n * (1.0 - a)

    # ----------------------------------------------------------------- simulation
    def sample(self) -> PlantSample:
        """Return what the sensors and motor report now."""
        return _new_tuple(PlantSample, plant_sample(self.kernel))

    def step(self, voltage_v: float, duration_s: float) -> PlantSample:
        """Hold ``voltage_v`` (clipped to the supply, the H-bridge limit) for ``duration_s``."""
        if not 0.0 < duration_s < math.inf:
            raise ValueError(f'duration must be finite and > 0, got {duration_s!r}')
        duration_ns = round(duration_s * 1e9)
        if duration_ns <= 0:
            raise ValueError(f'duration must be at least 1 ns, got {duration_s!r}')
        if not -math.inf < voltage_v < math.inf:
            raise ValueError(f'voltage must be finite, got {voltage_v!r}')
        return _new_tuple(PlantSample, _step_and_sample(self.kernel, float(voltage_v),
                                                        duration_ns))
