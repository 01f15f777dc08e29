"""Dynamic matrix control (paper eqs. 17-22) and the cascaded MPC-PD / MPC-PI.

The DMC's model is the step response of the *inner closed loop* (PD or PI around the plant), so
its output is the inner controller's setpoint (paper sec. III-C). The least-squares gain of eq. 20
depends only on the model, so it is computed once; a control step is then one dot product of
length N plus a shift of the prediction vector.

Limit awareness (ours; the paper's structure is ``CascadedMpc(respect_inner_limits=False)``).
The DMC predicts with the *unsaturated* inner loop, so under the +-24 V limit it must be kept
honest in two ways, both cheap enough for a 10 ms ROS loop:

1. Each sample its output is clamped to the setpoint range in which the inner PD's voltage stays
   within the limit (:meth:`PID.setpoint_range`), and the DMC books the move actually made: the
   inner loop stays linear, as the model assumes, and nothing winds up.
2. Braking. With the clamp alone the DMC, believing it can brake at will, brakes early and then
   creeps in (4.19 s to settle for 0.1 m). :class:`BrakingGovernor` makes the large move in
   minimum time on the exact ZOH model: full voltage until braking at ``braking_v`` from one
   sample later would no longer stop the finger short of the setpoint, then braking until the
   finger would stop. Each forced voltage is handed to the inner PD as the one setpoint that
   gives it, so the cascade's structure stays (the MPC layer sets the PD's setpoint); the DMC is
   held at the measurement meanwhile. At the handover, at rest, both loops start afresh and the
   DMC finishes and holds. 0.1 m with ``braking_v`` = 20 V: 2.64 s to 2 % (floor 2.54 s,
   ``position_limit``), 0.05 % overshoot, RMS 0.02415 (floor 0.02414), two sign changes of the
   command above 1 V in 20 s (accelerate, brake).
   Two earlier versions failed: a DMC left running through the forced samples, braking on its
   own, chattered between +-24 V for seconds at the setpoint (it predicts from moves it did
   not choose); a handover without resetting the PD kept the forced samples' derivative memory
   and overshot by 1.3-5 %.

Rejected: a DMC that constrains the predicted inner voltage over the horizon (a QP each sample)
cannot express the bang-bang plan with n_u = 10 consecutive moves followed by a constant
setpoint, and tracking a precomputed minimum-time trajectory with this DMC lags (both slower
than the clamp alone in trials).

The per-sample work (DMC step, governor command and bookkeeping, cascade step) is compiled:
``dmc_*``, ``governor_*`` and ``cascade_*`` kernels over records and arrays shared with the
stage kernels of :mod:`gripper_ros.core.control.stages`; the classes below are the Python façades
that build the models (step responses, gains, powers of ``Ad``) and call the kernels.
"""
from __future__ import annotations

import enum
import functools
import math
from typing import Callable

from gripper_ros.core import linalg
from gripper_ros.core.control.pid import (law_error, LAW_NUMBERS, LAW_OK, PID, PID_DTYPE,
                                          pid_reset, pid_setpoint_for_output, pid_setpoint_range,
                                          pid_step_checked, py_max, py_min)
from gripper_ros.core.records import as_record, face_kernel, FLOATS, RecordField, RecordPair
import numba
import numpy as np


def dynamic_matrix(step_response: np.ndarray, control_horizon: int) -> np.ndarray:
    """Eq. 18: N x n_u lower-triangular Toeplitz matrix of the step-response coefficients."""
    a = np.asarray(step_response, dtype=float)
    n = a.size
    if not 1 <= control_horizon <= n:
        raise ValueError(f'control horizon must be in [1, {n}], got {control_horizon}')
    matrix = np.zeros((n, control_horizon))
    for m in range(control_horizon):
        matrix[m:, m] = a[:n - m]
    return matrix


def dmc_gain(step_response: np.ndarray, control_horizon: int,
             move_suppression: float) -> np.ndarray:
    """Eq. 20: K = (A^T A + lambda I)^-1 A^T, all n_u rows (row 0 is the move applied)."""
    if not (math.isfinite(move_suppression) and move_suppression >= 0.0):
        raise ValueError(f'move suppression must be finite and >= 0, got {move_suppression!r}')
    a = dynamic_matrix(step_response, control_horizon)
    a_t = np.ascontiguousarray(a.T)
    return linalg.solve(linalg.matmul(a_t, a) + move_suppression * np.eye(control_horizon), a_t)


@functools.lru_cache(maxsize=64)
def _dmc_gain(step_response: bytes, control_horizon: int, move_suppression: float) -> np.ndarray:
    """:func:`dmc_gain` of a step response given as its bytes, once per process."""
    return dmc_gain(np.frombuffer(step_response), control_horizon, move_suppression)


DMC_DTYPE = np.dtype([
    ('horizon', 'i8'),                     # N: samples of the step response
    ('last_output', 'f8'),                 # the manipulated variable now
    ('last_move', 'f8'),
    ('has_limits', 'u1'),                  # 0: no output_limits (None)
    ('limit_low', 'f8'), ('limit_high', 'f8'),
], align=True)
"""One DMC's scalars. Its vectors are one float buffer of :func:`dmc_buffer_size` (N): the
step response (N), the first gain row (N), the prediction (N + 1) and a work vector (N)."""


def dmc_buffer_size(horizon: int) -> int:
    """Return the length of a DMC's vector buffer for this horizon."""
    return 4 * horizon + 1


@numba.njit(cache=True)
def dmc_vectors(d, buf):
    """Return (step_response, k0, prediction, work): views into the DMC's buffer."""
    n = as_record(d).horizon
    return buf[0:n], buf[n:2 * n], buf[2 * n:3 * n + 1], buf[3 * n + 1:4 * n + 1]


@face_kernel(DMC_DTYPE, FLOATS, float, float)
@numba.njit(cache=True)
def dmc_reset(d, buf, measurement, output):
    """At rest: output steady at ``measurement``, manipulated variable at ``output``."""
    s = as_record(d)
    n = s.horizon
    buf[2 * n:3 * n + 1] = measurement
    s.last_output = output
    s.last_move = 0.0


@face_kernel(DMC_DTYPE, FLOATS, float, float, bool, float, float)
@numba.njit(cache=True)
def dmc_step(d, buf, setpoint, measurement, has_range, range_low, range_high):
    """One sample (eqs. 19-22): returns the new manipulated variable.

    With ``has_range`` the output is narrowed to [range_low, range_high] for this sample only;
    the prediction is updated with the move actually made.
    """
    s = as_record(d)
    step_response, k0, pred, error = dmc_vectors(s, buf)
    n = s.horizon
    correction = measurement - pred[0]                       # eq. 22
    for j in range(n):
        error[j] = setpoint - (pred[j + 1] + correction)     # eq. 19
    move = linalg.dot(k0, error)                             # eq. 20, first move
    output = s.last_output + move
    if s.has_limits:
        output = py_min(s.limit_high, py_max(s.limit_low, output))
    if has_range:
        output = py_min(range_high, py_max(range_low, output))
    move = output - s.last_output
    for j in range(n):
        pred[j + 1] += step_response[j] * move               # eq. 21
    for j in range(n):
        pred[j] = pred[j + 1]                                # advance one sample
    s.last_output = output
    s.last_move = move
    return output


class DynamicMatrixControl:
    """Receding-horizon DMC on a unit-step-response model ``a_1..a_N`` (N = horizon).

    ``prediction[j]`` is the output expected j samples ahead from the moves made so far; the
    measured-minus-predicted difference (eq. 22) shifts the whole prediction (constant output
    disturbance), which gives offset-free tracking. ``record`` and ``buffer`` are the kernels'
    state (a stage may re-home them into its own arrays).
    """

    def __init__(self, step_response: np.ndarray, control_horizon: int, move_suppression: float,
                 output_limits: tuple[float, float] | None = None):
        self.step_response = np.asarray(step_response, dtype=float)
        self.horizon = n = self.step_response.size
        self.gain = _dmc_gain(self.step_response.tobytes(), control_horizon,
                              move_suppression).copy()
        self.record = np.zeros(1, DMC_DTYPE)
        self.record[0]['horizon'] = n
        self.buffer = np.zeros(dmc_buffer_size(n))
        self.buffer[0:n] = self.step_response
        self.buffer[n:2 * n] = self.gain[0]
        self.output_limits = output_limits
        self.reset(0.0, 0.0)

    @property
    def kernel(self) -> tuple:
        """(record, buffer): what the ``dmc_*`` kernels take."""
        return (self.record, self.buffer)

    output_limits = RecordPair('limit_low', 'limit_high', flag='has_limits')

    last_output = RecordField(writable=False)

    last_move = RecordField(writable=False)

    def reset(self, measurement: float, output: float) -> None:
        """At rest: output steady at ``measurement``, manipulated variable at ``output``."""
        dmc_reset(self.record, self.buffer, float(measurement), float(output))

    @property
    def prediction(self) -> np.ndarray:
        n = self.horizon
        return self.buffer[2 * n:3 * n + 1].copy()

    def step(self, setpoint: float, measurement: float,
             output_range: tuple[float, float] | None = None) -> float:
        """One sample: returns the new manipulated variable (the inner loop's setpoint).

        ``output_range`` narrows the output for this sample only (e.g. what keeps an inner loop
        out of saturation); the prediction is updated with the move actually made.
        """
        low, high = (0.0, 0.0) if output_range is None else output_range
        return dmc_step(self.record, self.buffer, float(setpoint), float(measurement),
                        output_range is not None, float(low), float(high))


def closed_loop_step_response(model_step: Callable[[float], float], controller: PID,
                              samples: int) -> np.ndarray:
    """Unit-step response ``a_1..a_N`` of an inner loop: controller around a plant model.

    ``model_step(u)`` advances a plant model at rest by one sample and returns its output.
    The controller should be unsaturated (the DMC model is linear).
    """
    controller.reset()
    y = 0.0
    out = np.empty(samples)
    for k in range(samples):
        u = controller.step(1.0, y)
        y = model_step(u)
        out[k] = y
    return out


class GovernorPhase(enum.Enum):
    ACCELERATE = 'accelerate'   # full voltage towards the setpoint
    BRAKE = 'brake'             # braking voltage until the finger would stop
    DMC = 'dmc'                 # handed over: the DMC (over the PD) finishes and holds


GOVERNOR_PHASES = (GovernorPhase.ACCELERATE, GovernorPhase.BRAKE, GovernorPhase.DMC)
"""The governor's phase by its code in :data:`GOVERNOR_DTYPE` (0, 1, 2)."""
GOVERNOR_TABLES_CACHED = 16
"""Governor tables kept per process: 700 samples of powers of Ad cost a few ms to build."""
PHASE_ACCELERATE = 0
PHASE_BRAKE = 1
PHASE_DMC = 2

GOVERNOR_DTYPE = np.dtype([
    ('limit_v', 'f8'),          # accelerating voltage
    ('braking_v', 'f8'),
    ('phase', 'i8'),            # PHASE_ACCELERATE, PHASE_BRAKE or PHASE_DMC
    ('direction', 'f8'),        # +1 / -1: the direction of the move being governed
    ('rows', 'i8'),             # samples + 1: rows of the precomputed responses
], align=True)
"""One governor's scalars. Its vectors are one float buffer (:func:`governor_buffer_size`):
``Ad`` (3 x 3), ``Bd`` (3), the state estimate [i, omega, x] (3), a work state (3), the
[omega, x] rows of the powers of ``Ad`` (2 rows x 3), the forced responses (rows x 2) and a work
trajectory (2 rows)."""


def governor_buffer_size(rows: int) -> int:
    """Return the length of a governor's vector buffer for ``rows`` = samples + 1."""
    return 18 + 10 * rows


@numba.njit(cache=True)
def governor_vectors(g, buf):
    """Return (ad, bd, state, ahead, free, forced, traj): views into the governor's buffer."""
    rows = as_record(g).rows
    free_end = 18 + 6 * rows
    forced_end = free_end + 2 * rows
    return (buf[0:9].reshape((3, 3)), buf[9:12], buf[12:15], buf[15:18],
            buf[18:free_end].reshape((2 * rows, 3)),
            buf[free_end:forced_end].reshape((rows, 2)), buf[forced_end:forced_end + 2 * rows])


@face_kernel(GOVERNOR_DTYPE, FLOATS, float)
@numba.njit(cache=True)
def governor_reset(g, buf, measurement):
    """At rest at ``measurement``; the next move starts with ACCELERATE."""
    buf[12] = 0.0
    buf[13] = 0.0
    buf[14] = measurement
    as_record(g).phase = PHASE_ACCELERATE


@numba.njit(cache=True)
def governor_moving(g, buf, current_a, speed_rad_s):
    """Start the model from the motor's current and speed (after :func:`governor_reset`).

    A move that starts while the finger moves is planned from that motion: from rest, the
    least-time rule would accelerate a finger already at speed and carry it past the setpoint.
    """
    buf[12] = current_a
    buf[13] = speed_rad_s


@numba.njit(cache=True)
def governor_stop_position(g, buf, state, direction):
    """Where the finger comes to rest (speed through zero) braking at ``braking_v``."""
    s = as_record(g)
    _, _, _, _, free, forced, traj = governor_vectors(s, buf)
    linalg.matvec_into(free, state, traj)
    scale = direction * s.braking_v
    last = s.rows - 1
    for k in range(last + 1):
        if not direction * (traj[2 * k] - scale * forced[k, 0]) > 0.0:
            return traj[2 * k + 1] - scale * forced[k, 1]
    return traj[2 * last + 1] - scale * forced[last, 1]


@numba.njit(cache=True)
def _governor_ahead(g, buf, voltage):
    """Fill and return ``ahead``: the model state one sample on at ``voltage``."""
    ad, bd, state, ahead, _, _, _ = governor_vectors(g, buf)
    linalg.matvec_into(ad, state, ahead)
    for j in range(3):
        ahead[j] = ahead[j] + bd[j] * voltage
    return ahead


@face_kernel(GOVERNOR_DTYPE, FLOATS, float, float)
@numba.njit(cache=True)
def governor_command(g, buf, setpoint, measurement):
    """Return (forced, voltage): the voltage to hold over the coming sample, if forced.

    ``forced`` False once the DMC is in charge.
    """
    s = as_record(g)
    buf[14] = measurement
    if s.phase == PHASE_ACCELERATE:
        d = 1.0 if setpoint >= measurement else -1.0
        s.direction = d
        ahead = _governor_ahead(s, buf, d * s.limit_v)
        if d * (governor_stop_position(s, buf, ahead, d) - setpoint) < 0.0:
            return True, d * s.limit_v
        s.phase = PHASE_BRAKE
    if s.phase == PHASE_BRAKE:
        d = s.direction
        ahead = _governor_ahead(s, buf, -d * s.braking_v)
        if d * ahead[1] > 0.0:
            return True, -d * s.braking_v
        s.phase = PHASE_DMC
    return False, 0.0


@face_kernel(GOVERNOR_DTYPE, FLOATS, float)
@numba.njit(cache=True)
def governor_applied(g, buf, voltage):
    """Book the voltage held over the sample that starts now."""
    ahead = _governor_ahead(g, buf, voltage)
    buf[12:15] = ahead


@numba.njit(cache=True)
def governor_applied_more(g, buf, voltage):
    """Book ``voltage`` more, held over the sample :func:`governor_applied` booked.

    The model is linear: its state one sample on moves by ``Bd`` times it.
    """
    _, bd, state, _, _, _, _ = governor_vectors(g, buf)
    for j in range(3):
        state[j] += bd[j] * voltage


@functools.lru_cache(maxsize=GOVERNOR_TABLES_CACHED)
def _governor_tables(ad_bytes: bytes, bd_bytes: bytes, samples: int):
    """``Ad^k`` and the forced response ``sum Ad^j Bd`` for k <= samples, once per model."""
    ad = np.frombuffer(ad_bytes).reshape(3, 3).copy()    # writable: the kernels' one type
    bd = np.frombuffer(bd_bytes).copy()
    powers = np.empty((samples + 1, 3, 3))
    steps = np.zeros((samples + 1, 3))
    powers[0] = np.eye(3)
    for k in range(samples):
        powers[k + 1] = linalg.matmul(ad, powers[k])
        steps[k + 1] = steps[k] + linalg.matvec(powers[k], bd)
    powers.flags.writeable = False
    steps.flags.writeable = False
    return powers, steps


class BrakingGovernor:
    """Minimum-time move under the voltage limit, then the DMC: one switch, one handover.

    Works on the exact ZOH model ``s[k+1] = Ad s[k] + Bd u[k]`` (state ``[i, omega, x]``). Its
    state estimate is the model run with the voltages actually applied, its position replaced by
    each measurement. Three phases (:class:`GovernorPhase`), each decided once per sample:

    * ACCELERATE at ``limit_v`` while, after one more such sample, braking at ``braking_v``
      would still stop the finger short of the setpoint (the minimum-time switching rule);
    * BRAKE at ``braking_v`` while one more braking sample leaves the finger moving towards the
      setpoint;
    * DMC: the finger is (nearly) at rest at the setpoint; :meth:`command` returns None from
      then on and the cascade hands over to its DMC, re-initialised at rest at the measurement.

    A short move goes straight to DMC. Handing back at rest matters: a DMC left running through
    the forced samples predicts from moves it did not choose and, with the paper's light move
    suppression, chatters between +-limit near the setpoint (measured: ~570 sign changes in 20 s).
    The stop position is one matrix-vector product over precomputed powers of ``Ad``
    (``samples`` long, enough to stop from full speed). ``record`` and ``buffer`` are the
    kernels' state (a stage may re-home them into its own arrays).
    """

    def __init__(self, ad: np.ndarray, bd: np.ndarray, limit_v: float, braking_v: float,
                 samples: int = 700):
        if not 0.0 < braking_v <= limit_v:
            raise ValueError(f'braking voltage must be in (0, {limit_v}], got {braking_v!r}')
        self.ad = np.asarray(ad, dtype=float)
        self.bd = np.asarray(bd, dtype=float)
        powers, steps = _governor_tables(self.ad.tobytes(), self.bd.tobytes(), samples)
        rows = samples + 1
        self.record = np.zeros(1, GOVERNOR_DTYPE)
        self.record[0]['rows'] = rows
        self.buffer = np.zeros(governor_buffer_size(rows))
        self.buffer[0:9] = self.ad.ravel()
        self.buffer[9:12] = self.bd
        self.buffer[18:18 + 6 * rows] = powers[:, 1:, :].ravel()       # [omega, x] rows
        self.buffer[18 + 6 * rows:18 + 8 * rows] = steps[:, 1:].ravel()
        self.limit_v = float(limit_v)
        self.braking_v = float(braking_v)
        self.record[0]['direction'] = 1.0
        self.phase = GovernorPhase.ACCELERATE

    @property
    def kernel(self) -> tuple:
        """(record, buffer): what the ``governor_*`` kernels take."""
        return (self.record, self.buffer)

    limit_v = RecordField()

    braking_v = RecordField()

    @property
    def phase(self) -> GovernorPhase:
        return GOVERNOR_PHASES[self.record[0]['phase']]

    @phase.setter
    def phase(self, value: GovernorPhase) -> None:
        self.record[0]['phase'] = GOVERNOR_PHASES.index(value)

    @property
    def state(self) -> np.ndarray:
        """The model's state estimate [i, omega, x] (a copy)."""
        return self.buffer[12:15].copy()

    @state.setter
    def state(self, value) -> None:
        self.buffer[12:15] = value

    def reset(self, measurement: float) -> None:
        """At rest at ``measurement``; the next move starts with ACCELERATE."""
        governor_reset(self.record, self.buffer, float(measurement))

    def command(self, setpoint: float, measurement: float) -> float | None:
        """Voltage to hold over the coming sample, or None once the DMC is in charge."""
        forced, voltage = governor_command(self.record, self.buffer, float(setpoint),
                                           float(measurement))
        return voltage if forced else None

    def applied(self, voltage: float) -> None:
        """Book the voltage held over the sample that starts now."""
        governor_applied(self.record, self.buffer, float(voltage))


CASCADE_DTYPE = np.dtype([
    ('respect_inner_limits', 'u1'),
    ('has_governor', 'u1'),            # 0: no braking governor (None)
    ('last_inner_setpoint', 'f8'),     # the DMC's output (the inner loop's setpoint)
    ('last_forced', 'f8'),             # the governor's voltage this sample (0: DMC free)
], align=True)
"""One cascade's flags and outputs; the kernels take it with the inner PID's record, the DMC's
record and buffer and the governor's (placeholders of the same types without a governor)."""

_CASCADE_ARRAYS = (CASCADE_DTYPE, PID_DTYPE, DMC_DTYPE, FLOATS, GOVERNOR_DTYPE, FLOATS)
"""The arrays the ``cascade_*`` kernels take first (:attr:`CascadedMpc.kernel`)."""


@face_kernel(*_CASCADE_ARRAYS, float, float)
@numba.njit(cache=True)
def cascade_reset(c, p, d, dbuf, g, gbuf, measurement, output):
    """At rest at ``measurement``, the inner loop starting from ``output``."""
    s = as_record(c)
    dmc_reset(d, dbuf, measurement, measurement)
    pid_reset(p, output, True, measurement, True, measurement)
    s.last_inner_setpoint = measurement
    if s.has_governor:
        governor_reset(g, gbuf, measurement)


@numba.njit(cache=True)
def _cascade_forced(s, p, d, dbuf, g, gbuf, voltage, measurement, numbers):
    """Governor sample: the inner PD is handed the setpoint that gives ``voltage``.

    The cascade's structure stays (the MPC layer sets the PD's setpoint); the DMC, which did
    not choose the move, is held at the measurement.
    """
    code, held = pid_setpoint_for_output(p, voltage, measurement)
    if code != LAW_OK:
        return code, 0.0
    code, output = pid_step_checked(p, held, measurement, numbers)
    if code != LAW_OK:
        return code, 0.0
    dmc_reset(d, dbuf, measurement, measurement)
    s.last_inner_setpoint = held
    s.last_forced = voltage
    governor_applied(g, gbuf, output)
    return LAW_OK, output


@face_kernel(*_CASCADE_ARRAYS, float, float, FLOATS)
@numba.njit(cache=True)
def cascade_step(c, p, d, dbuf, g, gbuf, setpoint, measurement, numbers):
    """Return (code, output): one sample of the cascade (``code`` LAW_OK unless refused)."""
    s = as_record(c)
    inner = as_record(p)
    model = as_record(d)
    governor = as_record(g)
    has_range = False
    low, high = 0.0, 0.0
    s.last_forced = 0.0
    if s.respect_inner_limits:
        if s.has_governor and governor.phase != PHASE_DMC:
            forced, voltage = governor_command(governor, gbuf, setpoint, measurement)
            if forced:
                return _cascade_forced(s, inner, model, dbuf, governor, gbuf, voltage,
                                       measurement, numbers)
            # handover, at rest: both loops start afresh from here, nothing remembered
            # of the forced samples (no derivative kick, no booked moves)
            dmc_reset(model, dbuf, measurement, measurement)
            pid_reset(inner, 0.0, True, measurement, True, measurement)
        has_range = True
        low, high = pid_setpoint_range(inner, measurement)
    inner_setpoint = dmc_step(model, dbuf, setpoint, measurement, has_range, low, high)
    s.last_inner_setpoint = inner_setpoint
    code, output = pid_step_checked(inner, inner_setpoint, measurement, numbers)
    if code != LAW_OK:
        return code, 0.0
    if s.has_governor:
        governor_applied(governor, gbuf, output)
    return LAW_OK, output


class CascadedMpc:
    """MPC-PD or MPC-PI: the DMC hands its output to an inner PD/PI as setpoint (Fig. 4).

    With ``respect_inner_limits`` (ours) the DMC's output is held, sample by sample, inside the
    range that keeps the inner loop's voltage within its limits, and the DMC books the move it
    actually made: the inner loop stays linear, as the DMC's model assumes, so neither loop
    winds up. Without it (the paper's structure) the inner loop saturates and the DMC, which
    predicts with the unsaturated model, winds up. The inner PID, the DMC and the governor are
    façades over the very records the kernels (and a stage's kernel) work on.
    """

    def __init__(self, dmc: DynamicMatrixControl, inner: PID, respect_inner_limits: bool = True,
                 governor: BrakingGovernor | None = None):
        self.record = np.zeros(1, CASCADE_DTYPE)
        self._numbers = np.zeros(LAW_NUMBERS)
        self._no_governor = (np.zeros(1, GOVERNOR_DTYPE), np.zeros(governor_buffer_size(1)))
        self.dmc = dmc
        self.inner = inner
        self.respect_inner_limits = respect_inner_limits
        self.governor = governor

    @property
    def governor(self) -> BrakingGovernor | None:
        return self._governor

    @governor.setter
    def governor(self, governor: BrakingGovernor | None) -> None:
        self._governor = governor
        self.record[0]['has_governor'] = governor is not None

    respect_inner_limits = RecordField(bool)

    last_inner_setpoint = RecordField(writable=False)

    last_forced = RecordField(writable=False)

    @property
    def kernel(self) -> tuple:
        """(cascade, inner PID, DMC record, DMC buffer, governor record, governor buffer)."""
        g = self._no_governor if self._governor is None else self._governor.kernel
        return (self.record, self.inner.record) + self.dmc.kernel + g

    def reset(self, measurement: float, output: float = 0.0) -> None:
        cascade_reset(*self.kernel, float(measurement), float(output))

    def step(self, setpoint: float, measurement: float) -> float:
        code, output = cascade_step(*self.kernel, float(setpoint), float(measurement),
                                    self._numbers)
        if code != LAW_OK:
            raise law_error(code, self._numbers)
        return output
