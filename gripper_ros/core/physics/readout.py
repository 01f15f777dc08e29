"""What the plant reports: its sensors and motor now, the wire's tick, the held object's state.

The force sensor (:mod:`gripper_ros.core.physics.force_sensor`) reads the contact force (NaN
once it has dropped out), its noise and the position's drawn per tick; a tick carries the four
pad channels' readings (:mod:`gripper_ros.core.physics.plant_pads`).
"""
from __future__ import annotations

from dataclasses import fields
import math
from typing import NamedTuple

from gripper_ros.core.physics.contact import contact_force_n
from gripper_ros.core.physics.force_sensor import (fsr_voltage_v, NOISE_CHANNEL_FORCE,
                                                   NOISE_CHANNEL_POSITION, noisy_reading)
from gripper_ros.core.physics.hold import (hold_capacity_n, hold_load_n, hold_presliding_m,
                                           hold_shear_n, HoldState, ObjectState)
from gripper_ros.core.physics.plant_pads import (PAD_DISPLACEMENT_1, PAD_DISPLACEMENT_2,
                                                 PAD_SHEAR_1, PAD_SHEAR_2)
from gripper_ros.core.physics.plant_records import PLANT_DTYPE
from gripper_ros.core.records import as_record, copy_fields, face_kernel
from gripper_ros.wire import TICK_LAYOUT
import numba
import numpy as np


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


@face_kernel(PLANT_DTYPE)
@numba.njit(cache=True)
def plant_sample(k):
    """Return what the sensors and motor report now, as PlantSample's fields in order."""
    pl = as_record(k)
    s = pl.state
    p = pl.params
    sensor = pl.sensor
    force = contact_force_n(s, p)
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
    return as_record(k).hold


@face_kernel(PLANT_DTYPE, TICK_LAYOUT.dtype, int, int)
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
    pads = as_record(k).pads
    r.pad1_shear_n = pads[PAD_SHEAR_1].reading
    r.pad2_shear_n = pads[PAD_SHEAR_2].reading
    r.pad1_displacement_m = pads[PAD_DISPLACEMENT_1].reading
    r.pad2_displacement_m = pads[PAD_DISPLACEMENT_2].reading


OBJECT_STATE_DTYPE = np.dtype([(f.name, np.int64 if f.name in ('state', 'lost_ns') else np.float64)
                               for f in fields(ObjectState)])
""":class:`ObjectState` as a record, field for field (``lost_ns`` -1: not lost), for a kernel."""
_HOLD_NONE = int(HoldState.NONE)


@face_kernel(PLANT_DTYPE, OBJECT_STATE_DTYPE)
@numba.njit(cache=True)
def _object_state(k, out):
    """Write the held object's :class:`ObjectState` into the record ``out[0]`` (lost_ns -1: not).

    Nothing held: all zeros; an object taken away (state NONE): only how far it had slid.
    """
    o = out[0]
    pl = as_record(k)
    h = pl.hold
    o.state = _HOLD_NONE
    o.slip_m = o.slip_speed_mps = o.load_n = o.capacity_n = 0.0
    o.lift_acceleration_mps2 = o.shear_n = o.presliding_m = 0.0
    o.lost_ns = -1
    if not h.has_hold:
        return
    o.slip_m = h.slip_m
    if h.state == HoldState.NONE:
        return
    force = contact_force_n(pl.state, pl.params)
    copy_fields(o, h, ('state', 'slip_speed_mps', 'lost_ns'))
    o.load_n = hold_load_n(h)
    o.capacity_n = hold_capacity_n(h, force)
    o.lift_acceleration_mps2 = h.acceleration_mps2
    o.shear_n = hold_shear_n(h, force)
    o.presliding_m = hold_presliding_m(h, force)
