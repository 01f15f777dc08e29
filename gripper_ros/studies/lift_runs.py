"""Table V's objects grasped, held, then lifted by the arm, under both force laws.

Each object is grasped with the request's a = A, held, and lifted ``delay_s`` after HOLDING
at A m/s^2 upward for ``duration_s`` (A = 0: lifted off its support at constant speed, so
only its weight loads the grip), in the headless lockstep loop
(:mod:`gripper_ros.core.runtime.headless`), the graph's own code tick for tick, in fast time.
Slip and loss are the simulator's ground truth; "detected" is when the supervisor, from its
own sensors, turned the outcome to OBJECT_LOST.
"""
from __future__ import annotations

import dataclasses
import math

from gripper_ros.core.config import ForceLaw
from gripper_ros.core.physics.plant import Lift
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.core.supervision.requests import RequestError
from gripper_ros.studies.paper import PAPER_OBJECTS

LIFT_DELAY_S = 0.2
"""Seconds from HOLDING to the start of the lift (``grasp_demo --lift``'s too)."""
LIFT_DURATION_S = 1.0
"""Seconds the arm accelerates upward."""
HOLD_AFTER_LIFT_S = 0.5
"""Simulated time kept after the lift ends, so that a late loss is seen."""


def lift_rows(config, accelerations, delay_s: float, duration_s: float) -> list[dict]:
    """One row per (object, acceleration, law)."""
    rows = []
    for width_m, mass_kg in PAPER_OBJECTS:
        for accel in accelerations:
            for law in ForceLaw:
                cfg = dataclasses.replace(config, supervisor=dataclasses.replace(
                    config.supervisor, force_law=law))
                row = {'width_m': width_m, 'mass_kg': mass_kg, 'a': accel, 'law': law.value}
                try:
                    g = simulate_grasp(cfg, width_m, mass_kg, acceleration_mps2=accel,
                                       lift=Lift(accel, delay_s, duration_s),
                                       hold_s=delay_s + duration_s + HOLD_AFTER_LIFT_S)
                except RequestError as exc:
                    rows.append({**row, 'outcome': 'REFUSED', 'note': str(exc)})
                    continue
                held = g.answer_ns
                rows.append({**row, 'force_setpoint_n': g.force_setpoint_n,
                             'outcome': g.outcome.name, 'slip_m': g.slip_m,
                             'lost_s': (g.lost_ns - held) * 1e-9
                             if g.lost_ns is not None and held is not None else math.nan,
                             'detected_s': (g.final_ns - held) * 1e-9
                             if g.outcome.name == 'OBJECT_LOST' and held is not None
                             else math.nan, 'note': ''})
    return rows
