"""The plant's four pad channels: what each pad senses of the held object, and when.

Each tick the plant samples, while the object is held (stuck or sliding), each pad's shear and
the object's displacement on it through a channel of :mod:`gripper_ros.core.physics.pad_sensor`
(latency, bandwidth, noise, resolution); otherwise the channels rest at 0. The readings go into
each tick (:func:`gripper_ros.core.physics.readout.plant_read_tick`).
"""
from __future__ import annotations

from gripper_ros.core.physics.contact import contact_force_n
from gripper_ros.core.physics.hold import hold_presliding_m, hold_shear_n
from gripper_ros.core.physics.pad_sensor import CHANNEL_DTYPE, channel_step, MAX_LATENCY_SAMPLES
import numba
import numpy as np

# The pad channels (the plant record's ``pads``, core/physics/pad_sensor.py), in PlantTick's
# order of their readings.
PAD_SHEAR_1, PAD_SHEAR_2, PAD_DISPLACEMENT_1, PAD_DISPLACEMENT_2 = range(4)
PAD_CHANNELS = 4
PAD_DTYPE = np.dtype([(name, CHANNEL_DTYPE.fields[name][0]) for name in CHANNEL_DTYPE.names]
                     + [('line', np.float64, (MAX_LATENCY_SAMPLES,))], align=True)
"""A pad channel's record (pad_sensor.CHANNEL_DTYPE) with its delay line."""


@numba.njit(cache=True)
def pads_rest(chans):
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
def pads_sample(s, p, h, chans, duration_ns):
    """Read each pad's shear and the object's displacement on it at the end of a step.

    While the object is held (stuck or sliding) each channel takes one sample per ``pad_dt_ns``
    of the step (at least one) of the value now; otherwise the channels rest at 0 (plant_step),
    so the readings, and the noise drawn, depend only on the held samples since ``set_object``.
    """
    s.pads_resting = 0
    force = contact_force_n(s, p)
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
