"""The physical floor of the position step under the +-24 V command limit.

No controller can beat these figures on the exact zero-order-hold model of Table I's plant
(state ``[i, omega, x]``, ``s[k+1] = Ad s[k] + Bd u[k]``, :meth:`GripperPlant.discrete_free_model`)
with the command held for each sample and ``|u| <= 24 V``:

* **Minimum time** (:func:`minimum_time_floor`). The position after ``N`` samples is linear in the
  inputs, so "can the finger be at rest on the setpoint after ``N`` samples" (terminal state
  ``[0, 0, r]``, an equilibrium at ``u = 0``) and "can it be inside the 2 % band from sample ``N``
  on for ever" (band constraints on every later sample and a terminal rest inside the band) are
  linear-programme feasibility questions over *all* input sequences. Feasibility is monotone in
  ``N`` (a state at rest stays at rest), so bisection gives the exact minimum sample count. The
  electrical pole (L/R = 0.1 ms) is in the model exactly, not neglected. Among the feasible
  sequences of the minimum length the LP picks the one that pushes hardest early, which is the
  bang-bang sequence: +24 V, one switch, -24 V (the plant is essentially second order), with a
  fractional voltage only in the switching sample and in the last one or two samples.
* **Minimum RMS error** (:func:`rms_floor`). The sampled positions are ``x = G u`` (``G`` lower
  triangular Toeplitz of the position's impulse response), so the smallest RMS of ``r - x`` over
  the horizon (the metric of Table III: all samples ``0..n`` of the 20 s record) is a bounded
  least-squares problem, solved with :func:`scipy.optimize.lsq_linear` (BVLS). The full problem
  (2000 inputs) takes about a minute, so it is bracketed instead: ignoring the error after the
  first ``M`` samples can only lower the minimum (a **lower bound**, the floor we report), and the
  inputs found, followed by 0 V, are a feasible sequence whose RMS over the full record is an
  **upper bound**. With ``M`` = 4 s the two agree to better than 1e-8 m.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.control.factories import make_plant
from gripper_ros.studies.metrics import SETTLING_BAND
import numpy as np
from scipy.optimize import linprog, lsq_linear

DEFAULT_SETPOINT_M = 0.1
DEFAULT_HORIZON_S = 20.0
RMS_WINDOW_S = 4.0          # rms_floor: errors counted exactly over this window (see docstring)
BAND_TAIL_S = 1.5           # minimum_time_floor: time allowed to come to rest inside the band


@dataclass
class MinimumTimeFloor:
    """Shortest times any |u| <= limit input sequence needs (multiples of the sampling time)."""

    setpoint_m: float
    dt_s: float
    voltage_limit_v: float
    band_fraction: float
    band_settling_time_s: float      # first sample from which x stays within the band for ever
    rest_time_s: float               # first sample at which the state is [0, 0, setpoint]
    band_switch_time_s: float        # start of the sample where the band sequence leaves +limit
    rest_switch_time_s: float
    band_inputs_v: np.ndarray = field(repr=False)   # a minimum-time sequence (then 0 V)
    rest_inputs_v: np.ndarray = field(repr=False)


@dataclass
class RmsFloor:
    """Smallest RMS error of the sampled position over the horizon, bracketed."""

    setpoint_m: float
    dt_s: float
    horizon_s: float
    voltage_limit_v: float
    rms_lower_m: float               # the floor: no input sequence does better
    rms_upper_m: float               # achieved by ``inputs_v`` (then 0 V): the bracket is tight
    window_s: float
    inputs_v: np.ndarray = field(repr=False)


def _markov(config: GripperConfig, dt_s: float, samples: int) -> np.ndarray:
    """``out[m] = Ad^m Bd`` for m < samples: the state's response to a unit input m samples ago."""
    ad, bd = make_plant(config).discrete_free_model(dt_s)
    out = np.empty((samples, 3))
    s = bd.copy()
    for m in range(samples):
        out[m] = s
        s = ad @ s
    return out


def _terminal_matrix(markov: np.ndarray, n: int) -> np.ndarray:
    """3 x n: ``s[n] = M u[0..n-1]`` from rest at the origin."""
    return markov[:n][::-1].T


def _position_matrix(markov: np.ndarray, rows: range, n: int) -> np.ndarray:
    """x[k] for k in ``rows`` as a function of u[0..n-1] (rows k < j+1 get no effect of u[j])."""
    h = markov[:, 2]
    out = np.zeros((len(rows), n))
    for r_i, k in enumerate(rows):
        m = min(k, n)
        out[r_i, :m] = h[k - 1::-1][:m] if k > 0 else 0.0
    return out


def _solve_lp(n: int, limit: float, a_eq, b_eq, a_ub=None, b_ub=None):
    """Feasible |u| <= limit with the equalities; the objective favours + early, - late."""
    scale = np.abs(a_eq).max(axis=1)
    kwargs = {}
    if a_ub is not None:
        s_ub = np.abs(a_ub).max(axis=1)
        kwargs = {'A_ub': a_ub / s_ub[:, None], 'b_ub': b_ub / s_ub}
    cost = -(n - np.arange(n)) / n
    return linprog(cost, A_eq=a_eq / scale[:, None], b_eq=b_eq / scale,
                   bounds=[(-limit, limit)] * n, method='highs', **kwargs)


def _bisect(feasible, n_max: int, start: int = 32, lower: int = 0) -> tuple[int, np.ndarray]:
    """Smallest n in [1, n_max] with ``feasible(n)`` (monotone) and its solution.

    ``lower``: an n known to be infeasible (0: none).
    """
    lo, hi = lower, min(start, n_max)
    best = feasible(hi)
    while best is None:                      # doubling search for a feasible length
        if hi >= n_max:
            raise RuntimeError(f'no input sequence of {n_max} samples reaches the target')
        lo, hi = hi, min(2 * hi, n_max)
        best = feasible(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        sol = feasible(mid)
        if sol is None:
            lo = mid
        else:
            hi, best = mid, sol
    return hi, best


def _switch_time(u: np.ndarray, limit: float, dt_s: float) -> float:
    below = np.flatnonzero(u < limit * (1.0 - 1e-9))
    return float(below[0] * dt_s) if below.size else math.inf


def _rest_inputs(markov: np.ndarray, n: int, limit: float, setpoint_m: float):
    """Return inputs |u| <= limit that bring the finger to rest at the setpoint in n samples."""
    res = _solve_lp(n, limit, _terminal_matrix(markov, n), np.array([0.0, 0.0, setpoint_m]))
    return res.x if res.status == 0 else None


def minimum_rest_times_s(config: GripperConfig, setpoints_m, dt_s: float | None = None,
                         max_time_s: float = 20.0) -> list[float]:
    """Return the minimum time from rest at fully open to rest at each setpoint.

    The ``rest`` floor of :func:`minimum_time_floor` alone (its band floor costs three times
    as much), for sweeps over many setpoints. The system is linear from rest, so a rest at ``r``
    reachable in n samples makes every rest nearer than ``r`` reachable in n too (scale the
    inputs): the floor grows with the setpoint, and the setpoints are searched in order, each
    from the one before.
    """
    dt = config.position.sample_time_s if dt_s is None else dt_s
    limit = config.plant.voltage_limit_v
    n_max = int(round(max_time_s / dt))
    markov = _markov(config, dt, n_max + 1)
    floors = {}
    n_lower = 0
    for r in sorted({float(abs(x)) for x in setpoints_m}):
        def feasible(n, r=r):
            return _rest_inputs(markov, n, limit, r)
        if n_lower and feasible(n_lower) is not None:
            n = n_lower
        else:
            n, _ = _bisect(feasible, n_max, start=max(1, n_lower + 1), lower=n_lower)
        floors[r] = n * dt
        n_lower = n
    return [floors[float(abs(x))] for x in setpoints_m]


def minimum_time_floor(config: GripperConfig, setpoint_m: float = DEFAULT_SETPOINT_M,
                       dt_s: float | None = None, band: float = SETTLING_BAND,
                       max_time_s: float = 20.0) -> MinimumTimeFloor:
    """Minimum-time floors (2 % band and exact rest) from rest at fully open, |u| <= limit."""
    dt = config.position.sample_time_s if dt_s is None else dt_s
    limit = config.plant.voltage_limit_v
    r = float(setpoint_m)
    tol = band * abs(r) * (1.0 - 1e-6)     # strictly inside: the optimum rests on the band edge
    n_max = int(round(max_time_s / dt))
    tail = int(round(BAND_TAIL_S / dt))
    markov = _markov(config, dt, n_max + tail + 1)

    def rest(n: int):
        return _rest_inputs(markov, n, limit, r)

    def in_band(n: int):
        total = n + tail
        term = _terminal_matrix(markov, total)[:2]           # i = omega = 0 at the end: rest
        pos = _position_matrix(markov, range(n, total + 1), total)
        a_ub = np.vstack([pos, -pos])
        b_ub = np.concatenate([np.full(len(pos), r + tol), np.full(len(pos), -(r - tol))])
        res = _solve_lp(total, limit, term, np.zeros(2), a_ub, b_ub)
        return res.x if res.status == 0 else None

    n_rest, u_rest = _bisect(rest, n_max)
    n_band, u_band = _bisect(in_band, n_rest, start=max(1, (17 * n_rest) // 20))
    u_rest = np.where(np.abs(u_rest) < 1e-6, 0.0, u_rest)   # LP round-off once at rest
    u_band = np.where(np.abs(u_band) < 1e-6, 0.0, u_band)
    return MinimumTimeFloor(r, dt, limit, band, n_band * dt, n_rest * dt,
                            _switch_time(u_band, limit, dt), _switch_time(u_rest, limit, dt),
                            u_band, u_rest)


def rms_floor(config: GripperConfig, setpoint_m: float = DEFAULT_SETPOINT_M,
              dt_s: float | None = None, horizon_s: float = DEFAULT_HORIZON_S,
              window_s: float = RMS_WINDOW_S) -> RmsFloor:
    """Smallest RMS of ``setpoint - x[k]``, k = 0..n (n = horizon / dt), over |u| <= limit."""
    dt = config.position.sample_time_s if dt_s is None else dt_s
    limit = config.plant.voltage_limit_v
    r = float(setpoint_m)
    n = int(round(horizon_s / dt))
    m = min(n, int(round(window_s / dt)))
    markov = _markov(config, dt, n)
    g = _position_matrix(markov, range(0, m + 1), m)          # x[0..m] from u[0..m-1]
    res = lsq_linear(g, np.full(m + 1, r), bounds=(-limit, limit), method='bvls')
    lower = math.sqrt(float(np.sum((r - g @ res.x) ** 2)) / (n + 1))
    # Upper bound: the same inputs, but made to come to rest by also counting a tail of errors.
    tail = min(n, m + int(round(1.0 / dt)))
    g_tail = _position_matrix(markov, range(0, tail + 1), m)
    res_up = lsq_linear(g_tail, np.full(tail + 1, r), bounds=(-limit, limit), method='bvls')
    u = np.zeros(n)
    u[:m] = res_up.x
    x = _position_matrix_apply(markov, u)
    upper = math.sqrt(float(np.mean((r - x) ** 2)))
    return RmsFloor(r, dt, horizon_s, limit, lower, upper, m * dt, res_up.x)


def _position_matrix_apply(markov: np.ndarray, u: np.ndarray) -> np.ndarray:
    """x[0..n] for inputs u[0..n-1] from rest at the origin (convolution)."""
    h = markov[:u.size, 2]
    x = np.zeros(u.size + 1)
    x[1:] = np.convolve(h, u)[:u.size]
    return x
