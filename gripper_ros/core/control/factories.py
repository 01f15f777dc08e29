"""Builds the paper's controllers (Table II) from the configuration and the plant model.

Kept apart from ``pid.py``/``dmc.py`` so those stay generic; this is where "which gain belongs
where" and "what model the DMC predicts with" are decided, once, for nodes, tables and tests.
"""
from __future__ import annotations

import functools

from gripper_ros.core import linalg
from gripper_ros.core.config import DmcTuning, GripperConfig, PidGains, PlantParams
from gripper_ros.core.control.contact_force import ContactForceController
from gripper_ros.core.control.dmc import (BrakingGovernor, CascadedMpc, closed_loop_step_response,
                                          DynamicMatrixControl)
from gripper_ros.core.control.pid import (AntiWindup, DerivativeOn,
                                          first_order_pi_by_pole_placement, PID)
from gripper_ros.core.physics.force_sensor import FsrVoltageDivider
from gripper_ros.core.physics.motor_zoh import force_model, free_model
from gripper_ros.core.physics.plant import GripperPlant
from gripper_ros.wire import ForceControllerKind, PositionControllerKind
import numpy as np

UNSATURATED_V = 1e12  # limits used when building a DMC's linear model
MODEL_CACHE_SIZE = 64  # DMC models kept per process: building one costs tens of ms, a grasp few


def make_plant(config: GripperConfig) -> GripperPlant:
    return GripperPlant(config.plant, FsrVoltageDivider(config.force_sensor, config.sensor_noise),
                        config.contact, config.pad_sensor, config.force.sample_time_s,
                        config.sensor_noise.seed)


def _limits(config: GripperConfig) -> tuple[float, float]:
    v = config.plant.voltage_limit_v
    return (-v, v)


def _position_inner(config: GripperConfig, gains: PidGains, limits) -> PID:
    return PID(gains, config.position.sample_time_s, limits, DerivativeOn.ERROR,
               AntiWindup.CONDITIONAL)


def position_step_response(config: GripperConfig, gains: PidGains, samples: int):
    """Unit-step response of PD + plant (exact ZOH, unsaturated): the MPC-PD's DMC model."""
    return _position_step_response(config.plant, config.position.sample_time_s, gains,
                                   samples).copy()


@functools.lru_cache(maxsize=MODEL_CACHE_SIZE)
def _position_step_response(plant_params: PlantParams, sample_time_s: float, gains: PidGains,
                            samples: int) -> np.ndarray:
    """:func:`position_step_response`, once per plant, sampling time, gains and length."""
    ad, bd = free_model(plant_params, sample_time_s)
    state = np.zeros(3)

    def model_step(u: float) -> float:
        state[:] = linalg.matvec(ad, state) + bd * u
        return state[2]

    inner = PID(gains, sample_time_s, (-UNSATURATED_V, UNSATURATED_V), DerivativeOn.ERROR,
                AntiWindup.CONDITIONAL)
    return closed_loop_step_response(model_step, inner, samples)


def force_pi_gains(config: GripperConfig, dt_s: float | None = None,
                   pole: float | None = None) -> PidGains:
    """Our force PI: discrete pole placement on the exact ZOH of eq. 13 at ``dt_s``."""
    f = config.force
    dt = f.sample_time_s if dt_s is None else dt_s
    a, b = force_model(config.plant, dt)
    return first_order_pi_by_pole_placement(a, b, dt, f.closed_loop_pole if pole is None else pole)


def force_step_response(config: GripperConfig, gains: PidGains, dt_s: float, samples: int):
    """Unit-step response of PI + eq. 13 (exact ZOH, unsaturated): the MPC-PI's DMC model."""
    a, b = force_model(config.plant, dt_s)
    state = [0.0]

    def model_step(u: float) -> float:
        state[0] = a * state[0] + b * u
        return state[0]

    inner = PID(gains, dt_s, (-UNSATURATED_V, UNSATURATED_V))
    return closed_loop_step_response(model_step, inner, samples)


def make_position_controller(config: GripperConfig, kind: PositionControllerKind):
    """PD, PID (Table II gains) or MPC-PD; all expose ``step(setpoint, measurement) -> volts``."""
    pos = config.position
    limits = _limits(config)
    if kind is PositionControllerKind.PD:
        return _position_inner(config, pos.pd, limits)
    if kind is PositionControllerKind.PID:
        return _position_inner(config, pos.pid, limits)
    tuning = pos.mpc_pd_dmc
    model = position_step_response(config, pos.mpc_pd, tuning.horizon)
    dmc = DynamicMatrixControl(model, tuning.control_horizon, tuning.move_suppression)
    ad, bd = free_model(config.plant, pos.sample_time_s)
    governor = None
    if pos.mpc_pd_braking_voltage_v > 0.0:  # ours, default on; 0 = the DMC's clamp alone
        governor = BrakingGovernor(ad, bd, config.plant.voltage_limit_v,
                                   pos.mpc_pd_braking_voltage_v, tuning.horizon)
    return CascadedMpc(dmc, _position_inner(config, pos.mpc_pd, limits), governor=governor)


def make_force_controller(config: GripperConfig, kind: ForceControllerKind,
                          gains: PidGains | None = None, dt_s: float | None = None,
                          tuning: DmcTuning | None = None):
    """PI (ours by default) or MPC-PI over it, at ``dt_s`` (default: the force sampling time)."""
    dt = config.force.sample_time_s if dt_s is None else dt_s
    if kind is ForceControllerKind.CONTACT_AWARE:
        return ContactForceController(config.plant, config.force.contact_aware, dt)
    pi_gains = gains if gains is not None else force_pi_gains(config, dt)
    inner = PID(pi_gains, dt, _limits(config))
    if kind is ForceControllerKind.PI:
        return inner
    tuning = tuning or config.force.mpc_pi_dmc
    model = force_step_response(config, pi_gains, dt, tuning.horizon)
    dmc = DynamicMatrixControl(model, tuning.control_horizon, tuning.move_suppression)
    return CascadedMpc(dmc, inner)
