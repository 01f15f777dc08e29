"""bench_graph: what one lockstep tick of the gripper graph costs, against a bare rclpy ping-pong.

    ros2 run gripper_ros bench_graph --executor events --demo none --record
    ros2 run gripper_ros bench_graph --repeat 3 --json-file bench.json
    ros2 run gripper_ros bench_graph --executor events --breakdown --record   # a tick's parts

Everything is measured in ONE run, in this order, so that the ratios compare figures taken
under the same machine load:

1. baseline: a lockstep std_msgs/Float64 ping-pong between two nodes in one executor
   (:mod:`gripper_ros.bench.pingpong`), and between two processes (the floor of step 3); and
   the transport floor of a tick: the three loop messages passed round a ring of three nodes
   with nothing done in the callbacks, bare and with a raw DDS tap on each hop (what a recorder
   subscribing over DDS would add; the graph's recorder taps the publishers);
2. graph: :class:`~gripper_ros.nodes.graph.GripperGraph` (the four nodes and the client, one
   executor thread) grasps each object of Table V through the real ``grasp`` service, in fast
   time, releasing between objects as ``grasp_demo`` does; ``--record`` records each grasp
   exactly as ``grasp_demo`` records it. A :class:`PhaseObserver` (one ``supervisor/status``
   subscription) marks each phase change, which splits wall time, ticks and simulated time
   into the position stage (10 ms ticks) and the force stage (0.1 ms ticks);
3. processes: the four nodes as four processes, started as ``ros2 run`` starts them, the same
   grasps from a client in this process, and the same grasps in one process without
   recording, so that the ratio compares like with like;
4. demo: ``grasp_demo --no-plot`` in a child process, timed from start to exit.

Every grasp is capped (``--grasp-cap-s``): one over its cap is stopped through the ``stop``
service and its row marked ``capped``.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import platform
import re
import subprocess
import sys
import tempfile
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

from gripper_ros.bench.common import call, process_cpu_s, reap, SpunNode
from gripper_ros.bench.observer import PhaseObserver, quiet_loggers
from gripper_ros.bench.pingpong import (BenchError, EXECUTOR_KINDS, measure_pingpong,
                                        measure_ring)
from gripper_ros.bench.report import format_report, median_of, ratios
from gripper_ros.nodes import NODE_MODULES
from gripper_ros.wire import (NODE_FORCE_CONTROLLER, NODE_PLANT, NODE_POSITION_CONTROLLER,
                              NODE_SUPERVISOR, Phase)

_MATCH_TIMEOUT_S = 20.0
_NODE_MODULES = tuple(NODE_MODULES[n] for n in (NODE_PLANT, NODE_POSITION_CONTROLLER,
                                                NODE_FORCE_CONTROLLER, NODE_SUPERVISOR))
_STAGES = {'position': Phase.POSITION, 'force': Phase.FORCE}


def _rates(ticks: float, wall_s: float, sim_s: float, cpu_s: float) -> Dict[str, float]:
    nan = float('nan')
    return {'ticks': ticks, 'wall_s': wall_s, 'sim_s': sim_s, 'cpu_s': cpu_s,
            'ticks_per_s': ticks / wall_s if wall_s > 0 else nan,
            'us_per_tick': wall_s / ticks * 1e6 if ticks else nan,
            'cpu_us_per_tick': cpu_s / ticks * 1e6 if ticks else nan,
            'rtf': sim_s / wall_s if wall_s > 0 else nan}


def _ticks_between(a: tuple, b: tuple, dt_s: float) -> float:
    if a[2] is not None and b[2] is not None:
        return b[2] - a[2]
    return round((b[3] - a[3]) * 1e-9 / dt_s)


def grasp_row(marks: list, dt_s: Dict[str, float], width_m: float, mass_kg: float,
              outcome: str, capped: bool) -> Dict[str, Any]:
    """One grasp's totals and per-stage rates from its phase marks."""
    if len(marks) < 2:
        raise BenchError(f'grasp of {width_m:g} m: the observer saw {len(marks)} phase '
                         f'change(s), cannot time it (outcome {outcome})')
    row: Dict[str, Any] = {'width_m': width_m, 'mass_kg': mass_kg, 'outcome': outcome,
                           'capped': capped}
    total = 0
    for stage, phase in _STAGES.items():
        row[stage] = None
        for i, mark in enumerate(marks[:-1]):
            if mark[0] == phase:
                nxt = marks[i + 1]
                n = _ticks_between(mark, nxt, dt_s[stage])
                total += n
                row[stage] = _rates(n, nxt[1] - mark[1], (nxt[3] - mark[3]) * 1e-9,
                                    nxt[4] - mark[4])
                break
    first, last = marks[0], marks[-1]
    row.update(_rates(total, last[1] - first[1], (last[3] - first[3]) * 1e-9,
                      last[4] - first[4]))
    return row


def total_row(rows: List[Dict[str, Any]]) -> Dict[str, Any]:
    """All grasps together, and each stage over all grasps."""
    def summed(parts):
        return _rates(*(sum(p[k] for p in parts) for k in ('ticks', 'wall_s', 'sim_s', 'cpu_s')))
    out = summed(rows)
    out['capped'] = any(r['capped'] for r in rows)
    for stage in _STAGES:
        parts = [r[stage] for r in rows if r[stage]]
        out[stage] = summed(parts) if parts else None
    return out


def _stage_dt_s(config) -> Dict[str, float]:
    return {'position': config.position.sample_time_s, 'force': config.force.sample_time_s}


# =================================================================================================
# 2. one process: the graph of grasp_demo
# =================================================================================================

def measure_graph(executor_kind: str, objects: Sequence[tuple], cap_s: float = 0.0,
                  record: bool = False) -> Dict[str, Any]:
    """Grasp each ``(width_m, mass_kg)`` in a fresh graph, in a private Context.

    As ``grasp_demo`` does: released between objects; recorded as it records with ``record``.
    """
    import rclpy
    from gripper_ros.core.config import ConfigError
    from gripper_ros.nodes.graph import GraphError, GraphOptions, GripperGraph
    from gripper_ros.nodes.process import ExecutorKind
    from gripper_ros.nodes.recording import recorded_grasp
    from gripper_ros.wire import Outcome

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    quiet_loggers()
    graph = None
    t_up = time.perf_counter()
    try:
        try:
            graph = GripperGraph(GraphOptions(executor=ExecutorKind(executor_kind),
                                              namespace=f'bench_graph_{os.getpid()}'),
                                 context=context)
        except (GraphError, ConfigError) as exc:
            raise BenchError(f'graph ({executor_kind}) did not come up: {exc}') from exc
        plant = graph.plant
        observer = PhaseObserver(graph.client_node, graph.namespace,
                                 lambda: plant.ticks_published, time.process_time,
                                 lambda: graph.supervisor.stop_grasp('bench_graph: cap reached'))
        _wait_matched(observer.sub, 'supervisor/status')
        up_s = time.perf_counter() - t_up
        fanout = _subscriptions_per_topic(graph)
        dt_s = _stage_dt_s(graph.plant.config)
        rows = []
        with tempfile.TemporaryDirectory(prefix='bench_graph_bags_') as tmp:
            for i, (width_m, mass_kg) in enumerate(objects, 1):
                before = graph.published_counts()
                observer.arm(cap_s)
                timeout = (cap_s or 600.0) + 60.0
                try:
                    if i > 1:
                        graph.release()
                    if record:
                        run = recorded_grasp(graph, Path(tmp) / f'grasp_{i}', width_m, mass_kg,
                                             wall_timeout_s=timeout)
                        if run.recording_error:
                            raise BenchError(f'recording: {run.recording_error}')
                        response = run.response
                    else:
                        placed = graph.set_object(width_m)
                        if not placed.success:
                            raise BenchError(f'set_object({width_m:g}): {placed.message}')
                        response = graph.grasp(width_m, mass_kg, wall_timeout_s=timeout)
                        graph.wait_still()
                except GraphError as exc:
                    raise BenchError(f'{executor_kind} grasp of {width_m:g} m: {exc}') from exc
                published = {t: n - before[t] for t, n in graph.published_counts().items()}
                row = grasp_row(observer.marks.get(response.grasp_id, []), dt_s, width_m,
                                mass_kg, Outcome(response.outcome).name,
                                response.grasp_id in observer.capped)
                row.update(_traffic(published, fanout))
                rows.append(row)
        return {'executor': executor_kind, 'record': record, 'graph_up_s': up_s,
                'subscriptions': fanout, 'grasps': rows, 'all': total_row(rows)}
    finally:
        if graph is not None:
            graph.close()
        context.try_shutdown()


def _wait_matched(sub, what: str) -> None:
    deadline = time.monotonic() + _MATCH_TIMEOUT_S
    while sub.get_publisher_count() < 1:
        if time.monotonic() > deadline:
            raise BenchError(f'the observer did not discover {what}')
        time.sleep(0.01)
    time.sleep(0.1)       # the writer's side of the match, too


def _subscriptions_per_topic(graph) -> Dict[str, int]:
    """Subscriptions in the graph's nodes per graph topic: callbacks one publication costs."""
    from gripper_ros.wire import GRAPH_TOPICS, qualified
    names = {qualified(graph.namespace, t): t for t in GRAPH_TOPICS}
    subs = dict.fromkeys(GRAPH_TOPICS, 0)
    for node in graph.nodes:
        for sub in node.subscriptions:
            if sub.topic_name in names:
                subs[names[sub.topic_name]] += 1
    return subs


def _traffic(published: Dict[str, int], fanout: Dict[str, int]) -> Dict[str, float]:
    from gripper_ros.wire import TOPIC_TICK
    ticks = published.get(TOPIC_TICK, 0)
    messages = sum(published.values())
    callbacks = sum(n * fanout.get(t, 0) for t, n in published.items())
    nan = float('nan')
    return {'messages_per_tick': messages / ticks if ticks else nan,
            'callbacks_per_tick': callbacks / ticks if ticks else nan}


# =================================================================================================
# 3. one process per node
# =================================================================================================

class _NodeProcesses:
    """The four node executables in a namespace of their own, fast time, and a client here."""

    def __init__(self, executor_kind: str, namespace: str) -> None:
        from gripper_interfaces.srv import Grasp, SetObject
        from std_srvs.srv import Trigger
        from gripper_ros.nodes.qos import SERVICE_QOS
        from gripper_ros.wire import (SERVICE_GRASP, SERVICE_RELEASE, SERVICE_SET_OBJECT,
                                      SERVICE_STOP, qualified)
        self.namespace = namespace
        self.procs: List[subprocess.Popen] = []
        for module in _NODE_MODULES:
            cmd = [sys.executable, '-m', f'gripper_ros.nodes.{module}', '--ros-args',
                   '-r', f'__ns:=/{namespace}', '-p', f'executor:={executor_kind}',
                   '--log-level', 'warn']
            if module == 'plant_simulator_node':
                cmd[-2:-2] = ['-p', 'time_mode:=fast']
            self.procs.append(subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                                               stdout=subprocess.DEVNULL,
                                               stderr=subprocess.PIPE, text=True))
        self.client = SpunNode('bench_graph_client', namespace)
        self.node = self.client.node
        ns = namespace
        self._set_object = self.node.create_client(SetObject, qualified(ns, SERVICE_SET_OBJECT))
        self._grasp = self.node.create_client(Grasp, qualified(ns, SERVICE_GRASP),
                                              qos_profile=SERVICE_QOS)
        self._release = self.node.create_client(Trigger, qualified(ns, SERVICE_RELEASE))
        self._stop = self.node.create_client(Trigger, qualified(ns, SERVICE_STOP))
        self.client.start()

    def wait_up(self) -> None:
        deadline = time.monotonic() + _MATCH_TIMEOUT_S
        for client in (self._set_object, self._grasp, self._release, self._stop):
            while not client.wait_for_service(timeout_sec=0.2):
                dead = [p for p in self.procs if p.poll() is not None]
                if dead:
                    err = (dead[0].stderr.read() or '').strip().splitlines()
                    raise BenchError(f'a node process exited ({dead[0].args[2]}, code '
                                     f'{dead[0].returncode}): {err[-1] if err else "no output"}')
                if time.monotonic() > deadline:
                    raise BenchError(f'{client.srv_name} did not come up')

    def call(self, client, request, timeout_s: float):
        return call(client, request, timeout_s)

    def set_object(self, width_m: float):
        from gripper_interfaces.srv import SetObject
        return self.call(self._set_object, SetObject.Request(width_m=float(width_m),
                                                             open_fingers=True), 20.0)

    def grasp(self, width_m: float, mass_kg: float, timeout_s: float):
        from gripper_interfaces.srv import Grasp
        return self.call(self._grasp, Grasp.Request(width_m=float(width_m),
                                                    mass_kg=float(mass_kg)), timeout_s)

    def release(self):
        from std_srvs.srv import Trigger
        return self.call(self._release, Trigger.Request(), 120.0)

    def stop_async(self) -> None:
        from std_srvs.srv import Trigger
        self._stop.call_async(Trigger.Request())

    def cpu_s(self) -> float:
        """CPU time of the four node processes (user + system)."""
        return sum(process_cpu_s(p.pid) for p in self.procs)

    def close(self) -> None:
        self.client.close()
        for p in self.procs:
            if p.poll() is None:
                p.terminate()
        for p in self.procs:
            reap(p, 5.0)
            if p.stderr:
                p.stderr.close()


def measure_processes(executor_kind: str, objects: Sequence[tuple],
                      cap_s: float = 0.0) -> Dict[str, Any]:
    """Grasp the same objects with one process per node, without recording.

    Each node runs as ``python -m gripper_ros.nodes.<node>``, as ``ros2 run`` starts them, with
    ``-p time_mode:=fast``.
    """
    from gripper_ros.core.config import load_config
    from gripper_ros.wire import Outcome
    t_up = time.perf_counter()
    procs = _NodeProcesses(executor_kind, f'bench_processes_{os.getpid()}')
    try:
        observer = PhaseObserver(procs.node, procs.namespace, None, procs.cpu_s,
                                 procs.stop_async)
        procs.wait_up()
        _wait_matched(observer.sub, 'supervisor/status')
        up_s = time.perf_counter() - t_up
        dt_s = _stage_dt_s(load_config())
        rows = []
        for i, (width_m, mass_kg) in enumerate(objects, 1):
            if i > 1:
                procs.release()
            placed = procs.set_object(width_m)
            if not placed.success:
                raise BenchError(f'set_object({width_m:g}): {placed.message}')
            observer.arm(cap_s)
            response = procs.grasp(width_m, mass_kg, (cap_s or 600.0) + 60.0)
            rows.append(grasp_row(observer.marks.get(response.grasp_id, []), dt_s, width_m,
                                  mass_kg, Outcome(response.outcome).name,
                                  response.grasp_id in observer.capped))
        return {'executor': executor_kind, 'processes_up_s': up_s, 'grasps': rows,
                'all': total_row(rows)}
    finally:
        procs.close()


# =================================================================================================
# 4. the default demo, in a child process
# =================================================================================================

_DEMO_CODE = ('import sys\nfrom gripper_ros.apps.grasp_demo import main\n'
              'sys.exit(main(sys.argv[1:]))\n')
_DEMO_ROW = re.compile(r'^\s*(\d+\.\d+)\s+(\d+\.\d+)\s+([A-Z_]+)\s.*\s(\d+\.\d+)\s*$')


def measure_demo(executor_kind: str, cap_s: float) -> Dict[str, Any]:
    """Time ``grasp_demo --output <tmp> --no-plot --executor <kind>`` from start to exit."""
    with tempfile.TemporaryDirectory(prefix='bench_graph_demo_') as tmp:
        cmd = [sys.executable, '-c', _DEMO_CODE, '--output', tmp, '--no-plot',
               '--executor', executor_kind]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, timeout=cap_s if cap_s > 0 else None,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return {'executor': executor_kind, 'wall_s': time.perf_counter() - t0,
                    'timed_out': True, 'cap_s': cap_s, 'exit_code': None, 'grasps': []}
        wall = time.perf_counter() - t0
    grasps = [{'width_m': float(m.group(1)), 'mass_kg': float(m.group(2)),
               'outcome': m.group(3), 'wall_s': float(m.group(4))}
              for m in map(_DEMO_ROW.match, proc.stdout.splitlines()) if m]
    out = {'executor': executor_kind, 'wall_s': wall, 'timed_out': False, 'cap_s': cap_s,
           'exit_code': proc.returncode, 'grasps': grasps,
           'grasps_wall_s': sum(g['wall_s'] for g in grasps)}
    if proc.returncode != 0:
        out['error'] = (proc.stderr.strip().splitlines() or ['(no stderr)'])[-1]
    return out


# =================================================================================================
# the run
# =================================================================================================

def run(opts: argparse.Namespace, objects: Sequence[tuple], kinds: Sequence[str],
        caps: Dict[str, float], demo_kinds: Sequence[str],
        progress: Callable[[str], None]) -> Dict[str, Any]:
    reps = []
    load_before = _loadavg()
    t_start = time.perf_counter()
    for r in range(opts.repeat):
        rep: Dict[str, Any] = {'pingpong': {}, 'pingpong_processes': {}, 'ring': {},
                               'graph': {}, 'processes': {}, 'demo': {}}
        tag = f'[{r + 1}/{opts.repeat}] ' if opts.repeat > 1 else ''
        for kind in kinds:
            progress(f'{tag}ping-pong {kind} ({opts.pingpong_seconds:g} s) ...')
            rep['pingpong'][kind] = measure_pingpong(kind, opts.pingpong_seconds)
            progress(f'{tag}the floor: a ring of the three loop messages, {kind} ...')
            rep['ring'][kind] = {'bare': measure_ring(kind, opts.pingpong_seconds),
                                 'tapped': measure_ring(kind, opts.pingpong_seconds, True)}
            if opts.processes:
                progress(f'{tag}ping-pong {kind} across two processes ...')
                rep['pingpong_processes'][kind] = measure_pingpong(
                    kind, opts.pingpong_seconds, across_processes=True)
        for kind in kinds:
            progress(f'{tag}graph {kind}: {len(objects)} grasp(s)'
                     + (', recorded' if opts.record else '') + ' ...')
            rep['graph'][kind] = measure_graph(kind, objects, caps[kind], opts.record)
        if opts.processes:
            for kind in kinds:
                progress(f'{tag}one process per node, {kind}: the same grasps ...')
                per_node = measure_processes(kind, objects, caps[kind])
                if opts.record:
                    progress(f'{tag}one process, {kind}, not recorded: the same grasps ...')
                    per_node['one_process'] = measure_graph(kind, objects, caps[kind], False)
                else:
                    per_node['one_process'] = rep['graph'][kind]
                rep['processes'][kind] = per_node
        for kind in demo_kinds:
            progress(f'{tag}grasp_demo --executor {kind} --no-plot (cap {opts.demo_cap_s:g} s)')
            rep['demo'][kind] = measure_demo(kind, opts.demo_cap_s)
        rep['ratios'] = ratios(rep)
        reps.append(rep)
    import rclpy
    median = median_of(reps) if opts.repeat > 1 else reps[0]
    return {
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform(), 'processor': _cpu_model(),
                    'rmw': rclpy.get_rmw_implementation_identifier(),
                    'ros_domain_id': os.environ.get('ROS_DOMAIN_ID', '0'),
                    'loadavg_1min_before': load_before, 'loadavg_1min_after': _loadavg()},
        'settings': {'executors': list(kinds), 'repeat': opts.repeat,
                     'pingpong_s': opts.pingpong_seconds, 'record': opts.record,
                     'processes': opts.processes, 'objects': [list(o) for o in objects],
                     'grasp_cap_s': caps, 'demo': list(demo_kinds),
                     'demo_cap_s': opts.demo_cap_s},
        'median': median,
        'ratios': median['ratios'] if opts.repeat == 1 else ratios(median),
        'repetitions': reps,
        'total_wall_s': time.perf_counter() - t_start,
    }


def _loadavg() -> Optional[float]:
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


def _cpu_model() -> str:
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or 'unknown'


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='bench_graph',
        description='Cost of one lockstep tick of the gripper graph against a bare rclpy '
                    'ping-pong, in one process and one process per node, and the wall time '
                    'of grasp_demo.')
    p.add_argument('--executor', choices=('events', 'single', 'both'), default='both',
                   help='executor(s) to measure (default both)')
    p.add_argument('--breakdown', action='store_true',
                   help='only split the one-process tick into its parts (callbacks, compiled '
                        'calls, hand-off, publish, recording) against a ping-pong '
                        '(gripper_ros.bench.breakdown)')
    p.add_argument('--record', action='store_true',
                   help='record each grasp of the one-process graph as grasp_demo does')
    p.add_argument('--no-processes', dest='processes', action='store_false',
                   help='skip the one-process-per-node measurement')
    p.add_argument('--repeat', type=int, default=1,
                   help='repeat the whole sequence N times and report medians (default 1)')
    p.add_argument('--json', action='store_true',
                   help='print one JSON document instead of the table (progress: stderr)')
    p.add_argument('--json-file', metavar='PATH', help='also write the JSON document to PATH')
    p.add_argument('--pingpong-seconds', type=float, default=2.0,
                   help='measured ping-pong seconds per executor (default 2)')
    p.add_argument('--objects', default='all',
                   help="Table V objects: 'all' or 1-based indices, e.g. '3' or '1,3'")
    p.add_argument('--grasp-cap-s', type=float, default=None,
                   help='wall seconds after which a grasp is stopped (0 = no cap; default 30 '
                        'for events, 60 for single)')
    p.add_argument('--demo', choices=('auto', 'events', 'single', 'both', 'none'),
                   default='auto',
                   help='grasp_demo runs to time (auto: events when measured, else single)')
    p.add_argument('--demo-cap-s', type=float, default=120.0,
                   help='wall seconds after which the demo child is killed (default 120)')
    return p


def _parse_objects(spec: str) -> List[tuple]:
    from gripper_ros.studies.paper import PAPER_OBJECTS
    if spec.strip() == 'all':
        return list(PAPER_OBJECTS)
    out = []
    for part in spec.split(','):
        try:
            i = int(part)
        except ValueError:
            raise ValueError(f"--objects: '{part}' is not an index") from None
        if not 1 <= i <= len(PAPER_OBJECTS):
            raise ValueError(f'--objects: index {i} not in 1..{len(PAPER_OBJECTS)}')
        out.append(PAPER_OBJECTS[i - 1])
    return out


def _fail(message: str, code: int = 2) -> int:
    print(f'bench_graph: error: {message}', file=sys.stderr)
    return code


def main(args: Optional[Sequence[str]] = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    try:
        import rclpy
    except ImportError as exc:
        return _fail(f'rclpy not importable ({exc}); source scripts/env.sh first', 1)
    argv = list(sys.argv[1:] if args is None else args)
    opts = build_parser().parse_args(rclpy.utilities.remove_ros_args(['bench_graph'] + argv)[1:])
    if opts.repeat < 1:
        return _fail('--repeat must be >= 1')
    if not opts.pingpong_seconds > 0:
        return _fail('--pingpong-seconds must be positive')
    for name in ('grasp_cap_s', 'demo_cap_s'):
        value = getattr(opts, name)
        if value is not None and not value >= 0:
            return _fail(f'--{name.replace("_", "-")} must be >= 0')
    try:
        objects = _parse_objects(opts.objects)
    except ValueError as exc:
        return _fail(str(exc))
    kinds = list(EXECUTOR_KINDS) if opts.executor == 'both' else [opts.executor]
    caps = {k: (opts.grasp_cap_s if opts.grasp_cap_s is not None else
                (30.0 if k == 'events' else 60.0)) for k in kinds}
    demo_kinds = {'auto': ['events'] if 'events' in kinds else ['single'],
                  'both': list(EXECUTOR_KINDS), 'none': []}.get(opts.demo, [opts.demo])
    if opts.breakdown:
        return _breakdown(opts, objects, kinds[0])
    return _measure_and_report(
        opts, lambda: run(opts, objects, kinds, caps, demo_kinds,
                          lambda text: print(text, file=sys.stderr, flush=True)),
        format_report)


def _breakdown(opts: argparse.Namespace, objects: Sequence[tuple], kind: str) -> int:
    from gripper_ros.bench.breakdown import format_breakdown, measure_breakdown
    return _measure_and_report(
        opts, lambda: measure_breakdown(kind, objects, opts.record, opts.pingpong_seconds),
        format_breakdown)


def _measure_and_report(opts: argparse.Namespace, measure: Callable[[], Dict[str, Any]],
                        format_text: Callable[[Dict[str, Any]], str]) -> int:
    """Run ``measure``, write ``--json-file``, print the report; one line and 1 or 130 if not."""
    from rclpy.executors import ExternalShutdownException
    try:
        report = measure()
    except BenchError as exc:
        return _fail(str(exc), 1)
    except (KeyboardInterrupt, ExternalShutdownException):
        print('bench_graph: interrupted', file=sys.stderr)
        return 130
    if opts.json_file:
        try:
            with open(opts.json_file, 'w') as f:
                json.dump(report, f, indent=2, default=str)
        except OSError as exc:
            return _fail(f'cannot write --json-file: {exc}', 1)
    print(json.dumps(report, indent=2, default=str) if opts.json else format_text(report))
    return 0


if __name__ == '__main__':
    sys.exit(main())
