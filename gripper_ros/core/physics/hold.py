"""The grasped object held between the finger pads by Coulomb friction (no rclpy).

The object rests on its support until the arm lifts it; from then on its weight and the arm's
upward acceleration ``a(t)`` load the two finger pads tangentially, ``W = m (g + a)``, and the
normal grip force ``F`` holds it through friction on both pads:

* stuck while ``W <= 2 mu_s F``;
* otherwise it slides down the pads, ``m x'' = W - 2 mu_k F``; if kinetic friction exceeds the
  load it decelerates, and when its slip speed reaches 0 it sticks again (``mu_k <= mu_s``, so
  the static condition then holds);
* it is lost once it has slid the pad length ``L``.

Before gross slip each pad shears elastically with partial slip at the rim of its contact
(Cattaneo 1938, Mindlin 1949; K. L. Johnson, *Contact Mechanics*, 1985, sec. 7.2): a pad of
initial tangential stiffness ``k_t`` under normal force ``F`` and shear ``Q`` displaces the object
by ``delta(Q) = delta_s [1 - (1 - Q / (mu_s F))^(2/3)]``, ``delta_s = 3 mu_s F / (2 k_t)``. Its
compliance ``d delta / dQ = (1 / k_t) (1 - Q / (mu_s F))^(-1/3)`` grows without bound as ``Q``
nears ``mu_s F``: incipient slip shows in the pads' shear and displacement before the object
moves as a whole. The law is quasi-static (the pad's tangential mode is far faster than the
grip) and, on unloading, follows the same curve (Mindlin-Deresiewicz hysteresis is left out);
it moves the object by ``delta`` without changing when or how it slides, so ``k_t -> inf``
(``0`` in the record: rigid pads) is the Coulomb law above, exactly.

A :class:`Lift` is the arm's vertical motion (along the pads, with gravity): an acceleration
``A``, a delay counted from the moment the grasp is declared HOLDING (:meth:`HoldModel.begin`),
a duration ``D`` and a profile (``wire.LiftProfile``); from ``t_lift`` on the object leaves its
support for good, and ``a = 0`` after ``t_lift + D``. The weight passes from the support to the
pads over the lift-off ``T_off`` (``contact.lift_off_s``), as the arm's rise stretches the pads'
tangential compliance: the pads carry ``min(1, (t - t_lift) / T_off)`` of ``m (g + a)``, in
pieces of :data:`SHAKE_SAMPLE_S` (a human's loading phase, over which grip and load rise
together, lasts about 0.1-0.2 s: Johansson and Westling 1984). ``T_off = 0`` is the idealised
instant lift-off, in which the whole weight lands on the pads at once:

* ``STEP``: ``a(t) = A`` over ``[t_lift, t_lift + D]``;
* ``PICK_AND_PLACE``: up, across and down, each ``D / 3``, up and down with a trapezoidal
  velocity that accelerates over the first quarter of its third and decelerates over the last:
  ``a = +A, 0, -A`` (up), ``0`` (across: horizontal, not along the pads), ``-A, 0, +A`` (down);
* ``SHAKE``: ``a(t) = A sin(2 pi f (t - t_lift))``, held at its value in the middle of each
  :data:`SHAKE_SAMPLE_S` (the force loop's period), so that every piece has a constant ``a``.

:meth:`HoldModel.advance` integrates one interval over which ``F`` and ``a`` are constant, in
closed form (constant relative acceleration), and finds the exact instants of slide -> stick and
of the loss inside it. The plant (:mod:`gripper_ros.core.physics.integration`) splits its
steps at the lift's start and end (:attr:`HoldModel.next_event_ns`) and at the loss.

The model is a set of compiled kernels (``hold_*``) over one :data:`HOLD_DTYPE` record (or, from
Python, its 1-element array): the
plant's kernels step the plant's own hold record, and :class:`HoldModel` is the Python view of
a 1-element record array (standalone, or the plant's).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from gripper_ros.core.records import (as_record, copy_fields, face_kernel, FLOATS, INTS,
                                      RecordField)
from gripper_ros.wire import FORCE_SAMPLE_S, HoldState, LiftProfile
import numba
import numpy as np

MAX_LIFT_TIME_S = 600.0        # a lift's delay or duration beyond this is a mistake
MAX_LIFT_OFF_S = 10.0          # contact.lift_off_s's bound too
SHAKE_SAMPLE_S = FORCE_SAMPLE_S  # a shake's acceleration is constant over pieces this long
SHAKE_SAMPLE_NS = round(SHAKE_SAMPLE_S * 1e9)
MAX_SHAKE_FREQUENCY_HZ = 100.0  # 50 pieces a period at the fastest
PICK_AND_PLACE_QUARTERS = 12   # D / 12: each ramp of the pick-and-place's trapezoids
# the pick-and-place's accelerations (x A) from each breakpoint (in D / 12) to the next
_PICK_AND_PLACE = ((0, 1.0), (1, 0.0), (3, -1.0), (4, 0.0), (8, -1.0), (9, 0.0), (11, 1.0))

HOLD_DTYPE = np.dtype([
    ('has_hold', np.uint8),            # the plant: an object with a hold is between the pads
    ('live', np.uint8),                # the plant: the model must be stepped (see hold_live)
    ('mass_kg', np.float64),
    ('static_friction', np.float64),
    ('kinetic_friction', np.float64),
    ('pad_length_m', np.float64),
    ('gravity_mps2', np.float64),
    ('has_lift', np.uint8),            # 0: no lift (the object stays on its support)
    ('lift_acceleration_mps2', np.float64),
    ('lift_delay_s', np.float64),
    ('lift_duration_s', np.float64),
    ('state', np.int64),               # HoldState
    ('slip_m', np.float64),
    ('slip_speed_mps', np.float64),
    ('acceleration_mps2', np.float64),  # the arm's, now
    ('hold_ns', np.int64),             # -1: not begun
    ('lift_start_ns', np.int64),       # -1: no lift begun
    ('lift_end_ns', np.int64),         # -1: no lift begun
    ('lost_ns', np.int64),             # -1: not lost
    ('next_event_ns', np.int64),       # -1: no lift event to come
    ('tangential_stiffness_n_per_m', np.float64),  # k_t per pad; 0: rigid pads (Coulomb)
    ('lift_profile', np.int64),        # LiftProfile
    ('lift_frequency_hz', np.float64),  # SHAKE
    ('lift_event', np.int64),          # index of the profile's next breakpoint
    ('driven_until_ns', np.int64),     # a live load (hold_drive) plays out until then; 0: none
    ('lift_off_ns', np.int64),         # the weight moves onto the pads over this; 0: at once
    ('support_share', np.float64),     # share of the weight its support still carries
    ('profile_next_ns', np.int64),     # the profile's next breakpoint; -1: none
    ('ramp_next_ns', np.int64),        # the lift-off's next piece; -1: none
], align=True)
"""One object's tangential hold (times in integer ns, -1 = none)."""


def check_finite_nonnegative(owner: str, name: str, value) -> float:
    """Return ``value`` as a float; ValueError naming ``owner.name`` if not finite and >= 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value) or value < 0.0:
        raise ValueError(f'{owner} {name} must be a finite number >= 0, got {value!r}')
    return float(value)


@dataclass(frozen=True)
class Lift:
    """The arm lifting the grasped object: upward acceleration over ``[delay, delay + duration]``.

    ``delay_s`` counts from the moment the grasp is declared HOLDING; the object leaves its
    support at ``delay_s`` and does not return to it.
    """

    acceleration_mps2: float
    delay_s: float = 0.0
    duration_s: float = 0.0
    profile: LiftProfile = LiftProfile.STEP
    frequency_hz: float = 0.0          # SHAKE only
    lift_off_s: float = 0.0            # the weight reaches the pads over this; 0: the config's

    def __post_init__(self):
        for name in ('acceleration_mps2', 'delay_s', 'duration_s', 'frequency_hz', 'lift_off_s'):
            check_finite_nonnegative('lift', name, getattr(self, name))
        if self.lift_off_s > MAX_LIFT_OFF_S:
            raise ValueError(f'lift lift_off_s must be <= {MAX_LIFT_OFF_S:g} s, '
                             f'got {self.lift_off_s!r}')
        for name in ('delay_s', 'duration_s'):
            if getattr(self, name) > MAX_LIFT_TIME_S:
                raise ValueError(f'lift {name} must be <= {MAX_LIFT_TIME_S:g} s, '
                                 f'got {getattr(self, name)!r}')
        try:
            object.__setattr__(self, 'profile', LiftProfile(self.profile))
        except ValueError:
            raise ValueError(f'lift profile must be one of '
                             f'{[int(p) for p in LiftProfile]}, got {self.profile!r}') from None
        if self.profile == LiftProfile.SHAKE and \
                not 0.0 < self.frequency_hz <= MAX_SHAKE_FREQUENCY_HZ:
            raise ValueError(f'lift frequency_hz of a shake must be in (0, '
                             f'{MAX_SHAKE_FREQUENCY_HZ:g}] Hz, got {self.frequency_hz!r}')

    def lift_off_or(self, default_s: float) -> float:
        """Return this lift's lift-off, or ``default_s`` (``contact.lift_off_s``) if it gives 0."""
        return self.lift_off_s if self.lift_off_s > 0.0 else default_s


PROFILE_NAMES = {'step': LiftProfile.STEP, 'pick-and-place': LiftProfile.PICK_AND_PLACE,
                 'shake': LiftProfile.SHAKE}
"""The profiles' names on a command line (``--profile NAME:A[,HZ]``)."""


def parse_profile(text: str) -> tuple[LiftProfile, float, float]:
    """Read ``step:A``, ``pick-and-place:A`` or ``shake:A,HZ`` as (profile, A m/s^2, f Hz).

    ValueError, in one line naming what is wrong, for anything else.
    """
    name, _, numbers = text.partition(':')
    if name not in PROFILE_NAMES or not numbers:
        raise ValueError(f'profile must be step:A, pick-and-place:A or shake:A,HZ, got '
                         f'{text!r}')
    profile = PROFILE_NAMES[name]
    parts = numbers.split(',')
    if len(parts) != (2 if profile == LiftProfile.SHAKE else 1):
        raise ValueError(f'profile {name} takes {"A,HZ" if profile == LiftProfile.SHAKE else "A"}'
                         f', got {numbers!r}')
    try:
        values = [float(v) for v in parts]
    except ValueError:
        raise ValueError(f'profile {name}: numbers expected, got {numbers!r}') from None
    accel, hz = values[0], (values[1] if len(values) > 1 else 0.0)
    Lift(accel, 0.0, 1.0, profile, hz)          # checks A and f, naming the field
    return profile, accel, hz


@dataclass(frozen=True)
class ObjectState:
    """The held object at one instant (all zeros but ``state`` when nothing is held)."""

    state: HoldState
    slip_m: float = 0.0            # distance slid down the pads since the lift
    slip_speed_mps: float = 0.0
    load_n: float = 0.0            # tangential load m (g + a) on the pads (0 on its support)
    capacity_n: float = 0.0        # most the pads can hold by static friction, 2 mu_s F
    lost_ns: int | None = None     # simulated time at which it left the pads
    lift_acceleration_mps2: float = 0.0   # the arm's upward acceleration now
    shear_n: float = 0.0           # tangential force on each pad (friction it carries)
    presliding_m: float = 0.0      # each pad's elastic (partial-slip) displacement of the object


@face_kernel(HOLD_DTYPE, int, float)
@numba.njit(cache=True)
def hold_begin(hold, t_ns, mass_kg):
    """Start the lift's clock at ``t_ns``; 1 (nothing changed) if the object is off its support."""
    h = as_record(hold)
    if h.state != HoldState.RESTING:
        return 1
    h.mass_kg = mass_kg
    h.hold_ns = t_ns
    h.lift_event = 0
    if h.has_lift:
        h.lift_start_ns = t_ns + round(h.lift_delay_s * 1e9)
        h.lift_end_ns = h.lift_start_ns + round(h.lift_duration_s * 1e9)
        _first_event(h)
    return 0


@numba.njit(cache=True)
def hold_scenario_in_progress(h, t_ns, after_lift_ns):
    """Whether a lift is still to be played out at ``t_ns``.

    True while it is to come, going on, the object sliding, or less than ``after_lift_ns``
    since the lift ended or the object was lost (the gripper's answer to a loss is part of
    the scenario).
    """
    if h.lift_start_ns == -1:
        return False                        # no lift: the object stays on its support
    if h.lost_ns != -1:
        return t_ns < h.lost_ns + after_lift_ns
    if h.state == HoldState.NONE:
        return False                        # taken away
    if t_ns < h.driven_until_ns:
        return True                         # a live load came less than after_lift_ns ago
    if h.next_event_ns != -1 or h.state == HoldState.SLIDING:
        return True
    return t_ns < h.lift_end_ns + after_lift_ns


@face_kernel(HOLD_DTYPE)
@numba.njit(cache=True, inline='always')
def hold_live(hold):
    """Tell whether the model must be stepped: a lift pending, or the object lifted and held."""
    h = as_record(hold)
    return h.next_event_ns != -1 or h.state == HoldState.STUCK or \
        h.state == HoldState.SLIDING


@numba.njit(cache=True, inline='always')
def _pads_load_n(h):
    """Return the share of ``m (g + a)`` the pads carry (all of it once off its support)."""
    return (1.0 - h.support_share) * (h.mass_kg * (h.gravity_mps2 + h.acceleration_mps2))


@face_kernel(HOLD_DTYPE)
@numba.njit(cache=True)
def hold_load_n(hold):
    """Tangential load on the pads now (0 unless lifted and between the pads)."""
    h = as_record(hold)
    if h.state == HoldState.STUCK or h.state == HoldState.SLIDING:
        return _pads_load_n(h)
    return 0.0


@face_kernel(HOLD_DTYPE, float)
@numba.njit(cache=True)
def hold_capacity_n(hold, force_n):
    """Most the two pads hold by static friction at grip force ``force_n``."""
    h = as_record(hold)
    return 2.0 * h.static_friction * (force_n if force_n > 0.0 else 0.0)


@face_kernel(HOLD_DTYPE, float)
@numba.njit(cache=True)
def hold_shear_n(hold, force_n):
    """Tangential force on each pad at grip ``force_n``: half the load while stuck, mu_k F sliding.

    Signed along the load (positive: the load pulls the object down the pads).
    """
    h = as_record(hold)
    grip_n = force_n if force_n > 0.0 else 0.0
    if h.state == HoldState.STUCK:
        return 0.5 * _pads_load_n(h)
    if h.state == HoldState.SLIDING:
        return h.kinetic_friction * grip_n
    return 0.0


@numba.njit(cache=True)
def presliding_m(shear_n, normal_n, static_friction, tangential_stiffness_n_per_m):
    """Cattaneo-Mindlin displacement of a pad under ``shear_n`` (signed) and ``normal_n``.

    ``3 mu_s N / (2 k_t) [1 - (1 - |Q| / (mu_s N))^(2/3)]`` with the sign of ``Q``, capped at
    gross slip (``|Q| = mu_s N``); 0 for rigid pads (``k_t = 0``) or no normal force.
    """
    limit_n = static_friction * normal_n
    if tangential_stiffness_n_per_m <= 0.0 or limit_n <= 0.0:
        return 0.0
    ratio = abs(shear_n) / limit_n
    if ratio > 1.0:
        ratio = 1.0
    full_m = 1.5 * limit_n / tangential_stiffness_n_per_m
    out = full_m * (1.0 - (1.0 - ratio) ** (2.0 / 3.0))
    return out if shear_n >= 0.0 else -out


@face_kernel(HOLD_DTYPE, float)
@numba.njit(cache=True)
def hold_presliding_m(hold, force_n):
    """Each pad's elastic displacement of the object now, at grip ``force_n`` (0 when rigid).

    While the object slides as a whole the pad carries mu_k F and stays sheared by it.
    """
    h = as_record(hold)
    if h.state != HoldState.STUCK and h.state != HoldState.SLIDING:
        return 0.0
    grip_n = force_n if force_n > 0.0 else 0.0
    return presliding_m(hold_shear_n(h, grip_n), grip_n, h.static_friction,
                        h.tangential_stiffness_n_per_m)


@numba.njit(cache=True, inline='always')
def hold_stays_stuck(h, force_n, until_ns):
    """Tell whether it stays stuck at grip ``force_n``, with no event before ``until_ns``.

    The step then needs no splitting: advancing it would change nothing.
    """
    event_ns = h.next_event_ns
    return h.state == HoldState.STUCK and (event_ns == -1 or event_ns >= until_ns) and \
        _pads_load_n(h) <= 2.0 * h.static_friction * force_n


@face_kernel(HOLD_DTYPE, int)
@numba.njit(cache=True)
def hold_fire_events(hold, t_ns):
    """Apply the lift's breakpoints (start, lift-off pieces, profile changes, end) now due."""
    h = as_record(hold)
    while h.next_event_ns != -1 and h.next_event_ns <= t_ns:
        at_ns = h.next_event_ns
        if h.state == HoldState.RESTING:            # the lift starts: leaving its support
            h.state = HoldState.STUCK
        if h.ramp_next_ns != -1 and h.ramp_next_ns <= at_ns:
            _lift_off_piece(h, at_ns)
        if h.profile_next_ns != -1 and h.profile_next_ns <= at_ns:
            _lift_segment(h)
        _next_event(h)


@numba.njit(cache=True, inline='always')
def _next_event(h):
    """Set the next event: the profile's next breakpoint or the lift-off's next piece."""
    p, r = h.profile_next_ns, h.ramp_next_ns
    h.next_event_ns = p if r == -1 or (p != -1 and p <= r) else r


@numba.njit(cache=True)
def _first_event(h):
    """Arm the lift's start: the profile's first segment and, with a lift-off, its first piece."""
    h.profile_next_ns = h.lift_start_ns
    h.ramp_next_ns = h.lift_start_ns if h.lift_off_ns > 0 else -1
    h.support_share = 0.0
    h.next_event_ns = h.lift_start_ns


@numba.njit(cache=True)
def _lift_off_piece(h, at_ns):
    """Enter the lift-off's piece that starts at ``at_ns``: the support's share at its middle."""
    end_ns = h.lift_start_ns + h.lift_off_ns
    if at_ns >= end_ns:
        h.support_share = 0.0
        h.ramp_next_ns = -1
        return
    nxt = at_ns + SHAKE_SAMPLE_NS
    if nxt > end_ns:
        nxt = end_ns
    mid_ns = 0.5 * ((at_ns - h.lift_start_ns) + (nxt - h.lift_start_ns))
    h.support_share = 1.0 - mid_ns / h.lift_off_ns
    h.ramp_next_ns = nxt


@numba.njit(cache=True)
def _lift_segment(h):
    """Enter the profile's segment that starts at ``h.profile_next_ns``: set ``a`` and its end."""
    i = h.lift_event
    h.lift_event = i + 1
    start_ns = h.lift_start_ns
    end_ns = h.lift_end_ns
    a_max = h.lift_acceleration_mps2
    at_ns = h.profile_next_ns
    if at_ns >= end_ns:                             # the lift ends: weight alone
        h.acceleration_mps2 = 0.0
        h.profile_next_ns = -1
        return
    if h.lift_profile == LiftProfile.PICK_AND_PLACE:
        quarters, scale = _PICK_AND_PLACE[i] if i < len(_PICK_AND_PLACE) else (12, 0.0)
        h.acceleration_mps2 = scale * a_max
        if i + 1 < len(_PICK_AND_PLACE):
            nxt = start_ns + round((end_ns - start_ns) * _PICK_AND_PLACE[i + 1][0] /
                                   PICK_AND_PLACE_QUARTERS)
        else:
            nxt = end_ns
    elif h.lift_profile == LiftProfile.SHAKE:
        nxt = at_ns + SHAKE_SAMPLE_NS
        if nxt > end_ns:
            nxt = end_ns
        mid_s = 0.5 * ((at_ns - start_ns) + (nxt - start_ns)) * 1e-9
        h.acceleration_mps2 = a_max * math.sin(2.0 * math.pi * h.lift_frequency_hz * mid_s)
    else:                                           # STEP
        h.acceleration_mps2 = a_max
        nxt = end_ns
    h.profile_next_ns = nxt if nxt > at_ns else end_ns


ANNOUNCE_PIECE_S = 0.005
"""A shake is announced as pieces this long, each at the acceleration in its middle."""
ANNOUNCE_MAX_PIECES = 1000
"""... at most this many: a longer shake's pieces are longer."""
ANNOUNCE_ROWS = ANNOUNCE_MAX_PIECES + 8
"""The most breakpoints :func:`hold_plan` writes."""


@face_kernel(HOLD_DTYPE, INTS, FLOATS)
@numba.njit(cache=True)
def hold_plan(hold, plan_t_ns, plan_accel_mps2):
    """Write the begun lift's plan, as its arm would announce it; return how many breakpoints.

    Each breakpoint: from ``plan_t_ns[i]`` on, the upward acceleration ``plan_accel_mps2[i]``;
    the last is the lift's end (0). 0 breakpoints without a lift whose clock has started.
    """
    h = as_record(hold)
    if not h.has_lift or h.lift_start_ns == -1 or h.lift_end_ns <= h.lift_start_ns:
        return 0
    start_ns = h.lift_start_ns
    end_ns = h.lift_end_ns
    a_max = h.lift_acceleration_mps2
    n = 0
    if h.lift_profile == LiftProfile.PICK_AND_PLACE:
        for quarters, scale in _PICK_AND_PLACE:
            plan_t_ns[n] = start_ns + round((end_ns - start_ns) * quarters /
                                            PICK_AND_PLACE_QUARTERS)
            plan_accel_mps2[n] = scale * a_max
            n += 1
    elif h.lift_profile == LiftProfile.SHAKE:
        piece_ns = round(ANNOUNCE_PIECE_S * 1e9)
        least_ns = (end_ns - start_ns + ANNOUNCE_MAX_PIECES - 1) // ANNOUNCE_MAX_PIECES
        if piece_ns < least_ns:
            piece_ns = least_ns
        at_ns = start_ns
        while at_ns < end_ns:
            nxt = at_ns + piece_ns if at_ns + piece_ns < end_ns else end_ns
            mid_s = 0.5 * ((at_ns - start_ns) + (nxt - start_ns)) * 1e-9
            plan_t_ns[n] = at_ns
            plan_accel_mps2[n] = a_max * math.sin(2.0 * math.pi * h.lift_frequency_hz * mid_s)
            n += 1
            at_ns = nxt
    else:                                           # STEP
        plan_t_ns[n] = start_ns
        plan_accel_mps2[n] = a_max
        n += 1
    plan_t_ns[n] = end_ns
    plan_accel_mps2[n] = 0.0
    return n + 1


@face_kernel(HOLD_DTYPE, int, float, int)
@numba.njit(cache=True)
def hold_drive(hold, t_ns, accel_mps2, after_ns):
    """Let a live arm set ``a`` from ``t_ns`` on; 1 (nothing changed) unless the hold has begun.

    The object leaves its support if it was on it, a profile still running stops, and the
    scenario lasts ``after_ns`` past the last live value (fast mode plays it out).
    """
    h = as_record(hold)
    if h.hold_ns == -1 or not (h.state == HoldState.RESTING or h.state == HoldState.STUCK or
                               h.state == HoldState.SLIDING):
        return 1
    if h.state == HoldState.RESTING:
        h.state = HoldState.STUCK
    if h.lift_start_ns == -1:
        h.lift_start_ns = t_ns
        h.lift_end_ns = t_ns
    h.next_event_ns = -1
    h.profile_next_ns = -1
    h.ramp_next_ns = -1
    h.support_share = 0.0                   # a live arm's load is on the pads at once
    h.acceleration_mps2 = accel_mps2
    h.driven_until_ns = t_ns + after_ns
    return 0


@face_kernel(HOLD_DTYPE)
@numba.njit(cache=True)
def hold_remove(hold):
    """Take the object away (not slid out): nothing is held from now on."""
    h = as_record(hold)
    h.state = HoldState.NONE
    h.slip_speed_mps = 0.0
    h.next_event_ns = -1
    h.profile_next_ns = -1
    h.ramp_next_ns = -1


@face_kernel(HOLD_DTYPE, float, float)
@numba.njit(cache=True)
def hold_advance(hold, force_n, dt_s):
    """Integrate ``dt_s`` at grip force ``force_n`` and the present ``a``, both constant.

    Returns the time into the interval at which the object is lost, or NaN.
    """
    h = as_record(hold)
    state = h.state
    if state != HoldState.STUCK and state != HoldState.SLIDING:
        return math.nan
    grip_n = force_n if force_n > 0.0 else 0.0
    load_n = _pads_load_n(h)
    if state == HoldState.STUCK:
        if load_n <= 2.0 * h.static_friction * grip_n:
            return math.nan
        h.state = HoldState.SLIDING
        h.slip_speed_mps = 0.0
    accel = (load_n - 2.0 * h.kinetic_friction * grip_n) / h.mass_kg
    x0 = h.slip_m
    v0 = h.slip_speed_mps
    t_stop = math.inf if accel >= 0.0 else -v0 / accel
    t_loss = _time_to_travel(h.pad_length_m - x0, v0, accel)
    if t_loss <= dt_s and t_loss <= t_stop:
        h.state = HoldState.LOST
        h.slip_m = h.pad_length_m
        h.slip_speed_mps = v0 + accel * t_loss
        return t_loss
    if t_stop <= dt_s:                                 # kinetic friction stopped it
        h.slip_m = x0 + 0.5 * v0 * t_stop
        h.slip_speed_mps = 0.0
        h.state = HoldState.STUCK
        return math.nan
    h.slip_m = x0 + (v0 + 0.5 * accel * dt_s) * dt_s
    h.slip_speed_mps = v0 + accel * dt_s
    return math.nan


@numba.njit(cache=True)
def _time_to_travel(distance_m, v0_mps, accel_mps2):
    """First t >= 0 with ``v0 t + a t^2 / 2 = distance`` (inf if never), rounding-stable."""
    if distance_m <= 0.0:
        return 0.0
    disc = v0_mps * v0_mps + 2.0 * accel_mps2 * distance_m
    if disc < 0.0:
        return math.inf
    denom = v0_mps + math.sqrt(disc)
    return math.inf if denom <= 0.0 else 2.0 * distance_m / denom


def _optional_ns(value) -> int | None:
    return None if value == -1 else int(value)


class HoldModel:
    """Tangential dynamics of one object between the pads; the grip force is given per call.

    A view of a :data:`HOLD_DTYPE` record: its own (standalone), or the plant's.
    """

    def __init__(self, mass_kg: float, static_friction: float, kinetic_friction: float,
                 pad_length_m: float, gravity_mps2: float, lift: Lift | None,
                 tangential_stiffness_n_per_m: float = 0.0, lift_off_s: float = 0.0):
        self.record = np.zeros(1, HOLD_DTYPE)
        r = self.record[0]
        r['lift_off_ns'] = round(check_finite_nonnegative('lift', 'lift_off_s', lift_off_s) * 1e9)
        copy_fields(r, {'mass_kg': mass_kg, 'static_friction': static_friction,
                        'kinetic_friction': kinetic_friction, 'pad_length_m': pad_length_m,
                        'gravity_mps2': gravity_mps2,
                        'tangential_stiffness_n_per_m': tangential_stiffness_n_per_m})
        if lift is not None:
            r['has_lift'] = 1
            copy_fields(r, lift, {f'lift_{name}': name for name in (
                'acceleration_mps2', 'delay_s', 'duration_s', 'profile', 'frequency_hz')})
        r['state'] = HoldState.RESTING
        for name in ('hold_ns', 'lift_start_ns', 'lift_end_ns', 'lost_ns', 'next_event_ns',
                     'profile_next_ns', 'ramp_next_ns'):
            r[name] = -1
        self.lift = lift

    @classmethod
    def view(cls, record: np.ndarray, lift: Lift | None) -> HoldModel:
        """Return a model reading and writing ``record`` (the plant's hold, for instance)."""
        model = cls.__new__(cls)
        model.record = record
        model.lift = lift
        return model

    mass_kg = RecordField(writable=False)
    static_friction = RecordField(writable=False)
    kinetic_friction = RecordField(writable=False)
    pad_length_m = RecordField(writable=False)
    gravity_mps2 = RecordField(writable=False)
    tangential_stiffness_n_per_m = RecordField(writable=False)
    state = RecordField(HoldState, writable=False)
    slip_m = RecordField(writable=False)
    slip_speed_mps = RecordField(writable=False)
    acceleration_mps2 = RecordField(writable=False, doc="The arm's upward acceleration now.")
    hold_ns = RecordField(_optional_ns, writable=False)
    lift_start_ns = RecordField(_optional_ns, writable=False)
    lift_end_ns = RecordField(_optional_ns, writable=False)
    lost_ns = RecordField(_optional_ns, writable=False)
    next_event_ns = RecordField(_optional_ns, writable=False)

    def begin(self, t_ns: int, mass_kg: float) -> None:
        """Start the lift's clock at ``t_ns`` (HOLDING declared); the object weighs ``mass_kg``."""
        if hold_begin(self.record, t_ns, mass_kg):
            raise ValueError(f'the object is already off its support ({self.state.name}); '
                             'place an object again before a new hold')

    @property
    def live(self) -> bool:
        """True while the model must be stepped: a lift pending, or the object lifted and held."""
        return hold_live(self.record)

    @property
    def load_n(self) -> float:
        """Tangential load on the pads now (0 unless lifted and between the pads)."""
        return hold_load_n(self.record)

    def capacity_n(self, force_n: float) -> float:
        """Most the two pads hold by static friction at grip force ``force_n``."""
        return hold_capacity_n(self.record, float(force_n))

    def shear_n(self, force_n: float) -> float:
        """Tangential force on each pad at grip ``force_n`` (see hold_shear_n)."""
        return hold_shear_n(self.record, float(force_n))

    def presliding_m(self, force_n: float) -> float:
        """Each pad's Cattaneo-Mindlin displacement of the object at grip ``force_n``."""
        return hold_presliding_m(self.record, float(force_n))

    def fire_events(self, t_ns: int) -> None:
        """Apply the lift's start and end if they are due at ``t_ns``."""
        hold_fire_events(self.record, t_ns)

    def drive(self, t_ns: int, accel_mps2: float, after_ns: int = 0) -> bool:
        """Set the arm's acceleration live from ``t_ns`` (see hold_drive); False if not held."""
        return hold_drive(self.record, t_ns, float(accel_mps2), after_ns) == 0

    def remove(self) -> None:
        """Take the object away (not slid out): nothing is held from now on."""
        hold_remove(self.record)

    def advance(self, force_n: float, dt_s: float) -> float | None:
        """Integrate ``dt_s`` at grip force ``force_n`` and the present ``a``, both constant.

        Returns the time into the interval at which the object is lost, or None.
        """
        loss_s = hold_advance(self.record, float(force_n), float(dt_s))
        return None if math.isnan(loss_s) else loss_s
