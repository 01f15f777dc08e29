"""PD / PI / PID with explicit sampling time, output limits and anti-windup.

Discrete positional form at sampling time ``dt_s``:

    u[k] = kc * (w * r[k] - y[k])  +  I[k]  +  D[k]
    I[k] = I[k-1] + ki * dt_s * e[k]                      (backward rectangle, e = r - y)
    D[k] = kd * (e[k] - e[k-1]) / dt_s                    (derivative on error), or
           -kd * (y[k] - y[k-1]) / dt_s                   (derivative on measurement: no kick)

The output is clamped to ``output_limits`` (the motor's +-24 V). Anti-windup by conditional
integration: the integrator does not move in a direction that would push a saturated output
further into saturation. :meth:`reset` with an output value gives bumpless transfer: the
integrator is seeded so the first output equals the command already on the motor.
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
import math

from gripper_ros.core.config import PidGains


class DerivativeOn(enum.Enum):
    ERROR = 'error'
    MEASUREMENT = 'measurement'


class AntiWindup(enum.Enum):
    NONE = 'none'                  # plain integrator (what winds up)
    CONDITIONAL = 'conditional'    # stop integrating while saturated in the same direction


@dataclass
class PidTerms:
    """The parts of the last output, for logging and tests."""

    proportional: float = 0.0
    integral: float = 0.0
    derivative: float = 0.0
    output: float = 0.0
    saturated: bool = False


class PID:
    """One PD, PI or PID loop; ``step(setpoint, measurement)`` once per ``dt_s``."""

    def __init__(self, gains: PidGains, dt_s: float, output_limits: tuple[float, float],
                 derivative_on: DerivativeOn = DerivativeOn.ERROR,
                 anti_windup: AntiWindup = AntiWindup.CONDITIONAL,
                 setpoint_weight: float = 1.0):
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f'dt_s must be finite and > 0, got {dt_s!r}')
        low, high = output_limits
        if not low < high:
            raise ValueError(f'output limits must satisfy low < high, got {output_limits!r}')
        for name in ('kc', 'ki', 'kd'):
            value = getattr(gains, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'gain {name} must be finite and >= 0, got {value!r}')
        self.gains = gains
        self.dt_s = dt_s
        self.output_limits = (float(low), float(high))
        self.derivative_on = derivative_on
        self.anti_windup = anti_windup
        self.setpoint_weight = setpoint_weight
        self.terms = PidTerms()
        self.reset()

    def reset(self, output: float = 0.0, setpoint: float | None = None,
              measurement: float | None = None) -> None:
        """Forget the past.

        With ``output`` (and the current setpoint/measurement) the next :meth:`step` starts
        from that output: bumpless transfer from another controller.
        """
        self._prev_error: float | None = None
        self._prev_measurement: float | None = measurement
        if setpoint is not None and measurement is not None:
            error = setpoint - measurement
            self._prev_error = error
            p_term = self.gains.kc * (self.setpoint_weight * setpoint - measurement)
            # the next step adds ki*dt*e to the integral: seed it so that step returns `output`
            self._integral = (self._clamp(output) - p_term - self.gains.ki * self.dt_s * error
                              if self.gains.ki > 0.0 else 0.0)
        else:
            self._integral = self._clamp(output) if self.gains.ki > 0.0 else 0.0
        self.last_output = self._clamp(output)

    def _clamp(self, value: float) -> float:
        low, high = self.output_limits
        return min(high, max(low, value))

    def _terms(self, setpoint: float, measurement: float) -> tuple[float, float, float]:
        """Proportional, integral and derivative terms of the next sample (nothing committed)."""
        g = self.gains
        error = setpoint - measurement
        p_term = g.kc * (self.setpoint_weight * setpoint - measurement)
        if g.kd == 0.0:
            d_term = 0.0
        elif self.derivative_on is DerivativeOn.MEASUREMENT:
            prev = self._prev_measurement
            d_term = 0.0 if prev is None else -g.kd * (measurement - prev) / self.dt_s
        else:
            prev = self._prev_error
            d_term = 0.0 if prev is None else g.kd * (error - prev) / self.dt_s
        return p_term, self._integral + g.ki * self.dt_s * error, d_term

    def _output_line(self, measurement: float) -> tuple[float, float]:
        """Return (base, slope): the next unclamped output is ``base + slope * setpoint``."""
        base = sum(self._terms(0.0, measurement))
        return base, sum(self._terms(1.0, measurement)) - base

    def setpoint_range(self, measurement: float) -> tuple[float, float]:
        """Setpoints for which the next output stays inside the limits.

        The output is affine in the setpoint. A cascade's outer loop uses this so the inner
        loop never saturates.
        """
        base, slope = self._output_line(measurement)
        low, high = self.output_limits
        if slope <= 0.0:
            return (-math.inf, math.inf)
        return ((low - base) / slope, (high - base) / slope)

    def setpoint_for_output(self, output: float, measurement: float) -> float:
        """Setpoint for which the next output is exactly ``output`` (inside the limits)."""
        base, slope = self._output_line(measurement)
        if slope <= 0.0:
            raise ValueError('the output does not depend on the setpoint (kc = 0?)')
        return (self._clamp(output) - base) / slope

    def step(self, setpoint: float, measurement: float) -> float:
        """One sample: returns the clamped output (e.g. armature voltage)."""
        if not (math.isfinite(setpoint) and math.isfinite(measurement)):
            raise ValueError(f'non-finite input: setpoint={setpoint!r}, '
                             f'measurement={measurement!r}')
        g = self.gains
        error = setpoint - measurement
        p_term, integral, d_term = self._terms(setpoint, measurement)
        raw = p_term + integral + d_term
        output = self._clamp(raw)
        saturated = output != raw
        if saturated and self.anti_windup is AntiWindup.CONDITIONAL and g.ki > 0.0:
            low, high = self.output_limits
            # Integrate only as far as the limit, never further into saturation.
            if raw > high and error > 0.0:
                integral = max(self._integral, min(integral, high - p_term - d_term))
            elif raw < low and error < 0.0:
                integral = min(self._integral, max(integral, low - p_term - d_term))
            output = self._clamp(p_term + integral + d_term)
        self._integral = integral
        self._prev_error = error
        self._prev_measurement = measurement
        self.last_output = output
        self.terms = PidTerms(p_term, integral, d_term, output, saturated)
        return output


def first_order_pi_by_pole_placement(a: float, b: float, dt_s: float,
                                     closed_loop_pole: float) -> PidGains:
    """PI gains that put both closed-loop poles at ``closed_loop_pole`` for ``y+ = a y + b u``.

    With this module's PI (backward-rectangle integrator) the loop's characteristic polynomial is
    ``z^2 + (b (kc + ki dt) - 1 - a) z + (a - b kc)``; matching ``(z - p)^2`` gives
    ``kc = (a - p^2) / b`` and ``ki = (1 - p)^2 / (b dt)``.
    """
    if not (0.0 <= closed_loop_pole < 1.0):
        raise ValueError('closed_loop_pole must be in [0, 1)')
    p = closed_loop_pole
    kc = (a - p * p) / b
    if kc < 0.0:
        raise ValueError(f'pole {p} is faster than the open loop allows with kc >= 0 (a={a:.4f})')
    return PidGains(kc=kc, ki=(1.0 - p) ** 2 / (b * dt_s))
