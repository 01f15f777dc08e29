"""bench_soak: many grasps against one serving graph, as a user's program would send them.

    ros2 run gripper_ros bench_soak                         # 200 grasps over the Table V objects
    ros2 run gripper_ros bench_soak --grasps 20 --objects cheap --json-file soak.json

This process serves the graph exactly as ``grasp_demo --serve`` does (:class:`GripperGraph`,
one bag per grasp via ``record_every_grasp``); a **separate client process** (this module with
``--client-worker``, the calls of ``grasp_client``: ``/gripper/sim/set_object`` then
``/gripper/grasp`` over DDS) sends the grasps one after another. ``--client grasp_client`` runs
the real ``grasp_client`` executable once per grasp instead (slower: one process start each).

For every grasp it records: the response, the wall time of the ``/gripper/grasp`` call, the
messages the nodes published during the grasp (the nodes' own counters,
``GripperGraph.published_counts()``, read after the object is placed and after the bag is
closed), the messages in that grasp's bag (read back from the MCAP file by the client process,
so that reading bags does not count against the server's memory), the bag's simulated
duration, and the server's resident memory (VmRSS of /proc/self/status).

It reports grasps, failures, count mismatches, RSS at start / after warm-up / at the end and
the growth after warm-up (with a least-squares slope per grasp), per-grasp wall time (median of
the first 10 and of the last 10, and their ratio), and whether identical requests gave
identical simulated durations and message counts. Bags go to a temporary folder and are deleted
once checked unless ``--output``/``--keep-bags`` is given.

Run it on a ROS_DOMAIN_ID nobody else uses: another process on the same domain that places
objects or requests grasps changes what this graph does (scripts/test.sh holds a lock file per
domain in /tmp/gripper_ros_domains.$UID/; ``flock -n .../67.lock bench_soak`` holds one too).

Exit codes: 0 all grasps held and every bag matched, 1 a grasp failed or a bag did not match,
2 bad arguments or the graph/client did not come up, 130 interrupted.
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass, field
import json
import os
from pathlib import Path
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from gripper_ros.studies.paper import PAPER_OBJECTS

# cheap: wide objects, short strokes (~1200-1400 plant ticks per grasp instead of 1500-2000)
CHEAP_OBJECTS = ((0.10, 0.75), (0.12, 0.5), (0.14, 1.0))
OBJECT_SETS = {'paper': PAPER_OBJECTS, 'cheap': CHEAP_OBJECTS}
DRIFT_WINDOW = 10
BAG_CLOSED_BOUND_S = 120.0
"""A bound on a grasp's bag closing after its answer: milliseconds unless the machine is loaded,
and a bag not closed by then counts as a mismatch."""


class SoakError(RuntimeError):
    """The graph or the client process did not come up or stopped answering."""


def rss_kb() -> int:
    """Resident set size of this process in KiB (VmRSS of /proc/self/status)."""
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except OSError:
        pass
    import resource  # fallback: the peak, not the current RSS
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def open_fds() -> int:
    """Open file descriptors of this process (entries of /proc/self/fd); -1 where unknown."""
    try:
        return len(os.listdir('/proc/self/fd'))
    except OSError:
        return -1


@dataclass
class GraspRow:
    index: int
    width_m: float
    mass_kg: float
    success: bool
    outcome: str
    message: str
    wall_s: float
    rss_kb: int
    ticks: int
    published: dict
    recorded: dict
    counts_match: bool
    sim_duration_ns: int
    bag: str
    fds: int = -1


@dataclass
class SoakReport:
    grasps: int
    failures: int
    count_mismatches: int
    warmup: int
    objects: list
    executor: str
    client: str
    rss_start_kb: int
    rss_warm_kb: int
    rss_end_kb: int
    rss_growth_after_warmup_kb: int
    rss_slope_after_warmup_kb_per_grasp: float
    wall_first_median_s: float
    wall_last_median_s: float
    wall_drift_ratio: float
    us_per_tick_first_median: float
    us_per_tick_last_median: float
    tick_drift_ratio: float
    identical_requests_identical: bool
    variants_per_object: dict
    total_wall_s: float
    machine: dict
    rows: list = field(default_factory=list)
    fds_start: int = -1
    fds_warm: int = -1
    fds_end: int = -1


# ------------------------------------------------------------------ client process
def client_worker() -> int:
    """Run the client side, in its own process: JSON lines in on stdin, out on stdout.

    ``{"op": "place", "width": w}`` -> sim/set_object (open fingers; a held object is
    released first);
    ``{"op": "grasp", "width": w, "mass": m}`` -> /gripper/grasp (the response's fields);
    ``{"op": "check", "bag": path}`` -> the bag's message counts and simulated span;
    ``{"op": "quit"}``. The calls are those of ``grasp_client``.
    """
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from gripper_interfaces.srv import Grasp, SetObject

    from gripper_ros.nodes.services import call_spinning, call_until_answered
    from gripper_ros.wire import Outcome

    out = sys.stdout
    sys.stdout = sys.stderr          # nothing but protocol lines on the real stdout

    def say(obj):
        out.write(json.dumps(obj) + '\n')
        out.flush()

    from std_srvs.srv import Trigger

    from gripper_ros.wire import (DEFAULT_NAMESPACE, SERVICE_GRASP, SERVICE_RELEASE,
                                  SERVICE_SET_OBJECT)
    rclpy.init(args=[])
    node = rclpy.create_node('bench_soak_client', namespace=DEFAULT_NAMESPACE)
    try:
        grasp = node.create_client(Grasp, SERVICE_GRASP)
        place = node.create_client(SetObject, SERVICE_SET_OBJECT)
        release = node.create_client(Trigger, SERVICE_RELEASE)
        for client in (grasp, place, release):
            if not client.wait_for_service(timeout_sec=60.0):
                say({'ready': False, 'error': f'{client.srv_name} not available'})
                return 2
        say({'ready': True, 'pid': os.getpid()})
        for line in sys.stdin:
            cmd = json.loads(line)
            op = cmd.get('op')
            if op == 'quit':
                break
            if op == 'place':
                request = SetObject.Request(width_m=float(cmd['width']), open_fingers=True)
                r = call_until_answered(node, place, request, 60.0)
                if r is not None and not r.success and 'is held' in r.message:
                    call_spinning(node, release, Trigger.Request(), 120.0)   # as grasp_client does
                    r = call_until_answered(node, place, request, 60.0)
                say({'ok': r is not None and r.success,
                     'message': 'no answer' if r is None else r.message})
            elif op == 'grasp':
                r = call_spinning(node, grasp, Grasp.Request(width_m=float(cmd['width']),
                                                             mass_kg=float(cmd['mass'])),
                                  float(cmd.get('timeout', 600.0)))
                if r is None:
                    say({'success': False, 'outcome': 'NO_ANSWER', 'message': 'no answer'})
                else:
                    outcome = Outcome(r.outcome).name if r.outcome in \
                        Outcome._value2member_map_ else str(r.outcome)
                    say({'success': bool(r.success), 'outcome': outcome, 'message': r.message,
                         'grasp_id': int(r.grasp_id), 'switch_time_s': r.switch_time_s,
                         'final_force_n': r.final_force_n})
            elif op == 'check':
                say(_check_bag(cmd['bag']))
            else:
                say({'error': f'unknown op {op!r}'})
        return 0
    except KeyboardInterrupt:
        return 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _check_bag(path: str) -> dict:
    from gripper_ros.bags.reader import BagError, read_bag
    try:
        bag = read_bag(path)
    except BagError as exc:
        return {'error': str(exc), 'counts': {}, 'truncated': True, 'span_ns': 0}
    return {'counts': bag.counts(), 'truncated': bool(bag.truncated),
            'span_ns': int(bag.duration_ns)}


class _WorkerClient:
    def __init__(self, env=None, timeout_s: float = 120.0):
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'gripper_ros.bench.soak', '--client-worker'],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1,
            env=env or os.environ.copy())
        hello = self._read(timeout_s)
        if not hello.get('ready'):
            self.close()
            raise SoakError(f'client process did not come up: {hello.get("error", hello)}')
        self.pid = hello['pid']

    def _read(self, timeout_s: float) -> dict:
        import select
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        line = self.proc.stdout.readline() if ready else ''
        if not line:
            raise SoakError(f'client process did not answer within {timeout_s:g} s '
                            f'(exit code {self.proc.poll()})')
        return json.loads(line)

    def ask(self, timeout_s: float = 600.0, **cmd) -> dict:
        self.proc.stdin.write(json.dumps(cmd) + '\n')
        self.proc.stdin.flush()
        return self._read(timeout_s)

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write('{"op": "quit"}\n')
                self.proc.stdin.flush()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


# ------------------------------------------------------------------ the soak
def _grasp_client_exe(width: float, mass: float, timeout_s: float) -> dict:
    """One grasp through the grasp_client executable (the object is placed by the caller)."""
    r = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client',
                        '--width', repr(width), '--mass', repr(mass), '--no-place'],
                       capture_output=True, text=True, timeout=timeout_s, env=os.environ.copy())
    fields = dict(line.split(': ', 1) for line in r.stdout.splitlines() if ': ' in line)
    return {'success': r.returncode == 0, 'outcome': fields.get('outcome', f'exit {r.returncode}'),
            'message': fields.get('message', r.stderr.strip()[-200:])}


def run_soak(graph, worker: _WorkerClient, objects, grasps: int, bag_root: Path,
             keep_bags: bool = False, client: str = 'worker', warmup: int = 10,
             grasp_timeout_s: float = 300.0, progress=None, rows: list | None = None,
             marks: dict | None = None) -> tuple[list, dict]:
    """Send ``grasps`` grasps (cycling over ``objects``); returns (rows, rss marks).

    ``rows``/``marks``, when given, are filled in place, so a caller still has the grasps done
    so far when a SoakError ends the run.
    """
    from gripper_ros.nodes.recording import ServeRecorder
    from gripper_ros.nodes.services import wait_until
    from gripper_ros.wire import LOOP_TOPICS, TOPIC_TICK, qualified
    loop = [qualified(graph.namespace, t) for t in LOOP_TOPICS]
    recorder = ServeRecorder(graph, bag_root)
    rows = [] if rows is None else rows
    marks = {} if marks is None else marks
    marks['start'] = rss_kb()
    marks['fds_start'] = open_fds()
    for i in range(grasps):
        width, mass = objects[i % len(objects)]
        if client == 'worker':
            placed = worker.ask(op='place', width=width, timeout_s=60.0)
            if not placed.get('ok'):
                raise SoakError(f'set_object refused: {placed.get("message")}')
        else:
            graph.set_object(width)
        graph.wait_still()          # set_object's tick is answered before the grasp
        before = graph.published_counts()
        n_bags = len(recorder.bags)
        t0 = time.perf_counter()
        if client == 'worker':
            resp = worker.ask(op='grasp', width=width, mass=mass, timeout=grasp_timeout_s,
                              timeout_s=grasp_timeout_s + 10.0)
        else:
            resp = _grasp_client_exe(width, mass, grasp_timeout_s + 30.0)
        wall = time.perf_counter() - t0
        # the tap lets go of a bag just before its writer finishes it: wait for the finished
        # file, else the check may read it mid-close and call it truncated
        closed = wait_until(lambda: len(recorder.bags) > n_bags and not recorder.recording
                            and _finished(recorder.bags[-1]), BAG_CLOSED_BOUND_S)
        # every lockstep message published from the grasp's request on (state topics are
        # sampled on the grid of simulated time, and the request's own status precedes it)
        published = {qualified(graph.namespace, t): n - before.get(t, 0)
                     for t, n in graph.published_counts().items()
                     if qualified(graph.namespace, t) in loop}
        bag = recorder.bags[-1] if len(recorder.bags) > n_bags else None
        check = worker.ask(op='check', bag=str(bag), timeout_s=120.0) if bag and closed else \
            {'counts': {}, 'span_ns': 0, 'truncated': True}
        recorded = {t: check['counts'].get(t, 0) for t in loop}
        match = closed and not check['truncated'] and recorded == published
        if bag is not None and not keep_bags:
            shutil.rmtree(bag, ignore_errors=True)
        row = GraspRow(i + 1, width, mass, bool(resp.get('success')), resp.get('outcome', '?'),
                       resp.get('message', ''), wall, rss_kb(),
                       published.get(qualified(graph.namespace, TOPIC_TICK), 0), published,
                       recorded, match,
                       int(check['span_ns']), str(bag) if keep_bags else '', open_fds())
        rows.append(row)
        if i + 1 == min(warmup, grasps):
            marks['warm'] = row.rss_kb
            marks['fds_warm'] = row.fds
        if progress is not None:
            progress(row)
    marks.setdefault('warm', marks['start'])
    marks['end'] = rows[-1].rss_kb if rows else marks['start']
    recorder.close()
    return rows, marks


def _finished(bag: Path) -> bool:
    """Whether every MCAP file of ``bag`` ends with the magic its writer writes last."""
    from gripper_ros.bags.mcap_file import MAGIC
    files = list(Path(bag).glob('*.mcap'))
    for f in files:
        try:
            with open(f, 'rb') as stream:
                stream.seek(-len(MAGIC), os.SEEK_END)
                if stream.read() != MAGIC:
                    return False
        except OSError:
            return False
    return bool(files)


def _slope(xs, ys) -> float:
    n = len(xs)
    if n < 2:
        return 0.0
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else 0.0


def summarise(rows: list, marks: dict, objects, warmup: int, executor: str, client: str,
              total_wall_s: float) -> SoakReport:
    w = min(DRIFT_WINDOW, len(rows))
    walls = [r.wall_s for r in rows]
    per_tick = [r.wall_s / r.ticks * 1e6 if r.ticks else 0.0 for r in rows]
    first, last = statistics.median(walls[:w]), statistics.median(walls[-w:])
    tfirst, tlast = statistics.median(per_tick[:w]), statistics.median(per_tick[-w:])
    variants = {}
    for r in rows:
        key = f'{r.width_m:g} m, {r.mass_kg:g} kg'
        variants.setdefault(key, set()).add(
            (r.outcome, r.sim_duration_ns, tuple(sorted(r.published.items()))))
    after = [r for r in rows if r.index > warmup]
    return SoakReport(
        grasps=len(rows), failures=sum(not r.success for r in rows),
        count_mismatches=sum(not r.counts_match for r in rows), warmup=warmup,
        objects=[list(o) for o in objects], executor=executor, client=client,
        rss_start_kb=marks['start'], rss_warm_kb=marks['warm'], rss_end_kb=marks['end'],
        rss_growth_after_warmup_kb=marks['end'] - marks['warm'],
        rss_slope_after_warmup_kb_per_grasp=_slope([r.index for r in after],
                                                   [r.rss_kb for r in after]),
        wall_first_median_s=first, wall_last_median_s=last,
        wall_drift_ratio=last / first if first else 0.0,
        us_per_tick_first_median=tfirst, us_per_tick_last_median=tlast,
        tick_drift_ratio=tlast / tfirst if tfirst else 0.0,
        identical_requests_identical=all(len(v) == 1 for v in variants.values()),
        variants_per_object={k: len(v) for k, v in variants.items()},
        total_wall_s=total_wall_s,
        machine={'python': platform.python_version(), 'cpus': os.cpu_count(),
                 'load_avg': list(os.getloadavg()),
                 'rmw': os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)')},
        rows=[asdict(r) for r in rows],
        fds_start=marks.get('fds_start', -1),
        fds_warm=marks.get('fds_warm', rows[0].fds if rows else -1),
        fds_end=rows[-1].fds if rows else -1)


def format_report(rep: SoakReport) -> str:
    mb = 1 / 1024
    lines = [
        f'bench_soak: {rep.grasps} grasps over {len(rep.objects)} objects '
        f'({", ".join(f"{w:g} m/{m:g} kg" for w, m in rep.objects)}), executor {rep.executor}, '
        f'client {rep.client}, bags recorded, {rep.total_wall_s:.1f} s wall',
        f'grasps {rep.grasps}   failures {rep.failures}   bag count mismatches '
        f'{rep.count_mismatches}',
        f'RSS of the serving process: start {rep.rss_start_kb * mb:.1f} MiB, after warm-up '
        f'({min(rep.warmup, rep.grasps)} grasps) {rep.rss_warm_kb * mb:.1f} MiB, '
        f'end {rep.rss_end_kb * mb:.1f} MiB'
        f'; growth after warm-up {rep.rss_growth_after_warmup_kb * mb:+.2f} MiB '
        f'(slope {rep.rss_slope_after_warmup_kb_per_grasp:+.1f} KiB/grasp), since start '
        f'{(rep.rss_end_kb - rep.rss_start_kb) * mb:+.1f} MiB',
        f'open file descriptors of the serving process: start {rep.fds_start}, after warm-up '
        f'{rep.fds_warm}, end {rep.fds_end}',
        f'wall per grasp: median first {min(DRIFT_WINDOW, rep.grasps)} '
        f'{rep.wall_first_median_s:.3f} s, last {min(DRIFT_WINDOW, rep.grasps)} '
        f'{rep.wall_last_median_s:.3f} s, drift ratio {rep.wall_drift_ratio:.3f}',
        f'wall per plant tick: median first {rep.us_per_tick_first_median:.0f} us, last '
        f'{rep.us_per_tick_last_median:.0f} us, drift ratio {rep.tick_drift_ratio:.3f}',
        f'identical requests -> identical simulated duration and message counts: '
        f'{rep.identical_requests_identical} '
        f'({", ".join(f"{k}: {v} variant(s)" for k, v in rep.variants_per_object.items())})',
        f'load average (1/5/15 min) at the end: '
        f'{" ".join(f"{x:.2f}" for x in rep.machine["load_avg"])} on {rep.machine["cpus"]} CPUs',
    ]
    for r in rep.rows:
        if not r['success'] or not r['counts_match']:
            lines.append(f'  grasp {r["index"]}: {r["outcome"]} {r["message"]!r} counts_match='
                         f'{r["counts_match"]} published={r["published"]} '
                         f'recorded={r["recorded"]}')
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='bench_soak', description=__doc__.splitlines()[0])
    p.add_argument('--grasps', type=int, default=200, help='number of grasps (default 200)')
    p.add_argument('--warmup', type=int, default=10,
                   help='grasps after which the warm RSS is taken (default 10)')
    p.add_argument('--objects', choices=sorted(OBJECT_SETS), default='paper',
                   help='paper: Table V (default); cheap: three wide objects, shorter grasps')
    p.add_argument('--client', choices=['worker', 'grasp_client'], default='worker',
                   help='worker: one client process for all grasps (default); grasp_client: '
                        'the grasp_client executable once per grasp')
    p.add_argument('--executor', choices=['events', 'single'], default='events')
    p.add_argument('--output', default='', help='keep the bags in this folder')
    p.add_argument('--keep-bags', action='store_true', help='do not delete checked bags')
    p.add_argument('--grasp-timeout', type=float, default=300.0, help='wall s per grasp call')
    p.add_argument('--json', action='store_true', help='JSON on stdout instead of the text')
    p.add_argument('--json-file', default='', help='also write the JSON report here')
    p.add_argument('--quiet', action='store_true',
                   help='no progress on stderr (a bar on a terminal, else a line a grasp)')
    p.add_argument('--client-worker', action='store_true', help=argparse.SUPPRESS)
    return p


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.utilities import remove_ros_args

    args = build_parser().parse_args(remove_ros_args(sys.argv if argv is None else
                                                     ['bench_soak', *argv])[1:])
    if args.client_worker:
        return client_worker()
    if args.grasps < 1 or args.warmup < 0:
        print('bench_soak: --grasps must be >= 1 and --warmup >= 0', file=sys.stderr)
        return 2
    from gripper_ros.nodes.graph import GraphError, GraphOptions, GripperGraph
    from gripper_ros.nodes.process import ExecutorKind
    from gripper_ros.progress import progress_bar

    objects = OBJECT_SETS[args.objects]
    keep = bool(args.output) or args.keep_bags
    bag_root = Path(args.output) if args.output else Path(tempfile.mkdtemp(prefix='bench_soak_'))
    bag_root.mkdir(parents=True, exist_ok=True)

    bar = progress_bar(args.grasps, 'bench_soak', quiet=args.quiet)

    def progress(r: GraspRow):
        line = (f'{r.width_m:g} m {r.mass_kg:g} kg {r.outcome} {r.wall_s:.2f} s, {r.ticks} '
                f'ticks, counts {"match" if r.counts_match else "MISMATCH"}, RSS '
                f'{r.rss_kb / 1024:.1f} MiB')
        if not bar.disable:                     # a terminal: count, rate, time left
            bar.set_postfix_str(line, refresh=False)
            bar.update(1)
        elif not args.quiet:                    # a log: one line a grasp
            print(f'[{r.index}/{args.grasps}] {line}', file=sys.stderr, flush=True)

    rclpy.init(args=[])
    graph = worker = None
    rows, marks = [], {}
    error, code = '', 0
    t0 = time.perf_counter()
    try:
        graph = GripperGraph(GraphOptions(executor=ExecutorKind(args.executor)))
        worker = _WorkerClient()
        run_soak(graph, worker, objects, args.grasps, bag_root, keep, args.client,
                 args.warmup, args.grasp_timeout, progress, rows, marks)
    except (GraphError, SoakError) as exc:
        error, code = str(exc), 2
    except KeyboardInterrupt:
        error, code = 'interrupted', 130
    finally:
        bar.close()
        if worker is not None:
            worker.close()
        if graph is not None:
            graph.close()
        rclpy.try_shutdown()
        if not keep:
            shutil.rmtree(bag_root, ignore_errors=True)
    if error:
        print(f'bench_soak: {error} (after {len(rows)} grasps)', file=sys.stderr)
        if not rows:
            return code
        marks.setdefault('warm', marks['start'])
        marks['end'] = rows[-1].rss_kb
    report = summarise(rows, marks, objects, args.warmup, args.executor, args.client,
                       time.perf_counter() - t0)
    text = json.dumps(asdict(report), indent=1)
    if args.json_file:
        Path(args.json_file).write_text(text + '\n')
    print(text if args.json else format_report(report))
    if error:
        return code
    return 0 if report.failures == 0 and report.count_mismatches == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
