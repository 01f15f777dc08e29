"""Console script: the physical floor of the position step under the +-24 V command limit.

    ros2 run gripper_ros position_limit [--config FILE] [--setpoint M] [--json]

The figures are computed by :mod:`gripper_ros.studies.position_floor`, which says how.
"""
from __future__ import annotations

import argparse
from dataclasses import asdict
import json
import math
import sys

from gripper_ros.apps.common import load_config_or_report
from gripper_ros.studies.paper import PAPER_TABLE_III
from gripper_ros.studies.position_floor import (DEFAULT_HORIZON_S, DEFAULT_SETPOINT_M,
                                                minimum_time_floor, rms_floor)
import numpy as np


def _jsonable(obj) -> dict:
    out = {}
    for key, value in asdict(obj).items():
        if isinstance(value, np.ndarray):
            continue
        out[key] = None if isinstance(value, float) and math.isinf(value) else value
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='position_limit', description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML file (default: the installed config/gripper.yaml)')
    parser.add_argument('--setpoint', type=float, default=DEFAULT_SETPOINT_M,
                        help='step from fully open, m (default %(default)g)')
    parser.add_argument('--horizon', type=float, default=DEFAULT_HORIZON_S,
                        help='RMS horizon, s (default %(default)g)')
    parser.add_argument('--json', action='store_true', help='print the figures as JSON')
    args = parser.parse_args(argv)
    config = load_config_or_report('position_limit', args.config)
    if config is None:
        return 2
    if not 0.0 < args.setpoint < config.plant.max_travel_m:
        print(f'position_limit: setpoint must be in (0, {config.plant.max_travel_m:g}) m',
              file=sys.stderr)
        return 2
    dt = config.position.sample_time_s
    mt = minimum_time_floor(config, args.setpoint, dt)
    rf = rms_floor(config, args.setpoint, dt, args.horizon)
    if args.json:
        print(json.dumps({'minimum_time': _jsonable(mt), 'rms': _jsonable(rf)}, indent=2))
        return 0
    lim = config.plant.voltage_limit_v
    print(f'Physical floor of the position step: {args.setpoint:g} m from fully open (at rest), '
          f'exact ZOH model of Table I (electrical pole included), t_s = {dt:g} s, '
          f'|u| <= {lim:g} V held per sample, any input sequence.')
    print(f'  minimum time to the {mt.band_fraction * 100:g} % band (and staying): '
          f'{mt.band_settling_time_s:.2f} s  (+{lim:g} V until {mt.band_switch_time_s:.2f} s, '
          f'then -{lim:g} V)')
    print(f'  minimum time to the setpoint at rest:            {mt.rest_time_s:.2f} s  '
          f'(+{lim:g} V until {mt.rest_switch_time_s:.2f} s, then -{lim:g} V)')
    samples = int(round(rf.horizon_s / dt))
    print(f'  minimum RMS error over {rf.horizon_s:g} s (samples 0..{samples}): '
          f'{rf.rms_lower_m:.5f} m  (achieved: {rf.rms_upper_m:.5f} m)')
    import dataclasses

    import numpy as np

    from gripper_ros.core.control.factories import make_position_controller
    from gripper_ros.wire import PositionControllerKind
    from gripper_ros.studies.step_runs import position_step
    braking_v = config.position.mpc_pd_braking_voltage_v or 20.0
    governed = dataclasses.replace(config, position=dataclasses.replace(
        config.position, mpc_pd_braking_voltage_v=braking_v))
    clamp_only = dataclasses.replace(config, position=dataclasses.replace(
        config.position, mpc_pd_braking_voltage_v=0.0))
    for label, cfg in ((f'ours, MPC-PD + braking governor at {braking_v:g} V', governed),
                       ('ours, MPC-PD clamp only (governor off)', clamp_only)):
        run = position_step(cfg, make_position_controller(cfg, PositionControllerKind.MPC_PD),
                            args.setpoint, args.horizon)
        m = run.metrics()
        u = run.command_v
        flips = int(np.sum((np.diff(np.sign(u)) != 0) & (np.abs(u[1:]) > 1.0)))
        print(f'  {label}: RMS {m.rms_error:.5f} m, {m.overshoot_pct:.3f} % overshoot, '
              f'{m.settling_time_s:.2f} s settling, max |V| {run.max_abs_command_v:.2f} V, '
              f'{flips} command sign changes beyond 1 V')
    paper = PAPER_TABLE_III['MPC-PD']
    print(f'  paper Table III MPC-PD (0.1 m): RMS {paper.rms_error:.4f} m, '
          f'{paper.overshoot_pct:.2f} % overshoot, {paper.settling_time_s:.2f} s settling '
          '(its RMS is below the floor)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
