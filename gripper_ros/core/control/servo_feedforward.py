"""The position servo's feed-forward: the voltage a trajectory needs, and where a stream goes.

Feed-forward. In free motion the motor and lead screw are linear (paper eqs. 1-11, Table I):
``L di/dt = u - R i - k_b w``, ``J dw/dt = k_t i - b w``, ``dx/dt = rho w`` (``rho = p / 2 pi``).
A finger that follows ``x(t)`` with velocity ``v`` and acceleration ``a`` therefore needs

    u = k_v v + k_a a + k_j da/dt,   k_v = (R b + k_t k_b) / (k_t rho),
                                     k_a = (R J + L b) / (k_t rho),   k_j = L J / (k_t rho)

(``1 / k_v`` is the free speed per volt, ``k_a / k_v`` the mechanical time constant with the
armature's L/R added). Held over a sample of ``dt_s`` (zero-order hold), the voltage that takes
the finger's speed from ``v`` to ``v + a dt_s`` is ``k_v (v + a dt_s / 2) + k_a a`` to second
order in ``dt_s / tau_m`` (1e-4 at 10 ms): :func:`feedforward_v`. ``k_j`` (0.04 V per m/s^3,
the 0.1 ms armature) is left out: no trajectory of the finger has the jerk to make it count.

Setpoint stream. A setpoint comes with its velocity and acceleration when the sender knows them
(a trajectory's sample); otherwise they are estimated from the stream's successive setpoints
by a least-squares cubic in time, each setpoint weighted by ``exp(-age / memory_s)`` (a
fading-memory polynomial filter: running sums shifted to the newest setpoint's instant as each
comes, no history kept; a cubic, so that a constant jerk biases no acceleration). A setpoint
sent again (a topic-based hardware repeats its command until the joint has reached it) says the
stream stands: velocity and acceleration 0.

Between setpoints the reference moves on from the newest with that velocity and acceleration,
for ``window_s`` (setpoints come late on a busy machine). Then it brakes to rest at the most the
voltage limit gives a finger at rest (``max_acceleration_mps2``): a topic-based hardware falls
silent while the joint is within its threshold of the command and speaks again as soon as it is
not, which the braking brings about within micrometres; a sender that has stopped has its newest
setpoint in force once the reference is at rest, and its next setpoint starts a new stream. A
setpoint farther from the one before than the motor's free speed at its voltage limit covers in
the time between them (plus the window) is a jump, not a trajectory: the estimate restarts
there, so the newest setpoint is in force at once and the position law makes the least-time
move to it.

The kernels work on one :data:`STREAM_DTYPE` record (the supervisor keeps it in its state); the
stage calls :func:`feedforward_v` with its own sampling time.
"""
from __future__ import annotations

import math

from gripper_ros.core import linalg
from gripper_ros.core.config import PlantParams
from gripper_ros.core.records import as_record
import numba
import numpy as np

NO_STREAM = -1
"""``t_ns`` of a record that holds no stream."""
FIT_DEGREE = 3
"""The fit's polynomial degree: a cubic, whose acceleration is unbiased by a constant jerk."""


STREAM_DTYPE = np.dtype([
    ('t_ns', 'i8'),                        # the newest setpoint's instant (NO_STREAM: none)
    ('changed_ns', 'i8'),                  # the instant of the last that changed
    ('position_m', 'f8'),                  # ... the newest setpoint
    ('velocity_mps', 'f8'),                # ... its velocity: given, or the fit's
    ('acceleration_mps2', 'f8'),           # ... its acceleration: given, or the fit's
    ('instants', 'i8'),                    # distinct instants in the fit since it (re)started
    ('moments', 'f8', (2 * FIT_DEGREE + 1,)),   # sum w s^k, s = (t - t_newest) / memory
    ('sums', 'f8', (FIT_DEGREE + 1,)),          # sum w s^k x
    ('jump_speed_mps', 'f8'),              # faster from one setpoint to the next: a jump
    ('max_acceleration_mps2', 'f8'),       # the most the motor gives the finger at rest
], align=True)
"""A setpoint stream: its newest setpoint, velocity and acceleration, and the fit's sums (about
the newest instant, in units of the memory)."""


def feedforward_gains(plant: PlantParams) -> tuple[float, float]:
    """Return (k_v in V per m/s, k_a in V per m/s^2) of the free finger (module docstring)."""
    rho = plant.travel_per_rad_m
    kt = plant.torque_constant_n_m_per_a
    r, ind = plant.resistance_ohm, plant.inductance_h
    b, inertia = plant.damping_n_m_s_per_rad, plant.inertia_kg_m2
    return ((r * b + kt * plant.back_emf_v_s_per_rad) / (kt * rho),
            (r * inertia + ind * b) / (kt * rho))


def voltage_needed_v(plant: PlantParams, velocity_mps, acceleration_mps2):
    """Return the voltage a finger moving at ``velocity_mps`` and accelerating needs (arrays)."""
    k_v, k_a = feedforward_gains(plant)
    return k_v * np.asarray(velocity_mps) + k_a * np.asarray(acceleration_mps2)


def new_stream(plant: PlantParams) -> np.ndarray:
    """Return a 1-element :data:`STREAM_DTYPE` array holding no stream, for this plant."""
    record = np.zeros(1, STREAM_DTYPE)
    stream_setup(record, plant)
    return record


def stream_bounds(plant: PlantParams) -> tuple[float, float]:
    """Return (jump speed in m/s, most acceleration at rest in m/s^2) of a stream's record.

    The free speed at the voltage limit, and the limit over ``k_a``.
    """
    return plant.max_free_speed_mps, plant.voltage_limit_v / feedforward_gains(plant)[1]


def stream_setup(record, plant: PlantParams) -> None:
    """Write the plant's bounds into ``record`` (a 1-element array); it holds no stream."""
    record['jump_speed_mps'], record['max_acceleration_mps2'] = stream_bounds(plant)
    record['t_ns'] = NO_STREAM


@numba.njit(cache=True)
def feedforward_v(v_per_mps, v_per_mps2, velocity_mps, acceleration_mps2, dt_s):
    """Return the voltage that, held for ``dt_s``, keeps the finger on the trajectory.

    ``velocity_mps`` and ``acceleration_mps2`` are the trajectory's as the hold starts; the
    speed term is taken at the middle of the hold (module docstring).
    """
    return v_per_mps * (velocity_mps + 0.5 * dt_s * acceleration_mps2) + \
        v_per_mps2 * acceleration_mps2


@numba.njit(cache=True)
def _shift(values, count, d, decay) -> None:
    """Re-centre ``values[k] = sum w s^k y`` (k < count) at ``s - d``, weights times ``decay``."""
    for k in range(count - 1, -1, -1):        # from the top: each uses the lower ones unshifted
        total = 0.0
        binomial = 1.0
        power = 1.0
        for j in range(k, -1, -1):            # sum_j C(k, j) (-d)^(k - j) values[j]
            total += binomial * power * values[j]
            binomial = binomial * j / (k - j + 1)
            power *= -d
        values[k] = decay * total


@numba.njit(cache=True)
def _add_older(s, u, position_m) -> None:
    """Add a setpoint at ``u = (t - t_newest) / memory`` (< 0) to the fit, weighted exp(u)."""
    weight = math.exp(u)
    for k in range(s.moments.size):
        s.moments[k] += weight
        if k < s.sums.size:
            s.sums[k] += weight * position_m
        weight *= u
    s.instants += 1


@numba.njit(cache=True)
def _fit(s, degree, memory_s):
    """Return (velocity, acceleration) at the newest instant from the polynomial fit.

    Of ``degree`` or, with fewer distinct instants, the highest they determine (none: 0, 0).
    """
    n = min(degree, s.instants - 1) + 1
    if n < 2:
        return 0.0, 0.0
    gram = np.empty((n, n))
    rhs = np.empty((n, 1))
    for i in range(n):
        rhs[i, 0] = s.sums[i]
        for j in range(n):
            gram[i, j] = s.moments[i + j]
    c = linalg.solve(gram, rhs)
    return c[1, 0] / memory_s, (2.0 * c[2, 0] / memory_s ** 2 if n > 2 else 0.0)


@numba.njit(cache=True)
def _moves_for_s(s, window_s):
    """Return how long after the newest setpoint the reference moves.

    The window, then the braking to rest (:func:`stream_reference`); a setpoint later than that
    starts a new stream.
    """
    v = s.velocity_mps + window_s * min(max(s.acceleration_mps2, -s.max_acceleration_mps2),
                                        s.max_acceleration_mps2)
    return window_s + abs(v) / s.max_acceleration_mps2


@numba.njit(cache=True)
def stream_sample(sv, t_ns, position_m, velocity_mps, acceleration_mps2, memory_s,
                  window_s) -> None:
    """Take the setpoint ``position_m`` of instant ``t_ns``.

    Its velocity and acceleration: NaN if not given, then the fit's. A setpoint older than the
    newest (sampled ahead by a varying period, or late) joins the fit at its own instant; the
    newest stays the reference's base.
    """
    s = as_record(sv)
    if s.t_ns != NO_STREAM and t_ns < s.t_ns:
        _add_older(s, (t_ns - s.t_ns) * 1e-9 / memory_s, position_m)
        if not math.isfinite(velocity_mps):          # the newest's own motion stands
            s.velocity_mps, s.acceleration_mps2 = _fit(s, FIT_DEGREE, memory_s)
        return
    restart = s.t_ns == NO_STREAM or (t_ns - s.t_ns) * 1e-9 > _moves_for_s(s, window_s)
    dt_s = 0.0
    if not restart:
        dt_s = max((t_ns - s.t_ns) * 1e-9, 0.0)
        restart = abs(position_m - s.position_m) > s.jump_speed_mps * (dt_s + window_s)
    if restart:
        s.instants = 0
        s.moments[:] = 0.0
        s.sums[:] = 0.0
        s.t_ns = NO_STREAM
    elif dt_s > 0.0:
        decay = math.exp(-dt_s / memory_s)
        _shift(s.moments, s.moments.size, dt_s / memory_s, decay)
        _shift(s.sums, s.sums.size, dt_s / memory_s, decay)
    s.moments[0] += 1.0
    s.sums[0] += position_m
    if restart or dt_s > 0.0:
        s.instants += 1
    if restart or position_m != s.position_m:
        s.changed_ns = t_ns
    s.t_ns = max(t_ns, s.t_ns)
    s.position_m = position_m
    fit_v, fit_a = _fit(s, FIT_DEGREE, memory_s)
    s.velocity_mps = velocity_mps if math.isfinite(velocity_mps) else fit_v
    s.acceleration_mps2 = acceleration_mps2 if math.isfinite(acceleration_mps2) else fit_a


@numba.njit(cache=True)
def stream_changing(sv, t_ns, window_s) -> bool:
    """Tell whether the stream has changed its setpoint within ``window_s`` of ``t_ns``."""
    s = as_record(sv)
    return s.t_ns != NO_STREAM and (t_ns - s.changed_ns) * 1e-9 <= window_s


@numba.njit(cache=True)
def stream_reference(sv, t_ns, window_s, lead_s, speed_limit_mps, travel_m):
    """Return (position, velocity, acceleration) of the reference at ``t_ns``.

    Within ``window_s`` of the newest setpoint: that setpoint moved on with its velocity (at
    most ``speed_limit_mps``) and acceleration (at most ``max_acceleration_mps2``, what the
    voltage limit gives at rest) to ``t_ns + lead_s``. After that the stream has fallen silent:
    the reference brakes to rest at ``max_acceleration_mps2`` (a topic-based hardware is silent
    while the joint is on its command, and speaks again as soon as it is not: a few
    micrometres later), then stands at the newest setpoint. Within [0, travel_m].
    """
    s = as_record(sv)
    tau = (t_ns - s.t_ns) * 1e-9 + lead_s
    v = min(max(s.velocity_mps, -speed_limit_mps), speed_limit_mps)
    a = min(max(s.acceleration_mps2, -s.max_acceleration_mps2), s.max_acceleration_mps2)
    x = s.position_m
    if s.t_ns != NO_STREAM and tau > window_s:
        x += window_s * (v + 0.5 * window_s * a)             # where the window took it
        v = min(max(v + window_s * a, -speed_limit_mps), speed_limit_mps)
        a = -math.copysign(s.max_acceleration_mps2, v)
        tau -= window_s
        if tau >= abs(v) / s.max_acceleration_mps2:          # at rest: the stream stopped
            x, v, a, tau = s.position_m, 0.0, 0.0, 0.0
    elif s.t_ns == NO_STREAM:
        tau = 0.0
    x += tau * (v + 0.5 * tau * a)
    v = min(max(v + tau * a, -speed_limit_mps), speed_limit_mps)
    if x <= 0.0:
        return 0.0, 0.0, 0.0
    if x >= travel_m:
        return travel_m, 0.0, 0.0
    return x, v, a
