"""The identification experiment: a seeded sequence of moves and grasps that excites the plant.

The gripper is driven through the ``move`` service it already has, so the supervisor's checks,
``stop`` and the travel limits all apply as to any move: the finger goes to pseudo-random
positions (a multi-level PRBS on the position: the next level is drawn from the half of the band
the finger is not in) at pseudo-random speed limits, with the voltage capped by the move's
effort at ``amplitude_v``; optionally every ``HOLD_EVERY``-th request, the second one first,
grasps a rigid stop (an object of ``STOP_WIDTH_M``) at a pseudo-random share of the force
``amplitude_v`` holds: the force stage's samples (0.1 ms) see the armature current settle after
each of its voltage steps (the electrical time constant L/R) and the rigid contact gives the
force model. Every target lies ``TRAVEL_MARGIN_M`` inside the travel (and short of the stop's
face), and each request's timeout is the time left, so the experiment ends within ``seconds``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
from typing import Iterator

from gripper_ros.core.config import GripperConfig, PlantParams
from gripper_ros.core.supervision.requests import (force_setpoint_n, GraspRequest,
                                                   MAX_TIMEOUT_S, MoveRequest)
import numpy as np

MAX_SECONDS = 300.0            # longest experiment accepted (simulated s)
MIN_SECONDS = 2.0              # shorter identifies nothing (about two mechanical time constants)
TRAVEL_MARGIN_M = 0.01         # targets stay this far inside the travel and off the stop's face
STOP_WIDTH_M = 0.03            # the rigid stop grasped for the force model and L/R
HOLD_EVERY = 4                 # every 4th request grasps the stop (with --hold), the 2nd first
SPEED_SHARE = (0.2, 1.0)       # a move's speed limit: this share of the amplitude's free speed
HOLD_FORCE_SHARE = (0.3, 0.9)  # a grasp's force: this share of the amplitude's stall force
MIN_STEP_SHARE = 0.15          # successive levels differ by at least this share of the band

__all__ = ['ExcitationSpec', 'HOLD_EVERY', 'MAX_SECONDS', 'MIN_SECONDS', 'STOP_WIDTH_M',
           'TRAVEL_MARGIN_M', 'check_spec', 'excitation_requests', 'free_band_m']


@dataclass(frozen=True)
class ExcitationSpec:
    """What the experiment may do: how long, how hard, which pseudo-random sequence."""

    seconds: float = 20.0
    amplitude_v: float = 12.0
    seed: int = 1
    hold: bool = True              # also grasp a rigid stop (force model, electrical pole)


def check_spec(spec: ExcitationSpec, plant: PlantParams) -> ExcitationSpec:
    """Return ``spec`` if the experiment may run; ValueError naming the field otherwise."""
    if isinstance(spec.seconds, bool) or not (
            math.isfinite(spec.seconds) and MIN_SECONDS <= spec.seconds <= MAX_SECONDS):
        raise ValueError(f'seconds must be in [{MIN_SECONDS:g}, {MAX_SECONDS:g}], '
                         f'got {spec.seconds!r}')
    if not (math.isfinite(spec.amplitude_v) and 0.0 < spec.amplitude_v <= plant.voltage_limit_v):
        raise ValueError(f'amplitude_v must be in (0, {plant.voltage_limit_v:g}] V (the '
                         f'voltage limit), got {spec.amplitude_v!r}')
    if isinstance(spec.seed, bool) or not isinstance(spec.seed, (int, np.integer)) or \
            not 0 <= spec.seed < 2 ** 32:
        raise ValueError(f'seed must be a whole number in [0, 2**32), got {spec.seed!r}')
    lo, hi = free_band_m(plant, spec.hold)
    if not hi - lo > 2.0 * TRAVEL_MARGIN_M:
        raise ValueError(f'the travel ({plant.max_travel_m:g} m) leaves no band to move in')
    return spec


def free_band_m(plant: PlantParams, hold: bool) -> tuple[float, float]:
    """Travel (from fully open) the free moves stay within: inside the ends and the stop."""
    end = plant.max_travel_m - (STOP_WIDTH_M if hold else 0.0)
    return TRAVEL_MARGIN_M, end - TRAVEL_MARGIN_M


def excitation_requests(spec: ExcitationSpec,
                        config: GripperConfig) -> Iterator[MoveRequest | GraspRequest]:
    """Yield the experiment's requests for ever (the runner stops at ``spec.seconds``).

    A request's ``timeout_s`` is left 0 here; the runner sets it to the time left.
    """
    plant = config.plant
    check_spec(spec, plant)
    rng = np.random.default_rng(spec.seed)
    lo, hi = free_band_m(plant, spec.hold)
    mid = 0.5 * (lo + hi)
    free_speed = plant.free_speed_per_volt_mps * spec.amplitude_v
    effort = plant.stall_force_per_volt_n * spec.amplitude_v
    sup = config.supervisor
    newton_per_kg = force_setpoint_n(1.0, sup.friction_coefficient, plant.gravity_mps2, 0.0,
                                     sup.force_law, sup.grip_safety_factor)
    x = 0.0
    n = 0
    while True:
        n += 1
        if spec.hold and n % HOLD_EVERY == 2:
            share = float(rng.uniform(*HOLD_FORCE_SHARE))
            yield GraspRequest(STOP_WIDTH_M, share * effort / newton_per_kg)
            x = plant.max_travel_m - STOP_WIDTH_M
            continue
        # the next level in the other half of the band, at least MIN_STEP_SHARE away
        if x < mid:
            target = float(rng.uniform(max(mid, x + MIN_STEP_SHARE * (hi - lo)), hi))
        else:
            target = float(rng.uniform(lo, min(mid, x - MIN_STEP_SHARE * (hi - lo))))
        speed = float(rng.uniform(*SPEED_SHARE)) * free_speed
        yield MoveRequest(plant.max_travel_m - target, speed, effort)
        x = target


CONTINUING_OUTCOMES = ('MOVED', 'STALLED', 'TIMEOUT', 'HOLDING', 'OBJECT_LOST', 'NO_OBJECT')
"""Outcomes after which the experiment goes on (what the supervisor judged of a grasp of the
stop changes nothing the bag records); any other (STOPPED, REFUSED, FAULT) ends it at once."""


class ExcitationRun:
    """The experiment's progress, the same for the console app and the service.

    Ask :meth:`next_request` with the simulated time now for the next request (None: done),
    send it (a :class:`MoveRequest` to ``move``, a :class:`GraspRequest` to ``grasp``), and hand
    its outcome's name to :meth:`answered`, which says whether to go on.
    """

    def __init__(self, spec: ExcitationSpec, config: GripperConfig, start_ns: int):
        self.spec = check_spec(spec, config.plant)
        self._requests = excitation_requests(spec, config)
        self.start_ns = start_ns
        self.moves = 0
        self.grasps = 0
        self._kind = ''
        self.ended_by = ''            # the outcome that ended it early ('' = ran its time)
        self.message = ''

    def next_request(self, now_ns: int) -> MoveRequest | GraspRequest | None:
        """Return the next request, its timeout the time left; None once time is up or ended."""
        left_s = self.spec.seconds - (now_ns - self.start_ns) * 1e-9
        if self.ended_by or left_s <= 0.0:
            return None
        request = next(self._requests)
        self._kind = 'grasps' if isinstance(request, GraspRequest) else 'moves'
        return replace(request, timeout_s=min(left_s, MAX_TIMEOUT_S))

    def answered(self, outcome_name: str, message: str = '') -> bool:
        """Count the answer to the last request; False (ended) unless a continuing outcome.

        RuntimeError, counting nothing, when no request was given since the last answer.
        """
        if not self._kind:
            raise RuntimeError('ExcitationRun.answered() without a request: each answer follows '
                               'a next_request() that returned one')
        setattr(self, self._kind, getattr(self, self._kind) + 1)
        self._kind = ''
        if outcome_name in CONTINUING_OUTCOMES:
            return True
        self.ended_by, self.message = outcome_name, message
        return False

    def summary(self, now_ns: int) -> str:
        """Say how the experiment ended, in one line."""
        elapsed = (now_ns - self.start_ns) * 1e-9
        done = (f'{self.moves} move{"s" * (self.moves != 1)} and {self.grasps} '
                f'grasp{"s" * (self.grasps != 1)}')
        if self.ended_by:
            return f'ended by {self.ended_by} after {done}, {elapsed:.2f} s: {self.message}'
        return f'{done} in {elapsed:.2f} s'
