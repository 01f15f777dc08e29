"""What ``bag_replay --closed-loop`` prints and draws of a what-if: table, JSON, sweep, plot.

The runs and their differences are computed in :mod:`gripper_ros.bags.rerun`; this module
only presents a :class:`~gripper_ros.bags.rerun.WhatIf`.
"""
from __future__ import annotations

from dataclasses import asdict
import json
import math
from typing import Any

from gripper_ros.bags.analyze import format_cell, GraspMetrics
from gripper_ros.bags.rerun import RECORDING_TOLERANCE, Rerun, series_nrmse, WhatIf
from gripper_ros.wire import DEFAULT_APPROACH_FORCE_MARGIN

SKIPPED = ('bag', 'grasp_id', 'truncated', 'grasp_start_s', 'grasp_end_s')
"""GraspMetrics fields that say which grasp, not how it went."""


def metrics_dict(m: GraspMetrics) -> dict[str, Any]:
    """Give a grasp's figures (bag_analyze's) by name.

    ``answer_time_s`` (from the start to the answer) takes the place of the absolute start and
    end.
    """
    out = {k: v for k, v in asdict(m).items() if k not in SKIPPED}
    out = {'outcome': out.pop('outcome'), 'final_outcome': out.pop('final_outcome'),
           'answer_time_s': m.grasp_end_s - m.grasp_start_s, **out}
    return out


def _difference(recorded, rerun):
    if isinstance(recorded, str) or isinstance(rerun, str):
        return None if recorded == rerun else 'changed'
    if not (math.isfinite(recorded) and math.isfinite(rerun)):
        return None if (math.isnan(recorded) and math.isnan(rerun)) or recorded == rerun \
            else 'changed'
    return rerun - recorded


def _signed(value) -> str:
    if isinstance(value, float):
        return '0' if value == 0.0 else f'{value:+.4g}'
    return format_cell(value)


def _json_value(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    if isinstance(value, dict):
        return {k: _json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    return value


def _rows(w: WhatIf, r: Rerun) -> list[tuple[str, Any, Any, Any]]:
    rec, new = metrics_dict(w.recorded), metrics_dict(r.metrics)
    rows = []
    for key in rec:
        a, b = rec[key], new[key]
        if a in ('', None) and b in ('', None):
            continue
        if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            continue                    # not applicable on either side (no lift, no loss)
        rows.append((key, a, b, _difference(a, b)))
    return rows


def _header(w: WhatIf) -> list[str]:
    rec = w.record
    r = w.reruns[0]
    ctl = rec.controllers
    truncated = '  (TRUNCATED: recorded figures cover the part recovered)' \
        if rec.truncated else ''
    lines = [f'bag:          {rec.path}{truncated}',
             f'recorded:     position {ctl.get("position_controller", "?")}, force '
             f'{ctl.get("force_controller", "?")}, approach_force_margin '
             f'{float(ctl.get("approach_force_margin", DEFAULT_APPROACH_FORCE_MARGIN)):g}; '
             f'{rec.time_mode} mode',
             "re-run:       closed loop, headless (the graph's plant, supervisor and stages, "
             'tick for tick)']
    if w.sweep_key is None:
        lines.append(f'controllers:  position {r.setup.position_controller}, force '
                     f'{r.setup.force_controller}, approach_force_margin '
                     f'{r.setup.approach_force_margin:g}')
        lines.append('changes:      ' + ('; '.join(r.setup.changes) or 'none'))
    return lines


def _series_line(r: Rerun) -> str:
    if r.difference is None:
        return ''
    if r.difference == '':
        n = r.series.ticks['stamp_ns'].size
        return (f'series:       identical to the recording ({n} ticks, '
                f'{r.series.references["stamp_ns"].size} references and commands, bit for bit)')
    if r.agreement == '':
        return (f'series:       equal to the recording within {RECORDING_TOLERANCE:g} of each '
                f"field's full scale, not bit for bit: {r.difference}")
    return f'series:       NOT identical to the recording: {r.agreement or r.difference}'


def _nrmse_line(w: WhatIf, r: Rerun) -> str:
    if r.difference == '':
        return ''
    values = series_nrmse(w.record.series, r.series)
    if not values:
        return ''
    return ('nrmse:        ' + ', '.join(f'{k} {v:.3g}' for k, v in values.items()) +
            ' (re-run against recorded, at the same instants, over the recorded range)')


def to_table(w: WhatIf) -> str:
    """Side by side: each figure recorded, re-run, and the difference (re-run - recorded)."""
    r = w.reruns[0]
    lines = _header(w)
    if _series_line(r):
        lines.append(_series_line(r))
    if _nrmse_line(w, r):
        lines.append(_nrmse_line(w, r))
    lines.append('')
    header = ('metric', 'recorded', 're-run', 'difference')
    body = [(k, format_cell(a), format_cell(b), _signed(d)) for k, a, b, d in _rows(w, r)]
    widths = [max(len(line[c]) for line in [header] + body) for c in range(4)]
    lines.append('  '.join(h.ljust(n) for h, n in zip(header, widths)).rstrip())
    lines.append('  '.join('-' * n for n in widths))
    lines.extend('  '.join(c.ljust(n) for c, n in zip(line, widths)).rstrip() for line in body)
    return '\n'.join(lines)


def to_json(w: WhatIf) -> str:
    """Give the side-by-side table as JSON: ``recorded``, ``rerun``, ``difference``."""
    r = w.reruns[0]
    rec, new = metrics_dict(w.recorded), metrics_dict(r.metrics)
    out = {'bag': str(w.record.path), 'time_mode': w.record.time_mode,
           'recorded_controllers': w.record.controllers,
           'controllers': {'position_controller': r.setup.position_controller,
                           'force_controller': r.setup.force_controller,
                           'approach_force_margin': r.setup.approach_force_margin},
           'changes': r.setup.changes,
           'series_identical': None if r.difference is None else r.difference == '',
           'series_difference': r.difference or None,
           'series_within_tolerance': None if r.difference is None else r.agreement == '',
           'series_nrmse': series_nrmse(w.record.series, r.series) if r.difference != ''
           else {},
           'recorded': rec, 'rerun': new,
           'difference': {k: d for k, _, _, d in _rows(w, r)}}
    return json.dumps(_json_value(out), indent=2)


SWEEP_COLUMNS = (
    ('outcome', 'outcome', 1.0), ('final_outcome', 'final', 1.0),
    ('time_to_contact_s', 'contact s', 1.0), ('switch_time_s', 'switch s', 1.0),
    ('answer_time_s', 'answer s', 1.0), ('position_settling_s', 'pos settle s', 1.0),
    ('position_overshoot_pct', 'pos OS %', 1.0), ('position_rms_m', 'pos RMS mm', 1e3),
    ('force_settling_s', 'F settle ms', 1e3), ('force_overshoot_pct', 'F OS %', 1.0),
    ('force_rms_n', 'F RMS N', 1.0), ('peak_force_ratio', 'peak/F_sp', 1.0),
    ('time_at_voltage_limit_s', 'at limit s', 1.0))
"""The sweep table's columns: metric, heading, scale."""


def _sweep_cell(value, scale: float) -> str:
    if isinstance(value, float) and math.isfinite(value):
        return f'{value * scale:.4g}'
    return format_cell(value)


def sweep_table(w: WhatIf) -> str:
    """One row per swept value (the recording first), so the best value can be picked."""
    lines = _header(w)
    lines.append(f'sweep:        {w.sweep_key} (recorded: {w.recorded_value})')
    r = w.reruns[0]
    lines.append(f'controllers:  position {r.setup.position_controller}, force '
                 f'{r.setup.force_controller}, approach_force_margin '
                 f'{r.setup.approach_force_margin:g}')
    lines.append('')
    header = [w.sweep_key] + [h for _, h, _ in SWEEP_COLUMNS]
    body = [[f'recorded ({w.recorded_value})'] +
            [_sweep_cell(metrics_dict(w.recorded)[k], s) for k, _, s in SWEEP_COLUMNS]]
    for run_ in w.reruns:
        m = metrics_dict(run_.metrics)
        mark = ' (= recording)' if run_.difference == '' else ''
        body.append([f'{run_.value}{mark}'] + [_sweep_cell(m[k], s) for k, _, s in SWEEP_COLUMNS])
    widths = [max(len(line[c]) for line in [header] + body) for c in range(len(header))]
    lines.append('  '.join(h.ljust(n) for h, n in zip(header, widths)).rstrip())
    lines.append('  '.join('-' * n for n in widths))
    lines.extend('  '.join(c.ljust(n) for c, n in zip(line, widths)).rstrip() for line in body)
    return '\n'.join(lines)


def sweep_json(w: WhatIf) -> str:
    """Give the sweep as JSON: ``recorded`` and ``rerun`` (one entry per value)."""
    out = {'bag': str(w.record.path), 'sweep': w.sweep_key,
           'recorded_value': w.recorded_value,
           'recorded': metrics_dict(w.recorded),
           'rerun': [{'value': r.value, 'changes': r.setup.changes,
                      'series_identical': None if r.difference is None else r.difference == '',
                      **metrics_dict(r.metrics)} for r in w.reruns]}
    return json.dumps(_json_value(out), indent=2)


# --- figure ------------------------------------------------------------------------------------

RERUN_COLORS = ('tab:red', 'tab:blue', 'tab:green', 'tab:purple', 'tab:brown', 'tab:olive',
                'tab:cyan', 'tab:pink')
ZOOM_MARGIN_S = 0.03
"""The right-hand column starts this long before each grasp's switch to the force stage."""


def _phase_times(m: GraspMetrics) -> tuple[float, float, float]:
    """(switch, answer, end of the hold) in seconds from the grasp start."""
    end = m.grasp_end_s - m.grasp_start_s
    switch = m.switch_time_s if math.isfinite(m.switch_time_s) else end
    return switch, end, end + (m.hold_s if math.isfinite(m.hold_s) else 0.0)


def plot(w: WhatIf, path: str) -> None:
    """Draw recorded and re-run position, force, motor and FSR voltage on shared time axes.

    On the left time runs from the grasp start over the whole grasp; on the right it runs from
    each grasp's switch to the force stage, so that the force stages lie over each other. The
    recording is drawn in black and its stages are shaded (as bag_analyze and grasp_demo shade
    them); each re-run's switch and answer are marked in its colour.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    runs = [('recorded', w.record.series, w.recorded, 'k', w.record.config)]
    for i, r in enumerate(w.reruns):
        label = 're-run' if w.sweep_key is None else f'{w.sweep_key}={r.value}'
        runs.append((label, r.series, r.metrics, RERUN_COLORS[i % len(RERUN_COLORS)],
                     r.setup.config))
    times = [_phase_times(m) for _, _, m, _, _ in runs]     # (switch, answer, hold end)
    columns = ((0.0, max(t[2] for t in times)),             # (from, to) of each column
               (-ZOOM_MARGIN_S, max(t[2] - t[0] for t in times)))
    fig, axes = plt.subplots(4, 2, figsize=(13, 9.5), sharex='col', squeeze=False,
                             gridspec_kw={'width_ratios': [3, 2]})
    rec_switch, rec_end, rec_hold = times[0]
    labels = ('position (mm)', 'force (N)', 'motor voltage (V)', 'FSR voltage (V)')
    for col, (lo, hi) in enumerate(columns):
        shift = rec_switch if col else 0.0                  # the recording's zero on this side
        for row in range(4):
            ax = axes[row][col]
            first = row == 0 and col == 0
            ax.axvspan(-shift, rec_switch - shift, color='tab:blue', alpha=0.08,
                       label='position stage (recorded)' if first else None)
            if rec_end > rec_switch:
                ax.axvspan(rec_switch - shift, rec_end - shift, color='tab:orange', alpha=0.10,
                           label='force stage (recorded)' if first else None)
            if rec_hold > rec_end:
                ax.axvspan(rec_end - shift, rec_hold - shift, color='tab:green', alpha=0.08,
                           label='hold after the answer (recorded)' if first else None)
            for (label, s, m, color, config), (switch, end, _) in zip(runs, times):
                zero = m.grasp_start_s + (switch if col else 0.0)
                t = s.t_s - zero
                keep = (t >= lo) & (t <= hi)
                y = (s.ticks['position_m'] * 1e3, s.ticks['force_n'], s.ticks['motor_voltage_v'],
                     s.ticks['sensor_voltage_v'])[row]
                width = 1.6 if color == 'k' else 1.1
                if row == 2:            # each voltage holds over the interval ending at its stamp
                    ax.step(t[keep], y[keep], where='pre', lw=width, color=color,
                            label=label if first else None)
                else:
                    ax.plot(t[keep], y[keep], lw=width, color=color,
                            label=label if first else None)
                if color != 'k':
                    if not col:
                        ax.axvline(switch, color=color, ls='--', lw=0.8)
                    ax.axvline(end - (switch if col else 0.0), color=color, ls=':', lw=0.8)
                setpoint = (m.position_setpoint_m * 1e3, m.force_setpoint_n, None, None)[row]
                if setpoint is not None and math.isfinite(setpoint) and color == 'k':
                    ax.axhline(setpoint, ls='--', lw=0.8, color='grey',
                               label='setpoint' if first else None)
                if row == 2 and color == 'k':
                    for limit in (config.plant.voltage_limit_v, -config.plant.voltage_limit_v):
                        ax.axhline(limit, ls=':', lw=0.8, color='grey')
            ax.set_xlim(lo, hi)
            if col == 0:
                ax.set_ylabel(labels[row])
            ax.grid(True, alpha=0.3)
    axes[3][0].set_xlabel('time from the grasp start (s)')
    axes[3][1].set_xlabel('time from the switch to the force stage (s)')
    changes = '; '.join(w.reruns[0].setup.changes) if w.sweep_key is None else \
        f'sweep {w.sweep_key}'
    outcomes = ', '.join(f'{label} {m.outcome}' for label, _, m, _, _ in runs)
    fig.suptitle(f'{w.record.path.name}: {changes or "no change"}\n{outcomes}; dashed: switch, '
                 f'dotted: answer of each re-run', fontsize=9)
    axes[0][0].legend(fontsize=7, loc='best')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
