"""What happens to the plant at an instant: injected faults, and the lift of a held object.

Fault injection (tests and demos; :meth:`GripperPlant.schedule_fault`, one fault fires at an exact
simulated instant, the step is split there):

* ``OBJECT_REMOVED``: the object vanishes; the finger is free to move on (to the other finger).
* ``OBJECT_SLIPPING`` (rigid objects): the object slides out of the grip. The most force it can
  resist decays as ``C(t) = F_0 exp(-(t - t_f)/tau)`` from the force ``F_0`` at the fault
  instant ``t_f``. While the motor pushes harder than ``C`` the finger advances against the
  constant load ``C`` (the face recedes with it) and the measured force is ``C``; once
  ``C < 1 %`` of ``F_0`` the object is out and gone. Fired while nothing is gripped
  (``F_0 = 0``), or with flexible fingers or pads (the chain), it acts as a removal.
* ``SENSOR_DROPOUT``: the force sensor reports NaN force and voltage from then on
  (:class:`gripper_ros.core.physics.force_sensor.FsrVoltageDivider`); the mechanics are unaffected.

Effects last until the next :meth:`GripperPlant.set_object` (a new object, a repaired sensor).

Holding (:mod:`gripper_ros.core.physics.hold`): a lifted object is held by Coulomb friction on both
pads at the plant's contact force, and may slide and be lost; :func:`plant_begin_hold` starts the
lift's clock, :func:`plant_drive_load` sets a live arm's acceleration. The step is split at the
lift's start and end and at the loss (:mod:`gripper_ros.core.physics.integration`); at the loss
the object is gone, as for ``OBJECT_REMOVED``.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from gripper_ros.core.physics.contact import (contact_force_n, CONTACT_RIGID, CONTACT_SLIPPING,
                                              remove_object)
from gripper_ros.core.physics.hold import (hold_begin, hold_drive, hold_live,
                                           hold_scenario_in_progress, HoldState)
from gripper_ros.core.physics.plant_records import PLANT_DTYPE
from gripper_ros.core.records import as_record, face_kernel
from gripper_ros.wire import FaultKind
import numba

DEFAULT_SLIP_TIME_CONSTANT_S = 0.01   # e-folding time of the slipping object's force capacity
MAX_FAULT_DELAY_S = 600.0


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


@numba.njit(cache=True)
def clear_fault_state(s, sensor):
    s.fault_kind = FaultKind.NONE
    s.fired_count = 0
    sensor.dropped_out = 0
    s.has_slip = 0
    if s.contact == CONTACT_SLIPPING:
        s.w = 0.0
        s.contact = CONTACT_RIGID


@numba.njit(cache=True)
def fire_fault(s, p, h, sensor, fired):
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
        remove_object(s, p, h, False)
    elif kind == FaultKind.OBJECT_SLIPPING:
        f_0 = contact_force_n(s, p)
        if f_0 <= 0.0 or p.chain:        # the decaying capacity is the rigid contact's
            remove_object(s, p, h, False)
        else:
            s.has_slip = 1
            s.slip_t_f_s = at_ns * 1e-9
            s.slip_f_0_n = f_0
            s.slip_tau_s = s.fault_time_constant_s


@face_kernel(PLANT_DTYPE, int, float)
@numba.njit(cache=True)
def plant_begin_hold(k, t_ns, grasp_mass_kg):
    """Start the lift's clock at ``t_ns``; 1 (nothing changed) if the object left its support."""
    h = as_record(k).hold
    if not h.has_hold or h.state == HoldState.NONE:
        return 0
    mass = h.mass_kg if h.mass_kg != 0.0 else grasp_mass_kg
    if hold_begin(h, t_ns, mass):
        return 1
    h.live = 1 if hold_live(h) else 0
    return 0


@face_kernel(PLANT_DTYPE, float)
@numba.njit(cache=True)
def plant_drive_load(k, accel_mps2):
    """Set the arm's acceleration live from now on; 1 (nothing changed) if nothing is held."""
    pl = as_record(k)
    h = pl.hold
    if not h.has_hold or hold_drive(h, pl.state.t_ns, accel_mps2, pl.params.after_lift_ns):
        return 1
    h.live = 1
    return 0


@face_kernel(PLANT_DTYPE)
@numba.njit(cache=True)
def plant_scenario_in_progress(k):
    """Whether a hold scenario (a lift) is still to be played out."""
    pl = as_record(k)
    h = pl.hold
    return h.has_hold != 0 and hold_scenario_in_progress(h, pl.state.t_ns,
                                                         pl.params.after_lift_ns)


@face_kernel(PLANT_DTYPE, int, int, float)
@numba.njit(cache=True)
def plant_schedule_fault(k, kind, at_ns, time_constant_s):
    """Fire ``kind`` at ``at_ns`` (>= now; replaces a scheduled one; NONE cancels)."""
    s = as_record(k).state
    s.fault_kind = kind
    s.fault_at_ns = at_ns if at_ns > s.t_ns else s.t_ns
    s.fault_time_constant_s = time_constant_s


@face_kernel(PLANT_DTYPE)
@numba.njit(cache=True)
def plant_cancel_fault(k):
    """Drop a scheduled fault that has not fired (its effects, once fired, stay)."""
    as_record(k).state.fault_kind = FaultKind.NONE


@face_kernel(PLANT_DTYPE)
@numba.njit(cache=True)
def plant_fault_scheduled(k):
    """Whether a fault is scheduled and has not fired."""
    return as_record(k).state.fault_kind != FaultKind.NONE
