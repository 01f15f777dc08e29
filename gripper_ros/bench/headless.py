"""bench_headless: ticks a second of the compiled headless loop, one grasp and a batch.

    ros2 run gripper_ros bench_headless                  # Table V, each held on for 1 s
    ros2 run gripper_ros bench_headless --repeat 20 --batch 64 --jobs 1 2 --json

Times, in ONE process run (so that ratios compare figures taken under the same machine load):

- ``simulate_grasp`` of each Table V object with ``--hold-s`` of hold after HOLDING, run
  compiled (the default path) and, as the in-run baseline, tick by tick from Python over the
  same compiled functions (``trace=``: what a loop driven from Python, like the graph's nodes,
  costs without DDS). Figure: simulated ticks per wall second (median of ``--repeat``), and
  the ratio of the two.
- ``simulate_grasps`` of ``--batch`` grasps (the Table V objects in turn) with ``--jobs``
  worker processes each, the batch entry point sweeps use; figure: ticks a second over the
  batch, and the ratio to one process. The engine's fork server is started first, once, and
  timed apart; and the cost of one task through the engine is measured on trivial tasks sent
  one a task.

The first call of each path is a warm-up (numba loads its compiled code from the cache then);
its time is reported apart as ``first_call_s``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time

TABLE_V = ((0.01, 1.27), (0.05, 1.69), (0.1, 0.75))
"""The paper's Table V objects: width (m), mass (kg)."""
OVERHEAD_ITEMS = 400
"""Trivial tasks sent one a task through the engine to measure what a task costs it."""


def _ticks(config, width_m: float, mass_kg: float, hold_s: float, traced: bool) -> int:
    from gripper_ros.core.headless import simulate_grasp
    if traced:
        count = [0]

        def trace(*_):
            count[0] += 1
        simulate_grasp(config, width_m, mass_kg, hold_s=hold_s, trace=trace)
        return count[0]
    return len(simulate_grasp(config, width_m, mass_kg, hold_s=hold_s).t_ns)


def _batch_ticks(case: dict, result) -> int:
    """Ticks of one batch grasp (runs in the worker: only the count comes back)."""
    return len(result.t_ns)


def measure(repeat: int = 5, hold_s: float = 1.0, batch: int = 32,
            jobs_list=(1, 2)) -> dict:
    """Return every figure of the benchmark (see the module docstring)."""
    from gripper_ros.core.config import load_config
    from gripper_ros.core.headless import map_cases, simulate_grasps
    config = load_config()
    out = {'platform': platform.platform(), 'cpus': os.cpu_count(), 'hold_s': hold_s,
           'grasps': []}
    t0 = time.perf_counter()
    _ticks(config, *TABLE_V[0], hold_s, traced=False)
    _ticks(config, *TABLE_V[0], 0.0, traced=True)
    out['first_call_s'] = time.perf_counter() - t0
    for width_m, mass_kg in TABLE_V:
        row = {'width_m': width_m, 'mass_kg': mass_kg}
        for name, traced in (('compiled', False), ('python_driven', True)):
            rates = []
            for _ in range(repeat if not traced else max(1, repeat // 5)):
                start = time.perf_counter()
                ticks = _ticks(config, width_m, mass_kg, hold_s, traced)
                rates.append(ticks / (time.perf_counter() - start))
            row['ticks'] = ticks
            row[f'{name}_ticks_per_s'] = statistics.median(rates)
        row['compiled_over_python_driven'] = \
            row['compiled_ticks_per_s'] / row['python_driven_ticks_per_s']
        out['grasps'].append(row)
    cases = [{'width_m': TABLE_V[i % 3][0], 'mass_kg': TABLE_V[i % 3][1], 'hold_s': hold_s}
             for i in range(batch)]
    start = time.perf_counter()           # the engine's fork server starts once per process
    simulate_grasps(config, cases[:max(jobs_list)], jobs=max(jobs_list), summarize=_batch_ticks)
    out['engine_start_s'] = time.perf_counter() - start
    items = list(range(OVERHEAD_ITEMS))
    start = time.perf_counter()
    map_cases(abs, items, jobs=max(jobs_list), chunks_per_job=OVERHEAD_ITEMS)
    out['per_task_overhead_us'] = (time.perf_counter() - start) / OVERHEAD_ITEMS * 1e6
    out['batch'] = []
    for jobs in jobs_list:
        start = time.perf_counter()
        ticks = sum(simulate_grasps(config, cases, jobs=jobs, summarize=_batch_ticks))
        wall_s = time.perf_counter() - start
        out['batch'].append({'jobs': jobs, 'grasps': batch, 'ticks': ticks, 'wall_s': wall_s,
                             'ticks_per_s': ticks / wall_s})
    base = out['batch'][0]['ticks_per_s']
    for row in out['batch']:
        row['over_first'] = row['ticks_per_s'] / base
    return out


def report(r: dict) -> str:
    """Return the figures as a table."""
    lines = [f'bench_headless: {r["platform"]}, {r["cpus"]} cores; each grasp held on for '
             f'{r["hold_s"]:g} s; first calls (cache load, warm-up) {r["first_call_s"]:.2f} s',
             f'{"width m":>8s} {"mass kg":>8s} {"ticks":>7s} {"compiled ticks/s":>17s} '
             f'{"python-driven ticks/s":>22s} {"ratio":>7s}']
    for g in r['grasps']:
        lines.append(f'{g["width_m"]:8.3f} {g["mass_kg"]:8.2f} {g["ticks"]:7d} '
                     f'{g["compiled_ticks_per_s"]:17,.0f} {g["python_driven_ticks_per_s"]:22,.0f} '
                     f'{g["compiled_over_python_driven"]:7.1f}')
    lines.append(f'batch engine: fork server started in {r["engine_start_s"]:.2f} s (once per '
                 f'process, not in the figures below); {r["per_task_overhead_us"]:.0f} us a task')
    lines.append(f'{"jobs":>8s} {"grasps":>8s} {"ticks":>9s} {"wall s":>8s} {"ticks/s":>12s} '
                 f'{"x 1st":>6s}')
    for b in r['batch']:
        lines.append(f'{b["jobs"]:8d} {b["grasps"]:8d} {b["ticks"]:9d} {b["wall_s"]:8.3f} '
                     f'{b["ticks_per_s"]:12,.0f} {b["over_first"]:6.2f}')
    return '\n'.join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='bench_headless', description=__doc__.split('\n')[0])
    parser.add_argument('--repeat', type=int, default=5, help='timed runs per grasp (median)')
    parser.add_argument('--hold-s', type=float, default=1.0,
                        help='seconds held on after HOLDING (default 1)')
    parser.add_argument('--batch', type=int, default=32, help='grasps in the batch')
    parser.add_argument('--jobs', type=int, nargs='+', default=[1, 2],
                        help='worker processes of each batch run (default 1 2)')
    parser.add_argument('--json', action='store_true', help='print JSON')
    args = parser.parse_args(argv)
    for name in ('repeat', 'batch'):
        if getattr(args, name) < 1:
            parser.error(f'--{name.replace("_", "-")} must be >= 1')
    if not (args.hold_s >= 0.0 and args.hold_s <= 60.0):
        parser.error('--hold-s must be in [0, 60]')
    if any(j < 1 for j in args.jobs):
        parser.error('--jobs must be >= 1')
    result = measure(args.repeat, args.hold_s, args.batch, args.jobs)
    print(json.dumps(result, indent=2) if args.json else report(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
