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
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from gripper_ros.wire import HoldState

MAX_LIFT_TIME_S = 600.0        # a lift's delay or duration beyond this is a mistake


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


class HoldModel:
    """Tangential dynamics of one object between the pads; the grip force is given per call."""

    def __init__(self, mass_kg: float, static_friction: float, kinetic_friction: float,
                 pad_length_m: float, gravity_mps2: float, lift: Lift | None):
        self.mass_kg = mass_kg
        self.static_friction = static_friction
        self.kinetic_friction = kinetic_friction
        self.pad_length_m = pad_length_m
        self.gravity_mps2 = gravity_mps2
        self.lift = lift
        self.state = HoldState.RESTING
        self.slip_m = 0.0
        self.slip_speed_mps = 0.0
        self.acceleration_mps2 = 0.0   # the arm's, now
        self.hold_ns: int | None = None
        self.lift_start_ns: int | None = None
        self.lift_end_ns: int | None = None
        self.lost_ns: int | None = None
        self.next_event_ns: int | None = None

    def begin(self, t_ns: int, mass_kg: float) -> None:
        """Start the lift's clock at ``t_ns`` (HOLDING declared); the object weighs ``mass_kg``."""
        if self.state is not HoldState.RESTING:
            raise ValueError(f'the object is already off its support ({self.state.name}); '
                             'place an object again before a new hold')
        self.mass_kg = mass_kg
        self.hold_ns = t_ns
        if self.lift is not None:
            self.lift_start_ns = t_ns + round(self.lift.delay_s * 1e9)
            self.lift_end_ns = self.lift_start_ns + round(self.lift.duration_s * 1e9)
            self.next_event_ns = self.lift_start_ns

    def scenario_in_progress(self, t_ns: int, after_lift_ns: int) -> bool:
        """A lift still to be played out at ``t_ns``: to come, going on, the object sliding,
        or less than ``after_lift_ns`` since the lift ended or the object was lost (the
        gripper's answer to a loss is part of the scenario)."""
        if self.lift_start_ns is None:
            return False                        # no lift: the object stays on its support
        if self.lost_ns is not None:
            return t_ns < self.lost_ns + after_lift_ns
        if self.state is HoldState.NONE:
            return False                        # taken away
        if self.next_event_ns is not None or self.state is HoldState.SLIDING:
            return True
        return t_ns < self.lift_end_ns + after_lift_ns

    @property
    def live(self) -> bool:
        """True while the model must be stepped: a lift pending, or the object lifted and held."""
        return self.next_event_ns is not None or self.state is HoldState.STUCK or \
            self.state is HoldState.SLIDING

    @property
    def load_n(self) -> float:
        """Tangential load on the pads now (0 unless lifted and between the pads)."""
        if self.state is HoldState.STUCK or self.state is HoldState.SLIDING:
            return self.mass_kg * (self.gravity_mps2 + self.acceleration_mps2)
        return 0.0

    def capacity_n(self, force_n: float) -> float:
        """Most the two pads hold by static friction at grip force ``force_n``."""
        return 2.0 * self.static_friction * max(0.0, force_n)

    def stays_stuck(self, force_n: float, until_ns: int) -> bool:
        """Tell whether it stays stuck at grip ``force_n``, with no event before ``until_ns``.

        The step then needs no splitting: advancing it would change nothing.
        """
        event_ns = self.next_event_ns
        return self.state is HoldState.STUCK and (event_ns is None or event_ns >= until_ns) and \
            self.mass_kg * (self.gravity_mps2 + self.acceleration_mps2) <= \
            2.0 * self.static_friction * force_n

    def fire_events(self, t_ns: int) -> None:
        """Apply the lift's start and end if they are due at ``t_ns``."""
        while self.next_event_ns is not None and self.next_event_ns <= t_ns:
            if self.state is HoldState.RESTING:            # the lift starts: off its support
                self.state = HoldState.STUCK
                self.acceleration_mps2 = self.lift.acceleration_mps2
                self.next_event_ns = self.lift_end_ns
            else:                                          # the lift ends: weight alone
                self.acceleration_mps2 = 0.0
                self.next_event_ns = None

    def remove(self) -> None:
        """Take the object away (not slid out): nothing is held from now on."""
        self.state = HoldState.NONE
        self.slip_speed_mps = 0.0
        self.next_event_ns = None

    def advance(self, force_n: float, dt_s: float) -> float | None:
        """Integrate ``dt_s`` at grip force ``force_n`` and the present ``a``, both constant.

        Returns the time into the interval at which the object is lost, or None.
        """
        state = self.state
        if state is not HoldState.STUCK and state is not HoldState.SLIDING:
            return None
        grip_n = max(0.0, force_n)
        load_n = self.mass_kg * (self.gravity_mps2 + self.acceleration_mps2)
        if state is HoldState.STUCK:
            if load_n <= 2.0 * self.static_friction * grip_n:
                return None
            self.state = HoldState.SLIDING
            self.slip_speed_mps = 0.0
        accel = (load_n - 2.0 * self.kinetic_friction * grip_n) / self.mass_kg
        x0, v0 = self.slip_m, self.slip_speed_mps
        t_stop = math.inf if accel >= 0.0 else -v0 / accel
        t_loss = _time_to_travel(self.pad_length_m - x0, v0, accel)
        if t_loss <= dt_s and t_loss <= t_stop:
            self.state = HoldState.LOST
            self.slip_m = self.pad_length_m
            self.slip_speed_mps = v0 + accel * t_loss
            return t_loss
        if t_stop <= dt_s:                                 # kinetic friction stopped it
            self.slip_m = x0 + 0.5 * v0 * t_stop
            self.slip_speed_mps = 0.0
            self.state = HoldState.STUCK
            return None
        self.slip_m = x0 + (v0 + 0.5 * accel * dt_s) * dt_s
        self.slip_speed_mps = v0 + accel * dt_s
        return None


def _time_to_travel(distance_m: float, v0_mps: float, accel_mps2: float) -> float:
    """First t >= 0 with ``v0 t + a t^2 / 2 = distance`` (inf if never), rounding-stable."""
    if distance_m <= 0.0:
        return 0.0
    disc = v0_mps * v0_mps + 2.0 * accel_mps2 * distance_m
    if disc < 0.0:
        return math.inf
    denom = v0_mps + math.sqrt(disc)
    return math.inf if denom <= 0.0 else 2.0 * distance_m / denom
