"""lift_table: the Table V objects grasped, then lifted, under both force laws.

    ros2 run gripper_ros lift_table                     # docs/GRIP.md's table (markdown)
    ros2 run gripper_ros lift_table --accelerations 0,2,5,10

The grasps, the lift and what each column means: :mod:`gripper_ros.studies.lift_runs`.
"""
from __future__ import annotations

import argparse
import math
import sys

from gripper_ros.apps.common import negative_option
from gripper_ros.core.config import ConfigError, load_config
from gripper_ros.studies.lift_runs import LIFT_DELAY_S, LIFT_DURATION_S, lift_rows


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
