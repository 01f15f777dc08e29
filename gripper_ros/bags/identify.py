"""bag_identify: fit the plant (Table I) to recorded bags and write a config with the result.

    bag_identify BAG... [--output identified.yaml] [--json] [--plot fit.png] [--config FILE]
                 [--compare FILE]

Every bag's ticks give the voltage applied and the measured position, motor speed, current and
force; the fit (:mod:`gripper_ros.identify.fit`) reports the identifiable combinations with
standard errors, the held-out NRMSE per channel, and which keys are fixed or cannot be told
apart. ``--output`` writes ``--config`` (default: the installed one) with the identified plant
keys: a file ``grasp_demo --config``, ``contact_sweep --config`` and ``bag_replay --resimulate
--closed-loop --config`` read. A bag that cannot be identified is refused in one line, exit 2.
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, fields
import json
import math
from pathlib import Path
import sys
from typing import Sequence

from gripper_ros.bags.reader import quiet_on_closed_pipe
from gripper_ros.text import one_line
import numpy as np

OBJECT_KEYS = ('width_m', 'stiffness_n_per_m', 'damping_n_s_per_m')
SCENARIO_KEYS = ('fault', 'lift_acceleration_mps2')
"""Object fields of a bag the fit does not model (a fault, a lift): such a bag is refused."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='bag_identify', description=__doc__.splitlines()[0])
    p.add_argument('bags', nargs='+', metavar='BAG', help='bag folders (or .mcap files)')
    p.add_argument('--output', default=None, metavar='FILE',
                   help='write the configuration with the identified plant keys here')
    p.add_argument('--json', action='store_true', help='print the result as one JSON object')
    p.add_argument('--plot', default=None, metavar='PNG', help='draw recorded vs simulated')
    p.add_argument('--compare', default=None, metavar='FILE',
                   help="print each combination of this configuration's plant beside the "
                        'identified one, with the relative difference')
    p.add_argument('--config', default='',
                   help='configuration giving the fixed keys and the starting point '
                        '(default: installed)')
    return p


def load_run(path: str):
    """Read one bag as a :class:`Run`; BagError or IdentifyError (one line) if it cannot be."""
    from gripper_ros.bags.reader import MissingTopicsError, open_bag
    from gripper_ros.bags.series import load_grasp_series
    from gripper_ros.identify.fit import IdentifyError, Run
    bag = open_bag(path)
    try:
        series = load_grasp_series(bag)
    except MissingTopicsError as exc:
        raise IdentifyError(f'{bag.path}: not a gripper_ros bag ({exc})') from None
    ticks = series.ticks
    if series.bag_format != 2 or not ticks.size:
        raise IdentifyError(f'{bag.path}: no loop ticks with the motor voltage (a bag of the '
                            f'older format or an empty one)')
    stamps = np.asarray(ticks['stamp_ns'], dtype=np.int64)
    order = np.argsort(stamps, kind='stable')
    keep = order[np.concatenate(([True], np.diff(stamps[order]) > 0))]   # a repeated tick once
    obj = series.custom_data.get('object') if isinstance(series.custom_data.get('object'),
                                                         dict) else {}
    for key in SCENARIO_KEYS:
        if obj.get(key):
            raise IdentifyError(f'{bag.path}: the recorded object has a {key} scenario, which '
                                f'the fit does not model')
    values = {k: float(obj.get(k, 0.0)) for k in OBJECT_KEYS}
    measured = {c: np.asarray(ticks[c], dtype=float)[keep]
                for c in ('position_m', 'speed_rad_s', 'current_a', 'force_n')}
    return Run(str(bag.path), stamps[keep], np.asarray(ticks['motor_voltage_v'],
                                                       dtype=float)[keep], measured,
               values['width_m'], values['stiffness_n_per_m'], values['damping_n_s_per_m'])


def _fail(message: str) -> int:
    print('bag_identify: ' + one_line(message), file=sys.stderr)
    return 2


def result_dict(result) -> dict:
    """Return the JSON object: every plant key, the combinations and their errors, the rest."""
    from gripper_ros.identify.fit import (COMBINATIONS, FIXED_PLANT_KEYS, NOT_SEPARABLE)
    plant = {f.name: float(getattr(result.plant, f.name)) for f in fields(result.plant)}
    return {
        'plant': plant,
        'combinations': {name: {'value': result.combinations[name],
                                'stderr': _finite(result.stderr[name]),
                                'unit': COMBINATIONS[name][0]}
                         for name in COMBINATIONS},
        'fitted_parameters': result.fitted,
        'not_excited': result.not_excited,
        'fixed_keys': list(FIXED_PLANT_KEYS),
        'not_separable': NOT_SEPARABLE,
        'warnings': result.warnings,
        'nrmse_held_out': {run: {c: _finite(v) for c, v in table.items()}
                           for run, table in result.nrmse.items()},
        'seed': {k: _finite(v) for k, v in asdict(result.seed).items()},
        'base_config': result.base.source,
    }


def _finite(value):
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


NEGLIGIBLE_REL = 1e-6
"""A std error or NRMSE below this share of its value is shown as a bound, not digits: there
the fit is exact to its floating-point round-off, whose digits change with the CPU's linear
algebra kernels."""


def _relative_text(value: float, scale: float, spec: str) -> str:
    """``value`` formatted by ``spec``, or the bound when below NEGLIGIBLE_REL of ``scale``."""
    if abs(value) < NEGLIGIBLE_REL * abs(scale):
        return f'< {NEGLIGIBLE_REL:.0e}' + (' rel' if scale != 1.0 else '')
    return format(value, spec)


def print_report(result, out=sys.stdout, compare=None) -> None:
    """Print the combinations (beside those of ``compare``, a config), the keys, the checks."""
    from gripper_ros.identify.fit import (COMBINATIONS, combinations, FIXED_PLANT_KEYS,
                                          NOT_SEPARABLE)
    other = combinations(compare.plant) if compare is not None else {}
    extra = f' {"compared":>13s} {"difference":>10s}' if other else ''
    print(f'{"combination":30s} {"value":>13s} {"std error":>11s}{extra}  unit', file=out)
    for name, (unit, _) in COMBINATIONS.items():
        err = result.stderr[name]
        value = result.combinations[name]
        err_text = f'{_relative_text(err, value, ".3g"):>11s}' if math.isfinite(err) else \
            f'{"not excited":>11s}'
        difference = round(100.0 * (value / other[name] - 1.0), 4) + 0.0 if other else 0.0
        extra = f' {other[name]:13.6g} {difference:+9.4f}%' if other else ''   # no -0.0000
        print(f'{name:30s} {value:13.6g} {err_text}{extra}  {unit}', file=out)
    if other:
        print(f'compared: {compare.source}', file=out)
    print(f'fitted: {", ".join(result.fitted)}', file=out)
    print(f'fixed: {", ".join(FIXED_PLANT_KEYS)}', file=out)
    print(f'not separable: {NOT_SEPARABLE}', file=out)
    for warning in result.warnings:
        print(f'warning: {warning}', file=out)
    print("held-out NRMSE (RMS error over the last 30 % of each bag / the bag's range):",
          file=out)
    for run, table in result.nrmse.items():
        cells = ', '.join(f'{c} {_relative_text(v, 1.0, ".2e")}' if math.isfinite(v) else f'{c} -'
                          for c, v in table.items())
        print(f'  {run}: {cells}', file=out)


def plot_fit(result, runs, path: Path) -> None:
    """Draw recorded against simulated, per channel and bag; the held-out part shaded."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from gripper_ros.identify.fit import CHANNELS
    units = {'position_m': 'position (m)', 'speed_rad_s': 'motor speed (rad/s)',
             'current_a': 'current (A)', 'force_n': 'force (N)'}
    fig, axes = plt.subplots(len(CHANNELS), len(runs), figsize=(7 * len(runs), 9),
                             squeeze=False, sharex='col')
    for col, run in enumerate(runs):
        t = (run.t_ns - run.t_ns[0]) * 1e-9
        sim = result.simulated[run.name]
        for row, c in enumerate(CHANNELS):
            ax = axes[row, col]
            ax.plot(t, run.measured[c], 'k', lw=0.8, label='recorded')
            ax.plot(t, sim[:, row], 'r--', lw=0.8, label='simulated (identified)')
            ax.axvspan(t[run.fit_end], t[-1], color='0.9', zorder=0)
            ax.set_ylabel(units[c])
            if row == 0:
                ax.set_title(Path(run.name).name, fontsize=8)
                ax.legend(fontsize=7, loc='upper right')
        axes[-1, col].set_xlabel('time (s); shaded: held out of the fit')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_config(result, path: Path, bags: list[str]) -> None:
    """Write the configuration with the identified plant; a note for what reads otherwise."""
    import yaml
    from gripper_ros.core.config import read_as_notes
    header = ('# Identified by bag_identify from ' + ', '.join(bags) + '\n'
              f'# on the base configuration {result.base.source}; the plant keys '
              'resistance_ohm, back_emf_v_s_per_rad, inductance_h, inertia_kg_m2,\n'
              "# damping_n_m_s_per_rad and efficiency are the fit's (k_t as configured: only "
              'k_t/J, b/J and k_t/lever are identifiable).\n')
    header += ''.join(f'# note: {note}\n' for note in read_as_notes(result.config()))
    path.write_text(header + yaml.safe_dump(result.config_data(), sort_keys=False),
                    encoding='utf-8')


@quiet_on_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from gripper_ros.bags.reader import BagError
    from gripper_ros.bags.resimulate import load_resim_config
    from gripper_ros.core.config import ConfigError
    from gripper_ros.identify.fit import identify, IdentifyError
    try:
        config = load_resim_config(args.config or None)
        compare = load_resim_config(args.compare) if args.compare else None
        runs = [load_run(b) for b in args.bags]
        result = identify(runs, config)
        result.config()                     # the reader must accept what is written
    except (BagError, IdentifyError, ConfigError) as exc:
        return _fail(exc)
    try:
        if args.output:
            write_config(result, Path(args.output), args.bags)
        if args.plot:
            plot_fit(result, runs, Path(args.plot))
    except OSError as exc:
        return _fail(f'cannot write: {exc}')
    if args.json:
        print(json.dumps(result_dict(result), indent=1))
    else:
        print_report(result, compare=compare)
        if args.output:
            print(f'wrote {args.output}')
    if args.plot:
        print(f'figure: {args.plot}', file=sys.stderr if args.json else sys.stdout)
    return 0
