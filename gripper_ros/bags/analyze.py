"""``bag_analyze BAG [BAG ...]``: the paper's step-response figures from recorded grasps.

Per bag: time to contact, switch time and the criterion that fired, position-stage and
force-stage RMS / overshoot / 2 % settling (all from :mod:`gripper_ros.studies.metrics`), peak
contact force and its ratio to the setpoint, voltage saturation, final errors. Terminal table,
JSON, CSV and a Fig.-8-like plot (position, force, motor voltage, sensor voltage; one column per
bag).

The grasp analysed is the first one in the bag: from the first status in the POSITION phase to
the last status with the same grasp id. Times are simulated seconds from that grasp start. A bag
without a grasp (a move's, an excitation's) gets one line saying what it holds instead.
"""
from __future__ import annotations

import argparse
import csv
from dataclasses import asdict, dataclass
import io
import json
import math
import sys
from typing import Sequence

from gripper_ros.bags.reader import BagError, EXIT_ERROR, EXIT_TRUNCATED, quiet_on_closed_pipe
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.core.series import GraspSeries, seconds
from gripper_ros.studies.metrics import step_metrics
from gripper_ros.wire import enum_name, HoldState, Outcome, Phase, SwitchCriterion
import numpy as np

PROG = 'bag_analyze'
LIMIT_TOL_V = 1e-9


@dataclass
class GraspMetrics:
    """One row of the analysis; NaN = not applicable, inf = did not settle in the record."""

    bag: str
    grasp_id: int
    outcome: str
    truncated: bool
    grasp_start_s: float
    grasp_end_s: float
    time_to_contact_s: float
    switch_time_s: float
    switch_criterion: str
    position_setpoint_m: float
    position_rms_m: float
    position_overshoot_pct: float
    position_settling_s: float
    force_setpoint_n: float
    force_rms_n: float
    force_overshoot_pct: float
    force_settling_s: float
    peak_contact_force_n: float
    peak_force_ratio: float
    max_abs_voltage_v: float
    time_at_voltage_limit_s: float
    final_position_error_m: float
    final_force_error_n: float
    final_outcome: str = ''             # after the hold that follows the answer (a lift)
    hold_s: float = math.nan            # simulated time recorded after the answer
    max_slip_m: float = math.nan        # ground truth: the most the object slid on the pads
    lost_at_s: float = math.nan         # ground truth: when it left the grip, after the answer
    loss_detected_s: float = math.nan   # when the supervisor reported OBJECT_LOST, after it
    hold_margin_mean: float = math.nan  # ground truth: grip over the slip limit once lifted off,
    hold_margin_max: float = math.nan   # 2 mu_s F / m (g + a) (sim/object_state's samples)
    overload_said_s: float = math.nan   # when the supervisor reported OVERLOADED, after the answer
    pad_shear_max_n: float = math.nan   # the most the pads read of the load (their mean shear)


class AnalysisError(BagError):
    """A bag whose content does not describe a grasp."""


class NoGraspError(AnalysisError):
    """A readable bag of the package that holds no grasp (a move's, an excitation's)."""


@dataclass(frozen=True)
class Stages:
    """Grasp time line in absolute simulated seconds."""

    grasp_id: int
    start_s: float
    switch_s: float   # nan when the grasp never reached the force stage
    end_s: float      # the answer (or the last decision of the grasp, unanswered)
    last_s: float     # the last decision of the grasp, the hold after the answer included


def find_stages(series: GraspSeries) -> Stages:
    """Find the stages of the bag's grasp: its start, its switch to force and its end.

    Start = first POSITION-phase decision, switch = first FORCE-phase decision of that grasp,
    end = its answer (the first decision with an outcome).
    """
    st = series.decisions
    st_t = seconds(st)
    in_position = np.flatnonzero(st['phase'] == Phase.POSITION)
    if in_position.size == 0:
        raise NoGraspError(f'{series.path}: no supervisor decision in the POSITION phase '
                           f'(no grasp was started)')
    first = in_position[0]
    grasp_id = int(st['grasp_id'][first])
    same = np.flatnonzero(st['grasp_id'] == grasp_id)
    same = same[same >= first]
    start_s = float(st_t[first])
    answered = same[st['outcome'][same] != 0]
    end_s = float(st_t[answered[0]] if answered.size else st_t[same[-1]])
    force_idx = same[(st['phase'][same] == Phase.FORCE) | (st['phase'][same] == Phase.HOLDING)]
    switch_s = float(st_t[force_idx[0]]) if force_idx.size else math.nan
    return Stages(grasp_id, start_s, switch_s, end_s, float(st_t[same[-1]]))


def bag_contents(series: GraspSeries) -> str:
    """Say what a bag without a grasp holds: its requests, their outcomes, time and ranges."""
    st = series.decisions
    kinds = {Phase.MOVING: 'move', Phase.RELEASING: 'release'}
    requests: dict[int, list] = {}
    for grasp_id, phase, outcome in zip(st['grasp_id'], st['phase'], st['outcome']):
        entry = requests.setdefault(int(grasp_id), [None, 0])
        entry[0] = entry[0] or kinds.get(int(phase))
        entry[1] = int(outcome) or entry[1]
    parts = []
    for kind in ('move', 'release'):
        ids = [i for i, (k, _) in requests.items() if k == kind]
        if ids:
            outcomes = [enum_name(Outcome, requests[i][1]) for i in ids if requests[i][1]]
            tally = ', '.join(f'{name} {outcomes.count(name)}' for name in sorted(set(outcomes)))
            parts.append(f'{len(ids)} {kind}{"s" if len(ids) > 1 else ""} (ids {min(ids)}-'
                         f'{max(ids)}{": " + tally if tally else ""})')
    what = ', '.join(parts) or 'no request'
    if 'excitation' in series.custom_data:
        what = f'an excitation ({what}; bag_identify fits the plant to it)'
    out = f'{series.path.name}: no grasp: {what}, {(series.end_ns - series.start_ns) * 1e-9:.3f} s'
    position_m, voltage_v = series.ticks['position_m'], series.commands['voltage_v']
    if position_m.size:
        out += f', finger {np.nanmin(position_m):.4f}-{np.nanmax(position_m):.4f} m'
    if voltage_v.size:
        out += f', motor {np.nanmin(voltage_v):.2f} to {np.nanmax(voltage_v):.2f} V'
    return out


def _window(t_s: np.ndarray, lo: float, hi: float, include_hi: bool = False) -> np.ndarray:
    return (t_s >= lo) & ((t_s <= hi) if include_hi else (t_s < hi))


def _safe_step(t_rel, y, setpoint, initial):
    """step_metrics, or NaNs when the stage is empty or has no step."""
    if len(y) == 0 or not math.isfinite(setpoint) or setpoint == initial:
        return math.nan, math.nan, math.nan
    m = step_metrics(t_rel, y, setpoint, initial)
    return m.rms_error, m.overshoot_pct, m.settling_time_s


def _time_at_limit(t_s: np.ndarray, voltage_v: np.ndarray, limit_v: float) -> float:
    """Each motor_state sample holds over the interval ending at its stamp."""
    if t_s.size < 2:
        return 0.0
    dt = np.diff(t_s)
    at_limit = np.abs(voltage_v[1:]) >= limit_v - LIMIT_TOL_V
    return float(np.sum(dt[at_limit]))


def recorded_voltage_limit_v(series: GraspSeries) -> float:
    """Return the command limit the bag was recorded with: its config's plant.voltage_limit_v.

    A bag that holds no config (format 1) is read with the installed config's limit.
    """
    config = series.custom_data.get('config')
    try:
        limit_v = float(config['plant']['voltage_limit_v'])
    except (TypeError, KeyError, ValueError):
        from gripper_ros.core.config import load_config
        return load_config().plant.voltage_limit_v
    return limit_v


def _lift_off_end_s(series: GraspSeries) -> float:
    """Return when, after the answer, the pads carry the whole weight: lift delay + lift-off.

    From the recorded object (its ``lift_off_s``, else the recorded config's
    ``contact.lift_off_s``); 0 for a bag that holds neither (an instant lift).
    """
    obj = series.custom_data.get('object')
    config = series.custom_data.get('config')
    try:
        delay_s = float(obj.get('lift_delay_s', 0.0))
        lift_off_s = float(obj.get('lift_off_s', 0.0)) or \
            float(config['contact'].get('lift_off_s', 0.0))
    except (AttributeError, TypeError, KeyError, ValueError):
        return 0.0
    return delay_s + lift_off_s if math.isfinite(delay_s + lift_off_s) else 0.0


def analyze_series(series: GraspSeries, voltage_limit_v: float | None = None) -> GraspMetrics:
    """All figures of one grasp (pure numpy; metrics from gripper_ros.studies.metrics).

    ``voltage_limit_v`` (time at the limit) defaults to the limit the bag was recorded with.
    """
    if voltage_limit_v is None:
        voltage_limit_v = recorded_voltage_limit_v(series)
    stages = find_stages(series)
    st, ticks, cmd = series.decisions, series.ticks, series.commands
    st_t, t_s, cmd_t = seconds(st), series.t_s, seconds(cmd)
    t0, t_sw, t_end = stages.start_s, stages.switch_s, stages.end_s
    in_grasp = _window(st_t, t0, t_end, include_hi=True) & (st['grasp_id'] == stages.grasp_id)
    first = np.flatnonzero(in_grasp)[0]
    pos_sp = float(st['position_setpoint_m'][first])

    # contact: the measured force first, supervisor's view as fallback
    jmask = _window(t_s, t0, t_end, include_hi=True)
    contact = np.flatnonzero(jmask & (ticks['force_n'] > 0.0))
    if contact.size:
        time_to_contact = float(t_s[contact[0]] - t0)
    else:
        c = np.flatnonzero(in_grasp & st['contact'])
        time_to_contact = float(st_t[c[0]] - t0) if c.size else math.nan

    # position stage: [start, switch)
    pos_end = t_sw if math.isfinite(t_sw) else t_end
    pmask = _window(t_s, t0, pos_end, include_hi=not math.isfinite(t_sw))
    p_t, p_y = t_s[pmask] - t0, ticks['position_m'][pmask]
    p_init = float(p_y[0]) if p_y.size else math.nan
    pos_rms, pos_os, pos_settle = _safe_step(p_t, p_y, pos_sp, p_init)

    # force stage: [switch, end]
    criterion, force_sp = 'NONE', math.nan
    f_rms = f_os = f_settle = math.nan
    if math.isfinite(t_sw):
        at_sw = np.flatnonzero(in_grasp & (st_t >= t_sw))[0]
        criterion = enum_name(SwitchCriterion, int(st['switch_criterion'][at_sw]))
        force_sp = float(st['force_setpoint_n'][at_sw])
        fmask = _window(t_s, t_sw, t_end, include_hi=True)
        f_t, f_y = t_s[fmask] - t_sw, ticks['force_n'][fmask]
        f_init = float(f_y[0]) if f_y.size else math.nan
        f_rms, f_os, f_settle = _safe_step(f_t, f_y, force_sp, f_init)
    elif np.any(st['force_setpoint_n'][in_grasp] > 0):
        setpoints = st['force_setpoint_n'][in_grasp]
        force_sp = float(setpoints[setpoints > 0][0])

    forces = ticks['force_n'][jmask]
    forces = forces[np.isfinite(forces)]
    peak = float(np.max(forces)) if forces.size else math.nan
    ratio = peak / force_sp if force_sp and math.isfinite(force_sp) else math.nan

    # voltage: applied (motor_state) preferred, commands (hold_s each) as fallback
    mmask = _window(t_s, t0, t_end, include_hi=True)
    if 'tick.motor_voltage_v' not in series.absent and np.any(mmask):
        volts = ticks['motor_voltage_v'][mmask]
        vmax = float(np.max(np.abs(volts)))
        idx = np.flatnonzero(mmask)
        t_lim = _time_at_limit(t_s[idx], ticks['motor_voltage_v'][idx], voltage_limit_v)
    else:
        cmask = _window(cmd_t, t0, t_end, include_hi=True)
        volts = cmd['voltage_v'][cmask]
        vmax = float(np.max(np.abs(volts))) if volts.size else math.nan
        t_lim = float(np.sum(cmd['hold_s'][cmask][np.abs(volts) >=
                                                  voltage_limit_v - LIMIT_TOL_V]))

    jlast = np.flatnonzero(jmask)
    final_pos_err = float(pos_sp - ticks['position_m'][jlast[-1]]) if jlast.size else math.nan
    final_force_err = (float(force_sp - ticks['force_n'][jlast[-1]])
                       if jlast.size and math.isfinite(force_sp) else math.nan)

    outcome_code = int(st['outcome'][np.flatnonzero(in_grasp)[-1]])
    hold = _hold_figures(series, stages)
    return GraspMetrics(
        bag=str(series.path), grasp_id=stages.grasp_id, outcome=enum_name(Outcome, outcome_code),
        truncated=series.truncated, grasp_start_s=t0, grasp_end_s=t_end,
        time_to_contact_s=time_to_contact,
        switch_time_s=(t_sw - t0) if math.isfinite(t_sw) else math.nan,
        switch_criterion=criterion, position_setpoint_m=pos_sp, position_rms_m=pos_rms,
        position_overshoot_pct=pos_os, position_settling_s=pos_settle, force_setpoint_n=force_sp,
        force_rms_n=f_rms, force_overshoot_pct=f_os, force_settling_s=f_settle,
        peak_contact_force_n=peak, peak_force_ratio=ratio, max_abs_voltage_v=vmax,
        time_at_voltage_limit_s=t_lim, final_position_error_m=final_pos_err,
        final_force_error_n=final_force_err, **hold)


def _hold_figures(series: GraspSeries, stages: Stages) -> dict:
    """Return what happened after the answer: the final outcome, the slip, the loss."""
    st = series.decisions
    st_t = seconds(st)
    same = np.flatnonzero((st['grasp_id'] == stages.grasp_id) & (st_t >= stages.start_s))
    final = enum_name(Outcome, int(st['outcome'][same[-1]])) if same.size else ''
    last_tick_s = float(series.t_s[-1]) if series.ticks.size else stages.last_s
    lost = same[(st['outcome'][same] == Outcome.OBJECT_LOST) & (st_t[same] > stages.end_s)]
    over = same[st['outcome'][same] == Outcome.OVERLOADED]
    figures = {'final_outcome': final, 'hold_s': max(0.0, last_tick_s - stages.end_s),
               'loss_detected_s': float(st_t[lost[0]] - stages.end_s) if lost.size
               else math.nan,
               'overload_said_s': float(st_t[over[0]] - stages.end_s) if over.size
               else math.nan}
    ticks = series.ticks
    if 'tick.pad1_shear_n' not in series.absent and ticks.size:
        figures['pad_shear_max_n'] = float(np.max(0.5 * (ticks['pad1_shear_n'] +
                                                         ticks['pad2_shear_n'])))
    obj = series.objects
    if obj.size:
        obj_t = seconds(obj)
        figures['max_slip_m'] = float(np.max(obj['slip_m']))
        gone = np.flatnonzero(obj['state'] == HoldState.LOST)
        if gone.size:
            figures['lost_at_s'] = float(obj_t[gone[0]] - stages.end_s)
        lifted = ((obj['state'] == HoldState.STUCK) | (obj['state'] == HoldState.SLIDING)) & \
            (obj['load_n'] > 0.0) & (obj_t >= stages.end_s + _lift_off_end_s(series))
        if np.any(lifted):
            margin = obj['capacity_n'][lifted] / obj['load_n'][lifted]
            figures['hold_margin_mean'] = float(np.mean(margin))
            figures['hold_margin_max'] = float(np.max(margin))
    return figures


# --- output -----------------------------------------------------------------------------------

def _json_value(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value


def to_json(rows: list[GraspMetrics]) -> str:
    """JSON list; NaN -> null, inf -> "inf" (strict JSON has neither)."""
    return json.dumps([{k: _json_value(v) for k, v in asdict(r).items()} for r in rows], indent=2)


def to_csv(rows: list[GraspMetrics]) -> str:
    buf = io.StringIO()
    fields = list(asdict(rows[0]).keys()) if rows else []
    writer = csv.DictWriter(buf, fieldnames=fields, lineterminator='\n')
    writer.writeheader()
    for r in rows:
        writer.writerow(asdict(r))
    return buf.getvalue()


def format_cell(value) -> str:
    """One metric as a table shows it: yes/no, '-' for none or NaN, 'not settled' for inf."""
    if value is None:
        return ''
    if isinstance(value, bool):
        return 'yes' if value else 'no'
    if isinstance(value, float):
        if math.isnan(value):
            return '-'
        if math.isinf(value):
            return 'not settled' if value > 0 else '-inf'
        return f'{value:.6g}'
    return str(value)


def to_table(rows: list[GraspMetrics]) -> str:
    """Metric per line, one column per bag."""
    if not rows:
        return ''
    fields = [f for f in asdict(rows[0]) if f != 'bag']
    header = ['metric'] + [f'bag {i + 1}' for i in range(len(rows))]
    body = [[f] + [format_cell(getattr(r, f)) for r in rows] for f in fields]
    widths = [max(len(line[c]) for line in [header] + body) for c in range(len(header))]
    out = [f'bag {i + 1}: {r.bag}' for i, r in enumerate(rows)]
    out.append('  '.join(h.ljust(w) for h, w in zip(header, widths)))
    out.append('  '.join('-' * w for w in widths))
    out.extend('  '.join(c.ljust(w) for c, w in zip(line, widths)) for line in body)
    return '\n'.join(out)


def plot(series_list: list[GraspSeries], metrics: list[GraspMetrics], path: str,
         voltage_limit_v: float | None = None) -> None:
    """Fig.-8-like grid: position, force, motor voltage, sensor voltage vs time; stages shaded."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    ncols = len(series_list)
    fig, axes = plt.subplots(4, ncols, figsize=(4.5 * ncols, 9), sharex='col', squeeze=False)
    for col, (s, m) in enumerate(zip(series_list, metrics)):
        t0 = m.grasp_start_s
        t_sw = t0 + m.switch_time_s if math.isfinite(m.switch_time_s) else m.grasp_end_s
        rows = [
            (s.t_s, s.ticks['position_m'] * 1e3, 'position (mm)', m.position_setpoint_m * 1e3),
            (s.t_s, s.ticks['force_n'], 'force (N)', m.force_setpoint_n),
            (s.t_s, s.ticks['motor_voltage_v'], 'motor voltage (V)', None),
            (s.t_s, s.ticks['sensor_voltage_v'], 'sensor voltage (V)', None),
        ]
        for r, (t, y, label, sp) in enumerate(rows):
            ax = axes[r][col]
            ax.axvspan(0.0, t_sw - t0, color='tab:blue', alpha=0.08,
                       label='position stage' if r == 0 else None)
            if math.isfinite(m.switch_time_s):
                ax.axvspan(t_sw - t0, m.grasp_end_s - t0, color='tab:orange', alpha=0.10,
                           label='force stage' if r == 0 else None)
            if m.hold_s > 0.0:
                ax.axvspan(m.grasp_end_s - t0, m.grasp_end_s - t0 + m.hold_s, color='tab:green',
                           alpha=0.08, label='hold after the answer' if r == 0 else None)
            if len(t) and r == 2:      # held over the interval ending at each stamp
                ax.step(t - t0, y, where='pre', lw=1.2, color='k')
            elif len(t):
                ax.plot(t - t0, y, lw=1.2, color='k')
            if sp is not None and math.isfinite(sp):
                ax.axhline(sp, ls='--', lw=0.8, color='tab:red', label='setpoint')
            if r == 2:
                limit_v = recorded_voltage_limit_v(s) if voltage_limit_v is None \
                    else voltage_limit_v
                for lim in (limit_v, -limit_v):
                    ax.axhline(lim, ls=':', lw=0.8, color='grey')
            if col == 0:
                ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
        final = f' -> {m.final_outcome}' if m.final_outcome and m.final_outcome != m.outcome \
            else ''
        axes[0][col].set_title(f'{s.path.name}\n{m.outcome}{final}', fontsize=9)
        axes[0][col].legend(fontsize=7, loc='best')
        axes[3][col].set_xlabel('time from grasp start (s)')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --- CLI --------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description='Step-response metrics of recorded '
                                     'grasps (position and force stages).')
    parser.add_argument('bags', metavar='BAG', nargs='+', help='bag folder or .mcap file')
    fmt = parser.add_mutually_exclusive_group()
    fmt.add_argument('--json', action='store_true', help='print JSON instead of the table')
    fmt.add_argument('--csv', action='store_true', help='print CSV instead of the table')
    parser.add_argument('--plot', metavar='FILE.png', help='also write a Fig.-8-like plot')
    parser.add_argument('--voltage-limit', type=float, default=None, metavar='V',
                        help='armature voltage limit for the time-at-limit figure (default: '
                             'plant.voltage_limit_v of the config the bag recorded)')
    parser.add_argument('--namespace', default=None,
                        help='the gripper to analyse when a bag holds several (default: the '
                             'one recorded)')
    return parser


def _fail(message: str) -> None:
    print(f'{PROG}: error: {message}', file=sys.stderr)
    sys.exit(EXIT_ERROR)


@quiet_on_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    """Exit 0; 1 on bad input (one line on stderr); 3 when a bag was truncated (figures shown)."""
    args = build_parser().parse_args(argv)
    if args.voltage_limit is not None and not (args.voltage_limit > 0
                                               and math.isfinite(args.voltage_limit)):
        _fail('--voltage-limit must be a positive number')
    if args.plot and not args.plot.lower().endswith('.png'):
        _fail(f'--plot needs a .png file name, got {args.plot!r}')
    series_list, rows, others = [], [], []
    for path in args.bags:
        try:
            series = load_grasp_series(path, args.namespace)
            try:
                rows.append(analyze_series(series, args.voltage_limit))
            except NoGraspError:
                others.append(bag_contents(series))
                continue
            series_list.append(series)
        except BagError as exc:
            _fail(str(exc))
    notes = sys.stderr if args.json or args.csv else sys.stdout
    if args.json:
        print(to_json(rows))
    elif args.csv:
        print(to_csv(rows), end='')
    elif rows:
        print(to_table(rows))
    for line in others:
        print(line, file=notes)
    if args.plot and rows:
        try:
            plot(series_list, rows, args.plot, args.voltage_limit)
        except OSError as exc:
            _fail(f'cannot write {args.plot}: {exc.strerror or exc}')
        print(f'figure: {args.plot}', file=notes)
    elif args.plot:
        print(f'no figure: no grasp in {"these bags" if len(others) > 1 else "this bag"}',
              file=notes)
    damaged = [s for s in series_list if s.truncated]
    for s in damaged:
        print(f'{PROG}: warning: {s.path}: truncated: {sum(s.counts.values())} complete messages '
              f'recovered ({s.damage}); figures cover that part', file=sys.stderr)
    if damaged:
        sys.exit(EXIT_TRUNCATED)
    return 0


if __name__ == '__main__':
    sys.exit(main())
