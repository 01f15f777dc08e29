"""bench_headless: ticks a second of the compiled headless loop, one grasp and a batch.

    ros2 run gripper_ros bench_headless                  # Table V, each held on for 1 s
    ros2 run gripper_ros bench_headless --repeat 20 --batch 64 --jobs 1 2 --json
    ros2 run gripper_ros bench_headless --scheduler tcp://HOST:8786   # an existing cluster

Times, in ONE process run (so that ratios compare figures taken under the same machine load):

- ``simulate_grasp`` of each Table V object with ``--hold-s`` of hold after HOLDING, and of an
  object of unknown mass (the load-tracking grip, the arm announcing a pick-and-place), run
  compiled (the default path) and, as the in-run baseline, tick by tick from Python over the
  same compiled functions (``trace=``: what a loop driven from Python, like the graph's nodes,
  costs without DDS), and compiled keeping every message as a closed-loop re-run needs them
  (``trace_state_period_ns``: the trace mode of ``bag_replay --resimulate --closed-loop``).
  Figure: simulated ticks per wall second (median of ``--repeat``), and the ratios of the
  compiled and the traced loop to the Python-driven one.
- ``simulate_grasps`` of ``--batch`` grasps (the Table V objects in turn), the batch entry point
  sweeps use, through the engine (:mod:`gripper_ros.core.runtime.engine`): in this process (the
  baseline), on a local Dask cluster of each ``--jobs`` worker processes, and through a
  scheduler with ``--scheduler-workers`` workers (``dask scheduler`` and ``dask worker``
  started here on localhost, or the cluster at ``--scheduler``). Figure: ticks a second over
  the batch (median of 3 runs), and its ratio to this process. Each engine is started and
  warmed up first (the batch once: a worker's first grasps load code), timed apart; and the
  cost of one task through the engine is measured on trivial tasks sent one a task.

The first call of each path is a warm-up (numba loads its compiled code from the cache then);
its time is reported apart as ``first_call_s``. ``--cpu-time`` times the single grasps in this
process's CPU time instead of wall time: on a machine others load, the figure of the work
itself (the batch figures stay wall time: they run in other processes).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import statistics
import sys
import time

TABLE_V = ((0.01, 1.27), (0.05, 1.69), (0.1, 0.75))
"""The paper's Table V objects: width (m), mass (kg)."""
UNKNOWN_MASS = (0.05, 0.0)
"""A 50 mm object of unknown mass (0.6 kg, mu_s 0.5): the load-tracking grip runs each tick,
through a pick-and-place of 3 m/s^2 its arm announces (lifted off over 0.1 s)."""
OVERHEAD_ITEMS = 400
"""Trivial tasks sent one a task through the engine to measure what a task costs it."""
BATCH_RUNS = 3
"""Timed runs of the batch on each engine (median)."""


TRACE_STATE_PERIOD_NS = 10_000_000
"""The state period a closed-loop re-run keeps the object state on (100 Hz, the default)."""


def _ticks(config, width_m: float, mass_kg: float, hold_s: float, traced: bool,
           captured: bool = False) -> int:
    from gripper_ros.core.runtime.headless import simulate_grasp
    more = {}
    if mass_kg == 0.0:
        from gripper_ros.core.physics.hold import Lift
        from gripper_ros.wire import LiftProfile
        more = {'object_mass_kg': 0.6, 'static_friction': 0.5, 'kinetic_friction': 0.4,
                'lift': Lift(3.0, 0.2, 1.2, LiftProfile.PICK_AND_PLACE, lift_off_s=0.1),
                'announce': True}
    if captured:
        return len(simulate_grasp(config, width_m, mass_kg, hold_s=hold_s,
                                  trace_state_period_ns=TRACE_STATE_PERIOD_NS,
                                  **more).series.ticks)
    if traced:
        count = [0]

        def trace(*_):
            count[0] += 1
        simulate_grasp(config, width_m, mass_kg, hold_s=hold_s, trace=trace, **more)
        return count[0]
    return len(simulate_grasp(config, width_m, mass_kg, hold_s=hold_s, **more).series.ticks)


def _batch_ticks(case: dict, result) -> int:
    """Ticks of one batch grasp (runs in the worker: only the count comes back)."""
    return len(result.series.ticks)


def measure(repeat: int = 5, hold_s: float = 1.0, batch: int = 32, jobs_list=(1, 2),
            scheduler_workers: int = 2, scheduler: str | None = None,
            cpu_time: bool = False) -> dict:
    """Return every figure of the benchmark (see the module docstring)."""
    clock = time.process_time if cpu_time else time.perf_counter
    from gripper_ros.core.config import load_config
    from gripper_ros.core.runtime.engine import (dask_cluster, local_client, map_cases,
                                                 remote_client)
    from gripper_ros.core.runtime.headless import simulate_grasps
    config = load_config()
    out = {'platform': platform.platform(), 'cpus': os.cpu_count(), 'hold_s': hold_s,
           'clock': 'cpu' if cpu_time else 'wall', 'grasps': []}
    t0 = time.perf_counter()
    _ticks(config, *TABLE_V[0], hold_s, traced=False)
    _ticks(config, *TABLE_V[0], 0.0, traced=True)
    _ticks(config, *TABLE_V[0], 0.0, traced=False, captured=True)
    out['first_call_s'] = time.perf_counter() - t0
    _ticks(config, *UNKNOWN_MASS, hold_s, traced=False)
    for width_m, mass_kg in TABLE_V + (UNKNOWN_MASS,):
        row = {'width_m': width_m, 'mass_kg': mass_kg}
        for name, traced, captured in (('compiled', False, False),
                                       ('python_driven', True, False),
                                       ('traced', False, True)):
            rates = []
            for _ in range(repeat if not traced else max(1, repeat // 5)):
                start = clock()
                ticks = _ticks(config, width_m, mass_kg, hold_s, traced, captured)
                rates.append(ticks / (clock() - start))
            row['ticks'] = ticks
            row[f'{name}_ticks_per_s'] = statistics.median(rates)
        row['compiled_over_python_driven'] = \
            row['compiled_ticks_per_s'] / row['python_driven_ticks_per_s']
        row['traced_over_python_driven'] = \
            row['traced_ticks_per_s'] / row['python_driven_ticks_per_s']
        out['grasps'].append(row)
    cases = [{'width_m': TABLE_V[i % 3][0], 'mass_kg': TABLE_V[i % 3][1], 'hold_s': hold_s}
             for i in range(batch)]
    out['batch'], out['engine_start_s'] = [], {}
    _time_batch(out, config, cases, 'this process', 1, None)
    for jobs in jobs_list:
        start = time.perf_counter()
        client = local_client(jobs)
        simulate_grasps(config, cases, summarize=_batch_ticks, scheduler=client)
        out['engine_start_s'][f'local {jobs}'] = time.perf_counter() - start
        _time_batch(out, config, cases, 'local cluster', jobs, client)
    items = list(range(OVERHEAD_ITEMS))
    start = time.perf_counter()
    map_cases(abs, items, scheduler=local_client(max(jobs_list)),
              chunks_per_job=OVERHEAD_ITEMS)
    out['per_task_overhead_us'] = (time.perf_counter() - start) / OVERHEAD_ITEMS * 1e6
    if scheduler is not None or scheduler_workers:
        with contextlib.ExitStack() as stack:
            start = time.perf_counter()
            address = scheduler or stack.enter_context(dask_cluster(scheduler_workers))
            client = remote_client(address)
            workers = len(client.nthreads())
            simulate_grasps(config, cases, summarize=_batch_ticks, scheduler=client)
            out['engine_start_s'][f'scheduler {workers}'] = time.perf_counter() - start
            _time_batch(out, config, cases, 'scheduler', workers, client)
    base = out['batch'][0]['ticks_per_s']
    for row in out['batch']:
        row['over_first'] = row['ticks_per_s'] / base
    return out


def _time_batch(out: dict, config, cases: list, engine: str, workers: int, client) -> None:
    """Time the batch on one engine: the median of BATCH_RUNS runs."""
    from gripper_ros.core.runtime.headless import simulate_grasps
    walls = []
    for _ in range(BATCH_RUNS):
        start = time.perf_counter()
        ticks = sum(simulate_grasps(config, cases, jobs=1, summarize=_batch_ticks,
                                    scheduler=client))
        walls.append(time.perf_counter() - start)
    wall_s = statistics.median(walls)
    out['batch'].append({'engine': engine, 'workers': workers, 'grasps': len(cases),
                         'ticks': ticks, 'wall_s': wall_s, 'ticks_per_s': ticks / wall_s})


def report(r: dict) -> str:
    """Return the figures as a table."""
    per = 'CPU s' if r.get('clock') == 'cpu' else 's'
    lines = [f'bench_headless: {r["platform"]}, {r["cpus"]} cores; each grasp held on for '
             f'{r["hold_s"]:g} s; first calls (cache load, warm-up) {r["first_call_s"]:.2f} s'
             + ('; the grasps timed in CPU time' if per != 's' else ''),
             f'{"width m":>8s} {"mass kg":>8s} {"ticks":>7s} {"compiled ticks/" + per:>17s} '
             f'{"python-driven ticks/s":>22s} {"ratio":>7s} {"traced ticks/s":>15s} '
             f'{"/ python-driven":>16s}']
    for g in r['grasps']:
        lines.append(f'{g["width_m"]:8.3f} {g["mass_kg"]:8.2f} {g["ticks"]:7d} '
                     f'{g["compiled_ticks_per_s"]:17,.0f} {g["python_driven_ticks_per_s"]:22,.0f} '
                     f'{g["compiled_over_python_driven"]:7.1f} {g["traced_ticks_per_s"]:15,.0f} '
                     f'{g["traced_over_python_driven"]:16.2f}')
    starts = ', '.join(f'{k} worker(s) {v:.2f} s' for k, v in r['engine_start_s'].items())
    lines.append(f'batch engine (Dask): started and warmed up (the batch once) in {starts} (not '
                 f'in the figures below); {r["per_task_overhead_us"]:.0f} us a task')
    lines.append(f'{"engine":>14s} {"workers":>8s} {"grasps":>7s} {"ticks":>9s} {"wall s":>8s} '
                 f'{"ticks/s":>12s} {"x this process":>15s}')
    for b in r['batch']:
        lines.append(f'{b["engine"]:>14s} {b["workers"]:8d} {b["grasps"]:7d} {b["ticks"]:9d} '
                     f'{b["wall_s"]:8.3f} {b["ticks_per_s"]:12,.0f} {b["over_first"]:15.2f}')
    return '\n'.join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='bench_headless', description=__doc__.split('\n')[0])
    parser.add_argument('--repeat', type=int, default=5, help='timed runs per grasp (median)')
    parser.add_argument('--hold-s', type=float, default=1.0,
                        help='seconds held on after HOLDING (default 1)')
    parser.add_argument('--batch', type=int, default=32, help='grasps in the batch')
    parser.add_argument('--jobs', type=int, nargs='+', default=[1, 2],
                        help='worker processes of each local-cluster run (default 1 2)')
    parser.add_argument('--scheduler-workers', type=int, default=2,
                        help='start dask scheduler and this many dask workers here for the '
                             'scheduler run (default 2; 0 = no scheduler run)')
    parser.add_argument('--scheduler', metavar='tcp://HOST:8786',
                        help='time the scheduler run on this existing cluster instead')
    parser.add_argument('--cpu-time', action='store_true',
                        help="time the single grasps in this process's CPU time, not wall time")
    parser.add_argument('--json', action='store_true', help='print JSON')
    args = parser.parse_args(argv)
    for name in ('repeat', 'batch'):
        if getattr(args, name) < 1:
            parser.error(f'--{name.replace("_", "-")} must be >= 1')
    if not (args.hold_s >= 0.0 and args.hold_s <= 60.0):
        parser.error('--hold-s must be in [0, 60]')
    if any(j < 1 for j in args.jobs) or args.scheduler_workers < 0:
        parser.error('--jobs must be >= 1 and --scheduler-workers >= 0')
    from gripper_ros.core.runtime.engine import options_problem
    if options_problem(scheduler=args.scheduler):
        parser.error(options_problem(scheduler=args.scheduler))
    result = measure(args.repeat, args.hold_s, args.batch, args.jobs, args.scheduler_workers,
                     args.scheduler, args.cpu_time)
    print(json.dumps(result, indent=2) if args.json else report(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
