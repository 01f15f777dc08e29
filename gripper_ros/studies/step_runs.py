"""Closed-loop step simulations without ROS: the paper's preliminary position and force runs.

Used by ``paper_tables``, the tests and the benchmarks, so that every figure comes from one
implementation. The plant is always the exact-discretised model of ``plant.py``.
"""
from __future__ import annotations

from dataclasses import dataclass

from gripper_ros.core.config import GripperConfig
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.studies.metrics import step_metrics, StepMetrics
import numpy as np


@dataclass
class StepRun:
    """Sampled closed-loop response: times, output, command (held from each sample)."""

    t_s: np.ndarray
    output: np.ndarray
    command_v: np.ndarray
    setpoint: float

    def metrics(self) -> StepMetrics:
        return step_metrics(self.t_s, self.output, self.setpoint)

    @property
    def max_abs_command_v(self) -> float:
        return float(np.max(np.abs(self.command_v)))


def position_step(config: GripperConfig, controller, setpoint_m: float = 0.1,
                  horizon_s: float = 20.0) -> StepRun:
    """Finger from fully open (no object) to ``setpoint_m``, sampled at the position rate."""
    dt = config.position.sample_time_s
    plant = make_plant(config)
    sample = plant.sample()
    n = int(round(horizon_s / dt))
    t = np.empty(n + 1)
    y = np.empty(n + 1)
    u = np.empty(n)
    t[0], y[0] = 0.0, sample.position_m
    for k in range(n):
        u[k] = controller.step(setpoint_m, sample.position_m)
        sample = plant.step(u[k], dt)
        t[k + 1], y[k + 1] = sample.t_s, sample.position_m
    return StepRun(t, y, u, setpoint_m)


def force_step(config: GripperConfig, controller, dt_s: float, setpoint_n: float = 1.0,
               horizon_s: float = 0.004, substeps: int = 10) -> StepRun:
    """Finger resting on a rigid object, motor off, force setpoint step at t = 0.

    The output is recorded ``substeps`` times per controller sample so that overshoot and
    settling between samples are seen (the command is held over each sample).
    """
    plant = make_plant(config)
    plant.set_object(GraspObject(width_m=0.05))
    plant.touch_object()
    t0 = plant.t_ns
    sample = plant.sample()
    n = int(round(horizon_s / dt_s))
    t = np.empty(n * substeps + 1)
    y = np.empty(n * substeps + 1)
    u = np.empty(n)
    t[0], y[0] = 0.0, sample.force_n
    for k in range(n):
        u[k] = controller.step(setpoint_n, sample.force_n)
        for j in range(substeps):
            sample = plant.step(u[k], dt_s / substeps)
            idx = k * substeps + j + 1
            t[idx], y[idx] = (sample.t_ns - t0) * 1e-9, sample.force_n
    return StepRun(t, y, u, setpoint_n)
