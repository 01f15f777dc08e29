"""Force-sensing resistor (FSR) in a voltage divider: the paper's second switching signal.

An FSR is an open circuit until a small activation force; above it its resistance falls roughly
as 1/F. In a divider with a fixed measuring resistor the output jumps on first contact, which
is the "change in the voltage reading above a set tolerance" the paper's supervisor looks for.
"""
from __future__ import annotations

from .config import ForceSensorParams


class FsrVoltageDivider:
    """``V_out = V_supply * R_m / (R_m + R_fsr(F))`` with an ideal activation threshold."""

    def __init__(self, params: ForceSensorParams):
        self.params = params

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
        """Voltage rise from no contact to the activation force: the switching tolerance's scale."""
        return self.voltage_v(self.params.activation_force_n) - self.voltage_v(0.0)
