"""bench_graph's figures: medians over repetitions, same-run ratios and the printed tables."""
from __future__ import annotations

import statistics
from typing import Any, Dict, List

TICK_AIM = 2.0              # a graph tick at most this many ping-pong round trips
FORCE_RTF_AIM = 1.0         # the force stage at least real time
POSITION_RTF_AIM = 20.0     # the position stage at least 20x real time
PER_NODE_FORCE_RTF_AIM = 0.5   # one process per node: the force stage at least half real time
HOPS_PER_TICK = 3           # plant -> supervisor -> stage controller -> plant


def _median(values):
    values = [v for v in values if isinstance(v, (int, float)) and v == v]
    return statistics.median(values) if values else float('nan')


def median_of(items: List[Any]) -> Any:
    """Return the element-wise median of equally shaped results (dicts and lists of numbers).

    Any other value is the first repetition's; a boolean is true when any repetition's is.
    """
    items = [it for it in items if it is not None]
    if not items:
        return None
    first = items[0]
    if isinstance(first, dict):
        return {k: median_of([it.get(k) for it in items]) for k in first}
    if isinstance(first, list):
        n = min(len(it) for it in items)
        return [median_of([it[i] for it in items]) for i in range(n)]
    if isinstance(first, bool):
        return any(items)
    if isinstance(first, (int, float)):
        return _median(items)
    return first


def ratios(res: Dict[str, Any]) -> Dict[str, float]:
    """Return the same-run ratios of one repetition (or of the medians)."""
    pp, graph, procs, demo = res['pingpong'], res['graph'], res['processes'], res['demo']
    out: Dict[str, float] = {}
    for kind, g in graph.items():
        rt, crt = pp[kind]['us_per_round_trip'], pp[kind]['cpu_us_per_round_trip']
        out[f'graph_tick_over_pingpong_{kind}'] = g['all']['us_per_tick'] / rt
        out[f'graph_tick_over_pingpong_cpu_{kind}'] = g['all']['cpu_us_per_tick'] / crt
        for stage in ('position', 'force'):
            if g['all'][stage]:
                out[f'{stage}_tick_over_pingpong_{kind}'] = g['all'][stage]['us_per_tick'] / rt
    for kind, ring in res.get('ring', {}).items():
        for variant, r in ring.items():
            out[f'ring_{variant}_over_pingpong_{kind}'] = (r['us_per_tick']
                                                           / pp[kind]['us_per_round_trip'])
    for kind, p in res.get('pingpong_processes', {}).items():
        out[f'pingpong_processes_over_pingpong_{kind}'] = (p['us_per_round_trip']
                                                           / pp[kind]['us_per_round_trip'])
    for kind, p in procs.items():
        one = p['one_process']
        out[f'processes_over_one_process_{kind}'] = p['all']['wall_s'] / one['all']['wall_s']
        across = res.get('pingpong_processes', {}).get(kind)
        if across is not None:
            # A tick is three hops (plant, supervisor, stage): across processes each costs at
            # least half a cross-process round trip in place of half an in-process one.
            tick_us = one['all']['us_per_tick']
            extra_us = HOPS_PER_TICK / 2 * (across['us_per_round_trip']
                                            - pp[kind]['us_per_round_trip'])
            out[f'processes_floor_over_one_process_{kind}'] = (tick_us + extra_us) / tick_us
            # the force stage's best across processes: its tick of simulated time over the
            # three hops alone
            force = one['all']['force']
            if force:
                force_tick_s = force['sim_s'] / force['ticks']
                out[f'processes_transport_force_rtf_{kind}'] = force_tick_s / (
                    HOPS_PER_TICK / 2 * across['us_per_round_trip'] * 1e-6)
        for row, base in zip(p['grasps'], one['grasps']):
            row['over_one_process'] = row['wall_s'] / base['wall_s']
    if 'events' in pp and 'single' in pp:
        out['pingpong_events_over_single'] = (pp['events']['round_trips_per_s']
                                              / pp['single']['round_trips_per_s'])
    if 'events' in graph and 'single' in graph:
        out['graph_events_over_single'] = (graph['events']['all']['ticks_per_s']
                                           / graph['single']['all']['ticks_per_s'])
    if ('events' in demo and 'single' in demo and not demo['events']['timed_out']
            and not demo['single']['timed_out']):
        out['demo_single_over_events'] = demo['single']['wall_s'] / demo['events']['wall_s']
    return out


def _f(value, fmt: str, width: int) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return f'{"-":>{width}s}'
    return f'{value:{width}{fmt}}'


def _verdict(value: float, aim: float, at_most: bool) -> str:
    if value != value:
        return 'not measured'
    met = value <= aim if at_most else value >= aim
    return ('met' if met else 'MISSED') + f' (aim {"<=" if at_most else ">="} {aim:g})'


_GRASP_HEAD = (f'{"executor":>8s} {"width m":>7s} {"mass kg":>7s} {"outcome":>8s} '
               f'{"ticks":>6s} {"pos/force":>10s} {"us/tick":>8s} {"x pp":>6s} '
               f'{"CPU us/t":>8s} {"us/t pos":>8s} {"us/t frc":>8s} {"RTF pos":>8s} '
               f'{"RTF frc":>8s} {"wall s":>7s}')


def _grasp_line(kind: str, r: Dict[str, Any], rt: float) -> str:
    pos, frc = r['position'] or {}, r['force'] or {}
    outcome = r['outcome'] + ('*' if r['capped'] else '')
    width = f'{r["width_m"]:7.3f}' if r.get('width_m') is not None else f'{"":>7s}'
    mass = f'{r["mass_kg"]:7.2f}' if r.get('mass_kg') is not None else f'{"":>7s}'
    split = f'{pos.get("ticks", 0):.0f}/{frc.get("ticks", 0):.0f}'
    return (f'{kind:>8s} {width} {mass} {outcome:>8s} {r["ticks"]:6.0f} {split:>10s} '
            f'{_f(r["us_per_tick"], ".0f", 8)} {_f(r["us_per_tick"] / rt, ".1f", 6)} '
            f'{_f(r["cpu_us_per_tick"], ".0f", 8)} '
            f'{_f(pos.get("us_per_tick"), ".0f", 8)} {_f(frc.get("us_per_tick"), ".0f", 8)} '
            f'{_f(pos.get("rtf"), ".2f", 8)} {_f(frc.get("rtf"), ".3f", 8)} '
            f'{r["wall_s"]:7.3f}')


def _grasp_table(kind: str, measured: Dict[str, Any], rt: float) -> List[str]:
    rows = measured['grasps'] + [dict(measured['all'], outcome='all')]
    return [_grasp_line(kind, r, rt) for r in rows]


def format_report(report: Dict[str, Any]) -> str:
    res, m, s, rat = report['median'], report['machine'], report['settings'], report['ratios']
    agg = f'median of {s["repeat"]} runs' if s['repeat'] > 1 else 'one run'
    lines = [f"bench_graph ({agg}): {m['cpus']} CPUs ({m['processor']}), Python {m['python']}, "
             f"{m['rmw']}, ROS_DOMAIN_ID={m['ros_domain_id']}, load average (1 min) "
             f"{_f(m['loadavg_1min_before'], '.2f', 0)} before, "
             f"{_f(m['loadavg_1min_after'], '.2f', 0)} after", '',
             '1. baseline: lockstep std_msgs/Float64 ping-pong, two nodes, one executor '
             f"({s['pingpong_s']:g} s each)",
             f'{"executor":>8s} {"round trips/s":>14s} {"us/round trip":>14s} '
             f'{"CPU us/round trip":>18s}']
    for label, table in (('', res['pingpong']),
                         (' (2 procs)', res.get('pingpong_processes', {}))):
        for kind, p in table.items():
            lines.append(f'{kind + label:>8s} {_f(p["round_trips_per_s"], ".0f", 14)} '
                         f'{_f(p["us_per_round_trip"], ".1f", 14)} '
                         f'{_f(p["cpu_us_per_round_trip"], ".1f", 18)}')
    for kind, ring in res.get('ring', {}).items():
        lines.append(f'{kind:>8s} floor of a tick: the three loop messages round a ring of three '
                     f'nodes, {ring["bare"]["us_per_tick"]:.1f} us bare, '
                     f'{ring["tapped"]["us_per_tick"]:.1f} us with a raw DDS tap on each hop '
                     f'(what a recorder subscribing over DDS would add; the tap is in the '
                     f'publishers)')
    lines += ['', '2. graph, one process: one grasp per Table V object, fast time, '
              + ('recorded as grasp_demo records' if s['record'] else 'not recorded')
              + '; x pp = us/tick over the ping-pong round trip', _GRASP_HEAD]
    for kind, g in res['graph'].items():
        lines += _grasp_table(kind, g, res['pingpong'][kind]['us_per_round_trip'])
    for kind, g in res['graph'].items():
        first = g['grasps'][0] if g['grasps'] else None
        if first:
            subs = ', '.join(f'{t} {n}' for t, n in g['subscriptions'].items() if n)
            lines.append(f'  {kind}: {first["messages_per_tick"]:.2f} publications/tick, '
                         f'{first["callbacks_per_tick"]:.2f} subscription callbacks/tick '
                         f'(subscribers per topic: {subs}); graph up in '
                         f'{g["graph_up_s"]:.2f} s')
    if any(g['all']['capped'] for g in res['graph'].values()):
        lines.append('  * capped: stopped after --grasp-cap-s wall seconds')
    if res['processes']:
        lines += ['', '3. one process per node (the four node executables, -p time_mode:=fast), '
                  'the same grasps, not recorded; x 1 = wall time over one process, '
                  'not recorded, same run', _GRASP_HEAD + f' {"x 1":>5s}']
        for kind, p in res['processes'].items():
            rt = res['pingpong'][kind]['us_per_round_trip']
            for row in p['grasps']:
                lines.append(_grasp_line(kind, row, rt)
                             + f' {_f(row.get("over_one_process"), ".2f", 5)}')
            lines.append(_grasp_line(kind, dict(p['all'], outcome='all'), rt)
                         + f' {_f(rat.get(f"processes_over_one_process_{kind}"), ".2f", 5)}')
            lines.append(f'  {kind}: CPU = the four node processes; processes up in '
                         f'{p["processes_up_s"]:.2f} s')
    if res['demo']:
        lines += ['', '4. grasp_demo --no-plot (three objects, bags to a temp dir), child '
                  f"process, cap {s['demo_cap_s']:g} s",
                  f'{"executor":>8s} {"wall s":>8s} {"grasps s":>9s} {"exit":>5s}']
        for kind, d in res['demo'].items():
            if d['timed_out']:
                lines.append(f'{kind:>8s} {">" + format(d["cap_s"], "g"):>8s} {"-":>9s} '
                             f'{"kill":>5s}')
            else:
                lines.append(f'{kind:>8s} {d["wall_s"]:8.2f} {d["grasps_wall_s"]:9.2f} '
                             f'{d["exit_code"]:5d}' + (f'  {d["error"]}' if 'error' in d else ''))
    lines += ['', 'aims (same run):']
    for kind, g in res['graph'].items():
        tick = rat[f'graph_tick_over_pingpong_{kind}']
        lines.append(f'  {kind}: graph tick / ping-pong round trip {tick:.2f}x: '
                     + _verdict(tick, TICK_AIM, True))
        floor = rat.get(f'ring_bare_over_pingpong_{kind}')   # recorded or not: no DDS tap
        if floor is not None:
            lines.append(f'  {kind}: its transport floor (ring of the loop messages) '
                         f'{floor:.2f}x')
        for stage, aim in (('force', FORCE_RTF_AIM), ('position', POSITION_RTF_AIM)):
            rtf = (g['all'][stage] or {}).get('rtf', float('nan'))
            lines.append(f'  {kind}: {stage} stage {_f(rtf, ".3f", 0)}x real time: '
                         + _verdict(rtf, aim, False))
        key = f'processes_over_one_process_{kind}'
        if key in rat:
            lines.append(f'  {kind}: one process per node / one process {rat[key]:.2f}x')
            force = (res['processes'][kind]['all']['force'] or {}).get('rtf', float('nan'))
            lines.append(f'  {kind}: one process per node, force stage {_f(force, ".3f", 0)}x '
                         'real time: ' + _verdict(force, PER_NODE_FORCE_RTF_AIM, False))
        key = f'processes_transport_force_rtf_{kind}'
        if key in rat:
            lines.append(f'  {kind}: the cross-process transport alone allows the force stage '
                         f'{rat[key]:.3f}x real time ({HOPS_PER_TICK} hops a tick)')
        key = f'pingpong_processes_over_pingpong_{kind}'
        if key in rat:
            lines.append(f'  {kind}: the floor of that: a ping-pong across two processes is '
                         f'{rat[key]:.2f}x the one in one process')
        key = f'processes_floor_over_one_process_{kind}'
        if key in rat:
            lines.append(f'  {kind}: so the {HOPS_PER_TICK} hops of a tick across processes '
                         f'cost at least {rat[key]:.2f}x the one-process tick')
    for key, text in (('pingpong_events_over_single', 'ping-pong events/single round trips/s'),
                      ('graph_events_over_single', 'graph events/single ticks/s'),
                      ('demo_single_over_events', 'demo wall single/events')):
        if key in rat:
            lines.append(f'  {text}: {rat[key]:.2f}x')
    lines.append(f"total benchmark wall time {report['total_wall_s']:.1f} s")
    return '\n'.join(lines)
