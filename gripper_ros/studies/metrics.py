"""Step-response metrics used by the paper's Tables III and IV (and by the bag tools).

All functions take sampled series (``t_s`` increasing, ``y`` the measured output) and a
constant setpoint. The RMS error is the root mean square of ``setpoint - y`` over the samples
given, as in the paper's tables; callers choose the horizon by what they pass.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SETTLING_BAND = 0.02  # 2 % band, the paper's settling criterion


@dataclass(frozen=True)
class StepMetrics:
    """The three figures the paper reports for a step response."""

    rms_error: float
    overshoot_pct: float
    settling_time_s: float


def _as_arrays(t_s, y):
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(y, dtype=float)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError('t_s and y must be 1-D series of equal length')
    if t.size == 0:
        raise ValueError('empty series')
    return t, v


def rms_error(y, setpoint: float) -> float:
    """Root mean square of the error ``setpoint - y`` over the samples."""
    v = np.asarray(y, dtype=float)
    if v.size == 0:
        raise ValueError('empty series')
    return float(np.sqrt(np.mean((setpoint - v) ** 2)))


def percent_overshoot(y, setpoint: float, initial: float = 0.0) -> float:
    """Peak excursion beyond the setpoint, in % of the step size (0 if none)."""
    v = np.asarray(y, dtype=float)
    step = setpoint - initial
    if step == 0.0:
        raise ValueError('setpoint equals the initial value: overshoot undefined')
    peak = np.max((v - setpoint) * np.sign(step))
    return float(max(0.0, peak / abs(step) * 100.0))


def settling_time(t_s, y, setpoint: float, initial: float = 0.0, band: float = SETTLING_BAND,
                  start_s: float | None = None) -> float:
    """Time from ``start_s`` (default: first sample) until ``y`` stays within ``band`` of the step.

    Returns ``inf`` when the last sample is outside the band (not settled within the record).
    The band is a fraction of the step size ``|setpoint - initial|``.
    """
    t, v = _as_arrays(t_s, y)
    t0 = t[0] if start_s is None else start_s
    tol = band * abs(setpoint - initial)
    outside = np.flatnonzero(np.abs(v - setpoint) > tol)
    if outside.size == 0:
        return 0.0
    last = outside[-1]
    if last + 1 >= t.size:
        return float('inf')
    return float(t[last + 1] - t0)


def step_metrics(t_s, y, setpoint: float, initial: float = 0.0) -> StepMetrics:
    """RMS error, % overshoot and 2 % settling time of one step response."""
    return StepMetrics(rms_error(y, setpoint), percent_overshoot(y, setpoint, initial),
                       settling_time(t_s, y, setpoint, initial))
