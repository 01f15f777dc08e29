"""contact_sweep: peak contact force, losses and time to a steady hold over the object envelope.

    ros2 run gripper_ros contact_sweep [--quick | --compliant | --fingers]
                                      [--exact-only | --band-only]
                                      [--band-design-stiffness N_PER_M] [--hold-s S]
                                      [--jobs N | --scheduler tcp://HOST:8786] [--quiet]
                                      [--force-controller contact_aware|pi|mpc_pi]
                                      [--plot FILE.png] [--json] [--config FILE]

The envelope, its grids, the grasps and each figure of a row:
:mod:`gripper_ros.studies.sweep_runs`.
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import asdict
import json
import math
import sys
import time

from gripper_ros.apps.common import load_config_or_report
from gripper_ros.core.runtime.engine import add_engine_arguments, options_problem, worker_count
from gripper_ros.studies.sweep_runs import (band_speed_mps, compliant_cases, DEFAULT_HOLD_S,
                                            envelope_cases, finger_cases, finger_kinds,
                                            quick_cases, sweep, SweepRow)


def summary(config, rows: list[SweepRow], excluded: int, hold_s: float,
            elapsed_s: float | None = None, jobs: int | str = 1) -> str:
    """Return the verdict: worst peak, losses, the continued hold, time to hold vs floor."""
    sup = config.supervisor
    band = sup.force_settle_band_fraction
    exact = [r for r in rows if r.width_tolerance_m == 0.0]
    banded = [r for r in rows if r.width_tolerance_m > 0.0]
    lines = [f'contact_sweep: {len(rows)} grasps ({len(exact)} at the exact width, '
             f'{len(banded)} within a tolerance)'
             + (f' in {elapsed_s:.0f} s wall on ' + (f'{jobs} process(es)' if isinstance(
                 jobs, int) else f'the cluster at {jobs}') if elapsed_s else '')
             + f'; {excluded} objects left out: squashed flat before F_sp (F_sp / k >= width)']
    if not rows:
        return '\n'.join(lines)
    for part, sel in (('at the exact width', exact), ('within a tolerance', banded)):
        if sel:
            worst = max(sel, key=lambda r: r.peak_ratio)
            lines.append(f'worst peak {part}: {worst.peak_ratio:.4f} x F_sp '
                         f'({_describe(worst)}); limit 1.10')
    chain = {name: (finger_n_per_m, pad_n_per_m1_5)
             for name, finger_n_per_m, pad_n_per_m1_5 in finger_kinds()}
    for finger in sorted({r.finger for r in rows if r.finger}):
        sel = [r for r in rows if r.finger == finger]
        worst = max(sel, key=lambda r: r.peak_ratio)
        lost = sum(r.outcome == 'OBJECT_LOST' for r in sel)
        finger_n_per_m, pad_n_per_m1_5 = chain.get(finger, (math.nan, math.nan))
        lines.append(f'  {finger} (k_f {finger_n_per_m:.3g} N/m, k_p {pad_n_per_m1_5:.3g} '
                     f'N/m^1.5): {len(sel)} grasps, worst peak {worst.peak_ratio:.4f} x F_sp '
                     f'({_describe(worst)}), {lost} lost')
    counts = {}
    for r in rows:
        counts[r.outcome] = counts.get(r.outcome, 0) + 1
    lines.append('outcomes: ' + ', '.join(f'{k} {v}' for k, v in sorted(counts.items())))
    lost = [r for r in rows if r.outcome == 'OBJECT_LOST']
    lines.append(f'objects lost: {len(lost)}'
                 + ''.join(f'\n  {_describe(r)}' for r in lost))
    held = [r for r in rows if r.outcome == 'HOLDING']
    if held and hold_s > 0.0:
        dev = max(max(abs(r.hold_min_ratio - 1.0), abs(r.hold_max_ratio - 1.0)) for r in held)
        out = [r for r in held if max(abs(r.hold_min_ratio - 1.0),
                                      abs(r.hold_max_ratio - 1.0)) > band]
        drift = max(r.hold_drift_m for r in held)
        lines.append(f'continued hold of {hold_s:g} s after HOLDING: {len(held) - len(out)} of '
                     f'{len(held)} stay within the {band * 100:g} % band (worst deviation '
                     f'{dev * 100:.3f} %), the finger moves on at most {drift * 1e3:.3f} mm '
                     f'(loss watch: {sup.no_object_margin_m * 1e3:g} mm)')
        for r in out:
            lines.append(f'  out of band: {_describe(r)}')
    not_held = [r for r in exact if r.outcome != 'HOLDING']
    for r in not_held:
        lines.append(f'  not held at the exact width: {r.outcome}: {_describe(r)}')
    lines.append('time to hold at the exact width, minus the floors (s), per contact:')
    lines.append(f'  {"contact":>7s} {"zeta":>5s} {"n":>3s} {"held":>4s} '
                 f'{"- rest: median":>14s} {"max":>6s} {"- reach: min":>12s} {"max hold s":>10s}')
    for key in sorted({(r.finger, r.stiffness_n_per_m, r.damping_ratio) for r in exact}):
        sel = [r for r in exact if (r.finger, r.stiffness_n_per_m, r.damping_ratio) == key]
        ok = [r for r in sel if math.isfinite(r.time_to_hold_s)]
        over_rest = sorted(r.time_to_hold_s - r.approach_floor_s for r in ok)
        over_reach = [r.time_to_hold_s - r.arrival_floor_s for r in ok]
        name = f'{key[0]} {sel[0].contact}' if key[0] else sel[0].contact
        if ok:
            lines.append(f'  {name:>7s} {key[2]:5.2f} {len(sel):3d} {len(ok):4d} '
                         f'{_figure(over_rest[len(over_rest) // 2], 14)} '
                         f'{_figure(over_rest[-1], 6)} '
                         f'{min(over_reach):12.2f} {max(r.time_to_hold_s for r in ok):10.2f}')
        else:
            lines.append(f'  {name:>7s} {key[2]:5.2f} {len(sel):3d}    0')
    if banded:
        per_n = band_speed_mps(config, 1.0)
        lines.append('within a tolerance: the band is crossed at the band speed '
                     f'({per_n * 1e6:.3g} um/s per N of F_sp); time to hold minus the rest '
                     'floor at the real face vs the crossing time:')
        for r in banded:
            crossing_s = r.band_offset_m / (per_n * r.force_setpoint_n)
            t = (f'{r.time_to_hold_s - r.approach_floor_s:8.2f}'
                 if math.isfinite(r.time_to_hold_s) else f'{"-":>8s}')
            lines.append(f'  {_describe(r):64s} {r.outcome:>11s} peak {r.peak_ratio:6.4f} '
                         f'{t} s, crossing {crossing_s:9.1f} s')
    return '\n'.join(lines)


def _figure(value: float, width: int) -> str:
    """Return ``value`` to two decimals in ``width`` characters, '-' if not computed (nan)."""
    return f'{"-":>{width}s}' if math.isnan(value) else f'{value:{width}.2f}'


def _describe(r: SweepRow) -> str:
    kind = 'rigid' if r.stiffness_n_per_m == 0.0 else \
        f'k {r.stiffness_n_per_m:.0e} N/m zeta {r.damping_ratio:g}'
    if r.finger:
        kind = f'{r.finger}, {kind}'
    where = f'{r.width_m * 1e3:g} mm'
    if r.width_tolerance_m:
        where += (f' +-{r.width_tolerance_m * 1e3:g} mm, placed {r.object_width_m * 1e3:g} mm')
    return f'{kind}, {where}, {r.mass_kg:g} kg'


def format_rows(rows: list[SweepRow]) -> str:
    fingers = any(r.finger for r in rows)        # a column of the chain kind, if any
    lead = f'{"fingers":>10s} ' if fingers else ''
    lines = [lead + f'{"k N/m":>7s} {"zeta":>5s} {"width":>6s} {"+-mm":>4s} {"placed":>6s} '
             f'{"kg":>5s} {"outcome":>11s} {"F_sp N":>7s} {"peak/F_sp":>9s} '
             f'{"hold min":>8s} {"hold max":>8s} {"hold s":>7s} {"rest s":>7s} {"reach s":>7s}']
    for r in rows:
        k = 'rigid' if r.stiffness_n_per_m == 0.0 else f'{r.stiffness_n_per_m:.0e}'
        lines.append(
            (f'{r.finger:>10s} ' if fingers else '')
            + f'{k:>7s} {r.damping_ratio:5.2f} {r.width_m * 1e3:6.0f} '
            f'{r.width_tolerance_m * 1e3:4.0f} {r.object_width_m * 1e3:6.1f} {r.mass_kg:5.2f} '
            f'{r.outcome:>11s} {r.force_setpoint_n:7.3f} {r.peak_ratio:9.4f} '
            f'{r.hold_min_ratio:8.4f} {r.hold_max_ratio:8.4f} {r.time_to_hold_s:7.2f} '
            f'{r.approach_floor_s:7.2f} {r.arrival_floor_s:7.2f}')
    lines.append('width, placed: requested and real object width (mm); hold min/max: force over '
                 'the continued hold / F_sp; rest s: minimum time to bring the finger to rest at '
                 'the held position (face + F_sp / k) under +-24 V (10 ms samples); reach s: '
                 'minimum time to reach it at any speed (24 V throughout)')
    return '\n'.join(lines)


def plot(config, rows: list[SweepRow], path: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    exact = [r for r in rows if r.width_tolerance_m == 0.0]
    banded = [r for r in rows if r.width_tolerance_m > 0.0]
    fig, axes = plt.subplots(1, 3 if banded else 2, figsize=(16 if banded else 11, 4.5))
    ax1, ax2 = axes[0], axes[1]
    rigid_x = min([r.stiffness_n_per_m for r in rows if r.stiffness_n_per_m > 0.0] + [1e2]) / 10
    zetas = sorted({r.damping_ratio for r in exact if r.stiffness_n_per_m > 0.0})
    markers = dict(zip(zetas, 'o^sDv'))
    for z in zetas:
        sel = [r for r in exact if r.stiffness_n_per_m > 0.0 and r.damping_ratio == z]
        ax1.scatter([r.stiffness_n_per_m for r in sel], [r.peak_ratio for r in sel],
                    marker=markers[z], s=14, label=f'zeta {z:g}')
        held = [r for r in sel if math.isfinite(r.time_to_hold_s)]
        ax2.scatter([r.stiffness_n_per_m for r in held],
                    [r.time_to_hold_s - r.approach_floor_s for r in held], marker=markers[z],
                    s=14, label=f'zeta {z:g}')
    rigid = [r for r in exact if r.stiffness_n_per_m == 0.0]
    ax1.scatter([rigid_x] * len(rigid), [r.peak_ratio for r in rigid], c='k', s=14, label='rigid')
    ax2.scatter([rigid_x] * len(rigid), [r.time_to_hold_s - r.approach_floor_s for r in rigid],
                c='k', s=14, label='rigid')
    ax1.axhline(1.10, color='r', ls='--', label='1.10 x setpoint')
    for ax in (ax1, ax2):
        ax.set_xscale('log')
        ax.set_xlabel('object stiffness (N/m); rigid at the left')
        ax.legend(fontsize=8)
    ax1.set_ylabel('peak contact force / setpoint')
    ax1.set_title('exact width: peak force')
    ax2.set_ylabel('time to hold - rest floor at the held position (s)')
    ax2.set_title('exact width: time to a steady hold')
    if banded:
        ax3 = axes[2]
        per_n = band_speed_mps(config, 1.0)
        floor_s = 0.01                      # at the widest face: no crossing, drawn here
        for tol in sorted({r.width_tolerance_m for r in banded}):
            sel = [r for r in banded if r.width_tolerance_m == tol]
            crossing = [max(r.band_offset_m / (per_n * r.force_setpoint_n), floor_s)
                        for r in sel]
            held = [(x, r) for x, r in zip(crossing, sel) if math.isfinite(r.time_to_hold_s)]
            ax3.scatter([x for x, _ in held],
                        [max(r.time_to_hold_s - r.approach_floor_s, floor_s) for _, r in held],
                        s=14, label=f'+-{tol * 1e3:g} mm, held')
            missed = [x for x, r in zip(crossing, sel) if not math.isfinite(r.time_to_hold_s)]
            ax3.scatter(missed, [config.supervisor.timeout_s] * len(missed), marker='x', s=20,
                        label=f'+-{tol * 1e3:g} mm, TIMEOUT')
        top = max(crossing_s for crossing_s in [r.band_offset_m / (per_n * r.force_setpoint_n)
                                                for r in banded] + [10.0])
        ax3.plot([floor_s, top], [floor_s, top], 'k:', label='crossing time')
        ax3.axhline(config.supervisor.timeout_s, color='r', ls='--', label='timeout')
        ax3.set_xscale('log')
        ax3.set_yscale('log')
        ax3.set_xlabel('distance into the band / band speed (s)')
        ax3.set_ylabel('time to hold - rest floor at the real face (s)')
        ax3.set_title('uncertain width: the band is crossed at v_c')
        ax3.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    from gripper_ros.wire import ForceControllerKind
    parser = argparse.ArgumentParser(prog='contact_sweep', description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML parameter file (default: installed)')
    grid = parser.add_mutually_exclusive_group()
    grid.add_argument('--quick', action='store_true',
                      help='the reduced exact-width grid the tests run (corners of the envelope)')
    grid.add_argument('--fingers', action='store_true',
                      help='flexible fingers and nonlinear pads: a printed finger, a rubber-dome '
                           'pad and both (core/physics/contact_chain.py) on rigid and '
                           'compliant objects, at the exact width and within a tolerance')
    grid.add_argument('--compliant', action='store_true',
                      help='only rigid, stiff (1e5 N/m) and soft (1e3 N/m) objects at the exact '
                           'width')
    part = parser.add_mutually_exclusive_group()
    part.add_argument('--exact-only', action='store_true',
                      help='leave out the uncertain-width grid')
    part.add_argument('--band-only', action='store_true',
                      help='only the uncertain-width grid')
    parser.add_argument('--band-design-stiffness', type=float, metavar='N_PER_M',
                        help='cross tolerance bands at the speed designed for this stiffness '
                             '(default: force_control.contact_aware.band_design_stiffness_n_per_m'
                             '); objects stiffer than it are met harder')
    parser.add_argument('--hold-s', type=float, default=DEFAULT_HOLD_S,
                        help='continued hold after HOLDING, checked against the settle band '
                             '(default %(default)s s)')
    add_engine_arguments(parser)
    parser.add_argument('--quiet', action='store_true',
                        help='no progress bar (it is shown only on a terminal anyway)')
    parser.add_argument('--force-controller', choices=[k.value for k in ForceControllerKind],
                        help="force stage (default: the graph's default, contact_aware); pi or "
                             'mpc_pi show the paper structure on compliant objects')
    parser.add_argument('--plot', help='write the sweep as PNG')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    band_k = args.band_design_stiffness
    if not (math.isfinite(args.hold_s) and args.hold_s >= 0.0) or (
            band_k is not None and not (math.isfinite(band_k) and band_k > 0.0)):
        print('contact_sweep: --hold-s must be finite and >= 0 and '
              '--band-design-stiffness finite and > 0', file=sys.stderr)
        return 2
    if options_problem(args.jobs, args.scheduler):
        print(f'contact_sweep: {options_problem(args.jobs, args.scheduler)}', file=sys.stderr)
        return 2
    args.jobs = worker_count(args.jobs)
    config = load_config_or_report('contact_sweep', args.config)
    if config is None:
        return 2
    if band_k is not None:
        tuning = dataclasses.replace(config.force.contact_aware,
                                     band_design_stiffness_n_per_m=band_k)
        config = dataclasses.replace(config, force=dataclasses.replace(config.force,
                                                                       contact_aware=tuning))
    if args.quick:
        cases, excluded = quick_cases(config)
    elif args.compliant:
        cases, excluded = compliant_cases(config)
    elif args.fingers:
        cases, excluded = finger_cases(config, exact=not args.band_only,
                                       band=not args.exact_only)
    else:
        cases, excluded = envelope_cases(config, exact=not args.band_only,
                                         band=not args.exact_only)
    from gripper_ros.core.runtime.engine import EngineError
    from gripper_ros.progress import progress_bar
    start = time.monotonic()
    try:
        with progress_bar(len(cases), 'contact_sweep', quiet=args.quiet) as bar:
            rows = sweep(config, cases, args.force_controller, args.hold_s, args.jobs,
                         scheduler=args.scheduler, progress=bar.update,
                         rest_floors=not args.fingers)
    except EngineError as exc:
        print(f'contact_sweep: {exc}', file=sys.stderr)
        return 2
    elapsed_s = time.monotonic() - start
    if args.json:
        print(json.dumps([{k: None if isinstance(v, float) and not math.isfinite(v) else v
                           for k, v in asdict(r).items()} for r in rows], indent=1))
    else:
        print(summary(config, rows, excluded, args.hold_s, elapsed_s,
                      args.scheduler or args.jobs))
        print()
        print(format_rows(rows))
    if args.plot:
        plot(config, rows, args.plot)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
