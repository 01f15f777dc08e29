"""bench_launch_stop: whether Ctrl-C always stops ``ros2 launch gripper_ros gripper.launch.py``.

    ros2 run gripper_ros bench_launch_stop                  # 30 launches, one process each
    ros2 run gripper_ros bench_launch_stop --runs 10 --per-node

Each run starts ``ros2 launch`` in a process group of its own (as a shell starts a foreground
job), waits for ``grasp``, places the 0.1 m / 0.75 kg object of Table V and grasps it (HOLDING),
then sends SIGINT to the whole group, as Ctrl-C in a terminal does, and times until no process
of the group is left (launch and every process it started). A run counts as stopped when that
takes at most ``--limit`` seconds (default 5: launch's own ``sigterm_timeout``, after which it
would escalate to SIGTERM). The report gives, over the runs: how many stopped within the limit,
the median and the longest time to stop, and each process's exit as launch reported it (a
``process has died`` line names an exit code other than 0). Without a terminal, launch runs
non-interactive and also sends SIGINT to each process itself; the processes take the first.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence

from gripper_ros.bench.common import (call, group_pids, ros2_launch_command, run_bench,
                                      SpunNode)
from gripper_ros.bench.pingpong import BenchError

GRASP = (0.10, 0.75)                   # Table V's third object
UP_TIMEOUT_S = 120.0
KILL_AFTER_S = 20.0                    # a group still there this long after SIGINT is killed
DIED = re.compile(r'process has died \[pid \d+, exit code (-?\d+)')


def _grasp(namespace: str) -> str:
    """Grasp the object through the launched graph; return its outcome's name."""
    from gripper_interfaces.srv import Grasp, SetObject
    from gripper_ros.wire import GRAPH_NOT_READY, Outcome, SERVICE_GRASP, SERVICE_SET_OBJECT
    spun = SpunNode('bench_launch_stop_client', namespace)
    try:
        place = spun.node.create_client(SetObject, SERVICE_SET_OBJECT)
        grasp = spun.node.create_client(Grasp, SERVICE_GRASP)
        spun.start()
        if not (place.wait_for_service(timeout_sec=UP_TIMEOUT_S)
                and grasp.wait_for_service(timeout_sec=UP_TIMEOUT_S)):
            raise BenchError(f'/{namespace}/grasp did not come up within {UP_TIMEOUT_S:g} s')
        placed = call(place, SetObject.Request(width_m=GRASP[0]), 30.0)
        if not placed.success:
            raise BenchError(f'set_object: {placed.message}')
        deadline = time.monotonic() + UP_TIMEOUT_S
        while True:                   # one process per node: refused until all are heard
            answer = call(grasp, Grasp.Request(width_m=GRASP[0], mass_kg=GRASP[1]), 120.0)
            if GRAPH_NOT_READY not in answer.message or time.monotonic() > deadline:
                return Outcome(answer.outcome).name
            time.sleep(0.2)
    finally:
        spun.close()


def one_run(index: int, per_node: bool, limit_s: float, folder: str) -> Dict[str, Any]:
    """Launch, grasp, SIGINT the group; return the time until the group was gone."""
    namespace = f'launch_stop_{os.getpid()}_{index}'
    log_path = os.path.join(folder, f'launch_{index}.log')
    with open(log_path, 'w') as log:
        proc = subprocess.Popen(ros2_launch_command(namespace, per_node), stdin=subprocess.DEVNULL,
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    outcome, killed, error = '', False, ''
    try:
        try:
            outcome = _grasp(namespace)
        except BenchError as exc:         # still stopped and timed; the log says why
            error = str(exc)
        processes = len(group_pids(proc.pid))
        t0 = time.perf_counter()
        if processes:
            os.killpg(proc.pid, signal.SIGINT)
        while group_pids(proc.pid):
            if time.perf_counter() - t0 > KILL_AFTER_S:
                os.killpg(proc.pid, signal.SIGKILL)
                killed = True
                break
            time.sleep(0.01)
        stop_s = time.perf_counter() - t0
    finally:
        if proc.poll() is None and group_pids(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    with open(log_path) as log:
        text = log.read()
    if error:
        error += ': ' + ' | '.join(text.strip().splitlines()[-5:])
    return {'run': index, 'outcome': outcome, 'error': error, 'processes': processes,
            'stop_s': stop_s,
            'within_limit': stop_s <= limit_s and not killed, 'killed': killed,
            'launch_exit': proc.returncode,
            'died_codes': [int(c) for c in DIED.findall(text)],
            'escalated': 'escalating to' in text}


def measure(runs: int, per_node: bool, limit_s: float) -> Dict[str, Any]:
    """Run ``runs`` launches; return each and the summary."""
    results: List[Dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix='bench_launch_stop_') as folder:
        for i in range(runs):
            r = one_run(i, per_node, limit_s, folder)
            results.append(r)
            print(f'run {i + 1:2d}/{runs}: {r["outcome"] or "no grasp: " + r["error"]}, '
                  f'{r["processes"]} processes, gone '
                  f'{r["stop_s"]:.2f} s after SIGINT'
                  + (f', died {r["died_codes"]}' if r['died_codes'] else '')
                  + (', ESCALATED' if r['escalated'] else '')
                  + (', KILLED' if r['killed'] else ''), file=sys.stderr, flush=True)
    stops = [r['stop_s'] for r in results]
    return {'runs': runs, 'per_node': per_node, 'limit_s': limit_s,
            'within_limit': sum(r['within_limit'] for r in results),
            'holding': sum(r['outcome'] == 'HOLDING' for r in results),
            'median_stop_s': statistics.median(stops), 'max_stop_s': max(stops),
            'nonzero_exits': sum(bool(r['died_codes']) for r in results),
            'results': results}


def format_report(r: Dict[str, Any]) -> str:
    layout = 'per_node:=true' if r['per_node'] else 'one process (the default)'
    return '\n'.join([
        f'bench_launch_stop: {r["runs"]} x (ros2 launch gripper_ros gripper.launch.py, '
        f'{layout}; grasp; SIGINT to the process group)',
        f'  grasps HOLDING:                {r["holding"]}/{r["runs"]}',
        f'  every process gone within {r["limit_s"]:g} s: {r["within_limit"]}/{r["runs"]}',
        f'  time to stop: median {r["median_stop_s"]:.2f} s, longest {r["max_stop_s"]:.2f} s',
        f'  runs with a process that exited non-zero: {r["nonzero_exits"]}'])


def main(args: Optional[Sequence[str]] = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    p = argparse.ArgumentParser(prog='bench_launch_stop', description=__doc__.splitlines()[0])
    p.add_argument('--runs', type=int, default=30, help='launches (default 30)')
    p.add_argument('--per-node', action='store_true', help='per_node:=true')
    p.add_argument('--limit', type=float, default=5.0,
                   help='seconds within which every process must be gone (default 5)')
    p.add_argument('--json', action='store_true', help='print JSON instead of the summary')
    opts = p.parse_args(list(sys.argv[1:] if args is None else args))
    if opts.runs < 1 or not (0.0 < opts.limit <= 60.0):
        print('bench_launch_stop: error: --runs must be >= 1 and --limit in (0, 60]',
              file=sys.stderr)
        return 2
    return run_bench('bench_launch_stop', lambda: _run(opts))


def _run(opts: argparse.Namespace) -> int:
    """Measure, print the report; 0 if every launch stopped within the limit."""
    report = measure(opts.runs, opts.per_node, opts.limit)
    print(json.dumps(report, indent=2) if opts.json else format_report(report))
    return 0 if report['within_limit'] == report['runs'] else 1


if __name__ == '__main__':
    sys.exit(main())
