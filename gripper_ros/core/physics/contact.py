"""The finger against the object: the three contact kinds, and a slipping object.

Contact with the object at ``x_c = L_ls - width`` uses one of these models:

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
at ``x = L_ls`` (a rigid object of width 0). A slipping object (``OBJECT_SLIPPING``,
:mod:`gripper_ros.core.physics.events`) resists at most its decaying capacity: while the motor
pushes harder the finger advances against that constant load and the face recedes with it.
The kernels here advance one regime over one (sub-)step;
:mod:`gripper_ros.core.physics.integration` chooses among them.
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
import math

from gripper_ros.core.physics.contact_chain import chain_solve
from gripper_ros.core.physics.hold import hold_remove, HoldState
from gripper_ros.core.physics.motor_zoh import (advance_zoh, DISC_COMPLIANT, disc_entry,
                                                DISC_LOADED, LD_IE, LD_IF, LD_II, LD_IW, LD_IX,
                                                LD_WE, LD_WF, LD_WI, LD_WW, LD_WX, LD_XE, LD_XF,
                                                LD_XI, LD_XW, LD_XX)
import numba

SLIP_GONE_FRACTION = 0.01             # the object is out once its capacity is below 1 % of F_0
# A compliant contact is stepped in one piece while its spring mode turns through at most this
# phase: far too little for the finger to leave the face and come back within the step.
COMPLIANT_ONE_STEP_PHASE_RAD = 0.1
# An interior force maximum this much above both ends of a one-piece compliant step is located
# on the sub-step grid (the reported peak); a smaller one is rounding.
PEAK_RESOLUTION_N = 1e-9


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

    ``mass_kg`` 0 = the grasp's mass (given to :meth:`GripperPlant.begin_hold`); pad length 0 =
    the configured ``contact`` default. The pad friction is the object's own: 0 is frictionless
    (nothing holds its weight); the configured friction is asked for with
    :meth:`GripperPlant.configured_friction`.
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


# Contact-state codes of the state record's ``contact`` field, and the ContactState of each.
CONTACT_FREE = 0
CONTACT_SLIPPING = 1
CONTACT_RIGID = 2
CONTACT_COMPLIANT = 3
CONTACT_OPEN_STOP = 4
CONTACT_STATES = (ContactState.FREE, ContactState.SLIPPING, ContactState.RIGID_OBJECT,
                  ContactState.COMPLIANT_OBJECT, ContactState.OPEN_STOP)


@numba.njit(cache=True, inline='always')
def slip_capacity_n(s, t_s):
    """Force the slipping object can still resist at ``t_s`` (inf when not slipping)."""
    if not s.has_slip:
        return math.inf
    d = t_s - s.slip_t_f_s
    return s.slip_f_0_n * math.exp(-(d if d > 0.0 else 0.0) / s.slip_tau_s)


@numba.njit(cache=True, inline='always')
def contact_force_n(s, p):
    """Contact force now (N): motor torque on a rigid face, Kelvin-Voigt, a slip's capacity."""
    state = s.contact
    if state == CONTACT_RIGID:
        motor = p.kt * s.i / p.lever
        if not motor > 0.0:
            motor = 0.0
        if not s.has_slip:
            return motor
        cap = slip_capacity_n(s, s.t_now_s)
        return cap if cap < motor else motor
    if state == CONTACT_COMPLIANT:
        if p.chain:
            return s.chain_force_n
        force = s.stiffness_n_per_m * (s.x - s.x_c) + s.damping_n_s_per_m * s.w * p.rho
        return force if force > 0.0 else 0.0
    if state == CONTACT_SLIPPING:
        return slip_capacity_n(s, s.t_now_s)
    return 0.0


@numba.njit(cache=True)
def refresh_contact_state(s, p):
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
            chain_at_rest(s, p)
    else:
        s.contact = CONTACT_FREE


@numba.njit(cache=True)
def use_object(s, p, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
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
def end_hold(h):
    if h.has_hold and h.state != HoldState.LOST:
        hold_remove(h)
    h.live = 0


@numba.njit(cache=True)
def remove_object(s, p, h, lost):
    """Nothing between the fingers from now on (slid out of the pads if ``lost``)."""
    s.has_slip = 0
    use_object(s, p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)   # the fingers would meet at L_ls
    if not lost:
        end_hold(h)
    state = s.contact
    if (state == CONTACT_RIGID or state == CONTACT_COMPLIANT or state == CONTACT_SLIPPING) \
            and s.x < p.max_travel_m:
        s.contact = CONTACT_FREE
    refresh_contact_state(s, p)


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
def advance_compliant_in_one_step(s, p, keys, coef, e, dt_s):
    """Step a compliant contact over ``dt_s`` at once; False (state kept) if it may not.

    It may not if the finger has left the face at the end (separation is then located on
    the sub-step grid), or if the force has an interior maximum above both ends (the peak is
    then found on the grid as well).
    """
    i0 = s.i
    w0 = s.w
    x0 = s.x
    rate0 = _compliant_force_rate(s, p)
    advance_zoh(s, p, keys, coef, DISC_COMPLIANT, e, dt_s)
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
def detect_contact(s, p):
    """After a free sub-step: arrival on the object (or the other finger) or the open stop."""
    x_c = s.x_c
    if s.x >= x_c:
        if p.chain:                  # the pads touch: the chain carries the force from here
            chain_untouched(s)
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
def chain_untouched(s):
    """Zero the chain: the pads just touch the object, nothing is compressed."""
    s.chain_force_n = 0.0
    s.chain_object_m = 0.0
    s.chain_pad_m = 0.0


@numba.njit(cache=True)
def chain_at_rest(s, p):
    """Set the chain's force for the finger at rest where it is (after a reset, a new object)."""
    rigid = s.stiffness_n_per_m == 0.0
    compliance = p.finger_compliance_m_per_n + (0.0 if rigid else 1.0 / s.stiffness_n_per_m)
    force, pad_m = chain_solve(s.x - s.x_c, compliance, p.pad_stiffness_n_per_m1_5, 0.0)
    s.chain_force_n = force
    s.chain_pad_m = pad_m
    s.chain_object_m = 0.0 if rigid else force / s.stiffness_n_per_m


@numba.njit(cache=True)
def advance_chain(s, p, keys, coef, e, dt_s):
    """One sub-step of the finger pressing through the chain (core/physics/contact_chain.py).

    The motor is the exact ZOH model with the chain's force as a held load input, taken as the
    mean of its values at the two ends (trapezoidal rule: second order, and on an undamped
    spring it neither adds nor removes energy); the object's damper is backward Euler,
    ``F = k_o d_o + c_o (d_o - d_prev) / dt``. The end force solves the chain for the end
    travel, which depends on it linearly. Free once the finger is back behind the object's
    face.
    """
    c = coef[disc_entry(s, p, keys, coef, DISC_LOADED, dt_s)]
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
        chain_untouched(s)
        s.contact = CONTACT_FREE


@numba.njit(cache=True, inline='always')
def detect_separation(s, p):
    """After a compliant sub-step: free once out of the face or pulling on it."""
    depth = s.x - s.x_c
    if depth <= 0.0 or s.stiffness_n_per_m * depth + s.damping_n_s_per_m * s.w * \
            p.rho < 0.0:
        s.contact = CONTACT_FREE


@numba.njit(cache=True, inline='always')
def advance_stalled(s, p, e, dt_s):
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
def advance_slipping(s, p, h, keys, coef, e, dt_s, remaining_s):
    """One sub-step of a gripped, slipping rigid object; returns the time left after it."""
    cap = slip_capacity_n(s, s.t_now_s)
    if cap < SLIP_GONE_FRACTION * s.slip_f_0_n:
        remove_object(s, p, h, False)             # slid out: nothing left to grip
        return remaining_s
    if s.contact == CONTACT_RIGID:
        if p.kt * s.i / p.lever <= cap:             # the object holds: stalled, as usual
            left = advance_stalled(s, p, e, dt_s)
            return remaining_s - dt_s + left
        s.contact = CONTACT_SLIPPING               # pushing harder than it can resist
    c = coef[disc_entry(s, p, keys, coef, DISC_LOADED, dt_s)]
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
        use_object(s, p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        end_hold(h)
        s.contact = CONTACT_RIGID
    else:                                          # the face recedes
        use_object(s, p, end - s.x, s.stiffness_n_per_m, s.damping_n_s_per_m, s.mass_kg,
                   s.static_friction, s.kinetic_friction, s.pad_length_m)
        if s.w <= 0.0:                             # the finger stopped: it grips again
            s.w = 0.0
            s.contact = CONTACT_RIGID
    return remaining_s - dt_s
