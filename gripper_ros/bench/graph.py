"""bench_graph: what one lockstep tick of the gripper graph costs, against a bare rclpy ping-pong.

    ros2 run gripper_ros bench_graph                      # both executors, one repetition
    ros2 run gripper_ros bench_graph --executor events --repeat 3 --json

Everything is measured in ONE process run, in this order, so that the ratios compare figures
taken under the same machine load:

1. baseline: a lockstep std_msgs/Float64 ping-pong between two nodes sharing one executor
   (exactly one message in flight; a round trip is two publish/take/callback cycles);
2. graph: :class:`gripper_ros.nodes.graph.GripperGraph` (the four nodes + the client node, one executor
   thread) grasps each object of Table V through the real ``/gripper/grasp`` service, without
   recording. An observer node in the same graph (one extra ``/gripper/supervisor/status``
   subscription) notes, for each phase change, the wall time, the plant's tick counter and the
   simulated stamp, which gives ticks/s, us per tick, and the real-time factor of the position
   stage (10 ms ticks) and of the force stage (0.1 ms ticks) separately;
3. demo: ``grasp_demo --no-plot`` (three objects, bags recorded to a temporary folder) in a child
   process, timed from start to exit.

Every measurement is capped (``--grasp-cap-s``, ``--demo-cap-s``): a grasp over its cap is ended
with ``SupervisorNode.stop_grasp`` from the observer's callback (executor thread, so thread-safe)
and its row is marked ``capped``; a demo over its cap is killed and reported as ``>cap``.
The SingleThreadedExecutor is ~10x slower than the EventsExecutor here, so by default its grasps
are capped and its demo is not run (``--demo both`` runs it, capped).

:func:`measure_pingpong` is the baseline used by ``bench/bench_pingpong.py`` as well. It runs in a
private rclpy Context, so it neither needs nor disturbs the caller's ``rclpy.init()``;
``isolated=True`` runs it in a fresh child process instead.

Notes for rclpy 7.1.6 (Jazzy): ``EventsExecutor.spin()`` and ``spin_until_future_complete(f)``
*without* a timeout never dispatch timer events and make ``wake()``/``add_node()`` from other
threads block; with a finite ``timeout_sec`` they work. Everything here spins with a finite
timeout (the graph through :func:`gripper_ros.nodes.common.spin_until_stopped`).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence

from gripper_ros.wire import Phase

EXECUTOR_KINDS = ('events', 'single')
_WARMUP_ROUND_TRIPS = 200
_MATCH_TIMEOUT_S = 10.0
_run_counter = 0

_GRAPH_LOGGERS = ('plant_simulator', 'position_controller', 'force_controller', 'supervisor',
                  'grasp_demo_client', 'bench_graph_observer')


class BenchError(RuntimeError):
    """A measurement could not be taken (discovery, a stalled echo, a graph error...)."""


_BenchError = BenchError  # old name, kept for bench/bench_pingpong.py users


# =================================================================================================
# 1. baseline: lockstep Float64 ping-pong
# =================================================================================================

def _pingpong_qos():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def _make_executor(kind: str, context):
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    if kind == 'single':
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    raise ValueError(f'executor_kind must be one of {EXECUTOR_KINDS}, got {kind!r}')


def _spin_until(executor, future, timeout_s: float) -> None:
    """Spin until ``future`` is done or ``timeout_s`` passed (always with a finite timeout).

    SingleThreadedExecutor: a ``spin_once`` loop (what ``spin()`` does, and measurably faster than
    its ``spin_until_future_complete(timeout_sec=...)``).  EventsExecutor: its native
    ``spin_until_future_complete`` with a finite timeout, which drains the event queue without
    returning to Python between events.
    """
    from rclpy.executors import SingleThreadedExecutor
    deadline = time.monotonic() + timeout_s
    single = isinstance(executor, SingleThreadedExecutor)
    while not future.done():
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            return
        if single:
            executor.spin_once(timeout_sec=min(remaining, 0.25))
        else:
            executor.spin_until_future_complete(future, timeout_sec=min(remaining, 1.0))


class _PingPong:
    """Node A (pinger) and node B (echoer) with the lockstep logic."""

    def __init__(self, context, tag: str) -> None:
        from rclpy.node import Node
        from std_msgs.msg import Float64
        qos = _pingpong_qos()
        self.ping_topic = f'bench_pingpong_{tag}/ping'
        self.pong_topic = f'bench_pingpong_{tag}/pong'
        self.node_a = Node(f'bench_ping_{tag}', context=context)
        self.node_b = Node(f'bench_echo_{tag}', context=context)
        self.ping_pub = self.node_a.create_publisher(Float64, self.ping_topic, qos)
        self.node_a.create_subscription(Float64, self.pong_topic, self._on_pong, qos)
        self.pong_pub = self.node_b.create_publisher(Float64, self.pong_topic, qos)
        self.node_b.create_subscription(Float64, self.ping_topic, self._on_ping, qos)
        self._ping_msg = Float64()
        self.sent = 0.0           # value of the ping in flight
        self.count = 0            # completed round trips in the current phase
        self.target = 0           # warm-up: stop after this many round trips
        self.deadline = 0.0       # measuring: stop sending after this perf_counter()
        self.measuring = False
        self.mismatches = 0
        self.done = None

    # B: echo back whatever arrives
    def _on_ping(self, msg) -> None:
        self.pong_pub.publish(msg)

    # A: count the round trip, send the next ping or finish
    def _on_pong(self, msg) -> None:
        if msg.data != self.sent:
            self.mismatches += 1
            return
        self.count += 1
        if self.measuring:
            finished = time.perf_counter() >= self.deadline
        else:
            finished = self.count >= self.target
        if finished:
            if self.done is not None and not self.done.done():
                self.done.set_result(True)
            return
        self.send_next()

    def send_next(self) -> None:
        self.sent += 1.0
        self._ping_msg.data = self.sent
        self.ping_pub.publish(self._ping_msg)

    def matched(self) -> bool:
        return (self.ping_pub.get_subscription_count() > 0
                and self.pong_pub.get_subscription_count() > 0)

    def destroy(self) -> None:
        self.node_a.destroy_node()
        self.node_b.destroy_node()


def measure_pingpong(executor_kind: str, seconds: float, *,
                     isolated: bool = False) -> Dict[str, Any]:
    """Measure lockstep Float64 ping-pong round trips with one executor kind.

    :param executor_kind: ``'events'`` (rclpy.experimental.EventsExecutor) or ``'single'``
        (rclpy.executors.SingleThreadedExecutor).
    :param seconds: length of the measured phase (after discovery and a short warm-up).
    :param isolated: run the measurement in a fresh (spawned) Python process, so nothing the
        caller has loaded or spinning in this process skews it.  A caller using this must have the
        usual ``if __name__ == '__main__':`` guard (multiprocessing 'spawn').  Default False:
        measure in this process, in a private Context that leaves the caller's rclpy state alone.
    :return: dict with ``executor``, ``round_trips``, ``seconds`` (measured wall time),
        ``round_trips_per_s``, ``us_per_round_trip``, ``mismatches`` and ``rmw``.
    :raises BenchError: when the two nodes do not discover each other or the echo stops.
    """
    if executor_kind not in EXECUTOR_KINDS:
        raise ValueError(f'executor_kind must be one of {EXECUTOR_KINDS}, got {executor_kind!r}')
    if not seconds > 0:
        raise ValueError('seconds must be positive')
    if not isolated:
        return _measure_pingpong_here(executor_kind, seconds)
    ctx = multiprocessing.get_context('spawn')
    parent_end, child_end = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_pingpong_child_main, args=(executor_kind, seconds, child_end),
                       daemon=True)
    proc.start()
    child_end.close()
    try:
        if not parent_end.poll(seconds + 2 * _MATCH_TIMEOUT_S + 30.0):
            raise BenchError(f'{executor_kind} measurement process timed out')
        ok, payload = parent_end.recv()
    except EOFError:
        raise BenchError(f'{executor_kind} measurement process died '
                         f'(exit code {proc.exitcode})') from None
    finally:
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join()
    if not ok:
        raise BenchError(payload)
    return payload


def _pingpong_child_main(executor_kind: str, seconds: float, conn) -> None:
    try:
        conn.send((True, _measure_pingpong_here(executor_kind, seconds)))
    except Exception as exc:  # reported to the parent, which raises it
        conn.send((False, f'{type(exc).__name__}: {exc}'))
    finally:
        conn.close()


def _measure_pingpong_here(executor_kind: str, seconds: float) -> Dict[str, Any]:
    import rclpy
    from rclpy.task import Future
    global _run_counter
    _run_counter += 1
    tag = f'{os.getpid()}_{_run_counter}_{executor_kind}'

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    executor = None
    pp = None
    try:
        executor = _make_executor(executor_kind, context)
        pp = _PingPong(context, tag)
        executor.add_node(pp.node_a)
        executor.add_node(pp.node_b)

        # Discovery: both publishers must see their subscriber.
        t_end = time.monotonic() + _MATCH_TIMEOUT_S
        while not pp.matched():
            if time.monotonic() > t_end:
                raise BenchError('ping and echo nodes did not discover each other')
            executor.spin_once(timeout_sec=0.01)

        # Warm-up; re-kick if the first ping was published before the reader matched.
        pp.target = 1
        for _ in range(int(_MATCH_TIMEOUT_S / 0.25)):
            pp.done = Future()
            pp.count = 0
            pp.send_next()
            _spin_until(executor, pp.done, 0.25)
            if pp.done.done():
                break
        else:
            raise BenchError('no echo received during warm-up')
        pp.target = _WARMUP_ROUND_TRIPS
        pp.done = Future()
        pp.count = 0
        pp.send_next()
        _spin_until(executor, pp.done, _MATCH_TIMEOUT_S)
        if not pp.done.done():
            raise BenchError(f'echo stalled during warm-up after {pp.count} round trips')

        # Measured phase.
        pp.count = 0
        pp.mismatches = 0
        pp.measuring = True
        pp.done = Future()
        c0 = time.process_time()
        t0 = time.perf_counter()
        pp.deadline = t0 + seconds
        pp.send_next()
        _spin_until(executor, pp.done, seconds + 10.0)
        elapsed = time.perf_counter() - t0
        cpu = time.process_time() - c0
        if not pp.done.done():
            raise BenchError(f'echo stalled after {pp.count} round trips')
        n = pp.count
        return {
            'executor': executor_kind,
            'round_trips': n,
            'seconds': elapsed,
            'round_trips_per_s': n / elapsed,
            'us_per_round_trip': elapsed / n * 1e6 if n else float('inf'),
            'cpu_us_per_round_trip': cpu / n * 1e6 if n else float('inf'),
            'mismatches': pp.mismatches,
            'rmw': rclpy.get_rmw_implementation_identifier(),
        }
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=5.0)
        if pp is not None:
            pp.destroy()
        context.try_shutdown()


def format_pingpong(result: Dict[str, Any]) -> str:
    return (f"{result['executor']:>6}: {result['round_trips_per_s']:10.0f} round trips/s  "
            f"{result['us_per_round_trip']:8.1f} us/round trip  "
            f"({result['round_trips']} in {result['seconds']:.2f} s)")


def build_pingpong_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='bench_pingpong',
        description='Lockstep std_msgs/Float64 ping-pong between two nodes in one process.')
    parser.add_argument('--executor', choices=('events', 'single', 'both'), default='both',
                        help='executor to measure (default: both, with the events/single ratio)')
    parser.add_argument('--seconds', type=float, default=3.0,
                        help='measured seconds per executor (default 3)')
    return parser


def pingpong_main(args: Optional[Sequence[str]] = None) -> int:
    """The ``bench/bench_pingpong.py`` command line (ping-pong only)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    argv = list(sys.argv[1:] if args is None else args)
    argv = rclpy.utilities.remove_ros_args(['bench_pingpong'] + argv)[1:]
    opts = build_pingpong_parser().parse_args(argv)
    if not opts.seconds > 0:
        print('bench_pingpong: error: --seconds must be positive', file=sys.stderr)
        return 2
    kinds: List[str] = list(EXECUTOR_KINDS) if opts.executor == 'both' else [opts.executor]
    results: Dict[str, Dict[str, Any]] = {}
    try:
        print(f'lockstep Float64 ping-pong, {opts.seconds:g} s per executor, '
              f'rmw={rclpy.get_rmw_implementation_identifier()}, '
              f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}", flush=True)
        for kind in kinds:
            results[kind] = measure_pingpong(kind, opts.seconds)
            print(format_pingpong(results[kind]), flush=True)
    except RuntimeError as exc:
        print(f'bench_pingpong: error: {exc}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    if len(results) == 2:
        ratio = results['events']['round_trips_per_s'] / results['single']['round_trips_per_s']
        print(f'ratio events/single: {ratio:.2f}x round trips/s')
    return 0


# =================================================================================================
# 2. graph: one grasp per paper object through the real service
# =================================================================================================

class _PhaseObserver:
    """One status subscription in the graph's executor: marks each phase change of each grasp.

    A mark is ``(phase, wall perf_counter s, plant ticks published, simulated stamp ns,
    process CPU s)``. The
    callback runs in the executor thread, the same one as the plant and the supervisor, so
    reading ``ticks_published`` and calling ``stop_grasp`` from it is race-free.
    """

    def __init__(self, graph, context) -> None:
        from gripper_interfaces.msg import SupervisorStatus
        from rclpy.node import Node
        from gripper_ros.nodes.common import GRAPH_QOS, TOPIC_STATUS
        self._plant = graph.plant
        self._supervisor = graph.supervisor
        self.node = Node('bench_graph_observer', context=context,
                         start_parameter_services=False)
        self.sub = self.node.create_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status,
                                                 GRAPH_QOS)
        self.marks: Dict[int, list] = {}
        self.finished: set = set()
        self.capped: set = set()
        self.cap_deadline: Optional[float] = None
        graph.add_node(self.node)

    def arm(self, cap_s: float) -> None:
        self.cap_deadline = time.perf_counter() + cap_s if cap_s > 0 else None

    def _on_status(self, msg) -> None:
        now = time.perf_counter()
        gid = msg.grasp_id
        if gid in self.finished:
            return
        phase = msg.phase
        marks = self.marks.setdefault(gid, [])
        if not marks or marks[-1][0] != phase:
            stamp = msg.header.stamp
            marks.append((phase, now, self._plant.ticks_published,
                          stamp.sec * 1_000_000_000 + stamp.nanosec, time.process_time()))
        if phase not in (Phase.POSITION, Phase.FORCE):
            self.finished.add(gid)
        elif (self.cap_deadline is not None and now > self.cap_deadline
              and gid not in self.capped):
            self.capped.add(gid)
            self._supervisor.stop_grasp('bench_graph: wall-time cap reached')


def _deliveries_per_message(graph) -> Dict[str, int]:
    """Subscriptions in the graph's nodes per graph topic: callbacks one publication costs."""
    from gripper_ros.nodes.common import GRAPH_TOPICS
    subs = {topic: 0 for topic in GRAPH_TOPICS}
    for node in graph.nodes:
        for sub in node.subscriptions:
            if sub.topic_name in subs:
                subs[sub.topic_name] += 1
    return subs


def _stage(marks: list, phase: int) -> Optional[Dict[str, float]]:
    """Wall, ticks and simulated time between the first mark of ``phase`` and the next mark."""
    for i, (p, wall, ticks, stamp, cpu) in enumerate(marks):
        if p == phase and i + 1 < len(marks):
            _, wall2, ticks2, stamp2, cpu2 = marks[i + 1]
            n, w, sim = ticks2 - ticks, wall2 - wall, (stamp2 - stamp) * 1e-9
            return {'ticks': n, 'wall_s': w, 'sim_s': sim, 'cpu_s': cpu2 - cpu,
                    'ticks_per_s': n / w if w > 0 else float('nan'),
                    'us_per_tick': w / n * 1e6 if n else float('nan'),
                    'cpu_us_per_tick': (cpu2 - cpu) / n * 1e6 if n else float('nan'),
                    'rtf': sim / w if w > 0 else float('nan')}
    return None


def measure_graph(executor_kind: str, objects: Sequence[tuple], cap_s: float = 0.0,
                  observe: bool = True) -> Dict[str, Any]:
    """Grasp each ``(width_m, mass_kg)`` once, without recording, and time every tick.

    Runs a fresh :class:`GripperGraph` in a private Context. ``cap_s`` (> 0) ends a grasp that
    has run that many wall seconds (outcome STOPPED, row marked ``capped``).
    """
    import rclpy
    from rclpy.logging import LoggingSeverity, set_logger_level
    from gripper_ros.core.config import ConfigError
    from gripper_ros.nodes.graph import GraphError, GraphOptions, GripperGraph
    from gripper_ros.core.supervisor import Outcome
    from gripper_ros.nodes.common import ExecutorKind

    if executor_kind not in EXECUTOR_KINDS:
        raise ValueError(f'executor_kind must be one of {EXECUTOR_KINDS}, got {executor_kind!r}')
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    for name in _GRAPH_LOGGERS:
        set_logger_level(name, LoggingSeverity.WARN)
    graph = None
    t_up = time.perf_counter()
    try:
        try:
            graph = GripperGraph(GraphOptions(executor=ExecutorKind(executor_kind)),
                                 context=context)
        except (GraphError, ConfigError) as exc:
            raise BenchError(f'graph ({executor_kind}) did not come up: {exc}') from exc
        observer = _PhaseObserver(graph, context)
        deadline = time.monotonic() + _MATCH_TIMEOUT_S
        while observer.sub.get_publisher_count() < 1:
            if time.monotonic() > deadline:
                raise BenchError('observer did not discover /gripper/supervisor/status')
            time.sleep(0.01)
        time.sleep(0.1)  # let the supervisor's writer match the observer's reader too
        up_s = time.perf_counter() - t_up
        fanout = _deliveries_per_message(graph)
        rows = []
        for width_m, mass_kg in objects:
            try:
                placed = graph.set_object(width_m)
                if not placed.success:
                    raise BenchError(f'set_object({width_m:g}): {placed.message}')
                before = graph.published_counts()
                observer.arm(cap_s)
                t0 = time.perf_counter()
                resp = graph.grasp(width_m, mass_kg, wall_timeout_s=(cap_s or 600.0) + 60.0)
                call_s = time.perf_counter() - t0
            except GraphError as exc:
                raise BenchError(f'{executor_kind} grasp of {width_m:g} m: {exc}') from exc
            published = {t: n - before[t] for t, n in graph.published_counts().items()}
            marks = observer.marks.get(resp.grasp_id, [])
            rows.append(_grasp_row(executor_kind, width_m, mass_kg, resp, Outcome, marks,
                                   call_s, published, fanout,
                                   resp.grasp_id in observer.capped))
        return {'executor': executor_kind, 'graph_up_s': up_s, 'subscriptions': fanout,
                'grasps': rows, 'all': _total_row(executor_kind, rows)}
    finally:
        if graph is not None:
            graph.close()
        context.try_shutdown()


def _grasp_row(kind, width_m, mass_kg, resp, outcome_enum, marks, call_s, published, fanout,
               capped) -> Dict[str, Any]:
    from gripper_ros.nodes.common import TOPIC_CLOCK
    pos = _stage(marks, Phase.POSITION)
    force = _stage(marks, Phase.FORCE)
    if len(marks) < 2:
        raise BenchError(f'{kind} grasp of {width_m:g} m: the observer saw {len(marks)} status '
                         f'phase change(s); cannot time it (outcome '
                         f'{outcome_enum(resp.outcome).name}: {resp.message})')
    _, w0, n0, s0, c0 = marks[0]
    _, w1, n1, s1, c1 = marks[-1]
    ticks, wall, cpu = n1 - n0, w1 - w0, c1 - c0
    plant_ticks = published.get(TOPIC_CLOCK, 0)
    messages = sum(published.values())
    deliveries = sum(n * fanout.get(t, 0) for t, n in published.items())
    return {
        'executor': kind, 'width_m': width_m, 'mass_kg': mass_kg,
        'outcome': outcome_enum(resp.outcome).name, 'capped': capped,
        'ticks': ticks, 'wall_s': wall, 'sim_s': (s1 - s0) * 1e-9, 'cpu_s': cpu,
        'ticks_per_s': ticks / wall if wall > 0 else float('nan'),
        'us_per_tick': wall / ticks * 1e6 if ticks else float('nan'),
        'cpu_us_per_tick': cpu / ticks * 1e6 if ticks else float('nan'),
        'service_call_s': call_s,
        'messages_per_tick': messages / plant_ticks if plant_ticks else float('nan'),
        'callbacks_per_tick': deliveries / plant_ticks if plant_ticks else float('nan'),
        'position': pos, 'force': force,
    }


def _total_row(kind, rows) -> Dict[str, Any]:
    ticks = sum(r['ticks'] for r in rows)
    wall = sum(r['wall_s'] for r in rows)
    cpu = sum(r['cpu_s'] for r in rows)
    out = {'executor': kind, 'ticks': ticks, 'wall_s': wall, 'cpu_s': cpu,
           'sim_s': sum(r['sim_s'] for r in rows),
           'ticks_per_s': ticks / wall if wall > 0 else float('nan'),
           'us_per_tick': wall / ticks * 1e6 if ticks else float('nan'),
           'cpu_us_per_tick': cpu / ticks * 1e6 if ticks else float('nan'),
           'capped': any(r['capped'] for r in rows)}
    for stage in ('position', 'force'):
        parts = [r[stage] for r in rows if r[stage]]
        n = sum(p['ticks'] for p in parts)
        w = sum(p['wall_s'] for p in parts)
        s = sum(p['sim_s'] for p in parts)
        c = sum(p['cpu_s'] for p in parts)
        out[stage] = ({'ticks': n, 'wall_s': w, 'sim_s': s, 'cpu_s': c,
                       'ticks_per_s': n / w if w > 0 else float('nan'),
                       'us_per_tick': w / n * 1e6 if n else float('nan'),
                       'cpu_us_per_tick': c / n * 1e6 if n else float('nan'),
                       'rtf': s / w if w > 0 else float('nan')} if parts else None)
    return out


# =================================================================================================
# 3. the default demo, in a child process
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
    grasps = []
    for line in proc.stdout.splitlines():
        m = _DEMO_ROW.match(line)
        if m:
            grasps.append({'width_m': float(m.group(1)), 'mass_kg': float(m.group(2)),
                           'outcome': m.group(3), 'wall_s': float(m.group(4))})
    out = {'executor': executor_kind, 'wall_s': wall, 'timed_out': False, 'cap_s': cap_s,
           'exit_code': proc.returncode, 'grasps': grasps,
           'grasps_wall_s': sum(g['wall_s'] for g in grasps)}
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ['(no stderr)'])[-1]
        out['error'] = tail
    return out


# =================================================================================================
# the run: table, ratios, JSON
# =================================================================================================

def _median(values):
    values = [v for v in values if isinstance(v, (int, float)) and v == v]
    return statistics.median(values) if values else float('nan')


def _median_dict(items: List[Any]) -> Any:
    """Element-wise median of equally shaped results (dicts/lists of numbers); other values:
    the first repetition's (booleans: any)."""
    items = [it for it in items if it is not None]
    if not items:
        return None
    first = items[0]
    if isinstance(first, dict):
        return {k: _median_dict([it.get(k) for it in items]) for k in first}
    if isinstance(first, list):
        n = min(len(it) for it in items)
        return [_median_dict([it[i] for it in items]) for i in range(n)]
    if isinstance(first, bool):
        return any(items)
    if isinstance(first, (int, float)):
        return _median(items)
    return first


def run(kinds: Sequence[str], repeat: int, pingpong_s: float, objects: Sequence[tuple],
        grasp_caps: Dict[str, float], demo_kinds: Sequence[str], demo_cap_s: float,
        progress=None) -> Dict[str, Any]:
    def say(text):
        if progress:
            progress(text)

    reps = []
    load_before = _loadavg()
    t_start = time.perf_counter()
    for r in range(repeat):
        rep = {'pingpong': {}, 'graph': {}, 'demo': {}}
        tag = f'[{r + 1}/{repeat}] ' if repeat > 1 else ''
        for kind in kinds:
            say(f'{tag}ping-pong {kind} ({pingpong_s:g} s) ...')
            rep['pingpong'][kind] = measure_pingpong(kind, pingpong_s)
        for kind in kinds:
            cap = grasp_caps[kind]
            say(f'{tag}graph {kind}: {len(objects)} grasp(s)'
                + (f', cap {cap:g} s each' if cap > 0 else '') + ' ...')
            rep['graph'][kind] = measure_graph(kind, objects, cap)
        for kind in demo_kinds:
            say(f'{tag}grasp_demo --executor {kind} --no-plot (cap {demo_cap_s:g} s) ...')
            rep['demo'][kind] = measure_demo(kind, demo_cap_s)
        reps.append(rep)
    import rclpy
    return {
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform(), 'processor': _cpu_model(),
                    'rmw': rclpy.get_rmw_implementation_identifier(),
                    'ros_domain_id': os.environ.get('ROS_DOMAIN_ID', '0'),
                    'loadavg_1min_before': load_before, 'loadavg_1min_after': _loadavg()},
        'settings': {'executors': list(kinds), 'repeat': repeat, 'pingpong_s': pingpong_s,
                     'objects': [list(o) for o in objects], 'grasp_cap_s': grasp_caps,
                     'demo': list(demo_kinds), 'demo_cap_s': demo_cap_s},
        'median': _median_dict(reps) if repeat > 1 else reps[0],
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


def _ratios(res: Dict[str, Any]) -> Dict[str, Any]:
    pp, graph, demo = res['pingpong'], res['graph'], res['demo']
    out: Dict[str, Any] = {}
    for kind, g in graph.items():
        rt = pp[kind]['us_per_round_trip']
        out[f'graph_tick_over_pingpong_{kind}'] = g['all']['us_per_tick'] / rt
        out[f'graph_tick_over_pingpong_cpu_{kind}'] = (g['all']['cpu_us_per_tick']
                                                       / pp[kind]['cpu_us_per_round_trip'])
        for stage in ('position', 'force'):
            if g['all'][stage]:
                out[f'{stage}_tick_over_pingpong_{kind}'] = g['all'][stage]['us_per_tick'] / rt
        for row in g['grasps']:
            row['tick_over_pingpong'] = row['us_per_tick'] / rt
            row['tick_over_pingpong_cpu'] = (row['cpu_us_per_tick']
                                             / pp[kind]['cpu_us_per_round_trip'])
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


def format_report(report: Dict[str, Any]) -> str:
    res, m, s = report['median'], report['machine'], report['settings']
    ratios = report['ratios']
    agg = 'median of ' + str(s['repeat']) + ' runs' if s['repeat'] > 1 else 'one run'
    lines = [f"bench_graph ({agg}): {m['cpus']} CPUs ({m['processor']}), Python {m['python']}, "
             f"{m['rmw']}, ROS_DOMAIN_ID={m['ros_domain_id']}, load average (1 min) "
             f"{_f(m['loadavg_1min_before'], '.2f', 0)} before, "
             f"{_f(m['loadavg_1min_after'], '.2f', 0)} after", '']
    lines.append(f"1. baseline: lockstep std_msgs/Float64 ping-pong, two nodes, one executor "
                 f"({s['pingpong_s']:g} s each)")
    lines.append(f'{"executor":>8s} {"round trips/s":>14s} {"us/round trip":>14s} '
                 f'{"CPU us/round trip":>18s}')
    for kind, p in res['pingpong'].items():
        lines.append(f'{kind:>8s} {_f(p["round_trips_per_s"], ".0f", 14)} '
                     f'{_f(p["us_per_round_trip"], ".1f", 14)} '
                     f'{_f(p["cpu_us_per_round_trip"], ".1f", 18)}')
    lines.append('')
    lines.append('2. graph: one grasp per paper object via /gripper/grasp, no recording; '
                 'x pp = us/tick / us per ping-pong round trip (aim <= 3); CPU = process '
                 'CPU time')
    lines.append(f'{"executor":>8s} {"width m":>7s} {"mass kg":>7s} {"outcome":>8s} '
                 f'{"ticks":>6s} {"pos/force":>10s} {"ticks/s":>8s} {"us/tick":>8s} '
                 f'{"x pp":>6s} {"CPU us/t":>8s} {"x pp CPU":>8s} {"us/t pos":>8s} '
                 f'{"us/t frc":>8s} {"RTF pos":>8s} '
                 f'{"RTF frc":>8s} {"wall s":>7s}')
    for kind, g in res['graph'].items():
        rt = res['pingpong'][kind]['us_per_round_trip']
        crt = res['pingpong'][kind]['cpu_us_per_round_trip']
        for r in g['grasps'] + [dict(g['all'], width_m=None, mass_kg=None,
                                     outcome='all')]:
            pos, frc = r['position'] or {}, r['force'] or {}
            outcome = r['outcome'] + ('*' if r['capped'] else '')
            width = f'{r["width_m"]:7.3f}' if r['width_m'] is not None else f'{"":>7s}'
            mass = f'{r["mass_kg"]:7.2f}' if r['mass_kg'] is not None else f'{"":>7s}'
            split = f'{pos.get("ticks", 0):.0f}/{frc.get("ticks", 0):.0f}'
            lines.append(
                f'{kind:>8s} {width} {mass} {outcome:>8s} {r["ticks"]:6.0f} {split:>10s} '
                f'{_f(r["ticks_per_s"], ".0f", 8)} {_f(r["us_per_tick"], ".0f", 8)} '
                f'{_f(r["us_per_tick"] / rt, ".1f", 6)} '
                f'{_f(r["cpu_us_per_tick"], ".0f", 8)} {_f(r["cpu_us_per_tick"] / crt, ".1f", 8)} '
                f'{_f(pos.get("us_per_tick"), ".0f", 8)} {_f(frc.get("us_per_tick"), ".0f", 8)} '
                f'{_f(pos.get("rtf"), ".3f", 8)} {_f(frc.get("rtf"), ".4f", 8)} '
                f'{r["wall_s"]:7.2f}')
    if any(g['all']['capped'] for g in res['graph'].values()):
        lines.append('  * capped: the grasp was stopped after --grasp-cap-s wall seconds '
                     '(force stage cut short; its rates are still valid)')
    for kind, g in res['graph'].items():
        first = g['grasps'][0] if g['grasps'] else None
        if first:
            subs = ', '.join(f'{t.rsplit("/", 1)[-1]} {n}' for t, n in g['subscriptions'].items())
            lines.append(f'  {kind}: {first["messages_per_tick"]:.2f} publications/tick, '
                         f'{first["callbacks_per_tick"]:.1f} subscription callbacks/tick '
                         f'(subscribers per topic: {subs}; includes the recorder tap and the '
                         f'observer); graph up in {g["graph_up_s"]:.2f} s')
    lines.append('')
    if res['demo']:
        lines.append(f"3. grasp_demo --no-plot (three objects, bags to a temp dir), child "
                     f"process, cap {s['demo_cap_s']:g} s")
        lines.append(f'{"executor":>8s} {"wall s":>8s} {"grasps s":>9s} {"exit":>5s}')
        for kind, d in res['demo'].items():
            if d['timed_out']:
                lines.append(f'{kind:>8s} {">" + format(d["cap_s"], "g"):>8s} {"-":>9s} '
                             f'{"kill":>5s}')
            else:
                lines.append(f'{kind:>8s} {d["wall_s"]:8.2f} {d["grasps_wall_s"]:9.2f} '
                             f'{d["exit_code"]:5d}' + (f'  {d["error"]}' if 'error' in d else ''))
        lines.append('')
    lines.append('ratios (same run):')
    for kind in res['graph']:
        parts = [f'all {ratios[f"graph_tick_over_pingpong_{kind}"]:.1f}x']
        for stage in ('position', 'force'):
            key = f'{stage}_tick_over_pingpong_{kind}'
            if key in ratios:
                parts.append(f'{stage} stage {ratios[key]:.1f}x')
        parts.append(f'CPU time all {ratios[f"graph_tick_over_pingpong_cpu_{kind}"]:.1f}x')
        lines.append(f'  graph tick / ping-pong round trip, {kind}: ' + ', '.join(parts)
                     + '   (aim: <= 3x)')
    if 'pingpong_events_over_single' in ratios:
        lines.append(f'  ping-pong events/single: {ratios["pingpong_events_over_single"]:.2f}x '
                     'round trips/s')
    if 'graph_events_over_single' in ratios:
        lines.append(f'  graph events/single: {ratios["graph_events_over_single"]:.2f}x ticks/s')
    if 'demo_single_over_events' in ratios:
        lines.append(f'  demo wall single/events: {ratios["demo_single_over_events"]:.2f}x')
    lines.append(f"total benchmark wall time {report['total_wall_s']:.1f} s")
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='bench_graph',
        description='Cost of one lockstep tick of the gripper graph against a bare rclpy '
                    'ping-pong, per executor, plus the wall time of grasp_demo.')
    p.add_argument('--executor', choices=('events', 'single', 'both'), default='both',
                   help='executor(s) to measure (default both)')
    p.add_argument('--repeat', type=int, default=1,
                   help='repeat the whole sequence N times and report medians (default 1)')
    p.add_argument('--json', action='store_true',
                   help='print one JSON document (every repetition + medians) instead of the '
                        'table; progress still goes to stderr')
    p.add_argument('--json-file', metavar='PATH',
                   help='also write the JSON document to PATH (the table still goes to stdout)')
    p.add_argument('--pingpong-seconds', type=float, default=2.0,
                   help='measured ping-pong seconds per executor (default 2)')
    p.add_argument('--objects', default='all',
                   help="paper objects to grasp: 'all' or 1-based indices of Table V, "
                        "e.g. '3' or '1,3' (default all)")
    p.add_argument('--grasp-cap-s', type=float, default=None,
                   help='wall seconds after which a grasp is stopped (0 = no cap; default 30 '
                        'for events, 15 for single)')
    p.add_argument('--demo', choices=('auto', 'events', 'single', 'both', 'none'),
                   default='auto',
                   help="which grasp_demo runs to time (default auto: events, when measured; "
                        "single only when it is the only executor measured)")
    p.add_argument('--demo-cap-s', type=float, default=120.0,
                   help='wall seconds after which the demo child is killed (default 120)')
    return p


def _parse_objects(spec: str) -> List[tuple]:
    from gripper_ros.apps.grasp_demo import PAPER_OBJECTS
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
        from rclpy.executors import ExternalShutdownException
    except ImportError as exc:
        return _fail(f'rclpy not importable ({exc}); source scripts/env.sh first', 1)
    argv = list(sys.argv[1:] if args is None else args)
    argv = rclpy.utilities.remove_ros_args(['bench_graph'] + argv)[1:]
    opts = build_parser().parse_args(argv)
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
                (30.0 if k == 'events' else 15.0)) for k in kinds}
    if opts.demo == 'auto':
        demo_kinds = ['events'] if 'events' in kinds else ['single']
    elif opts.demo == 'both':
        demo_kinds = list(EXECUTOR_KINDS)
    elif opts.demo == 'none':
        demo_kinds = []
    else:
        demo_kinds = [opts.demo]

    def progress(text):
        print(text, file=sys.stderr, flush=True)

    try:
        report = run(kinds, opts.repeat, opts.pingpong_seconds, objects, caps, demo_kinds,
                     opts.demo_cap_s, progress)
    except BenchError as exc:
        return _fail(str(exc), 1)
    except (KeyboardInterrupt, ExternalShutdownException):
        print('bench_graph: interrupted', file=sys.stderr)
        return 130
    report['ratios'] = _ratios(report['median'])
    for rep in report['repetitions']:
        rep['ratios'] = _ratios(rep)
    if opts.json_file:
        try:
            with open(opts.json_file, 'w') as f:
                json.dump(report, f, indent=2, default=str)
        except OSError as exc:
            return _fail(f'cannot write --json-file: {exc}', 1)
    if opts.json:
        print(json.dumps(report, indent=2, default=str))
    else:
        print(format_report(report))
    return 0


if __name__ == '__main__':
    sys.exit(main())
