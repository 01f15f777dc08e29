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
"""
from __future__ import annotations

import math

from gripper_ros.core.config import ForceSensorParams


class FsrVoltageDivider:
    """``V_out = V_supply * R_m / (R_m + R_fsr(F))`` with an ideal activation threshold."""

    def __init__(self, params: ForceSensorParams):
        self.params = params
        self.dropped_out = False     # True: every reading is invalid (NaN) until repaired

    def read(self, force_n: float) -> tuple[float, float]:
        """``(force_n, voltage_v)`` as the sensor reports them; both NaN after a dropout."""
        if self.dropped_out:
            return math.nan, math.nan
        return force_n, self.voltage_v(force_n)

    def resistance_ohm(self, force_n: float) -> float:
        p = self.params
        if force_n < p.activation_force_n:
            return p.open_resistance_ohm
        return min(p.open_resistance_ohm, p.fsr_resistance_at_1n_ohm / force_n)

    def voltage_v(self, force_n: float) -> float:
        p = self.params
        r_m = p.measuring_resistor_ohm
        return p.supply_v * r_m / (r_m + self.resistance_ohm(force_n))

    @property
    def activation_step_v(self) -> float:
        """Voltage rise from zero to the activation force: the switching tolerance's scale."""
        return self.voltage_v(self.params.activation_force_n) - self.voltage_v(0.0)
