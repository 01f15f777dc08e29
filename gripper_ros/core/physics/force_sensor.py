"""Force-sensing resistor (FSR) in a voltage divider: the paper's second switching signal.

An FSR is an open circuit until a small activation force; above it its resistance falls roughly
as 1/F. In a divider with a fixed measuring resistor the output jumps on first contact, which
is the "change in the voltage reading above a set tolerance" the paper's supervisor looks for.

Dropout (fault injection, ``SetObject.FAULT_SENSOR_DROPOUT``): the sensor's read-out stops
delivering valid samples (a broken FSR lead or a failed ADC channel detected by the driver, e.g.
by a wire-break check). The driver then marks the sample invalid the ROS way, with NaN force and
NaN voltage (cf. REP 117: NaN for an invalid reading), rather than passing on the 0 V a broken
divider would show: 0 V is within ADC resolution of the no-contact output (4.995 mV) and would
read as "no force", i.e. as a lost object, and a force loop would wind up on it.

The divider's law is a compiled kernel over a 1-element record array (:data:`SENSOR_DTYPE`),
shared by the plant's kernels and by :class:`FsrVoltageDivider`.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import ForceSensorParams, SensorNoiseParams
from gripper_ros.core.records import copy_fields, face_kernel
import numba
import numpy as np

SENSOR_DTYPE = np.dtype([
    ('supply_v', np.float64),
    ('measuring_resistor_ohm', np.float64),
    ('fsr_resistance_at_1n_ohm', np.float64),
    ('open_resistance_ohm', np.float64),
    ('activation_force_n', np.float64),
    ('dropped_out', np.uint8),          # 1: every reading is invalid (NaN) until repaired
    # Measurement noise (config ``sensor_noise``) of the plant's position and force readings.
    ('noisy', np.uint8),                # 0: ideal readings (the noise below is not drawn)
    ('position_noise_m', np.float64),
    ('position_quantum_m', np.float64),
    ('force_noise_n', np.float64),
    ('force_quantum_n', np.float64),
    ('noise_seed', np.uint64),
], align=True)
"""The sensor's parameters, its dropout flag and the readings' noise, as one record."""

NOISE_CHANNEL_POSITION = 1
NOISE_CHANNEL_FORCE = 2
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX_1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX_2 = np.uint64(0x94D049BB133111EB)
_TWO_POW_MINUS_53 = 2.0 ** -53


@numba.njit(cache=True, inline='always')
def _mix64(z):
    """SplitMix64's finaliser: a well-mixed 64-bit word from a counter (uint64 throughout)."""
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX_1
    z = (z ^ (z >> np.uint64(27))) * _MIX_2
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True)
def gaussian_at(seed, channel, t_ns):
    """Draw a standard normal keyed by (seed, channel, instant): counter-based, reproducible.

    Box-Muller on two uniforms in (0, 1) from SplitMix64 of the key, so a reading depends on
    the simulated instant only, never on how often or in which process it was read.
    """
    key = _mix64(np.uint64(seed) ^ _mix64(np.uint64(channel) ^ _mix64(np.uint64(t_ns))))
    u1 = (float(key >> np.uint64(11)) + 0.5) * _TWO_POW_MINUS_53
    u2 = (float(_mix64(key) >> np.uint64(11)) + 0.5) * _TWO_POW_MINUS_53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@numba.njit(cache=True)
def noisy_reading(r, value, channel, t_ns, sigma, quantum):
    """``value`` as a noisy, quantised sensor reports it at ``t_ns`` (sensor record ``r``)."""
    if sigma > 0.0:
        value = value + sigma * gaussian_at(r.noise_seed, channel, t_ns)
    if quantum > 0.0:
        value = quantum * math.floor(value / quantum + 0.5)
    return value


@numba.njit(cache=True, inline='always')
def fsr_resistance_ohm(r, force_n):
    """FSR resistance at ``force_n`` (sensor record ``r``): open below activation, R_1N / F."""
    if force_n < r.activation_force_n:
        return r.open_resistance_ohm
    fsr = r.fsr_resistance_at_1n_ohm / force_n
    return fsr if fsr < r.open_resistance_ohm else r.open_resistance_ohm


@numba.njit(cache=True, inline='always')
def fsr_voltage_v(r, force_n):
    """Divider output ``V_supply R_m / (R_m + R_fsr(F))`` at ``force_n`` (sensor record ``r``)."""
    r_m = r.measuring_resistor_ohm
    return r.supply_v * r_m / (r_m + fsr_resistance_ohm(r, force_n))


# Array-level entry points for Python (FsrVoltageDivider): the kernels above on ``sensor[0]``.
@face_kernel(SENSOR_DTYPE, float)
@numba.njit(cache=True)
def _resistance_ohm(sensor, force_n):
    return fsr_resistance_ohm(sensor[0], force_n)


@face_kernel(SENSOR_DTYPE, float)
@numba.njit(cache=True)
def _voltage_v(sensor, force_n):
    return fsr_voltage_v(sensor[0], force_n)


class FsrVoltageDivider:
    """``V_out = V_supply * R_m / (R_m + R_fsr(F))`` with an ideal activation threshold."""

    def __init__(self, params: ForceSensorParams, noise: SensorNoiseParams | None = None):
        self.params = params
        self.noise = noise or SensorNoiseParams.ideal()
        self.record = np.zeros(1, SENSOR_DTYPE)   # what the plant's kernels read and write
        r = self.record[0]
        copy_fields(r, self.noise, {'noisy': 'enabled', 'noise_seed': 'seed'})
        copy_fields(r, self.noise, ('position_noise_m', 'position_quantum_m', 'force_noise_n',
                                    'force_quantum_n'))
        copy_fields(r, params, ('supply_v', 'measuring_resistor_ohm', 'fsr_resistance_at_1n_ohm',
                                'open_resistance_ohm', 'activation_force_n'))

    @property
    def dropped_out(self) -> bool:
        """True: every reading is invalid (NaN) until repaired."""
        return bool(self.record[0]['dropped_out'])

    @dropped_out.setter
    def dropped_out(self, value: bool) -> None:
        self.record[0]['dropped_out'] = bool(value)

    def read(self, force_n: float) -> tuple[float, float]:
        """``(force_n, voltage_v)`` as the sensor reports them; both NaN after a dropout."""
        if self.dropped_out:
            return math.nan, math.nan
        return force_n, self.voltage_v(force_n)

    def resistance_ohm(self, force_n: float) -> float:
        """FSR resistance at ``force_n`` (ohm)."""
        return _resistance_ohm(self.record, float(force_n))

    def voltage_v(self, force_n: float) -> float:
        """Divider output at ``force_n`` (V)."""
        return _voltage_v(self.record, float(force_n))

    @property
    def activation_step_v(self) -> float:
        """Voltage rise from zero to the activation force: the switching tolerance's scale."""
        return self.voltage_v(self.params.activation_force_n) - self.voltage_v(0.0)
