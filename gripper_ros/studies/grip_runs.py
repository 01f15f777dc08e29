"""One grasp and hold of the grip study: a grip law through an arm's motion (no rclpy).

Every law runs the graph's own path, :func:`gripper_ros.core.runtime.headless.simulate_grasp` (the
supervisor, its stages and the plant, as ``time_mode`` fast runs them). Apart from
:mod:`gripper_ros.core.control.load_grip` (the law) because it drives the whole loop, which the
supervisor's own use of the law must not import back.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import enum
import math

from gripper_ros.core.config import ForceLaw, GripperConfig, LoadGripParams
from gripper_ros.core.control.load_grip import ROW_FIELDS
from gripper_ros.core.physics.hold import HoldState, Lift
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.core.supervision.requests import RequestError
from gripper_ros.wire import Outcome
import numpy as np


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
    landed_force_n: float = math.nan   # the grip on the first tick the pads carry a load


def _graph_path_run(config: GripperConfig, width_m: float, mass_kg: float,
                    static_friction: float, kinetic_friction: float, lift: Lift | None,
                    stiffness_n_per_m: float, damping_n_s_per_m: float,
                    params: LoadGripParams | None, after_s: float, decimate: int,
                    seed: int, declared_mass_kg: float = 0.0, announce: bool = False) -> GripRun:
    """Run a grasp and its hold as the graph does; the study's figures of it.

    ``declared_mass_kg`` is the request's (0: unknown, the load-tracking grip), which carries
    the lift's acceleration for a fixed law; ``announce``: the arm announces the lift.
    """
    config = replace(config, load_grip=params or config.load_grip,
                     sensor_noise=replace(config.sensor_noise, seed=seed))
    hold_s = ((lift.delay_s + lift.duration_s) if lift is not None else 0.0) + after_s
    try:
        accel = lift.acceleration_mps2 if lift is not None and declared_mass_kg else 0.0
        h = simulate_grasp(config, width_m, declared_mass_kg, acceleration_mps2=accel,
                           stiffness_n_per_m=stiffness_n_per_m,
                           damping_n_s_per_m=damping_n_s_per_m, object_mass_kg=mass_kg,
                           static_friction=static_friction, kinetic_friction=kinetic_friction,
                           lift=lift, hold_s=hold_s, announce=announce)
    except RequestError as exc:
        return GripRun('REFUSED', str(exc), math.nan, math.nan, math.nan, math.nan,
                       math.nan, math.nan, math.nan)
    ticks, states = h.series.ticks, h.series.tick_states
    t_ns = ticks['stamp_ns']
    grasp = t_ns <= (h.answer_ns if h.answer_ns is not None else h.end_ns)
    ratio = float(np.nanmax(ticks['peak_force_n'][grasp])) / h.force_setpoint_n
    if h.answer is not Outcome.HOLDING:
        return GripRun(h.answer.name, h.message, ratio, 0.0, math.nan, math.nan, math.nan,
                       math.nan, math.nan)
    lift_start_ns = h.answer_ns + (round(lift.delay_s * 1e9) if lift is not None else 0)
    end_ns = h.answer_ns + round(hold_s * 1e9)
    hold = np.flatnonzero((t_ns >= h.answer_ns) & (t_ns <= end_ns))
    lost = np.flatnonzero(states['hold_state'][hold] == HoldState.LOST)
    if lost.size:                                   # the hold ends with the object
        hold = hold[:lost[0] + 1]
    rows = np.column_stack([
        t_ns, ticks['force_n'], states['force_setpoint_n'], states['load_n'],
        2.0 * static_friction * np.maximum(ticks['force_n'], 0.0), states['slip_m'],
        0.5 * (ticks['pad1_shear_n'] + ticks['pad2_shear_n']),
        0.5 * (ticks['pad1_displacement_m'] + ticks['pad2_displacement_m']), states['mu_est'],
        states['hold_state']]).astype(float)[hold]
    lift_off_s = lift.lift_off_or(config.contact.lift_off_s) if lift is not None else 0.0
    margin = _margins(rows, static_friction, lift_start_ns + round(lift_off_s * 1e9))
    carried = np.flatnonzero(rows[:, 3] > 0.0)
    landed_force_n = float(rows[carried[0], 1]) if carried.size else math.nan
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
                   float(margin.min()) if margin.size else math.nan, rows, landed_force_n)


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
                       decimate: int = 10, seed: int = 1, announce: bool = False) -> GripRun:
    """Grasp an object of ``mass_kg`` and pad friction ``mu_s, mu_k`` and hold it through ``lift``.

    ``load_tracking``: the request carries no mass (``mass_kg`` 0): the graph's own path,
    :func:`gripper_ros.core.runtime.headless.simulate_grasp`, whose supervisor closes to the touch
    force and then runs the law each tick on the pads' readings (``seed`` seeds the pads' noise).
    ``friction`` / ``paper``: the request declares ``declared_mass_kg`` (default: the true mass)
    and the lift's ``A`` and the configured mu_s, as a user of the fixed laws must; the grip
    stays at that setpoint. Both through the same path. ``announce``: the arm announces its
    motion ahead (the supervisor's grip anticipates it); otherwise it moves without notice.
    """
    law = GripLaw(law)
    if law is not GripLaw.LOAD_TRACKING:
        config = replace(config, supervisor=replace(config.supervisor,
                                                    force_law=ForceLaw(law.value)))
    declared = 0.0 if law is GripLaw.LOAD_TRACKING else (
        mass_kg if declared_mass_kg is None else declared_mass_kg)
    return _graph_path_run(config, width_m, mass_kg, static_friction, kinetic_friction, lift,
                           stiffness_n_per_m, damping_n_s_per_m, params, after_s, decimate,
                           seed, declared, announce)
