"""One step of the plant: a held voltage over an interval, integrated through the contact kinds.

Integration: an interval in which no contact event can happen is one exact ZOH step
(:mod:`gripper_ros.core.physics.motor_zoh`). Free motion is one step when a rigorous bound on the
finger's reach (its speed grows by at most the acceleration the current can give) keeps it clear
of both stops; compliant contact is one step when the step is short against the object's spring
mode and the finger is still in contact at its end. Otherwise the interval is sub-stepped at
``contact_substep_s`` and contact or separation is located on that grid
(:mod:`gripper_ros.core.physics.contact`).

A step is split at a fault's instant, at the lift's start and end and at the loss of a held
object (:mod:`gripper_ros.core.physics.events`), and the grip force is taken at the start of each
piece (at most one ``contact_substep_s`` long while the object slides).
"""
from __future__ import annotations

import math

from gripper_ros.core.physics.contact import (advance_chain, advance_compliant_in_one_step,
                                              advance_slipping, advance_stalled, contact_force_n,
                                              CONTACT_FREE, CONTACT_OPEN_STOP, CONTACT_RIGID,
                                              CONTACT_SLIPPING, detect_contact, detect_separation,
                                              remove_object)
from gripper_ros.core.physics.events import fire_fault
from gripper_ros.core.physics.hold import (hold_advance, hold_fire_events, hold_live,
                                           hold_stays_stuck, HoldState)
from gripper_ros.core.physics.motor_zoh import advance_zoh, DISC_COMPLIANT, DISC_FREE
from gripper_ros.core.physics.plant_pads import pads_rest, pads_sample
from gripper_ros.core.records import as_record
from gripper_ros.wire import FaultKind
import numba

FREE_REACH_MARGIN_MPS = 1e-9          # added to the speed bound of a free step (rounding)


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
            remaining = advance_slipping(s, p, h, keys, coef, e,
                                         remaining if remaining < sub else sub, remaining)
        elif state == CONTACT_FREE:
            if _free_step_is_safe(s, p, e, remaining):
                advance_zoh(s, p, keys, coef, DISC_FREE, e, remaining)
                remaining = 0.0
            else:
                dt = remaining if remaining < sub else sub
                advance_zoh(s, p, keys, coef, DISC_FREE, e, dt)
                remaining -= dt
                detect_contact(s, p)
        elif state == CONTACT_RIGID or state == CONTACT_OPEN_STOP:
            remaining = advance_stalled(s, p, e, remaining)
        elif p.chain:
            dt = remaining if remaining < sub else sub
            advance_chain(s, p, keys, coef, e, dt)
            remaining -= dt
        else:
            if one_step and remaining <= s.compliant_one_step_s and \
                    advance_compliant_in_one_step(s, p, keys, coef, e, remaining):
                remaining = 0.0
            else:
                one_step = False   # the rest of this interval on the sub-step grid
                dt = remaining if remaining < sub else sub
                advance_zoh(s, p, keys, coef, DISC_COMPLIANT, e, dt)
                remaining -= dt
                detect_separation(s, p)
        force = contact_force_n(s, p)
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
            fire_fault(s, p, h, sensor, fired)
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
            loss_s = hold_advance(h, contact_force_n(s, p), (piece_end_ns - t_ns) * 1e-9)
            if not math.isnan(loss_s):
                loss_ns = t_ns + round(loss_s * 1e9)
                if piece_end_ns < loss_ns:
                    loss_ns = piece_end_ns
                if loss_ns > t_ns:
                    _integrate(s, p, h, keys, coef, e, (loss_ns - t_ns) * 1e-9, t_ns * 1e-9)
                h.lost_ns = loss_ns
                remove_object(s, p, h, True)
                h.live = 0
                t_ns = loss_ns
                continue
        _integrate(s, p, h, keys, coef, e, (piece_end_ns - t_ns) * 1e-9, t_ns * 1e-9)
        t_ns = piece_end_ns


@numba.njit(cache=True)
def plant_step(k, voltage_v, duration_ns):
    """Hold ``voltage_v`` (clipped to the supply) for ``duration_ns`` >= 1 (validated)."""
    pl = as_record(k)
    s = pl.state
    p = pl.params
    h = pl.hold
    keys = pl.disc_keys
    coef = pl.disc_coef
    limit = p.limit_v
    e = limit if voltage_v > limit else (-limit if voltage_v < -limit else voltage_v)
    s.voltage = e
    s.peak = contact_force_n(s, p)
    start_ns = s.t_ns
    end_ns = start_ns + duration_ns
    if s.fault_kind == FaultKind.NONE and (
            h.live == 0 or hold_stays_stuck(h, s.peak, end_ns)):
        _integrate(s, p, h, keys, coef, e, duration_ns * 1e-9, start_ns * 1e-9)
    else:
        _step_in_pieces(s, p, h, pl.sensor, pl.fired, keys, coef, e, start_ns, end_ns)
    s.t_ns = end_ns
    s.t_now_s = end_ns * 1e-9
    if h.has_hold != 0 and (h.state == HoldState.STUCK or h.state == HoldState.SLIDING):
        pads_sample(s, p, h, pl.pads, duration_ns)
    elif not s.pads_resting:
        pads_rest(pl.pads)
        s.pads_resting = 1
