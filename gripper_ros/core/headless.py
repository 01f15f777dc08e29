"""One grasp without ROS: the node graph's lockstep loop, run in plain Python.

The same plant (:mod:`plant`), supervisor state machine (:mod:`grasp_logic`) and controller logic
(:mod:`controller_logic`) the nodes call, wired exactly as the nodes wire them: each tick the
supervisor decides from the tick's measurements, the controller it names answers, and the plant
holds that answer for the controller's sampling time. A grasp here gives the same series as the
graph (``test/test_graph.py`` checks it bit for bit against the recorded bags), in a fraction of
the time, so sweeps over many objects are practical.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.controllers import make_plant
from gripper_ros.core.plant import GraspObject
from gripper_ros.core.stages import (DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                                     DEFAULT_POSITION_CONTROLLER, ForceStageController,
                                     LockstepAnswerer, PositionStageController)
from gripper_ros.core.supervisor import (Controller, GraspRequest, GraspSupervisor, Outcome,
                                         Phase, SwitchCriterion, validate_request)
import numpy as np


@dataclass
class _Status:
    """The fields of SupervisorStatus the controllers read."""

    active_controller: int = 0
    grasp_id: int = 1
    position_setpoint_m: float = 0.0
    force_setpoint_n: float = 0.0
    seed_voltage_v: float = 0.0
    contact: bool = False
    position_m: float = 0.0
    approach_setpoint_m: float = 0.0


@dataclass
class HeadlessGrasp:
    """Per-tick series (one entry per plant sample) and the grasp's result."""

    outcome: Outcome
    message: str
    switch_criterion: SwitchCriterion
    position_setpoint_m: float
    force_setpoint_n: float
    start_ns: int
    switch_ns: int | None
    contact_ns: int | None
    end_ns: int
    t_ns: np.ndarray = field(repr=False)
    position_m: np.ndarray = field(repr=False)
    force_n: np.ndarray = field(repr=False)
    peak_force_n: np.ndarray = field(repr=False)
    motor_voltage_v: np.ndarray = field(repr=False)
    sensor_voltage_v: np.ndarray = field(repr=False)
    phase: np.ndarray = field(repr=False)
    hold_s: float = 0.0     # the plant and force stage ran on this long after HOLDING (series)

    @property
    def peak_contact_force_n(self) -> float:
        """Largest contact force, between samples included, over the grasp and the hold."""
        return float(np.max(self.peak_force_n))

    @property
    def continued_hold(self) -> slice:
        """The samples of the continued hold (after the HOLDING answer; empty without one)."""
        return slice(int(np.searchsorted(self.t_ns, self.end_ns, side='right')), None)

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
                   start_ns: int = 0, hold_s: float = 0.0) -> HeadlessGrasp:
    """Grasp from fully open, as the node graph does.

    ``object_width_m`` (default ``width_m``; 0 = nothing) is the real object, ``width_m`` the
    expected one. Raises RequestError for a request the graph refuses.

    ``hold_s`` > 0: after a HOLDING answer the plant and the force stage run on for this long
    (the series go on, phase HOLDING), to check that the held force stays settled.
    """
    if not (math.isfinite(hold_s) and hold_s >= 0.0):
        raise ValueError(f'hold_s must be finite and >= 0, got {hold_s!r}')
    targets = validate_request(GraspRequest(width_m, mass_kg, friction_coefficient,
                                            acceleration_mps2, timeout_s, width_tolerance_m),
                               config.plant, config.supervisor)
    plant = make_plant(config)
    plant.t_ns = start_ns
    plant.set_object(GraspObject(width_m if object_width_m is None else object_width_m,
                                 stiffness_n_per_m, damping_n_s_per_m))
    stages = {Controller.POSITION: LockstepAnswerer(
                  PositionStageController(config, position_controller)),
              Controller.FORCE: LockstepAnswerer(
                  ForceStageController(config, force_controller, approach_force_margin))}
    supervisor = GraspSupervisor(config.plant, config.supervisor)
    sample = plant.sample()
    decision = supervisor.start(targets, sample.t_ns, sample.sensor_voltage_v)
    rows = []
    status = _Status(position_setpoint_m=targets.position_setpoint_m,
                     force_setpoint_n=targets.force_setpoint_n,
                     approach_setpoint_m=targets.approach_setpoint_m)
    while True:
        rows.append((sample.t_ns, sample.position_m, sample.force_n, sample.peak_force_n,
                     sample.voltage_v, sample.sensor_voltage_v, int(decision.phase)))
        status.active_controller = int(decision.active)
        status.contact = supervisor.contact_ns is not None
        status.seed_voltage_v = sample.voltage_v
        status.position_m = sample.position_m
        for answerer in stages.values():
            answerer.on_status(status)
        if decision.active is Controller.NONE:
            break
        answerer = stages[decision.active]
        measurement = sample.position_m if decision.active is Controller.POSITION \
            else sample.force_n
        answer = answerer.answer(status, sample.t_ns, measurement)
        sample = plant.step(answer.voltage_v, answerer.stage.sample_time_s)
        decision = supervisor.step(sample.t_ns, sample.position_m, sample.force_n,
                                   sample.sensor_voltage_v, sample.velocity_mps)
    end_ns = sample.t_ns
    if hold_s > 0.0 and supervisor.outcome is Outcome.HOLDING:
        force_stage = stages[Controller.FORCE].stage    # no re-activation: the same force loop
        status.active_controller = int(Controller.FORCE)
        hold_end_ns = sample.t_ns + round(hold_s * 1e9)
        while sample.t_ns < hold_end_ns:
            status.position_m = sample.position_m
            voltage, _ = force_stage.compute(status, sample.force_n)
            sample = plant.step(voltage, force_stage.sample_time_s)
            rows.append((sample.t_ns, sample.position_m, sample.force_n, sample.peak_force_n,
                         sample.voltage_v, sample.sensor_voltage_v, int(Phase.HOLDING)))
    cols = list(zip(*rows))
    return HeadlessGrasp(
        supervisor.outcome, supervisor.message, supervisor.switch_criterion,
        targets.position_setpoint_m, targets.force_setpoint_n, start_ns, supervisor.switch_ns,
        supervisor.contact_ns, end_ns, np.array(cols[0], dtype=np.int64),
        *(np.array(c, dtype=float) for c in cols[1:6]), np.array(cols[6], dtype=np.int8),
        hold_s if supervisor.outcome is Outcome.HOLDING else 0.0)


__all__ = ['HeadlessGrasp', 'Phase', 'simulate_grasp']
