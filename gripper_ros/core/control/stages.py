"""What a stage controller node does with one lockstep tick, without rclpy.

The position and force controller nodes are thin: each takes the supervisor's
``StageReference`` for tick ``t_k`` (it carries that tick's measurement) and publishes the
answer. Everything else lives here, so that the headless loop
(:mod:`gripper_ros.core.runtime.headless`) and ``bag_replay --resimulate`` run the very same code
and get bit-identical commands:

- :class:`PositionStageController`: MPC-PD (or PD / PID), restarted from rest at the measured
  position whenever it takes over a stage; its voltage capped at the reference's
  ``voltage_limit_v`` (a move's effort limit) when that is set.
- :class:`ForceStageController`: the contact-aware force stage (or the paper's PI / MPC-PI,
  seeded bumplessly from ``seed_voltage_v`` and capped before contact at
  ``approach_force_margin`` x F_sp / (N per V)).
- :class:`LockstepAnswerer`: the per-tick bookkeeping of a node: answer each (stage, stamp)
  once, restart the law on a new stage, hold 0 V on a non-finite measurement or reference
  number without touching the law's state, and hold 0 V on a non-finite output or a law that
  refuses its inputs, restarting the law at the next good tick.

A *reference* is anything with the fields of ``gripper_interfaces/msg/StageReference``:
:data:`Reference` (built from the message's bytes), the rclpy message, or a test double.

The per-tick work is one compiled entry point, :func:`stage_answer` (``k, ref, cmd``), over a
stage's ``kernel`` tuple ``k`` (layout in :data:`KERNEL_LAYOUT`); the compiled headless loop
calls it, and the classes below are Python façades over the same records. A 0 V answer's
reason is a code plus numbers in ``k`` (``REASON_*``); :func:`reason_text` formats it as text.
"""
from __future__ import annotations

from collections import namedtuple
import enum
import math

from gripper_ros.core.config import ConfigError, GripperConfig
from gripper_ros.core.control.contact_force import CONTACT_DTYPE, contact_reset, contact_step
from gripper_ros.core.control.dmc import (CASCADE_DTYPE, cascade_reset, cascade_step,
                                          dmc_buffer_size, DMC_DTYPE, dmc_reset,
                                          governor_applied_more, governor_buffer_size,
                                          GOVERNOR_DTYPE, governor_moving, PHASE_ACCELERATE,
                                          PHASE_DMC)
from gripper_ros.core.control.factories import make_force_controller, make_position_controller
from gripper_ros.core.control.pid import (law_error, LAW_NUMBERS, LAW_OK, PID_DTYPE, pid_reset,
                                          pid_step_checked, py_max, py_min)
from gripper_ros.core.control.servo_feedforward import feedforward_gains, feedforward_v
from gripper_ros.core.records import (as_record, copy_fields, face_kernel, fields_into, FLOATS,
                                      RecordPair)
from gripper_ros.wire import (COMMAND_LAYOUT, Controller, DEFAULT_APPROACH_FORCE_MARGIN,
                              DEFAULT_FORCE_CONTROLLER, DEFAULT_POSITION_CONTROLLER,
                              ForceControllerKind, MSG_REFERENCE, PositionControllerKind,
                              REFERENCE_LAYOUT)
import numba
import numpy as np

SOURCE_POSITION = Controller.POSITION
SOURCE_FORCE = Controller.FORCE


Reference = REFERENCE_LAYOUT.tuple
"""One StageReference's fields, in message order (``Reference._make(values)``); the last four
default to 0: a move's ``speed_limit_mps`` and ``voltage_limit_v`` (no limit) and the motion of
its approach setpoint (it stands)."""

REFERENCE_NUMBERS = ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                     'seed_voltage_v', 'position_m')
"""The reference fields a stage computes with; a non-finite one is never acted on."""
LIMIT_NUMBERS = ('speed_limit_mps', 'voltage_limit_v')
"""... and the position stage's limits (a stage's ``reference_numbers`` name all it uses)."""
MOTION_NUMBERS = ('approach_velocity_mps', 'approach_acceleration_mps2')
"""... and the motion of its setpoint (its feed-forward)."""
NUMBER_FIELDS = REFERENCE_NUMBERS + LIMIT_NUMBERS + MOTION_NUMBERS
"""Bit i of a last-answer record's ``numbers_mask`` / ``bad_mask`` is ``NUMBER_FIELDS[i]``."""
N_NUMBERS = len(NUMBER_FIELDS)


def parse_kind(kind_cls: type[enum.Enum], value, name: str = 'controller'):
    """Return ``value`` as a member of ``kind_cls``; ConfigError naming the parameter if not."""
    if isinstance(value, kind_cls):
        return value
    try:
        return kind_cls(value)
    except ValueError:
        raise ConfigError(f'parameter "{name}" must be one of '
                          f'{[k.value for k in kind_cls]}, got {value!r}') from None


# --- records ---------------------------------------------------------------------------------
KIND_PD = 0
KIND_PID = 1
KIND_MPC_PD = 2
KIND_CONTACT_AWARE = 3
KIND_PI = 4
KIND_MPC_PI = 5
KIND_CODES = {PositionControllerKind.PD: KIND_PD, PositionControllerKind.PID: KIND_PID,
              PositionControllerKind.MPC_PD: KIND_MPC_PD,
              ForceControllerKind.CONTACT_AWARE: KIND_CONTACT_AWARE,
              ForceControllerKind.PI: KIND_PI, ForceControllerKind.MPC_PI: KIND_MPC_PI}
"""A stage's ``kind`` code in :data:`STAGE_DTYPE`."""

STAGE_DTYPE = np.dtype([
    ('source', 'i8'),                      # Controller.POSITION or Controller.FORCE
    ('kind', 'i8'),                        # KIND_*
    ('sample_time_s', 'f8'),               # the command's hold_s
    # position stage
    ('full_v', 'f8'),                      # the plant's voltage limit
    ('limit_low', 'f8'), ('limit_high', 'f8'),     # this tick's output limits
    ('speed_gain_limit', 'f8'),            # V per m/s of the speed limit
    ('speed_gain_speed', 'f8'),            # V per m/s of the speed towards the setpoint
    ('ff_v_per_mps', 'f8'),                # feed-forward: V per m/s of the setpoint's speed
    ('ff_v_per_mps2', 'f8'),               # ... and per m/s^2 of its acceleration
    ('feedforward_v', 'f8'),               # this tick's feed-forward (within its limits)
    ('frame_advance_m', 'f8'),             # how far it moves the reference by the next tick
    ('rad_per_m', 'f8'),                   # the motor's turn per metre of the finger
    ('back_emf_v_s_per_rad', 'f8'), ('resistance_ohm', 'f8'),   # its armature
    # force stage
    ('approach_margin', 'f8'),
    ('contact', 'u1'),                     # contact seen since activation (PI / MPC-PI cap off)
    ('full_low', 'f8'), ('full_high', 'f8'),       # the PI's limits without the cap
    ('stall_force_per_volt_n', 'f8'),
], align=True)
"""A stage controller's kind, limits and flags (both stages; each uses its share)."""

ANSWER_REPEATED = -1
REASON_NONE = 0
REASON_MEASUREMENT = 1     # 'non-finite measurement'
REASON_REFERENCE = 2       # 'non-finite reference (...)': bad_mask, the numbers as read
REASON_LAW = 3             # 'control law failed: ...': law_code, the law's numbers
REASON_OUTPUT = 4          # 'non-finite output (...)': law numbers [0] voltage, [1] inner

LAST_ANSWER_DTYPE = np.dtype([
    ('has_answered', 'u1'),                # 0: nothing answered yet (None)
    ('answered_stage_id', 'i8'), ('answered_stamp_ns', 'i8'),
    ('active_stage', 'i8'),                # the stage the law was started for; -1: none
    ('numbers_mask', 'i8'),                # NUMBER_FIELDS checked (the stage's numbers)
    ('reason', 'i8'),                      # REASON_* of the last answer
    ('bad_mask', 'i8'),                    # REASON_REFERENCE: the non-finite NUMBER_FIELDS
    ('law_code', 'i8'),                    # REASON_LAW: the law's LAW_* code
], align=True)
"""The lockstep bookkeeping of one controller around a stage."""

REFERENCE_DTYPE = REFERENCE_LAYOUT.dtype
COMMAND_DTYPE = COMMAND_LAYOUT.dtype

STATE_DTYPE = np.dtype([
    ('last_answer', LAST_ANSWER_DTYPE), ('stage', STAGE_DTYPE), ('pid', PID_DTYPE),
    ('cascade', CASCADE_DTYPE), ('dmc', DMC_DTYPE), ('governor', GOVERNOR_DTYPE),
    ('contact', CONTACT_DTYPE),
], align=True)
"""Every record of one stage controller, nested: the last answer, the stage, the PID (the
PD/PID/PI or a cascade's inner loop), the cascade, the DMC, the governor and the contact-aware
stage. Parts a kind does not use are placeholders, so every stage compiles to one
:func:`stage_answer`. The law façades view their part (``controller.record`` is
``state['pid']`` ...)."""

LAW_NUMBERS_AT = 0                                       # buffers[0:5]: a refusing law's numbers
REFERENCE_NUMBERS_AT = LAW_NUMBERS_AT + LAW_NUMBERS      # buffers[5:14]: the reference's, as read
DMC_BUFFER_AT = REFERENCE_NUMBERS_AT + len(NUMBER_FIELDS)  # buffers[14:]: DMC's, governor's

STAGE_KERNEL = (STATE_DTYPE, FLOATS)
"""The types of a stage's kernel ``k`` (:func:`~gripper_ros.core.records.face_kernel`)."""

KERNEL_LAYOUT = ('state', 'buffers')
"""``k = (state, buffers)``: ``state`` a 1-element :data:`STATE_DTYPE` array, ``buffers`` one
float array: a refusing law's numbers (5, ``LAW_NUMBERS_AT``), the reference numbers as read
(``NUMBER_FIELDS`` order, 9, ``REFERENCE_NUMBERS_AT``), the DMC's buffer (``DMC_BUFFER_AT``,
:func:`~gripper_ros.core.control.dmc.dmc_buffer_size`) and the governor's buffer after it
(:func:`~gripper_ros.core.control.dmc.governor_buffer_size`). Two arrays, so a call costs few
reference counts: the kernels below pass records."""


# --- kernels ---------------------------------------------------------------------------------
@numba.njit(cache=True)
def stage_buffers(st, buffers):
    """Return (law numbers, reference numbers, DMC buffer, governor buffer) of a stage."""
    dmc_end = DMC_BUFFER_AT + 4 * st.dmc.horizon + 1
    return (buffers[LAW_NUMBERS_AT:REFERENCE_NUMBERS_AT],
            buffers[REFERENCE_NUMBERS_AT:DMC_BUFFER_AT], buffers[DMC_BUFFER_AT:dmc_end],
            buffers[dmc_end:])


@numba.njit(cache=True)
def position_voltage_cap_v(state, ref, toward_speed_mps):
    """Return the most voltage towards the setpoint this tick (``ref`` a reference record)."""
    s = as_record(state).stage
    r = as_record(ref)
    cap = s.full_v
    if r.voltage_limit_v > 0.0:
        cap = py_min(cap, r.voltage_limit_v)
    limit = r.speed_limit_mps
    if limit > 0.0:
        cap = py_min(cap, py_max(0.0, s.speed_gain_limit * limit
                                 - s.speed_gain_speed * toward_speed_mps))
    return cap


@numba.njit(cache=True)
def _position_apply_limits(st, r, measurement, feedforward):
    """Set this tick's output limits; return the feed-forward within them.

    Only a move's reference changes the limits. The law's own limits are the stage's less the
    feed-forward, so that every loop books the voltage applied.
    """
    s = st.stage
    if r.voltage_limit_v == 0.0 and r.speed_limit_mps == 0.0:
        low, high = -s.full_v, s.full_v
    elif r.approach_setpoint_m >= measurement:
        low, high = -s.full_v, position_voltage_cap_v(st, r, r.velocity_mps)
    else:
        low, high = -position_voltage_cap_v(st, r, -r.velocity_mps), s.full_v
    law_low, law_high = low, high
    if feedforward != 0.0:
        feedforward = py_min(high, py_max(low, feedforward))
        law_low, law_high = low - feedforward, high - feedforward
    p = st.pid
    if not (low == s.limit_low and high == s.limit_high and law_low == p.low and
            law_high == p.high):
        s.limit_low = low
        s.limit_high = high
        p.low = law_low
        p.high = law_high
        if s.kind == KIND_MPC_PD and st.cascade.has_governor:
            st.governor.limit_v = py_min(-low, high)
    return feedforward


@numba.njit(cache=True)
def _position_feedforward(st, buffers, r, measurement):
    """Return the voltage the reference's motion needs over the coming hold (0: it stands).

    The braking governor plans a least-time move to a setpoint that stands; a moving reference
    hands the cascade over to its DMC at once (as the governor does at rest: both loops start
    afresh from the measurement), and one that stands again has the governor plan the rest.
    """
    s = st.stage
    governed = s.kind == KIND_MPC_PD and st.cascade.has_governor
    if r.approach_velocity_mps == 0.0 and r.approach_acceleration_mps2 == 0.0:
        if governed and s.frame_advance_m != 0.0:   # it stood still again: least time to it
            st.governor.phase = PHASE_ACCELERATE
        return 0.0
    if governed and st.governor.phase != PHASE_DMC:
        _, _, dbuf, _ = stage_buffers(st, buffers)
        st.governor.phase = PHASE_DMC
        dmc_reset(st.dmc, dbuf, measurement, measurement)
        pid_reset(st.pid, 0.0, True, measurement, True, measurement)
        s.frame_advance_m = 0.0
    return feedforward_v(s.ff_v_per_mps, s.ff_v_per_mps2, r.approach_velocity_mps,
                         r.approach_acceleration_mps2, s.sample_time_s)


@numba.njit(cache=True)
def _force_apply_limits(st, r):
    """Set the PI's limits: capped before contact at the margin's stall voltage."""
    s = st.stage
    low, high = s.full_low, s.full_high
    if not s.contact and s.approach_margin > 0.0:
        cap = s.approach_margin * r.force_setpoint_n / s.stall_force_per_volt_n
        high = py_min(high, cap)
    p = st.pid
    p.low = low
    p.high = high


@face_kernel(STATE_DTYPE, FLOATS, REFERENCE_DTYPE, float)
@numba.njit(cache=True)
def stage_activate(state, buffers, ref, measurement):
    """Restart the law for a new stage (position: from the finger's motion; force: seeded)."""
    st = as_record(state)
    r = as_record(ref)
    s = st.stage
    _, _, dbuf, gbuf = stage_buffers(st, buffers)
    if s.source == Controller.POSITION:
        s.feedforward_v = _position_apply_limits(st, r, measurement, 0.0)
        s.frame_advance_m = 0.0
        if s.kind == KIND_MPC_PD:
            cascade_reset(st.cascade, st.pid, st.dmc, dbuf, st.governor, gbuf, measurement, 0.0)
            if st.cascade.has_governor and math.isfinite(r.velocity_mps) and \
                    math.isfinite(r.seed_voltage_v):      # from the finger's motion now
                speed = r.velocity_mps * s.rad_per_m
                governor_moving(st.governor, gbuf, (r.seed_voltage_v - s.back_emf_v_s_per_rad
                                                    * speed) / s.resistance_ohm, speed)
        else:
            pid_reset(st.pid, 0.0, False, 0.0, True, measurement)
        return
    s.contact = 0
    if s.kind == KIND_CONTACT_AWARE:       # speed-shaped approach from where the finger is now
        contact_reset(st.contact, True, r.position_m)
        return
    _force_apply_limits(st, r)
    if s.kind == KIND_MPC_PI:
        cascade_reset(st.cascade, st.pid, st.dmc, dbuf, st.governor, gbuf, measurement,
                      r.seed_voltage_v)
    else:
        pid_reset(st.pid, r.seed_voltage_v, True, r.force_setpoint_n, True, measurement)


@face_kernel(STATE_DTYPE, FLOATS, REFERENCE_DTYPE, float)
@numba.njit(cache=True)
def stage_compute(state, buffers, ref, measurement):
    """Return (code, voltage_v, inner_setpoint) for this tick (``code`` LAW_OK unless refused).

    A refusing law's numbers are in ``buffers[LAW_NUMBERS_AT:]``.
    """
    st = as_record(state)
    r = as_record(ref)
    s = st.stage
    numbers = buffers[LAW_NUMBERS_AT:REFERENCE_NUMBERS_AT]
    feedforward = 0.0
    if s.source == Controller.POSITION:
        feedforward = _position_apply_limits(st, r, measurement,
                                             _position_feedforward(st, buffers, r, measurement))
        s.feedforward_v = feedforward
        setpoint = r.approach_setpoint_m
    else:
        setpoint = r.force_setpoint_n
        if s.kind == KIND_CONTACT_AWARE:
            face_m = r.position_setpoint_m
            code, voltage = contact_step(st.contact, setpoint, measurement, r.position_m, face_m,
                                         py_max(face_m - r.approach_setpoint_m, 0.0), numbers)
            return code, voltage, setpoint
        if not s.contact and r.contact:    # the cap ends at first contact
            s.contact = 1
            _force_apply_limits(st, r)
    if s.kind == KIND_MPC_PD or s.kind == KIND_MPC_PI:
        _, _, dbuf, gbuf = stage_buffers(st, buffers)
        if s.source == Controller.POSITION:
            _move_frame(st, r, feedforward)
        code, voltage = cascade_step(st.cascade, st.pid, st.dmc, dbuf, st.governor, gbuf,
                                     setpoint, measurement, numbers)
        if feedforward != 0.0 and st.cascade.has_governor:
            governor_applied_more(st.governor, gbuf, feedforward)
        return code, _plus(s, voltage, feedforward), st.cascade.last_inner_setpoint
    code, voltage = pid_step_checked(st.pid, setpoint, measurement, numbers)
    return code, _plus(s, voltage, feedforward), setpoint


@numba.njit(cache=True)
def _move_frame(st, r, feedforward):
    """Move the DMC's output (the inner PD's setpoint) on with the reference's motion.

    The feed-forward moves the finger along the reference; the DMC then predicts and corrects
    the deviation from it, in a frame that moves as the reference did over the last hold, so
    that its output follows the reference without booking that as a move of its own (the
    cascade works on the deviation exactly as it works on a standing setpoint).
    """
    s = st.stage
    if s.frame_advance_m != 0.0 and feedforward != 0.0:
        st.dmc.last_output += s.frame_advance_m
    s.frame_advance_m = 0.0
    if feedforward != 0.0:
        dt = s.sample_time_s
        s.frame_advance_m = dt * (r.approach_velocity_mps
                                  + 0.5 * dt * r.approach_acceleration_mps2)


@numba.njit(cache=True)
def _plus(s, voltage, feedforward):
    """Return the law's voltage with the feed-forward added, within the stage's limits."""
    if feedforward == 0.0:
        return voltage
    return py_min(s.limit_high, py_max(s.limit_low, voltage + feedforward))


@numba.njit(cache=True)
def answer_open(last, reference_numbers, ref, measurement):
    """Start answering ``ref``: ANSWER_REPEATED, REASON_NONE (go on) or the reason for 0 V.

    Each (stage_id, stamp_ns) is answered once; a non-finite measurement or reference number
    is never acted on.
    """
    b = as_record(last)
    r = as_record(ref)
    if b.has_answered and b.answered_stage_id == r.stage_id and \
            b.answered_stamp_ns == r.stamp_ns:
        return ANSWER_REPEATED
    b.has_answered = 1
    b.answered_stage_id = r.stage_id
    b.answered_stamp_ns = r.stamp_ns
    b.reason = REASON_NONE
    if not math.isfinite(measurement):
        b.reason = REASON_MEASUREMENT
        return REASON_MEASUREMENT
    fields_into(reference_numbers, r, NUMBER_FIELDS)
    bad = 0
    for i in range(N_NUMBERS):
        if (b.numbers_mask >> i) & 1 and not math.isfinite(reference_numbers[i]):
            bad |= 1 << i
    if bad:
        b.bad_mask = bad
        b.reason = REASON_REFERENCE
        return REASON_REFERENCE
    return REASON_NONE


@numba.njit(cache=True)
def answer_close(last, law_numbers, code, voltage, inner):
    """Return (finite, voltage, inner): the law's answer, or 0 V when it refused or went bad.

    Either way the law's state is no longer trustworthy: it restarts at the next good tick.
    """
    b = as_record(last)
    if code != LAW_OK:                     # a law that refuses its numbers
        b.active_stage = -1
        b.reason = REASON_LAW
        b.law_code = code
        return 0, 0.0, 0.0
    if not (math.isfinite(voltage) and math.isfinite(inner)):
        b.active_stage = -1
        b.reason = REASON_OUTPUT
        law_numbers[0] = voltage
        law_numbers[1] = inner
        return 0, 0.0, 0.0
    return 1, voltage, inner


_ECHOED_FIELDS = COMMAND_LAYOUT.copied_from(MSG_REFERENCE)
"""What a MotorCommand repeats of the StageReference it answers."""


@face_kernel(STAGE_KERNEL, REFERENCE_DTYPE, COMMAND_DTYPE)
@numba.njit(cache=True)
def stage_answer(k, ref, cmd):
    """Answer the reference record ``ref`` into the command record ``cmd``; False if repeated.

    What ``LockstepAnswerer.answer`` and the command ``lockstep.StageSide.answer`` builds do:
    restart the law on a new stage, hold 0 V (reason in the last answer) on a non-finite
    measurement or reference number, a refused or non-finite output.
    """
    st = k[0][0]
    buffers = k[1]
    r = ref[0]
    s = st.stage
    last = st.last_answer
    measurement = r.position_m if s.source == Controller.POSITION else r.force_n
    reason = answer_open(last, buffers[REFERENCE_NUMBERS_AT:DMC_BUFFER_AT], r, measurement)
    if reason == ANSWER_REPEATED:
        return False
    finite, voltage, inner = 0, 0.0, 0.0
    if reason == REASON_NONE:
        if last.active_stage != r.stage_id:
            stage_activate(st, buffers, r, measurement)
            last.active_stage = r.stage_id
        code, voltage, inner = stage_compute(st, buffers, r, measurement)
        finite, voltage, inner = answer_close(
            last, buffers[LAW_NUMBERS_AT:REFERENCE_NUMBERS_AT], code, voltage, inner)
    c = cmd[0]
    copy_fields(c, r, _ECHOED_FIELDS)
    c.source = s.source
    c.finite = finite
    c.voltage_v = voltage
    c.hold_s = s.sample_time_s
    c.inner_setpoint = inner
    return True


# --- façades ---------------------------------------------------------------------------------
def numbers_mask(names) -> int:
    """Return the ``numbers_mask`` of these reference fields (each one of NUMBER_FIELDS)."""
    mask = 0
    for name in names:
        if name not in NUMBER_FIELDS:
            raise ValueError(f'{name!r} is not a reference number the stages check '
                             f'({", ".join(NUMBER_FIELDS)})')
        mask |= 1 << NUMBER_FIELDS.index(name)
    return mask


def reset_last_answer(last: np.ndarray, names=REFERENCE_NUMBERS) -> np.ndarray:
    """Reset ``last`` (1-element array): nothing answered, no stage active, checking ``names``."""
    last[0] = np.zeros(1, LAST_ANSWER_DTYPE)[0]
    last[0]['active_stage'] = -1
    last[0]['numbers_mask'] = numbers_mask(names)
    return last


def reason_text(last, reference_numbers, law_numbers, names=NUMBER_FIELDS) -> str:
    """Return the text of the last answer's 0 V reason ('' when it was answered).

    ``names``: the stage's reference numbers, in the order they are listed.
    """
    b = last[0]
    reason = int(b['reason'])
    if reason == REASON_MEASUREMENT:
        return 'non-finite measurement'
    if reason == REASON_REFERENCE:
        bad = [f'{n}={float(reference_numbers[NUMBER_FIELDS.index(n)])!r}' for n in names
               if (int(b['bad_mask']) >> NUMBER_FIELDS.index(n)) & 1]
        return f'non-finite reference ({", ".join(bad)})'
    if reason == REASON_LAW:
        return f'control law failed: {law_error(int(b["law_code"]), law_numbers)}'
    if reason == REASON_OUTPUT:
        return (f'non-finite output (voltage {float(law_numbers[0])!r}, inner setpoint '
                f'{float(law_numbers[1])!r})')
    return ''


_DEFAULTS = Reference._field_defaults


def fill_reference(ref, out: np.ndarray) -> np.ndarray:
    """Write ``ref`` (a :data:`Reference`, an rclpy message, a double) into the record ``out``.

    A field the sender's message type lacks takes the layout's default.
    """
    if type(ref) is Reference:
        out[0] = ref
    else:
        out[0] = tuple(getattr(ref, name) if name not in _DEFAULTS
                       else getattr(ref, name, _DEFAULTS[name]) for name in Reference._fields)
    return out


def _rehome(facade, state: np.ndarray, field: str) -> None:
    """Move a law façade's record into ``state[field]``: both then share the same memory."""
    state[0][field] = facade.record[0]
    facade.record = state[field]


class _KernelStage:
    """What both stage façades share: the kernel ``k`` and the Python entry points over it."""

    reference_numbers = REFERENCE_NUMBERS

    def _build_kernel(self, kind, pid=None, cascade=None, contact=None) -> None:
        """Gather the laws' records and buffers into ``k = (state, buffers)``."""
        self.state = state = np.zeros(1, STATE_DTYPE)
        dmc = cascade.dmc if cascade is not None else None
        governor = cascade.governor if cascade is not None else None
        dmc_size = dmc_buffer_size(dmc.horizon if dmc is not None else 1)
        rows = int(governor.record[0]['rows']) if governor is not None else 1
        self.buffers = buffers = np.zeros(DMC_BUFFER_AT + dmc_size + governor_buffer_size(rows))
        st = state[0]
        st['dmc']['horizon'] = 1
        st['governor']['rows'] = 1
        if cascade is not None:
            pid = cascade.inner
            _rehome(cascade, state, 'cascade')
            buffers[DMC_BUFFER_AT:DMC_BUFFER_AT + dmc_size] = dmc.buffer
            dmc.buffer = buffers[DMC_BUFFER_AT:DMC_BUFFER_AT + dmc_size]
            _rehome(dmc, state, 'dmc')
            if governor is not None:
                buffers[DMC_BUFFER_AT + dmc_size:] = governor.buffer
                governor.buffer = buffers[DMC_BUFFER_AT + dmc_size:]
                _rehome(governor, state, 'governor')
        if pid is not None:
            _rehome(pid, state, 'pid')
        if contact is not None:
            _rehome(contact, state, 'contact')
        s = st['stage']
        s['source'] = int(self.source)
        s['kind'] = KIND_CODES[kind]
        s['sample_time_s'] = self.sample_time_s
        reset_last_answer(state['last_answer'], self.reference_numbers)
        self.record = state['stage']
        self.kernel = (state, buffers)
        self._ref = np.zeros(1, REFERENCE_DTYPE)

    def activate(self, ref, measurement: float) -> None:
        """Restart the law for a new stage."""
        stage_activate(self.state, self.buffers, fill_reference(ref, self._ref),
                       float(measurement))

    def compute(self, ref, measurement: float) -> tuple[float, float]:
        """Return (voltage_v, inner_setpoint) for this tick (the law's exception if refused)."""
        code, voltage, inner = stage_compute(self.state, self.buffers,
                                             fill_reference(ref, self._ref), float(measurement))
        if code != LAW_OK:
            raise law_error(code, self.buffers[LAW_NUMBERS_AT:REFERENCE_NUMBERS_AT])
        return voltage, inner


class PositionStageController(_KernelStage):
    """The position controller node's control law (10 ms, Table II), with a move's limits.

    A reference's ``voltage_limit_v`` and ``speed_limit_mps`` (> 0; 0 = none) cap the voltage
    that drives the finger towards its setpoint: at ``voltage_limit_v`` (the stall voltage of
    a move's effort), and at what keeps the speed below ``speed_limit_mps`` on the exact
    first-order model of the finger's speed (``position_control.speed_limit_pole``). The
    voltage away from the setpoint (braking) keeps the plant's limit. The cap is the output
    limit of the PD / PID (the inner PD of the MPC-PD, whose DMC then keeps within it, and the
    braking governor's accelerating voltage), so that every loop books the voltage applied.
    """

    source = SOURCE_POSITION
    reference_numbers = REFERENCE_NUMBERS + LIMIT_NUMBERS + MOTION_NUMBERS

    def __init__(self, config: GripperConfig,
                 kind: PositionControllerKind | str = DEFAULT_POSITION_CONTROLLER):
        self.config = config
        self.kind = parse_kind(PositionControllerKind, kind)
        self.controller = make_position_controller(config, self.kind)
        self.sample_time_s = config.position.sample_time_s
        mpc = self.kind is PositionControllerKind.MPC_PD
        self._build_kernel(self.kind, pid=None if mpc else self.controller,
                           cascade=self.controller if mpc else None)
        plant = config.plant
        # speed one sample on: a v + (1 - a) k_v u; the cap u puts it at v_lim - pole (v_lim - v)
        a = math.exp(-self.sample_time_s / plant.mechanical_time_constant_s)
        pole = config.position.speed_limit_pole
        gain = 1.0 / ((1.0 - a) * plant.free_speed_per_volt_mps)
        ff_v_per_mps, ff_v_per_mps2 = feedforward_gains(plant)
        copy_fields(self.record[0], {
            'full_v': plant.voltage_limit_v, 'limit_low': -plant.voltage_limit_v,
            'limit_high': plant.voltage_limit_v, 'speed_gain_limit': (1.0 - pole) * gain,
            'speed_gain_speed': (a - pole) * gain, 'ff_v_per_mps': ff_v_per_mps,
            'ff_v_per_mps2': ff_v_per_mps2, 'rad_per_m': 1.0 / plant.travel_per_rad_m,
            'back_emf_v_s_per_rad': plant.back_emf_v_s_per_rad,
            'resistance_ohm': plant.resistance_ohm})

    @staticmethod
    def measurement(ref) -> float:
        """Return what this stage controls, from the tick's reference: the finger position."""
        return ref.position_m


class ForceStageController(_KernelStage):
    """The force controller node's control law (force sampling time, bumpless, approach cap)."""

    source = SOURCE_FORCE

    def __init__(self, config: GripperConfig,
                 kind: ForceControllerKind | str = DEFAULT_FORCE_CONTROLLER,
                 approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN):
        margin = float(approach_force_margin)
        if not (math.isfinite(margin) and margin >= 0.0):
            raise ConfigError(f'approach_force_margin must be finite and >= 0, got {margin!r}')
        self.config = config
        self.kind = parse_kind(ForceControllerKind, kind)
        self.approach_margin = margin
        self.controller = make_force_controller(config, self.kind)
        self.contact_aware = self.kind is ForceControllerKind.CONTACT_AWARE
        self._pi = None if self.contact_aware else (
            self.controller.inner if self.kind is ForceControllerKind.MPC_PI
            else self.controller)
        self.sample_time_s = config.force.sample_time_s
        self._build_kernel(self.kind,
                           pid=self.controller if self.kind is ForceControllerKind.PI else None,
                           cascade=(self.controller if self.kind is ForceControllerKind.MPC_PI
                                    else None),
                           contact=self.controller if self.contact_aware else None)
        s = self.record[0]
        s['approach_margin'] = margin
        s['stall_force_per_volt_n'] = config.plant.stall_force_per_volt_n
        if not self.contact_aware:
            s['full_low'], s['full_high'] = self._pi.output_limits

    @property
    def _contact(self) -> bool:
        return bool(self.record[0]['contact'])

    @property
    def capped(self) -> bool:
        """Tell whether the pre-contact cap is in force.

        Only for PI / MPC-PI: the contact-aware stage caps its approach itself, at the
        feed-forward.
        """
        return not self._contact and self.approach_margin > 0.0 and not self.contact_aware

    @staticmethod
    def measurement(ref) -> float:
        """Return what this stage controls, from the tick's reference: the gripping force."""
        return ref.force_n


class TickAnswer(namedtuple('TickAnswer', 'voltage_v inner_setpoint finite reason',
                            defaults=(True, ''))):
    """A controller's answer to one tick (what goes into MotorCommand).

    ``finite`` False means a measurement or output was not finite and 0 V is held, ``reason``
    says why.
    """

    __slots__ = ()


# where the answerer reads a command record: its finite byte, and its two float64 numbers
_FINITE_BYTE = COMMAND_DTYPE.fields['finite'][1]
_VOLTAGE_AT, _INNER_AT = (COMMAND_DTYPE.fields[name][1] // 8
                          for name in ('voltage_v', 'inner_setpoint'))


class LockstepAnswerer:
    """The lockstep bookkeeping of one controller around a stage.

    ``stage`` is one of the stage controllers above: :func:`stage_answer` answers it on its own
    last-answer record. Call :meth:`answer` with every reference addressed to this controller.
    """

    def __init__(self, stage):
        self.stage = stage
        self.numbers = stage.reference_numbers
        self._kernel = stage.kernel
        state, buffers = self._kernel
        self._last_answer = state['last_answer']
        self._reference_numbers = buffers[REFERENCE_NUMBERS_AT:DMC_BUFFER_AT]
        self._law_numbers = buffers[LAW_NUMBERS_AT:REFERENCE_NUMBERS_AT]
        reset_last_answer(self._last_answer, self.numbers)
        self._ref = np.zeros(1, REFERENCE_DTYPE)
        self._cmd = np.zeros(1, COMMAND_DTYPE)
        self._cmd_bytes = self._cmd.view(np.uint8)
        self._cmd_floats = self._cmd.view(np.float64)

    answered = RecordPair('answered_stage_id', 'answered_stamp_ns', int, flag='has_answered',
                          at='_last_answer')
    """(stage_id, stamp) last answered, None before the first answer."""

    @property
    def active_stage(self) -> int | None:
        """The stage the law was started for."""
        active = int(self._last_answer[0]['active_stage'])
        return None if active < 0 else active

    @active_stage.setter
    def active_stage(self, stage_id: int | None) -> None:
        self._last_answer[0]['active_stage'] = -1 if stage_id is None else stage_id

    @property
    def reason(self) -> str:
        """Why the last answer held 0 V ('' when it did not)."""
        return reason_text(self._last_answer, self._reference_numbers, self._law_numbers,
                           self.numbers)

    def answer(self, ref) -> TickAnswer | None:
        """Return the command for this tick, or None when this (stage, stamp) was answered."""
        fill_reference(ref, self._ref)
        if not stage_answer(self._kernel, self._ref, self._cmd):
            return None
        if self._cmd_bytes[_FINITE_BYTE]:
            numbers = self._cmd_floats.tolist()
            return TickAnswer(numbers[_VOLTAGE_AT], numbers[_INNER_AT])
        return TickAnswer(0.0, 0.0, finite=False, reason=self.reason)
