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

The per-sample work is compiled (``pid_*`` kernels over one :data:`PID_DTYPE` record, the
state shared with the stage kernels of :mod:`gripper_ros.core.control.stages`); :class:`PID` is the
Python façade that validates and calls them. This module also holds what every compiled law
shares: Python's ``min``/``max`` semantics (:func:`py_min`, :func:`py_max`) and the codes of a
law that refuses its numbers (``LAW_*``, formatted by :func:`law_error`).
"""
from __future__ import annotations

import enum
import math

from gripper_ros.core.config import PidGains
from gripper_ros.core.records import (as_record, face_kernel, record_view, RecordChoice,
                                      RecordField, RecordPair, RecordParams)
import numba
import numpy as np


class DerivativeOn(enum.Enum):
    ERROR = 'error'
    MEASUREMENT = 'measurement'


class AntiWindup(enum.Enum):
    NONE = 'none'                  # plain integrator (what winds up)
    CONDITIONAL = 'conditional'    # stop integrating while saturated in the same direction


# --- what a compiled law returns when it refuses its numbers (as exceptions) ---------------
LAW_OK = 0
LAW_PID_INPUT = 1        # ValueError: non-finite PID input (law numbers: setpoint, measurement)
LAW_NO_SLOPE = 2         # ValueError: the output does not depend on the setpoint
LAW_CONTACT_INPUT = 3    # ValueError: non-finite contact-stage input (its five numbers)
LAW_ZERO_DIVISION = 4    # ZeroDivisionError: float division by zero
LAW_MATH_DOMAIN = 5      # ValueError: math domain error (square root of a negative number)
LAW_NUMBERS = 5
"""Length of the float array a compiled law writes the numbers of its refusal into."""


LAW_ERRORS = {
    LAW_PID_INPUT: (ValueError, 'non-finite input: setpoint={0!r}, measurement={1!r}'),
    LAW_NO_SLOPE: (ValueError, 'the output does not depend on the setpoint (kc = 0?)'),
    LAW_CONTACT_INPUT: (ValueError, 'non-finite input: force_setpoint_n={0!r}, force_n={1!r}, '
                        'position_m={2!r}, face_m={3!r}, width_tolerance_m={4!r}'),
    LAW_ZERO_DIVISION: (ZeroDivisionError, 'float division by zero'),
    LAW_MATH_DOMAIN: (ValueError, 'math domain error'),
}
"""Each refusal's exception and text, over the law's numbers in the order it writes them."""


def law_error(code: int, numbers) -> Exception:
    """Return the exception for a compiled law's refusal ``code`` and its ``numbers``."""
    if code not in LAW_ERRORS:
        return RuntimeError(f'unknown control-law code {code}')
    kind, text = LAW_ERRORS[code]
    return kind(text.format(*(float(x) for x in numbers)))


@numba.njit(cache=True)
def py_max(a, b):
    """Python's ``max(a, b)``: ``a`` unless ``b > a`` (NaN handled as Python does)."""
    return b if b > a else a


@numba.njit(cache=True)
def py_min(a, b):
    """Python's ``min(a, b)``: ``a`` unless ``b < a``."""
    return b if b < a else a


PID_DTYPE = np.dtype([
    ('kc', 'f8'), ('ki', 'f8'), ('kd', 'f8'),       # gains (kc in output per input unit)
    ('dt_s', 'f8'),
    ('low', 'f8'), ('high', 'f8'),                  # output_limits
    ('setpoint_weight', 'f8'),
    ('derivative_on_measurement', 'u1'),            # DerivativeOn.MEASUREMENT (0: ERROR)
    ('conditional', 'u1'),                          # AntiWindup.CONDITIONAL (0: NONE)
    ('has_prev_error', 'u1'),                       # 0: no previous error (None)
    ('has_prev_measurement', 'u1'),                 # 0: no previous measurement (None)
    ('prev_error', 'f8'), ('prev_measurement', 'f8'),
    ('integral', 'f8'),
    ('last_output', 'f8'),
    ('proportional', 'f8'), ('integral_term', 'f8'), ('derivative', 'f8'),   # last terms
    ('output', 'f8'), ('saturated', 'u1'),
], align=True)
"""One PID's gains, limits, memory and last terms (a 1-element array is the kernels' state)."""


@numba.njit(cache=True)
def pid_clamp(p, value):
    """Clamp ``value`` to the output limits."""
    s = as_record(p)
    return py_min(s.high, py_max(s.low, value))


@face_kernel(PID_DTYPE, float, bool, float, bool, float)
@numba.njit(cache=True)
def pid_reset(p, output, has_setpoint, setpoint, has_measurement, measurement):
    """Forget the past; with setpoint and measurement the next step returns ``output``."""
    s = as_record(p)
    s.has_prev_error = 0
    s.has_prev_measurement = 1 if has_measurement else 0
    s.prev_measurement = measurement if has_measurement else 0.0
    if has_setpoint and has_measurement:
        error = setpoint - measurement
        s.has_prev_error = 1
        s.prev_error = error
        p_term = s.kc * (s.setpoint_weight * setpoint - measurement)
        # the next step adds ki*dt*e to the integral: seed it so that step returns `output`
        s.integral = (pid_clamp(s, output) - p_term - s.ki * s.dt_s * error
                      if s.ki > 0.0 else 0.0)
    else:
        s.integral = pid_clamp(s, output) if s.ki > 0.0 else 0.0
    s.last_output = pid_clamp(s, output)


@numba.njit(cache=True)
def pid_terms(p, setpoint, measurement):
    """Proportional, integral and derivative terms of the next sample (nothing committed)."""
    s = as_record(p)
    error = setpoint - measurement
    p_term = s.kc * (s.setpoint_weight * setpoint - measurement)
    if s.kd == 0.0:
        d_term = 0.0
    elif s.derivative_on_measurement:
        d_term = (-s.kd * (measurement - s.prev_measurement) / s.dt_s
                  if s.has_prev_measurement else 0.0)
    else:
        d_term = s.kd * (error - s.prev_error) / s.dt_s if s.has_prev_error else 0.0
    return p_term, s.integral + s.ki * s.dt_s * error, d_term


@numba.njit(cache=True)
def pid_output_line(p, measurement):
    """Return (base, slope): the next unclamped output is ``base + slope * setpoint``."""
    s = as_record(p)
    p0, i0, d0 = pid_terms(s, 0.0, measurement)
    base = 0.0 + p0 + i0 + d0
    p1, i1, d1 = pid_terms(s, 1.0, measurement)
    return base, (0.0 + p1 + i1 + d1) - base


@face_kernel(PID_DTYPE, float)
@numba.njit(cache=True)
def pid_setpoint_range(p, measurement):
    """Setpoints for which the next output stays inside the limits (-inf, inf: any)."""
    s = as_record(p)
    base, slope = pid_output_line(s, measurement)
    if slope <= 0.0:
        return -math.inf, math.inf
    return (s.low - base) / slope, (s.high - base) / slope


@face_kernel(PID_DTYPE, float, float)
@numba.njit(cache=True)
def pid_setpoint_for_output(p, output, measurement):
    """Return (code, setpoint): the setpoint for which the next output is ``output``.

    ``LAW_NO_SLOPE`` when the output does not depend on the setpoint.
    """
    s = as_record(p)
    base, slope = pid_output_line(s, measurement)
    if slope <= 0.0:
        return LAW_NO_SLOPE, 0.0
    return LAW_OK, (pid_clamp(s, output) - base) / slope


@face_kernel(PID_DTYPE, float, float)
@numba.njit(cache=True)
def pid_step(p, setpoint, measurement):
    """One sample on finite inputs: returns the clamped output and books the terms."""
    s = as_record(p)
    error = setpoint - measurement
    p_term, integral, d_term = pid_terms(s, setpoint, measurement)
    raw = p_term + integral + d_term
    output = pid_clamp(s, raw)
    saturated = output != raw
    if saturated and s.conditional and s.ki > 0.0:
        # Integrate only as far as the limit, never further into saturation.
        if raw > s.high and error > 0.0:
            integral = py_max(s.integral, py_min(integral, s.high - p_term - d_term))
        elif raw < s.low and error < 0.0:
            integral = py_min(s.integral, py_max(integral, s.low - p_term - d_term))
        output = pid_clamp(s, p_term + integral + d_term)
    s.integral = integral
    s.has_prev_error = 1
    s.prev_error = error
    s.has_prev_measurement = 1
    s.prev_measurement = measurement
    s.last_output = output
    s.proportional = p_term
    s.integral_term = integral
    s.derivative = d_term
    s.output = output
    s.saturated = 1 if saturated else 0
    return output


@numba.njit(cache=True)
def pid_step_checked(p, setpoint, measurement, numbers):
    """Return (code, output): :func:`pid_step`, or ``LAW_PID_INPUT`` on a non-finite input."""
    if not (math.isfinite(setpoint) and math.isfinite(measurement)):
        numbers[0] = setpoint
        numbers[1] = measurement
        return LAW_PID_INPUT, 0.0
    return LAW_OK, pid_step(p, setpoint, measurement)


PidTerms = record_view('PidTerms', PID_DTYPE,
                       {'proportional': 'proportional', 'integral': 'integral_term',
                        'derivative': 'derivative', 'output': 'output', 'saturated': 'saturated'},
                       'The parts of the last output, for logging and tests.')


class PID:
    """One PD, PI or PID loop; ``step(setpoint, measurement)`` once per ``dt_s``.

    The state is the 1-element :data:`PID_DTYPE` array ``record`` (shared with the kernels of
    any cascade or stage built on this loop).
    """

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
        self.record = np.zeros(1, PID_DTYPE)
        self.gains = gains
        self.dt_s = dt_s
        self.output_limits = (float(low), float(high))
        self.derivative_on = derivative_on
        self.anti_windup = anti_windup
        self.setpoint_weight = setpoint_weight
        self.reset()

    gains = RecordParams(('kc', 'ki', 'kd'))

    dt_s = RecordField()

    output_limits = RecordPair('low', 'high')

    derivative_on = RecordChoice('derivative_on_measurement', DerivativeOn.MEASUREMENT,
                                 DerivativeOn.ERROR)

    anti_windup = RecordChoice('conditional', AntiWindup.CONDITIONAL, AntiWindup.NONE)

    setpoint_weight = RecordField()

    last_output = RecordField(writable=False)

    terms = property(lambda self: PidTerms.of(self.record), doc=PidTerms.__doc__)

    def reset(self, output: float = 0.0, setpoint: float | None = None,
              measurement: float | None = None) -> None:
        """Forget the past.

        With ``output`` (and the current setpoint/measurement) the next :meth:`step` starts
        from that output: bumpless transfer from another controller.
        """
        pid_reset(self.record, float(output), setpoint is not None,
                  0.0 if setpoint is None else float(setpoint), measurement is not None,
                  0.0 if measurement is None else float(measurement))

    def setpoint_range(self, measurement: float) -> tuple[float, float]:
        """Setpoints for which the next output stays inside the limits.

        The output is affine in the setpoint. A cascade's outer loop uses this so the inner
        loop never saturates.
        """
        return pid_setpoint_range(self.record, float(measurement))

    def setpoint_for_output(self, output: float, measurement: float) -> float:
        """Setpoint for which the next output is exactly ``output`` (inside the limits)."""
        code, setpoint = pid_setpoint_for_output(self.record, float(output), float(measurement))
        if code != LAW_OK:
            raise law_error(code, ())
        return setpoint

    def step(self, setpoint: float, measurement: float) -> float:
        """One sample: returns the clamped output (e.g. armature voltage)."""
        if not (math.isfinite(setpoint) and math.isfinite(measurement)):
            raise law_error(LAW_PID_INPUT, (setpoint, measurement))
        return pid_step(self.record, float(setpoint), float(measurement))


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
