"""lift_table: the Table V objects grasped, then lifted, under both force laws.

    ros2 run gripper_ros lift_table                     # docs/GRIP.md's table (markdown)
    ros2 run gripper_ros lift_table --accelerations 0,2,5,10

Each object is grasped with the request's a = A, held, and lifted ``--lift-delay`` s after
HOLDING at A m/s^2 upward for ``--lift-duration`` s (A = 0: lifted off its support at constant
speed, so only its weight loads the grip). The grasps run in the headless lockstep loop
(:mod:`gripper_ros.core.runtime.headless`), the graph's own code tick for tick, in fast time.
Slip and loss are the simulator's ground truth; "detected" is when the supervisor, from its
own sensors, turned the outcome to OBJECT_LOST.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys

from gripper_ros.apps.common import negative_option
from gripper_ros.apps.grasp_demo import LIFT_DELAY_S, LIFT_DURATION_S, PAPER_OBJECTS
from gripper_ros.core.config import ConfigError, ForceLaw, load_config
from gripper_ros.core.physics.plant import Lift
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.core.supervision.requests import RequestError

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


def _cell(value: float, fmt: str) -> str:
    return '-' if value != value else format(value, fmt)


def markdown(rows: list[dict], delay_s: float, duration_s: float) -> str:
    lines = ['| object (width, mass) | a m/s² | law | F_sp N | outcome | slip mm | lost s | '
             'detected s |', '|---|---:|---|---:|---|---:|---:|---:|']
    for r in rows:
        obj = f'{r["width_m"] * 1e3:g} mm, {r["mass_kg"]:g} kg'
        if r['outcome'] == 'REFUSED':
            lines.append(f'| {obj} | {r["a"]:g} | {r["law"]} | - | REFUSED: {r["note"]} | '
                         f'- | - | - |')
            continue
        lines.append(f'| {obj} | {r["a"]:g} | {r["law"]} | {r["force_setpoint_n"]:.2f} | '
                     f'{r["outcome"]} | {_cell(r["slip_m"] * 1e3, ".2f")} | '
                     f'{_cell(r["lost_s"], ".3f")} | {_cell(r["detected_s"], ".3f")} |')
    lines.append('')
    lines.append(f'Lift {delay_s:g} s after HOLDING, for {duration_s:g} s; lost and detected: '
                 "seconds after HOLDING (ground truth, and the supervisor's OBJECT_LOST).")
    return '\n'.join(lines)


def _accelerations(text: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(',')]
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a list of numbers: {text!r}') from None
    for v in values:
        if not (math.isfinite(v) and v >= 0.0):
            raise argparse.ArgumentTypeError(f'accelerations must be finite and >= 0, got {v!r}')
    return values


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='lift_table', description=__doc__.splitlines()[0])
    p.add_argument('--accelerations', type=_accelerations, default=[0.0, 2.0, 5.0],
                   help='comma-separated lift accelerations, m/s^2 (default 0,2,5)')
    p.add_argument('--lift-delay', type=float, default=LIFT_DELAY_S)
    p.add_argument('--lift-duration', type=float, default=LIFT_DURATION_S)
    p.add_argument('--config', default='', help='YAML parameter file (default: installed)')
    args = p.parse_args(argv)
    negative = negative_option(args, ('lift_delay', 'lift_duration'))
    if negative:
        print(f'lift_table: {negative}', file=sys.stderr)
        return 2
    try:
        config = load_config(args.config or None)
        rows = lift_rows(config, args.accelerations, args.lift_delay, args.lift_duration)
    except (ConfigError, ValueError) as exc:
        print(f'lift_table: {exc}', file=sys.stderr)
        return 2
    print(markdown(rows, args.lift_delay, args.lift_duration))
    return 0


if __name__ == '__main__':
    sys.exit(main())
