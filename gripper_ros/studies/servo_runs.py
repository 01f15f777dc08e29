"""Trajectories streamed to the position servo, headless, and what each needs of the motor.

A trajectory is a closed form of the finger's position, velocity and acceleration in time
(travel from fully open, m): a trapezoidal velocity profile, a sine that starts at rest, a
cubic spline through knots (clamped: at rest at both ends). What it needs of the motor is
its feed-forward voltage, ``k_v v + k_a a`` (:mod:`gripper_ros.core.control.servo_feedforward`),
at its peak: the bound against the voltage limit.

:func:`track` plays one as a setpoint stream through the graph's own loop (plant, supervisor,
position stage; :mod:`gripper_ros.core.runtime.lockstep`), as ros2_control's topic-based
hardware (JointStateTopicSystem) sends it on ``joint_commands``: the finger first moved to the
trajectory's start and at rest there, then at each controller update (``period_s``) the
trajectory sampled at that update's tick, sent unless the finger is within the hardware's
threshold of it (the same command again too: a repeat), stamped with the update's instant (the
hardware's clock on the gripper's) and handed to the supervisor before the next tick is
decided; positions alone or with velocities (and accelerations), as a FollowJointTrajectory
server's samples. A busy machine: ``late_share`` of the setpoints come up to ``late_updates``
updates late (those after them queue behind, in order, as one writer's messages do),
``skip_share`` of the updates are lost.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.servo_feedforward import voltage_needed_v
from gripper_ros.core.control.stages import PositionStageController
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.core.runtime.lockstep import PlantSide, StageSide, SupervisorSide
from gripper_ros.core.supervision.requests import MoveRequest, validate_move
from gripper_ros.core.supervision.supervisor import GraspSupervisor, load_law
from gripper_ros.wire import Outcome
import numpy as np
from scipy.interpolate import CubicSpline

GIVEN = ('positions', 'velocities', 'accelerations')
"""What each setpoint carries: its position alone, with its velocity, with both."""
REACHED_M = 1e-5
"""The topic-based hardware sends the command while the joint is farther from it than this
(``trigger_joint_command_threshold``'s default), the same command again too."""


@dataclass(frozen=True)
class Trapezoid:
    """From ``start_m`` to ``end_m``: a trapezoidal velocity profile.

    Accelerate at ``accel_mps2`` to ``speed_mps``, cruise, decelerate to rest (a triangle when
    the distance is too short to reach the speed).
    """

    start_m: float
    end_m: float
    speed_mps: float
    accel_mps2: float

    @property
    def name(self) -> str:
        return (f'trapezoid {self.start_m * 1e3:g}->{self.end_m * 1e3:g} mm, '
                f'{self.speed_mps:g} m/s, {self.accel_mps2:g} m/s^2')

    @property
    def _ramp(self) -> tuple[float, float, float]:
        """(distance, ramp time, cruise time)."""
        d = abs(self.end_m - self.start_m)
        t_ramp = min(self.speed_mps / self.accel_mps2, math.sqrt(d / self.accel_mps2))
        cruise = (d - self.accel_mps2 * t_ramp ** 2) / (self.accel_mps2 * t_ramp)
        return d, t_ramp, max(cruise, 0.0)

    @property
    def duration_s(self) -> float:
        _, t_ramp, cruise = self._ramp
        return 2.0 * t_ramp + cruise

    def at(self, t_s):
        """Return (position, velocity, acceleration) at times ``t_s`` (array)."""
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.duration_s)
        _, t_ramp, cruise = self._ramp
        a, sign = self.accel_mps2, math.copysign(1.0, self.end_m - self.start_m)
        top = a * t_ramp
        t_brake = t_ramp + cruise
        rise = t < t_ramp
        fall = t > t_brake
        tb = t - t_brake
        x = np.where(rise, 0.5 * a * t ** 2,
                     np.where(fall, 0.5 * a * t_ramp ** 2 + top * (t_brake - t_ramp) + top * tb
                              - 0.5 * a * tb ** 2,
                              0.5 * a * t_ramp ** 2 + top * (t - t_ramp)))
        v = np.where(rise, a * t, np.where(fall, top - a * tb, top))
        acc = np.where(rise, a, np.where(fall, -a, 0.0))
        acc = np.where(np.asarray(t_s) >= self.duration_s, 0.0, acc)
        return self.start_m + sign * x, sign * v, sign * acc


@dataclass(frozen=True)
class Ramp:
    """From rest at ``start_m``, at once at ``speed_mps`` for ``ramp_s``, then standing.

    What joint_trajectory_controller makes of one position-only point (needs an infinite
    voltage at its start).
    """

    start_m: float
    speed_mps: float
    ramp_s: float

    @property
    def name(self) -> str:
        return (f'ramp from {self.start_m * 1e3:g} mm at {self.speed_mps:g} m/s for '
                f'{self.ramp_s:g} s')

    @property
    def duration_s(self) -> float:
        return self.ramp_s

    def at(self, t_s):
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.ramp_s)
        on = (np.asarray(t_s) >= 0.0) & (np.asarray(t_s) < self.ramp_s)
        return (self.start_m + self.speed_mps * t, np.where(on, self.speed_mps, 0.0),
                np.zeros_like(t))


@dataclass(frozen=True)
class Sine:
    """``center - amplitude cos(2 pi t / period)`` for ``cycles`` periods.

    From rest at its lowest, through its highest, back to rest at its lowest.
    """

    center_m: float
    amplitude_m: float
    period_s: float
    cycles: float = 1.0

    @property
    def name(self) -> str:
        return (f'sine {self.center_m * 1e3:g} +- {self.amplitude_m * 1e3:g} mm, '
                f'period {self.period_s:g} s')

    @property
    def start_m(self) -> float:
        return self.center_m - self.amplitude_m

    @property
    def duration_s(self) -> float:
        return self.cycles * self.period_s

    def at(self, t_s):
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.duration_s)
        w = 2.0 * math.pi / self.period_s
        a = self.amplitude_m
        on = np.asarray(t_s) < self.duration_s
        return (self.center_m - a * np.cos(w * t), np.where(on, a * w * np.sin(w * t), 0.0),
                np.where(on, a * w * w * np.cos(w * t), 0.0))


@dataclass(frozen=True)
class Spline:
    """A cubic spline through ``(time_s, position_m)`` knots, at rest at both ends."""

    knots: tuple[tuple[float, float], ...]

    @property
    def name(self) -> str:
        return 'spline through ' + ', '.join(f'{x * 1e3:g} mm' for _, x in self.knots)

    @property
    def start_m(self) -> float:
        return self.knots[0][1]

    @property
    def duration_s(self) -> float:
        return self.knots[-1][0] - self.knots[0][0]

    def at(self, t_s):
        times, positions = zip(*self.knots)
        curve = CubicSpline(np.asarray(times) - times[0], positions, bc_type='clamped')
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.duration_s)
        on = np.asarray(t_s) < self.duration_s
        return curve(t), np.where(on, curve(t, 1), 0.0), np.where(on, curve(t, 2), 0.0)


def farthest_m(plant, t_s: float, speed_limit_mps: float) -> float:
    """Return the farthest a finger at rest gets in ``t_s``: the voltage limit, then the limit.

    The least lag of a ramp from rest is the ramp less this. ``x(t) = v_max (t - tau (1 -
    exp(-t / tau)))`` until the speed ``v_max (1 - exp(-t / tau))`` reaches the limit, at
    ``t_1 = tau ln(v_max / (v_max - limit))``; at the limit after.
    """
    v_max, tau = plant.max_free_speed_mps, plant.mechanical_time_constant_s
    t_1 = tau * math.log(v_max / (v_max - speed_limit_mps))
    at = min(t_s, t_1)
    return v_max * (at - tau * (1.0 - math.exp(-at / tau))) + speed_limit_mps * (t_s - at)


def stopping_m(plant, speed_mps: float, volts: float = 0.0) -> float:
    """Return how far a finger at ``speed_mps`` runs on with ``volts`` against it.

    ``volts`` 0: the voltage limit. The speed ``-v_b + (v0 + v_b) exp(-t / tau)`` (``v_b`` the
    free speed at those volts) reaches 0 at ``tau ln((v0 + v_b) / v_b)``; the distance is its
    integral to then.
    """
    v_max = plant.free_speed_per_volt_mps * (volts or plant.voltage_limit_v)
    tau = plant.mechanical_time_constant_s
    speed = abs(speed_mps)
    t_s = tau * math.log((speed + v_max) / v_max)
    return -v_max * t_s + (speed + v_max) * tau * (1.0 - math.exp(-t_s / tau))


def needed_peak_v(config: GripperConfig, trajectory, step_s: float = 1e-3) -> float:
    """Return the most voltage the trajectory needs at any instant (its feed-forward's peak)."""
    t = np.arange(0.0, trajectory.duration_s + step_s, step_s)
    _, v, a = trajectory.at(t)
    return float(np.max(np.abs(voltage_needed_v(config.plant, v, a))))


@dataclass
class Tracking:
    """One trajectory streamed to the servo: every tick from the stream's first on."""

    t_s: np.ndarray                    # since the first setpoint
    position_m: np.ndarray             # the finger
    reference_m: np.ndarray            # the trajectory at that instant
    voltage_v: np.ndarray              # held from that tick on
    outcome: Outcome | None            # how the stream's move ended (None: still running)
    moves: int                         # requests the stream was (1: one move throughout)

    @property
    def error_m(self) -> np.ndarray:
        return self.reference_m - self.position_m

    @property
    def worst_error_m(self) -> float:
        return float(np.max(np.abs(self.error_m)))


def track(config: GripperConfig, trajectory, *, given: str = 'positions',
          stamped: bool = True, period_s: float = 0.01, late_share: float = 0.0,
          late_updates: int = 1, skip_share: float = 0.0, seed: int = 0, settle_s: float = 1.0,
          speed_mps: float = 0.0, position_controller='mpc_pd') -> Tracking:
    """Stream ``trajectory`` to the servo headless (module docstring) and return the run.

    ``given``: what each setpoint carries (:data:`GIVEN`); ``stamped``: the instant it was
    sampled (else the supervisor takes it when it comes). ``speed_mps``: the setpoints' speed
    limit (0: the default). Time runs on ``settle_s`` after the trajectory's end.
    """
    if given not in GIVEN:
        raise ValueError(f'given must be one of {GIVEN}, got {given!r}')
    plant_side = PlantSide(make_plant(config))
    plant_side.set_object(GraspObject(0.0, 0.0, 0.0), open_fingers=True)
    supervisor = GraspSupervisor(config.plant, config.supervisor, load_law(config))
    decide = SupervisorSide(supervisor).decide
    stage = StageSide(PositionStageController(config, position_controller))
    travel = config.plant.max_travel_m

    def targets(position_m: float):
        return validate_move(MoveRequest(travel - position_m, speed_mps), config.plant,
                             config.supervisor)

    tick = plant_side.tick()
    decision, ref = decide(tick)
    supervisor.request_move(targets(trajectory.start_m), after_ns=tick.stamp_ns)
    while True:                               # to the start, at rest
        tick = plant_side.step(stage.answer(ref))
        decision, ref = decide(tick)
        if decision.answer is not None:
            break
    period_ns = round(period_s * 1e9)
    rng = np.random.default_rng(seed)
    start_ns = tick.stamp_ns
    end_ns = start_ns + round((trajectory.duration_s + settle_s) * 1e9)
    queue: list[tuple] = []                   # (due tick, sample instant, x, v, a) on the way
    next_update_ns = start_ns
    first_id = None
    last_m = math.nan
    rows = []
    while tick.stamp_ns <= end_ns:
        if tick.stamp_ns >= next_update_ns:   # an update: the command, sent unless reached
            x, v, a = (float(q) for q in trajectory.at((tick.stamp_ns - start_ns) * 1e-9))
            late = rng.random() < late_share
            due = tick.stamp_ns + (int(rng.integers(1, late_updates + 1)) * period_ns
                                   if late else 0)
            if abs(tick.position_m - x) > REACHED_M and rng.random() >= skip_share:
                queue.append((max(due, queue[-1][0]) if queue else due, tick.stamp_ns, x, v, a))
            next_update_ns = tick.stamp_ns - (tick.stamp_ns - start_ns) % period_ns + period_ns
        while queue and queue[0][0] <= tick.stamp_ns:
            _, sample_ns, x, v, a = queue.pop(0)
            instant = sample_ns if stamped else None
            if x == last_m:
                supervisor.servo_repeated(instant)
                continue
            last_m = x
            supervisor.request_servo(
                targets(x), after_ns=tick.stamp_ns,
                velocity_mps=v if given != 'positions' else math.nan,
                acceleration_mps2=a if given == 'accelerations' else math.nan,
                sample_ns=instant)
            if first_id is None:
                first_id = supervisor.grasp_id + 1
        cmd = stage.answer(ref)
        rows.append((tick.stamp_ns, tick.position_m, cmd.voltage_v))
        tick = plant_side.step(cmd)
        decision, ref = decide(tick)
    t_ns, position, voltage = (np.array(c) for c in zip(*rows))
    t_s = (t_ns - start_ns) * 1e-9
    reference = trajectory.at(t_s)[0]
    outcome = None if supervisor.running else supervisor.outcome
    return Tracking(t_s, position, reference, voltage, outcome,
                    supervisor.grasp_id - first_id + 1)
