"""One grasp without ROS: the node graph's lockstep loop, run in plain Python.

The same plant, supervisor and stage code the nodes call (:mod:`gripper_ros.core.lockstep`),
wired exactly as the graph wires them in ``time_mode`` fast: the position stage holds the
open fingers, the grasp request starts at the next tick, each tick the supervisor decides, the
stage it names answers and the plant holds that answer; simulated time stops when the request
no longer needs it (answered, and no lift left to play out), or ``hold_s`` after the answer.
A grasp here gives the same series as the graph, tick for tick, in a fraction of the time, so
sweeps over many objects are practical.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Callable

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.controllers import make_plant
from gripper_ros.core.lockstep import PlantSide, StageSide, SupervisorSide
from gripper_ros.core.plant import check_fault, GraspObject, Lift
from gripper_ros.core.requests import GraspRequest, MoveRequest, validate_move, validate_request
from gripper_ros.core.stages import (DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                                     DEFAULT_POSITION_CONTROLLER, ForceStageController,
                                     PositionStageController)
from gripper_ros.core.supervisor import GraspSupervisor
from gripper_ros.wire import Controller, FaultKind, Outcome, Phase, SwitchCriterion
import numpy as np


@dataclass
class HeadlessGrasp:
    """Per-tick series (one entry per plant tick) and the grasp's result."""

    outcome: Outcome                    # the final outcome (after the hold, when it went on)
    message: str
    switch_criterion: SwitchCriterion
    position_setpoint_m: float
    force_setpoint_n: float
    start_ns: int
    switch_ns: int | None
    contact_ns: int | None
    end_ns: int                         # the last tick simulated
    answer: Outcome = Outcome.UNKNOWN   # what the grasp service answered
    answer_ns: int | None = None        # when
    t_ns: np.ndarray = field(repr=False, default=None)
    position_m: np.ndarray = field(repr=False, default=None)
    force_n: np.ndarray = field(repr=False, default=None)
    peak_force_n: np.ndarray = field(repr=False, default=None)
    motor_voltage_v: np.ndarray = field(repr=False, default=None)
    sensor_voltage_v: np.ndarray = field(repr=False, default=None)
    phase: np.ndarray = field(repr=False, default=None)
    final_ns: int | None = None         # when the final outcome was reached
    slip_m: float = 0.0                 # ground truth: how far the object slid on the pads
    lost_ns: int | None = None          # ground truth: when it left the pads

    @property
    def peak_contact_force_n(self) -> float:
        """Largest contact force, between samples included, over the grasp and the hold."""
        return float(np.max(self.peak_force_n))

    @property
    def time_to_answer_s(self) -> float:
        """From the request to the grasp service's answer (inf without one)."""
        if self.answer_ns is None:
            return math.inf
        return (self.answer_ns - self.start_ns) * 1e-9

    @property
    def continued_hold(self) -> slice:
        """The samples after a HOLDING answer (empty without one or without ``hold_s``)."""
        if self.answer is not Outcome.HOLDING:
            return slice(0, 0)
        return slice(int(np.searchsorted(self.t_ns, self.answer_ns, side='right')), None)

    def hold_force_range_n(self) -> tuple[float, float]:
        """Return (min, max) of the force over the continued hold; (nan, nan) without one.

        The max includes the peaks between samples.
        """
        hold = self.continued_hold
        if self.force_n[hold].size == 0:
            return math.nan, math.nan
        return float(np.min(self.force_n[hold])), float(np.max(self.peak_force_n[hold]))

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


def simulate_grasp(config: GripperConfig, width_m: float, mass_kg: float, *,
                   object_width_m: float | None = None, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, friction_coefficient: float = 0.0,
                   acceleration_mps2: float = 0.0, timeout_s: float = 0.0,
                   width_tolerance_m: float = 0.0,
                   position_controller=DEFAULT_POSITION_CONTROLLER,
                   force_controller=DEFAULT_FORCE_CONTROLLER,
                   approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN,
                   object_mass_kg: float = 0.0, static_friction: float = 0.0,
                   kinetic_friction: float = 0.0, pad_length_m: float = 0.0,
                   lift: Lift | None = None, hold_s: float = 0.0,
                   start_ns: int = 0,
                   fault: tuple[FaultKind | int, float, float] | None = None,
                   idle_unpowered_s: float = 0.0,
                   trace: Callable | None = None) -> HeadlessGrasp:
    """Grasp from fully open, as the graph grasps in fast mode.

    ``object_width_m`` (default ``width_m``; 0 = nothing) is the real
    object, ``width_m`` the expected one. The object's own mass and pad friction (0 = the
    grasp's mass, the configured friction) hold it once ``lift`` lifts it; time runs until the
    lift has played out, and ``hold_s`` at least that long after the answer. Raises
    RequestError for a request the graph refuses.

    ``fault`` = (kind, seconds after the grasp's start, time constant; 0 = the default) is
    scheduled as ``sim/set_object`` schedules it (ValueError when refused).
    ``idle_unpowered_s`` > 0: the tick before the grasp goes unanswered and the motor is held at
    0 V this long, as in the graph after a FAULT (its supervisor names no stage until the next
    request, and the plant steps unpowered for one state period). ``trace``, when
    given, is called every tick with (plant, tick, decision, reference, command) before the
    plant reacts to the command (reference and command None on the tick no stage is named);
    the decision is the supervisor's reused object, to be read at once.
    """
    targets = validate_request(GraspRequest(width_m, mass_kg, friction_coefficient,
                                            acceleration_mps2, timeout_s, width_tolerance_m),
                               config.plant, config.supervisor)
    plant = make_plant(config)
    plant.t_ns = start_ns
    plant_side = PlantSide(plant)
    plant_side.grasp_mass_kg = mass_kg
    obj = GraspObject(width_m if object_width_m is None else object_width_m, stiffness_n_per_m,
                      damping_n_s_per_m, object_mass_kg, static_friction, kinetic_friction,
                      pad_length_m)
    if fault is not None:
        kind, tau = check_fault(fault[0], fault[1], fault[2], obj.rigid)
        fault = (kind, fault[1], tau)
    plant_side.set_object(obj, fault=fault, lift=lift)
    supervisor = GraspSupervisor(config.plant, config.supervisor)
    decide = SupervisorSide(supervisor).decide
    position_stage = PositionStageController(config, position_controller)
    force_stage = ForceStageController(config, force_controller, approach_force_margin)
    stages = {Controller.POSITION: StageSide(position_stage),
              Controller.FORCE: StageSide(force_stage)}
    tick = plant_side.tick()
    decision, ref = decide(tick)                    # the position stage holds the open fingers
    supervisor.request_grasp(targets, mass_kg, after_ns=tick.stamp_ns)
    woken = True                                    # the request wakes the paused simulation
    hold_until_ns = None
    rows = []
    if idle_unpowered_s > 0.0:
        rows.append((tick.stamp_ns, tick.position_m, tick.force_n, tick.peak_force_n,
                     tick.motor_voltage_v, tick.sensor_voltage_v, int(decision.phase)))
        if trace is not None:
            trace(plant, tick, decision, None, None)
        tick = plant_side.step_unpowered(idle_unpowered_s)
        decision, ref = decide(tick)
        woken = False
    while True:
        rows.append((tick.stamp_ns, tick.position_m, tick.force_n, tick.peak_force_n,
                     tick.motor_voltage_v, tick.sensor_voltage_v, int(decision.phase)))
        if hold_until_ns is None and supervisor.answer_ns is not None:
            hold_until_ns = supervisor.answer_ns + round(hold_s * 1e9)
        if ref is None:
            if trace is not None:
                trace(plant, tick, decision, None, None)
            break                                   # a FAULT: nothing drives the motor
        cmd = stages[ref.controller].answer(ref)
        if trace is not None:
            trace(plant, tick, decision, ref, cmd)
        plant_side.accept(cmd)
        needed = plant_side.needs_time(cmd) or woken or \
            (hold_until_ns is not None and tick.stamp_ns < hold_until_ns)
        if not needed:
            break                                   # fast mode: simulated time pauses
        woken = False
        tick = plant_side.step(cmd)
        decision, ref = decide(tick)
    cols = list(zip(*rows))
    s = supervisor
    return HeadlessGrasp(
        s.outcome, s.message, s.switch_criterion, targets.position_setpoint_m,
        targets.force_setpoint_n, s.start_ns, s.switch_ns, s.contact_ns, tick.stamp_ns,
        s.answer, s.answer_ns, np.array(cols[0], dtype=np.int64),
        *(np.array(c, dtype=float) for c in cols[1:6]), np.array(cols[6], dtype=np.int8),
        s.end_ns, plant.object_state.slip_m, plant.object_state.lost_ns)


@dataclass
class MoveAnswer:
    """What the move service answered one request (srv/Move's result)."""

    outcome: Outcome
    message: str
    start_ns: int
    answer_ns: int
    position_m: float
    effort_n: float

    @property
    def reached_goal(self) -> bool:
        return self.outcome is Outcome.MOVED

    @property
    def stalled(self) -> bool:
        return self.outcome is Outcome.STALLED


@dataclass
class HeadlessMoves:
    """Per-tick series of a sequence of moves and each move's answer."""

    answers: list
    t_ns: np.ndarray = field(repr=False, default=None)
    position_m: np.ndarray = field(repr=False, default=None)
    velocity_mps: np.ndarray = field(repr=False, default=None)
    force_n: np.ndarray = field(repr=False, default=None)
    peak_force_n: np.ndarray = field(repr=False, default=None)
    motor_voltage_v: np.ndarray = field(repr=False, default=None)
    phase: np.ndarray = field(repr=False, default=None)
    approach_setpoint_m: np.ndarray = field(repr=False, default=None)


def simulate_moves(config: GripperConfig, moves, *, object_width_m: float = 0.0,
                   stiffness_n_per_m: float = 0.0, damping_n_s_per_m: float = 0.0,
                   position_controller=DEFAULT_POSITION_CONTROLLER, hold_s: float = 0.0,
                   start_ns: int = 0) -> HeadlessMoves:
    """Run moves (:class:`MoveRequest`) one after the other from fully open.

    Each is requested when the one before has been answered and simulated time has paused (as
    a client of the graph in fast mode does); ``object_width_m`` 0 = nothing between the
    fingers. Time runs on ``hold_s`` after the last answer (the position stage keeps the last
    command). Raises RequestError for a request the graph refuses (before anything runs).
    """
    targets = [validate_move(m, config.plant, config.supervisor) for m in moves]
    plant = make_plant(config)
    plant.t_ns = start_ns
    plant_side = PlantSide(plant)
    plant_side.set_object(GraspObject(object_width_m, stiffness_n_per_m, damping_n_s_per_m))
    supervisor = GraspSupervisor(config.plant, config.supervisor)
    decide = SupervisorSide(supervisor).decide
    stage = StageSide(PositionStageController(config, position_controller))
    tick = plant_side.tick()
    decision, ref = decide(tick)                    # the position stage holds the open fingers
    pending = list(targets)
    answers, rows = [], []
    while True:
        rows.append((tick.stamp_ns, tick.position_m, tick.velocity_mps, tick.force_n,
                     tick.peak_force_n, tick.motor_voltage_v, int(decision.phase),
                     decision.approach_setpoint_m))
        if decision.answer is not None:
            answers.append(MoveAnswer(decision.answer, decision.message, supervisor.start_ns,
                                      tick.stamp_ns, tick.position_m, tick.force_n))
        if ref is None:
            break                                   # a FAULT: nothing drives the motor
        cmd = stage.answer(ref)
        plant_side.accept(cmd)
        if not plant_side.needs_time(cmd):
            if not pending:
                if answers and tick.stamp_ns < answers[-1].answer_ns + round(hold_s * 1e9):
                    tick = plant_side.step(cmd)
                    decision, ref = decide(tick)
                    continue
                break                               # fast mode: simulated time pauses
            # the next request wakes the paused simulation; it starts at the next tick
            supervisor.request_move(pending.pop(0), after_ns=tick.stamp_ns)
        tick = plant_side.step(cmd)
        decision, ref = decide(tick)
    cols = list(zip(*rows))
    return HeadlessMoves(answers, np.array(cols[0], dtype=np.int64),
                         *(np.array(c, dtype=float) for c in cols[1:6]),
                         np.array(cols[6], dtype=np.int8), np.array(cols[7], dtype=float))


__all__ = ['HeadlessGrasp', 'HeadlessMoves', 'MoveAnswer', 'MoveRequest', 'Phase',
           'simulate_grasp', 'simulate_moves']
