"""The grasped object held between the finger pads by Coulomb friction (no rclpy).

The object rests on its support until the arm lifts it; from then on its weight and the arm's
upward acceleration ``a(t)`` load the two finger pads tangentially, ``W = m (g + a)``, and the
normal grip force ``F`` holds it through friction on both pads:

* stuck while ``W <= 2 mu_s F``;
* otherwise it slides down the pads, ``m x'' = W - 2 mu_k F``; if kinetic friction exceeds the
  load it decelerates, and when its slip speed reaches 0 it sticks again (``mu_k <= mu_s``, so
  the static condition then holds);
* it is lost once it has slid the pad length ``L``.

A :class:`Lift` has an acceleration ``a``, a delay counted from the moment the grasp is declared
HOLDING (:meth:`HoldModel.begin`) and a duration: ``a(t) = a`` during ``[t_lift, t_lift +
duration]`` and 0 after it; from ``t_lift`` on the object is off its support for good.

:meth:`HoldModel.advance` integrates one interval over which ``F`` and ``a`` are constant, in
closed form (constant relative acceleration), and finds the exact instants of slide -> stick and
of the loss inside it. The caller (:class:`gripper_ros.core.plant.GripperPlant`) splits its steps
at the lift's start and end (:attr:`HoldModel.next_event_ns`) and at the loss.

The model is a set of compiled kernels (``hold_*``) over one :data:`HOLD_DTYPE` record: the
plant's kernels step the plant's own hold record, and :class:`HoldModel` is the Python view of
a 1-element record array (standalone, or the plant's).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from gripper_ros.wire import HoldState
import numba
import numpy as np

MAX_LIFT_TIME_S = 600.0        # a lift's delay or duration beyond this is a mistake

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

    def __post_init__(self):
        for name in ('acceleration_mps2', 'delay_s', 'duration_s'):
            check_finite_nonnegative('lift', name, getattr(self, name))
        for name in ('delay_s', 'duration_s'):
            if getattr(self, name) > MAX_LIFT_TIME_S:
                raise ValueError(f'lift {name} must be <= {MAX_LIFT_TIME_S:g} s, '
                                 f'got {getattr(self, name)!r}')


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


@numba.njit(cache=True)
def hold_begin(h, t_ns, mass_kg):
    """Start the lift's clock at ``t_ns``; 1 (nothing changed) if the object is off its support."""
    if h.state != HoldState.RESTING:
        return 1
    h.mass_kg = mass_kg
    h.hold_ns = t_ns
    if h.has_lift:
        h.lift_start_ns = t_ns + round(h.lift_delay_s * 1e9)
        h.lift_end_ns = h.lift_start_ns + round(h.lift_duration_s * 1e9)
        h.next_event_ns = h.lift_start_ns
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
    if h.next_event_ns != -1 or h.state == HoldState.SLIDING:
        return True
    return t_ns < h.lift_end_ns + after_lift_ns


@numba.njit(cache=True, inline='always')
def hold_live(h):
    """Tell whether the model must be stepped: a lift pending, or the object lifted and held."""
    return h.next_event_ns != -1 or h.state == HoldState.STUCK or \
        h.state == HoldState.SLIDING


@numba.njit(cache=True)
def hold_load_n(h):
    """Tangential load on the pads now (0 unless lifted and between the pads)."""
    if h.state == HoldState.STUCK or h.state == HoldState.SLIDING:
        return h.mass_kg * (h.gravity_mps2 + h.acceleration_mps2)
    return 0.0


@numba.njit(cache=True)
def hold_capacity_n(h, force_n):
    """Most the two pads hold by static friction at grip force ``force_n``."""
    return 2.0 * h.static_friction * (force_n if force_n > 0.0 else 0.0)


@numba.njit(cache=True, inline='always')
def hold_stays_stuck(h, force_n, until_ns):
    """Tell whether it stays stuck at grip ``force_n``, with no event before ``until_ns``.

    The step then needs no splitting: advancing it would change nothing.
    """
    event_ns = h.next_event_ns
    return h.state == HoldState.STUCK and (event_ns == -1 or event_ns >= until_ns) and \
        h.mass_kg * (h.gravity_mps2 + h.acceleration_mps2) <= \
        2.0 * h.static_friction * force_n


@numba.njit(cache=True)
def hold_fire_events(h, t_ns):
    """Apply the lift's start and end if they are due at ``t_ns``."""
    while h.next_event_ns != -1 and h.next_event_ns <= t_ns:
        if h.state == HoldState.RESTING:            # the lift starts: off its support
            h.state = HoldState.STUCK
            h.acceleration_mps2 = h.lift_acceleration_mps2
            h.next_event_ns = h.lift_end_ns
        else:                                       # the lift ends: weight alone
            h.acceleration_mps2 = 0.0
            h.next_event_ns = -1


@numba.njit(cache=True)
def hold_remove(h):
    """Take the object away (not slid out): nothing is held from now on."""
    h.state = HoldState.NONE
    h.slip_speed_mps = 0.0
    h.next_event_ns = -1


@numba.njit(cache=True)
def hold_advance(h, force_n, dt_s):
    """Integrate ``dt_s`` at grip force ``force_n`` and the present ``a``, both constant.

    Returns the time into the interval at which the object is lost, or NaN.
    """
    state = h.state
    if state != HoldState.STUCK and state != HoldState.SLIDING:
        return math.nan
    grip_n = force_n if force_n > 0.0 else 0.0
    load_n = h.mass_kg * (h.gravity_mps2 + h.acceleration_mps2)
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


# Array-level entry points for Python (HoldModel): each runs the kernel above on ``hold[0]``.
@numba.njit(cache=True)
def _begin(hold, t_ns, mass_kg):
    return hold_begin(hold[0], t_ns, mass_kg)


@numba.njit(cache=True)
def _scenario_in_progress(hold, t_ns, after_lift_ns):
    return hold_scenario_in_progress(hold[0], t_ns, after_lift_ns)


@numba.njit(cache=True)
def _live(hold):
    return hold_live(hold[0])


@numba.njit(cache=True)
def _load_n(hold):
    return hold_load_n(hold[0])


@numba.njit(cache=True)
def _capacity_n(hold, force_n):
    return hold_capacity_n(hold[0], force_n)


@numba.njit(cache=True)
def _stays_stuck(hold, force_n, until_ns):
    return hold_stays_stuck(hold[0], force_n, until_ns)


@numba.njit(cache=True)
def _fire_events(hold, t_ns):
    hold_fire_events(hold[0], t_ns)


@numba.njit(cache=True)
def _remove(hold):
    hold_remove(hold[0])


@numba.njit(cache=True)
def _advance(hold, force_n, dt_s):
    return hold_advance(hold[0], force_n, dt_s)


def _optional_ns(value) -> int | None:
    return None if value == -1 else int(value)


class HoldModel:
    """Tangential dynamics of one object between the pads; the grip force is given per call.

    A view of a :data:`HOLD_DTYPE` record: its own (standalone), or the plant's.
    """

    def __init__(self, mass_kg: float, static_friction: float, kinetic_friction: float,
                 pad_length_m: float, gravity_mps2: float, lift: Lift | None):
        self.record = np.zeros(1, HOLD_DTYPE)
        r = self.record[0]
        r['mass_kg'] = mass_kg
        r['static_friction'] = static_friction
        r['kinetic_friction'] = kinetic_friction
        r['pad_length_m'] = pad_length_m
        r['gravity_mps2'] = gravity_mps2
        if lift is not None:
            r['has_lift'] = 1
            r['lift_acceleration_mps2'] = lift.acceleration_mps2
            r['lift_delay_s'] = lift.delay_s
            r['lift_duration_s'] = lift.duration_s
        r['state'] = HoldState.RESTING
        for name in ('hold_ns', 'lift_start_ns', 'lift_end_ns', 'lost_ns', 'next_event_ns'):
            r[name] = -1
        self.lift = lift

    @classmethod
    def view(cls, record: np.ndarray, lift: Lift | None) -> HoldModel:
        """Return a model reading and writing ``record`` (the plant's hold, for instance)."""
        model = cls.__new__(cls)
        model.record = record
        model.lift = lift
        return model

    def _get(self, name):
        return self.record[0][name]

    mass_kg = property(lambda self: float(self._get('mass_kg')))
    static_friction = property(lambda self: float(self._get('static_friction')))
    kinetic_friction = property(lambda self: float(self._get('kinetic_friction')))
    pad_length_m = property(lambda self: float(self._get('pad_length_m')))
    gravity_mps2 = property(lambda self: float(self._get('gravity_mps2')))
    state = property(lambda self: HoldState(int(self._get('state'))))
    slip_m = property(lambda self: float(self._get('slip_m')))
    slip_speed_mps = property(lambda self: float(self._get('slip_speed_mps')))
    acceleration_mps2 = property(lambda self: float(self._get('acceleration_mps2')),
                                 doc="The arm's upward acceleration now.")
    hold_ns = property(lambda self: _optional_ns(self._get('hold_ns')))
    lift_start_ns = property(lambda self: _optional_ns(self._get('lift_start_ns')))
    lift_end_ns = property(lambda self: _optional_ns(self._get('lift_end_ns')))
    lost_ns = property(lambda self: _optional_ns(self._get('lost_ns')))
    next_event_ns = property(lambda self: _optional_ns(self._get('next_event_ns')))

    def begin(self, t_ns: int, mass_kg: float) -> None:
        """Start the lift's clock at ``t_ns`` (HOLDING declared); the object weighs ``mass_kg``."""
        if _begin(self.record, t_ns, mass_kg):
            raise ValueError(f'the object is already off its support ({self.state.name}); '
                             'place an object again before a new hold')

    def scenario_in_progress(self, t_ns: int, after_lift_ns: int) -> bool:
        """Whether a lift is still to be played out at ``t_ns`` (see hold_scenario_in_progress)."""
        return _scenario_in_progress(self.record, t_ns, after_lift_ns)

    @property
    def live(self) -> bool:
        """True while the model must be stepped: a lift pending, or the object lifted and held."""
        return _live(self.record)

    @property
    def load_n(self) -> float:
        """Tangential load on the pads now (0 unless lifted and between the pads)."""
        return _load_n(self.record)

    def capacity_n(self, force_n: float) -> float:
        """Most the two pads hold by static friction at grip force ``force_n``."""
        return _capacity_n(self.record, float(force_n))

    def stays_stuck(self, force_n: float, until_ns: int) -> bool:
        """Tell whether it stays stuck at grip ``force_n``, with no event before ``until_ns``."""
        return _stays_stuck(self.record, float(force_n), until_ns)

    def fire_events(self, t_ns: int) -> None:
        """Apply the lift's start and end if they are due at ``t_ns``."""
        _fire_events(self.record, t_ns)

    def remove(self) -> None:
        """Take the object away (not slid out): nothing is held from now on."""
        _remove(self.record)

    def advance(self, force_n: float, dt_s: float) -> float | None:
        """Integrate ``dt_s`` at grip force ``force_n`` and the present ``a``, both constant.

        Returns the time into the interval at which the object is lost, or None.
        """
        loss_s = _advance(self.record, float(force_n), float(dt_s))
        return None if math.isnan(loss_s) else loss_s
