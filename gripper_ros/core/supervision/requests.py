"""Grasp and move requests: their fields, validation and the grip force law (no rclpy).

A request is refused (:class:`RequestError`, the reason with the numbers) when a value is
non-finite, out of range, or asks for more force than 24 V can hold; a valid one resolves its
defaults from the configuration into :class:`GraspTargets` or :class:`MoveTargets`, what the
supervisor runs. The grip force is :func:`force_setpoint_n`: ``k m (g + a) / (2 mu_s)`` (two
pads of friction, safety factor ``k``) by default, eq. 23's ``mu_s m (g + a)`` with
``supervisor.force_law: paper``. A request of mass 0 leaves the mass unknown: the grip then
tracks the load the pads measure (:mod:`gripper_ros.core.control.load_grip`, run by the
supervisor), from a touch at ``load_grip.touch_force_n``.

The compiled supervisor keeps a request as a :data:`TARGETS_DTYPE` record (its kind, mass and
start besides the targets): the one record type of the current, the waiting and the decided
request (:func:`targets_record` makes one, :func:`targets_of` reads one back).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
import math

from gripper_ros.core.config import (ForceLaw, LoadGripParams, PlantParams, shipped_config,
                                     SupervisorParams)
from gripper_ros.wire import PendingRequest
import numpy as np

MAX_TIMEOUT_S = 600.0  # simulated seconds; a longer grasp is a mistake, not a request


class RequestError(ValueError):
    """A grasp request that must be refused; the message says why, with the numbers."""


@dataclass(frozen=True)
class GraspRequest:
    width_m: float
    mass_kg: float                      # 0 = unknown: the load-tracking grip
    friction_coefficient: float = 0.0   # 0 = default
    acceleration_mps2: float = 0.0
    timeout_s: float = 0.0              # 0 = default
    width_tolerance_m: float = 0.0      # 0 = default


@dataclass(frozen=True)
class MoveRequest:
    width_m: float
    speed_mps: float = 0.0              # 0 = default
    max_effort_n: float = 0.0           # 0 = the motor's limit
    timeout_s: float = 0.0              # 0 = the travel at speed + the default timeout


@dataclass(frozen=True)
class MoveTargets:
    """What a valid move resolves to; the attributes the status reads are a grasp's names."""

    position_setpoint_m: float          # the goal, L_ls - width
    speed_mps: float
    max_effort_n: float                 # the effort limit (the motor's when the request gave 0)
    voltage_limit_v: float              # its stall voltage; 0 = no cap below the plant's
    timeout_s: float                    # 0 = the travel at speed + the default timeout
    tolerance_m: float
    friction_coefficient: float = 0.0
    width_tolerance_m: float = 0.0

    @property
    def approach_setpoint_m(self) -> float:
        return self.position_setpoint_m

    @property
    def force_setpoint_n(self) -> float:
        """The status' force setpoint of a move: its effort limit."""
        return self.max_effort_n


@dataclass(frozen=True)
class GraspTargets:
    """What a valid request resolves to."""

    position_setpoint_m: float          # expected face, L_ls - width
    force_setpoint_n: float
    friction_coefficient: float
    timeout_s: float
    width_tolerance_m: float = 0.0
    load_tracking: bool = False         # mass unknown: the grip follows the measured load

    @property
    def approach_setpoint_m(self) -> float:
        """The position stage's target: the face of the widest object the request allows."""
        return self.position_setpoint_m - self.width_tolerance_m


TARGETS_DTYPE = np.dtype([
    ('kind', 'i4'),                        # PendingRequest: GRASP, RELEASE, MOVE; 0: none
    ('mass_kg', 'f8'),                     # a grasp's declared mass (0: unknown)
    ('after_ns', 'i8'),                    # waiting: it starts at the first tick after this
    ('position_setpoint_m', 'f8'), ('approach_setpoint_m', 'f8'), ('force_setpoint_n', 'f8'),
    ('friction_coefficient', 'f8'), ('timeout_s', 'f8'), ('width_tolerance_m', 'f8'),
    ('speed_mps', 'f8'), ('max_effort_n', 'f8'), ('voltage_limit_v', 'f8'),
    ('tolerance_m', 'f8'), ('load_tracking', 'b1')], align=True)
"""A request as the compiled supervisor keeps it: kind, mass, start and targets (a grasp's move
fields are 0, a move's grasp fields its own: approach = the goal, force = the effort limit)."""

_TARGET_FIELDS = ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                  'friction_coefficient', 'timeout_s', 'width_tolerance_m', 'speed_mps',
                  'max_effort_n', 'voltage_limit_v', 'tolerance_m', 'load_tracking')


def targets_record(kind: PendingRequest, targets, mass_kg: float = 0.0,
                   after_ns: int = -1) -> np.ndarray:
    """Return ``targets`` (:class:`GraspTargets`, :class:`MoveTargets`) as a 1-element record."""
    record = np.zeros(1, TARGETS_DTYPE)
    r = record[0]
    r['kind'] = int(kind)
    r['mass_kg'] = mass_kg
    r['after_ns'] = after_ns
    for name in _TARGET_FIELDS:
        r[name] = getattr(targets, name, 0.0)
    return record


def targets_of(record) -> GraspTargets | MoveTargets | None:
    """Return the targets a :data:`TARGETS_DTYPE` record holds (None: no request)."""
    kind = int(record['kind'])
    if kind == PendingRequest.NONE:
        return None
    if kind == PendingRequest.MOVE:
        return MoveTargets(*(float(record[f.name]) for f in fields(MoveTargets)))
    return GraspTargets(*(float(record[name]) for name in (
        'position_setpoint_m', 'force_setpoint_n', 'friction_coefficient', 'timeout_s',
        'width_tolerance_m')), load_tracking=bool(record['load_tracking']))


def force_setpoint_n(mass_kg: float, friction_coefficient: float, gravity_mps2: float,
                     acceleration_mps2: float, law: ForceLaw, safety_factor: float) -> float:
    """Grip force to hold ``m`` under ``g + a`` by friction ``mu_s`` on the two finger pads.

    ``FRICTION``: each pad holds at most ``mu_s F``, so ``F_sp = k m (g + a) / (2 mu_s)`` with the
    safety factor ``k``. ``PAPER``: eq. 23 as printed, ``F_sp = mu_s m (g + a)`` (``k`` unused).
    """
    if law is ForceLaw.PAPER:
        return friction_coefficient * mass_kg * (gravity_mps2 + acceleration_mps2)
    return safety_factor * mass_kg * (gravity_mps2 + acceleration_mps2) / (
        2.0 * friction_coefficient)


def _force_law_text(law: ForceLaw, mu: float, mass_kg: float, g_plus_a: float,
                    safety_factor: float) -> str:
    """Write the setpoint's formula with the request's numbers, for a refusal."""
    if law is ForceLaw.PAPER:
        return f'paper law, eq. 23: mu_s={mu:g} x m={mass_kg:g} kg x (g+a)={g_plus_a:g} m/s^2'
    return (f'friction law: k={safety_factor:g} x m={mass_kg:g} kg x (g+a)={g_plus_a:g} m/s^2 '
            f'/ (2 mu_s={2.0 * mu:g})')


def validate_request(req: GraspRequest, plant: PlantParams, sup: SupervisorParams,
                     load_grip: LoadGripParams | None = None) -> GraspTargets:
    """Resolve defaults and refuse anything non-finite, out of range or beyond 24 V.

    Mass 0: the load-tracking grip, whose contact stage closes to ``load_grip.touch_force_n``
    (``load_grip`` None: its defaults).
    """
    for name in ('width_m', 'mass_kg', 'friction_coefficient', 'acceleration_mps2', 'timeout_s',
                 'width_tolerance_m'):
        value = getattr(req, name)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or \
                not math.isfinite(value):
            raise RequestError(f'{name} must be a finite number, got {value!r}')
    if not 0.0 < req.width_m < plant.max_travel_m:
        raise RequestError(f'width_m must be in (0, {plant.max_travel_m:g}) m (the finger '
                           f'travel), got {req.width_m!r}')
    if req.mass_kg < 0.0:
        raise RequestError(f'mass_kg must be > 0, or 0 (unknown: the load-tracking grip), got '
                           f'{req.mass_kg!r}')
    if req.friction_coefficient < 0.0:
        raise RequestError(f'friction_coefficient must be >= 0 (0 = default '
                           f'{sup.friction_coefficient:g}), got {req.friction_coefficient!r}')
    if req.acceleration_mps2 < 0.0:
        raise RequestError(f'acceleration_mps2 must be >= 0, got {req.acceleration_mps2!r}')
    if not 0.0 <= req.timeout_s <= MAX_TIMEOUT_S:
        raise RequestError(f'timeout_s must be in [0, {MAX_TIMEOUT_S:g}] s (0 = default '
                           f'{sup.timeout_s:g}), got {req.timeout_s!r}')
    if req.width_tolerance_m < 0.0:
        raise RequestError(f'width_tolerance_m must be >= 0 (0 = default '
                           f'{sup.width_tolerance_m:g}), got {req.width_tolerance_m!r}')
    tolerance = req.width_tolerance_m or sup.width_tolerance_m
    if not req.width_m + tolerance < plant.max_travel_m:
        raise RequestError(f'width_m + width_tolerance_m must be < {plant.max_travel_m:g} m (the '
                           f'finger travel), got {req.width_m:g} + {tolerance:g} m')
    mu = req.friction_coefficient or sup.friction_coefficient
    if req.mass_kg == 0.0:
        touch_n = (load_grip or shipped_config().load_grip).touch_force_n
        if not 0.0 < touch_n <= plant.max_force_n:
            raise RequestError(f'load_grip.touch_force_n must be in (0, {plant.max_force_n:.2f}] '
                               f'N (the most {plant.voltage_limit_v:g} V holds), got {touch_n!r}')
        return GraspTargets(plant.max_travel_m - req.width_m, touch_n, mu,
                            req.timeout_s or sup.timeout_s, tolerance, load_tracking=True)
    accel = req.acceleration_mps2 or sup.acceleration_mps2
    law, k = sup.force_law, sup.grip_safety_factor
    force = force_setpoint_n(req.mass_kg, mu, plant.gravity_mps2, accel, law, k)
    if force > plant.max_force_n:
        raise RequestError(
            f'force setpoint {force:.2f} N ('
            f'{_force_law_text(law, mu, req.mass_kg, plant.gravity_mps2 + accel, k)}) exceeds '
            f'the {plant.max_force_n:.2f} N the motor can hold at {plant.voltage_limit_v:g} V')
    if force <= 0.0:
        raise RequestError(f'force setpoint must be > 0 N, got {force!r}')
    return GraspTargets(plant.max_travel_m - req.width_m, force, mu,
                        req.timeout_s or sup.timeout_s, tolerance)


def _check_finite(req, names) -> None:
    for name in names:
        value = getattr(req, name)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or \
                not math.isfinite(value):
            raise RequestError(f'{name} must be a finite number, got {value!r}')


def check_move_limits(req: MoveRequest, plant: PlantParams) -> None:
    """Refuse a move that is non-finite or beyond the plant (travel, free speed, stall force).

    What needs no supervisor setting: a move action server checks goals with it, and the
    supervisor, the one holder of ``supervisor.*``, judges the rest.
    """
    _check_finite(req, ('width_m', 'speed_mps', 'max_effort_n', 'timeout_s'))
    if not 0.0 <= req.width_m <= plant.max_travel_m:
        raise RequestError(f'width_m must be in [0, {plant.max_travel_m:g}] m (0 = closed, '
                           f'{plant.max_travel_m:g} = fully open), got {req.width_m!r}')
    if req.speed_mps != 0.0 and not 0.0 < req.speed_mps <= plant.max_free_speed_mps:
        raise RequestError(f'speed_mps must be in (0, {plant.max_free_speed_mps:.6g}] m/s (the '
                           f'free speed at {plant.voltage_limit_v:g} V) or 0 (the default), '
                           f'got {req.speed_mps!r}')
    if req.max_effort_n != 0.0 and not 0.0 < req.max_effort_n <= plant.max_force_n:
        raise RequestError(
            f'max_effort_n must be in (0, {plant.max_force_n:.6g}] N (the force of '
            f'{plant.voltage_limit_v:g} V at stall) or 0 (the limit of the motor), '
            f'got {req.max_effort_n!r}')


def validate_move(req: MoveRequest, plant: PlantParams, sup: SupervisorParams) -> MoveTargets:
    """Resolve a move's defaults and refuse anything non-finite or out of range."""
    check_move_limits(req, plant)
    top_speed = plant.max_free_speed_mps
    if req.speed_mps != 0.0 and not sup.move_rest_speed_mps < req.speed_mps:
        raise RequestError(
            f'speed_mps must be in ({sup.move_rest_speed_mps:g}, {top_speed:.6g}] m/s (at rest '
            f'below; the free speed at {plant.voltage_limit_v:g} V above) or 0 (default '
            f'{sup.move_default_speed_mps:g}), got {req.speed_mps!r}')
    if not 0.0 <= req.timeout_s <= MAX_TIMEOUT_S:
        raise RequestError(f'timeout_s must be in [0, {MAX_TIMEOUT_S:g}] s (0 = the travel at '
                           f'speed + {sup.timeout_s:g} s), got {req.timeout_s!r}')
    effort = req.max_effort_n or plant.max_force_n
    cap_v = req.max_effort_n / plant.stall_force_per_volt_n if req.max_effort_n else 0.0
    return MoveTargets(plant.max_travel_m - req.width_m,
                       req.speed_mps or sup.move_default_speed_mps, effort, cap_v,
                       req.timeout_s, sup.move_tolerance_m)
