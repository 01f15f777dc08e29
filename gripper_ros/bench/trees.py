"""bench_trees: the headless grasp and the contact sweep of several checkouts, side by side.

    ros2 run gripper_ros bench_trees BASE_TREE [OTHER_TREE ...] [--rounds 3] [--grasps 15]
    ros2 run gripper_ros bench_trees /tmp/base . --sweep-rounds 1 --sweep-args --quick

Each tree is a checkout of this package set up with the same venv (``scripts/setup.sh``); its
code and its shipped configuration run in a child process with the tree first on ``PYTHONPATH``
and its ``install/gripper_ros`` first on ``AMENT_PREFIX_PATH``. The trees take turns, round
by round, so that a change of the machine's load falls on all of them alike, and every figure is
CPU time of the same work (a loaded machine inflates it alike for each tree, wall time it does
not):

- headless: ``simulate_grasp`` of the paper's Table V 50 mm / 1.69 kg object held ``--hold-s``
  (1 s: 11,314 ticks), ``--grasps`` timed calls after one untimed (numba loads its code then),
  each timed by ``time.process_time``: ticks per CPU second, best and median.
- sweep: ``contact_sweep --jobs 1`` (its options after ``--sweep-args``), the user + system CPU
  of the process and its workers; and whether its printed table is the same line for line as
  the first tree's (only the line naming the wall time may differ).

Printed: each figure per tree and round, and its ratio to the first tree's (the baseline).
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import resource
import statistics
import subprocess
import sys
import time

GRASP = (0.05, 1.69)
"""Table V's 50 mm / 1.69 kg object (width m, mass kg)."""

_HEADLESS = """
import json, sys, time
from gripper_ros.core.config import load_config
from gripper_ros.core.runtime.headless import simulate_grasp
config = load_config()
width_m, mass_kg, hold_s, grasps = float(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), \\
    int(sys.argv[4])
grasp = simulate_grasp(config, width_m, mass_kg, hold_s=hold_s)
ticks = len(grasp.series.ticks) if hasattr(grasp, 'series') else len(grasp.t_ns)   # older trees
cpu = []
for _ in range(grasps):
    t0 = time.process_time()
    simulate_grasp(config, width_m, mass_kg, hold_s=hold_s)
    cpu.append(time.process_time() - t0)
print(json.dumps({'ticks': ticks, 'cpu_s': cpu}))
"""


def _env(tree: Path) -> dict:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, (str(tree), env.get('PYTHONPATH'))))
    env['AMENT_PREFIX_PATH'] = os.pathsep.join(filter(None, (      # the tree's shipped config
        str(tree / 'install' / 'gripper_ros'), env.get('AMENT_PREFIX_PATH'))))
    return env


class TreeFailed(Exception):
    """A tree's child process failed: its command and the last lines it wrote."""


def _run(tree: Path, command: list[str]) -> str:
    run = subprocess.run([sys.executable, *command], cwd=tree, env=_env(tree),
                         capture_output=True, text=True)
    if run.returncode != 0:
        tail = ' | '.join((run.stderr or run.stdout).strip().splitlines()[-3:])
        raise TreeFailed(f'{tree}: exit {run.returncode}: {tail}')
    return run.stdout


def headless(tree: Path, hold_s: float, grasps: int) -> dict:
    """Time the Table V grasp in a child process running ``tree``'s code."""
    out = _run(tree, ['-c', _HEADLESS, str(GRASP[0]), str(GRASP[1]), str(hold_s), str(grasps)])
    result = json.loads(out.strip().splitlines()[-1])
    rates = [result['ticks'] / s for s in result['cpu_s']]
    return {'ticks': result['ticks'], 'best': max(rates), 'median': statistics.median(rates)}


def sweep(tree: Path, sweep_args: list[str]) -> dict:
    """Run ``tree``'s contact sweep in one worker; its CPU (children included) and its table."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = _run(tree, ['-m', 'gripper_ros.apps.contact_sweep', '--jobs', '1', '--quiet',
                      *sweep_args])
    wall_s = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    table = [line for line in out.splitlines() if ' s wall on ' not in line]
    return {'cpu_s': (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            'wall_s': wall_s, 'table': table}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='bench_trees', description=__doc__.splitlines()[0])
    parser.add_argument('trees', nargs='+', type=Path,
                        help='checkouts, the first the baseline the ratios divide by')
    parser.add_argument('--rounds', type=int, default=3, help='headless rounds (trees in turn)')
    parser.add_argument('--grasps', type=int, default=15, help='timed grasps per round')
    parser.add_argument('--hold-s', type=float, default=1.0, help='hold after HOLDING (s)')
    parser.add_argument('--sweep-rounds', type=int, default=1,
                        help='contact sweeps per tree (0: none)')
    parser.add_argument('--sweep-args', nargs=argparse.REMAINDER, default=[],
                        help='contact_sweep options (last on the line)')
    args = parser.parse_args(argv)
    trees = [t.resolve() for t in args.trees]
    missing = [str(t) for t in trees if not (t / 'gripper_ros' / '__init__.py').is_file()]
    if missing:
        print(f'bench_trees: not a checkout of gripper_ros: {", ".join(missing)}',
              file=sys.stderr)
        return 2
    names = [f'{t.name}@{_head(t)}' for t in trees]
    try:
        _bench(args, trees, names)
    except TreeFailed as exc:
        print(f'bench_trees: {exc}', file=sys.stderr)
        return 1
    return 0


def _bench(args, trees: list[Path], names: list[str]) -> None:
    print(f'trees: {", ".join(names)} (baseline: the first)', flush=True)
    print(f'headless: {GRASP[0]:g} m / {GRASP[1]:g} kg held {args.hold_s:g} s, '
          f'{args.grasps} timed grasps a round, ticks per CPU second', flush=True)
    best = {n: [] for n in names}
    for r in range(1, args.rounds + 1):
        figures = {n: headless(t, args.hold_s, args.grasps) for n, t in zip(names, trees)}
        base = figures[names[0]]
        for n in names:
            f = figures[n]
            best[n].append(f['best'])
            print(f'  round {r} {n:>28s}: {f["ticks"]:6d} ticks, best {f["best"]:10,.0f} '
                  f'({f["best"] / base["best"]:.2f}x), median {f["median"]:10,.0f} '
                  f'({f["median"] / base["median"]:.2f}x)', flush=True)
    if args.rounds > 1:
        top = {n: max(v) for n, v in best.items()}
        print('  best of all rounds: ' + ', '.join(
            f'{n} {top[n]:,.0f} ({top[n] / top[names[0]]:.2f}x)' for n in names), flush=True)
    if args.sweep_rounds > 0:
        print(f'contact_sweep --jobs 1 {" ".join(args.sweep_args)}: CPU s (user + system, '
              'workers included)', flush=True)
        tables = {}
        for r in range(1, args.sweep_rounds + 1):
            figures = {n: sweep(t, args.sweep_args) for n, t in zip(names, trees)}
            base = figures[names[0]]
            for n in names:
                f = figures[n]
                tables.setdefault(n, f['table'])
                same = 'same table' if f['table'] == base['table'] else 'TABLE DIFFERS'
                print(f'  round {r} {n:>28s}: {f["cpu_s"]:7.1f} s CPU '
                      f'({f["cpu_s"] / base["cpu_s"]:.2f}x), {f["wall_s"]:7.1f} s wall, {same}',
                      flush=True)


def _head(tree: Path) -> str:
    try:
        return subprocess.run(['git', '-C', str(tree), 'rev-parse', '--short', 'HEAD'],
                              check=True, capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return '?'


if __name__ == '__main__':
    sys.exit(main())
