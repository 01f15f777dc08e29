"""One grasp and hold of the grip study: a grip law through an arm's motion (no rclpy).

Apart from :mod:`gripper_ros.core.load_grip` (the law) because it drives the whole loop
(headless, supervisor), which the supervisor's own use of the law must not import back.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import enum
import math

from gripper_ros.core.config import ForceLaw, GripperConfig, LoadGripParams
from gripper_ros.core.controllers import make_plant
from gripper_ros.core.headless import _Loop, simulate_grasp
from gripper_ros.core.hold import hold_schedule_lift, HoldState, Lift
from gripper_ros.core.load_grip import make_law, MU_GRID, ROW_FIELDS, run_load_grip
from gripper_ros.core.lockstep import PlantSide
from gripper_ros.core.pad_sensor import CHANNEL_DTYPE, make_channel, MAX_LATENCY_SAMPLES
from gripper_ros.core.plant import GraspObject, K_HOLD
from gripper_ros.core.requests import GraspRequest, RequestError, validate_request
from gripper_ros.core.stages import ForceStageController, PositionStageController
from gripper_ros.core.supervisor import GraspSupervisor
from gripper_ros.wire import Controller, Outcome
import numba
import numpy as np


@numba.njit(cache=True)
def _schedule_lift(plant_k, accel, delay_s, duration_s, profile, hz):
    h = plant_k[K_HOLD][0]
    if hold_schedule_lift(h, accel, delay_s, duration_s, profile, hz):
        return 1
    h.live = 1
    return 0


class GripLaw(str, enum.Enum):
    """The grip laws a study compares."""

    LOAD_TRACKING = 'load_tracking'
    FRICTION = 'friction'
    PAPER = 'paper'


@dataclass
class GripRun:
    """One grasp and hold: what a user sees of it, and its series (ROW_FIELDS)."""

    outcome: str                       # HOLDING, OBJECT_LOST, REFUSED, or the grasp's outcome
    note: str
    contact_peak_ratio: float          # peak force at contact / the grasp's setpoint
    slip_m: float
    lost_s: float                      # after the lift's start; NaN: never
    overload_s: float                  # when the law said overload, after the lift's start
    mean_margin: float                 # grip / slip limit m (g + a) / (2 mu_s), while lifted
    max_margin: float
    min_margin: float
    rows: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, len(ROW_FIELDS))))


def _graph_path_run(config: GripperConfig, width_m: float, mass_kg: float,
                    static_friction: float, kinetic_friction: float, lift: Lift | None,
                    stiffness_n_per_m: float, damping_n_s_per_m: float,
                    params: LoadGripParams | None, after_s: float, decimate: int,
                    seed: int) -> GripRun:
    """Run a mass-0 grasp and its hold as the graph does; the study's figures of it."""
    config = replace(config, load_grip=params or config.load_grip,
                     sensor_noise=replace(config.sensor_noise, seed=seed))
    hold_s = ((lift.delay_s + lift.duration_s) if lift is not None else 0.0) + after_s
    try:
        h = simulate_grasp(config, width_m, 0.0, stiffness_n_per_m=stiffness_n_per_m,
                           damping_n_s_per_m=damping_n_s_per_m, object_mass_kg=mass_kg,
                           static_friction=static_friction, kinetic_friction=kinetic_friction,
                           lift=lift, hold_s=hold_s)
    except RequestError as exc:
        return GripRun('REFUSED', str(exc), math.nan, math.nan, math.nan, math.nan,
                       math.nan, math.nan, math.nan)
    grasp = h.t_ns <= (h.answer_ns if h.answer_ns is not None else h.end_ns)
    ratio = float(np.nanmax(h.peak_force_n[grasp])) / h.force_setpoint_n
    if h.answer is not Outcome.HOLDING:
        return GripRun(h.answer.name, h.message, ratio, 0.0, math.nan, math.nan, math.nan,
                       math.nan, math.nan)
    lift_start_ns = h.answer_ns + (round(lift.delay_s * 1e9) if lift is not None else 0)
    end_ns = h.answer_ns + round(hold_s * 1e9)
    hold = np.flatnonzero((h.t_ns >= h.answer_ns) & (h.t_ns <= end_ns))
    lost = np.flatnonzero(h.hold_state[hold] == HoldState.LOST)
    if lost.size:                                   # the hold ends with the object
        hold = hold[:lost[0] + 1]
    rows = np.column_stack([
        h.t_ns, h.force_n, h.setpoint_n, h.load_n,
        2.0 * static_friction * np.maximum(h.force_n, 0.0), h.slip_series_m,
        0.5 * (h.pad1_shear_n + h.pad2_shear_n),
        0.5 * (h.pad1_displacement_m + h.pad2_displacement_m), h.mu_est,
        h.hold_state]).astype(float)[hold]
    margin = _margins(rows, static_friction,
                      lift_start_ns + round(config.contact.lift_off_s * 1e9))
    rows = rows[::decimate]
    overload_s = math.nan if h.overload_ns is None else (h.overload_ns - lift_start_ns) * 1e-9
    lost_s = math.nan if h.lost_ns is None else (h.lost_ns - lift_start_ns) * 1e-9
    note = ''
    if h.overload_ns is not None:
        note = (f"overload said {overload_s:.3f} s after the lift's start: "
                f'{h.overload_need_n:.2f} N needed, {h.overload_limit_n:.2f} N '
                f'at {config.plant.voltage_limit_v:g} V')
    return GripRun('OBJECT_LOST' if h.lost_ns is not None else 'HOLDING', note, ratio,
                   float(h.slip_m), lost_s, overload_s,
                   float(margin.mean()) if margin.size else math.nan,
                   float(margin.max()) if margin.size else math.nan,
                   float(margin.min()) if margin.size else math.nan, rows)


def _margins(rows: np.ndarray, static_friction: float, lifted_off_ns: int) -> np.ndarray:
    """Grip over the slip limit m (g + a) / (2 mu_s) of each row (ROW_FIELDS) while lifted.

    Counted from ``lifted_off_ns``, once the pads carry the whole weight (after the lift-off).
    """
    lifted = (rows[:, 3] > 0.0) & ((rows[:, 9] == HoldState.STUCK) |
                                   (rows[:, 9] == HoldState.SLIDING)) & \
        (rows[:, 0] >= lifted_off_ns)
    limit = rows[lifted, 3] / (2.0 * static_friction)
    return rows[lifted, 1] / limit if limit.size else np.zeros(0)


def simulate_load_grip(config: GripperConfig, width_m: float, mass_kg: float,
                       static_friction: float, kinetic_friction: float, lift: Lift | None,
                       law: GripLaw | str = GripLaw.LOAD_TRACKING,
                       declared_mass_kg: float | None = None,
                       stiffness_n_per_m: float = 0.0, damping_n_s_per_m: float = 0.0,
                       params: LoadGripParams | None = None, after_s: float = 0.5,
                       decimate: int = 10, seed: int = 1) -> GripRun:
    """Grasp an object of ``mass_kg`` and pad friction ``mu_s, mu_k`` and hold it through ``lift``.

    ``load_tracking``: the request carries no mass (``mass_kg`` 0): the graph's own path,
    :func:`gripper_ros.core.headless.simulate_grasp`, whose supervisor closes to the touch force
    and then runs the law each tick on the pads' readings (``seed`` seeds the pads' noise).
    ``friction`` / ``paper``: the request declares ``declared_mass_kg`` (default: the true mass)
    and the lift's ``A`` and the configured mu_s, as a user of the fixed laws must; the grip
    stays at that setpoint, held in :func:`gripper_ros.core.load_grip.run_load_grip`.
    """
    law = GripLaw(law)
    if law is GripLaw.LOAD_TRACKING:
        return _graph_path_run(config, width_m, mass_kg, static_friction, kinetic_friction,
                               lift, stiffness_n_per_m, damping_n_s_per_m, params, after_s,
                               decimate, seed)
    params = params or config.load_grip
    sup = config.supervisor
    accel = lift.acceleration_mps2 if lift is not None else 0.0
    declared = mass_kg if declared_mass_kg is None else declared_mass_kg
    law_sup = replace(sup, force_law=ForceLaw(law.value))
    try:
        targets = validate_request(GraspRequest(width_m, declared, 0.0, accel), config.plant,
                                   law_sup)
    except RequestError as exc:
        return GripRun('REFUSED', str(exc), math.nan, math.nan, math.nan, math.nan, math.nan,
                       math.nan, math.nan)
    plant = make_plant(config)
    side = PlantSide(plant)
    side.grasp_mass_kg = mass_kg
    side.set_object(GraspObject(width_m, stiffness_n_per_m, damping_n_s_per_m, mass_kg,
                                static_friction, kinetic_friction))
    supervisor = GraspSupervisor(config.plant, sup)
    loop = _Loop(side, supervisor, PositionStageController(config),
                 ForceStageController(config))
    side.tick()
    loop.decide()
    supervisor.request_grasp(targets, declared, after_ns=int(loop.tick[0]['stamp_ns']))
    loop.state[0]['woken'] = True
    loop.run()
    series = loop.series()
    peak = float(np.nanmax(series[3])) if series[3].size else math.nan
    ratio = peak / targets.force_setpoint_n
    if supervisor.outcome is not Outcome.HOLDING:
        return GripRun(supervisor.outcome.name, supervisor.message, ratio, 0.0, math.nan,
                       math.nan, math.nan, math.nan, math.nan)
    start_ns = int(loop.tick[0]['stamp_ns'])
    end_ns = start_ns + round(((lift.delay_s + lift.duration_s) if lift else 0.0) * 1e9) + \
        round(after_s * 1e9)
    lift_start_ns = start_ns
    if lift is not None:
        if _schedule_lift(plant.kernel, lift.acceleration_mps2, lift.delay_s, lift.duration_s,
                          int(lift.profile), lift.frequency_hz):
            raise RuntimeError('the lift could not be scheduled: the hold has not begun')
        lift_start_ns = int(plant.kernel[K_HOLD][0]['lift_start_ns'])
    dt_s = config.force.sample_time_s
    pads = config.pad_sensor
    g, history, sums = make_law(params, config.plant.max_force_n,
                                config.contact.pad_tangential_stiffness_n_per_m, dt_s,
                                pads.displacement_noise_m, pads.displacement_resolution_m)
    g[0]['force_setpoint_n'] = targets.force_setpoint_n
    channels = np.zeros(5, CHANNEL_DTYPE)
    buffers = np.zeros((5, MAX_LATENCY_SAMPLES))
    for i, spec in enumerate((pads.shear, pads.shear, pads.displacement, pads.displacement,
                              pads.shear)):
        rec, _ = make_channel(spec, dt_s, seed * 5 + i)
        channels[i] = rec[0]
    rows = np.zeros(((end_ns - start_ns) // round(dt_s * 1e9) // decimate + 2, len(ROW_FIELDS)))
    kept = run_load_grip(plant.kernel, loop.stages[Controller.FORCE].stage.kernel, loop.ref,
                         loop.cmd, loop.tick, g, history, sums, MU_GRID, channels, buffers,
                         end_ns, decimate, rows, True)
    rows = rows[:kept]
    state = plant.object_state
    lost_s = math.nan if state.lost_ns is None else (state.lost_ns - lift_start_ns) * 1e-9
    over = int(g[0]['overload_ns'])
    overload_s = math.nan if over == -1 else (over - lift_start_ns) * 1e-9
    margin = _margins(rows, static_friction,
                      lift_start_ns + round(config.contact.lift_off_s * 1e9))
    outcome = 'OBJECT_LOST' if state.lost_ns is not None else 'HOLDING'
    note = ''
    if over != -1:
        note = (f"overload said {overload_s:.3f} s after the lift's start: "
                f'{g[0]["overload_need_n"]:.2f} N needed, {config.plant.max_force_n:.2f} N '
                f'at {config.plant.voltage_limit_v:g} V')
    return GripRun(outcome, note, ratio, float(np.max(rows[:, 5])) if kept else 0.0, lost_s,
                   overload_s, float(margin.mean()) if margin.size else math.nan,
                   float(margin.max()) if margin.size else math.nan,
                   float(margin.min()) if margin.size else math.nan, rows)
