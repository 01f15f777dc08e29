"""The baseline of every graph figure: a lockstep std_msgs/Float64 ping-pong between two nodes.

    python -m gripper_ros.bench.pingpong --executor both --seconds 3

Exactly one message is in flight; a round trip is two publish/take/callback cycles, the least a
tick of any two-node loop can cost. :func:`measure_pingpong` runs in a private rclpy Context, so it
neither needs nor disturbs the caller's ``rclpy.init()``; ``isolated=True`` runs it in a fresh
child process instead.

rclpy 7.1.6 (Jazzy): ``EventsExecutor.spin()`` and ``spin_until_future_complete(f)`` *without* a
timeout never dispatch timer events; everything here spins with a finite timeout.
"""
from __future__ import annotations

import argparse
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from typing import Any, Dict, List, Optional, Sequence

EXECUTOR_KINDS = ('events', 'single')
_WARMUP_ROUND_TRIPS = 200
_MATCH_TIMEOUT_S = 10.0
_run_counter = 0


class BenchError(RuntimeError):
    """A measurement could not be taken (discovery, a stalled echo, a graph error...)."""


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

    def __init__(self, context, tag: str, pinger: bool = True, echo: bool = True) -> None:
        from rclpy.node import Node
        from std_msgs.msg import Float64
        qos = _pingpong_qos()
        self.ping_topic = f'bench_pingpong_{tag}/ping'
        self.pong_topic = f'bench_pingpong_{tag}/pong'
        self.nodes = []
        if pinger:
            self.node_a = Node(f'bench_ping_{tag}', context=context)
            self.ping_pub = self.node_a.create_publisher(Float64, self.ping_topic, qos)
            self.pong_sub = self.node_a.create_subscription(Float64, self.pong_topic,
                                                            self._on_pong, qos)
            self.nodes.append(self.node_a)
        if echo:
            self.node_b = Node(f'bench_echo_{tag}', context=context)
            self.pong_pub = self.node_b.create_publisher(Float64, self.pong_topic, qos)
            self.node_b.create_subscription(Float64, self.ping_topic, self._on_ping, qos)
            self.nodes.append(self.node_b)
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
                and self.pong_sub.get_publisher_count() > 0)

    def destroy(self) -> None:
        for node in self.nodes:
            node.destroy_node()


def measure_pingpong(executor_kind: str, seconds: float, *, isolated: bool = False,
                     across_processes: bool = False) -> Dict[str, Any]:
    """Measure lockstep Float64 ping-pong round trips with one executor kind.

    :param executor_kind: ``'events'`` (rclpy.experimental.EventsExecutor) or ``'single'``
        (rclpy.executors.SingleThreadedExecutor).
    :param seconds: length of the measured phase (after discovery and a short warm-up).
    :param isolated: run the measurement in a fresh (spawned) Python process, so nothing the
        caller has loaded or spinning in this process skews it.  A caller using this must have the
        usual ``if __name__ == '__main__':`` guard (multiprocessing 'spawn').  Default False:
        measure in this process, in a private Context that leaves the caller's rclpy state alone.
    :param across_processes: the echo node runs in a child process of its own (the floor of
        a graph with one process per node).
    :return: dict with ``executor``, ``round_trips``, ``seconds`` (measured wall time),
        ``round_trips_per_s``, ``us_per_round_trip``, ``mismatches`` and ``rmw``.
    :raises BenchError: when the two nodes do not discover each other or the echo stops.
    """
    if executor_kind not in EXECUTOR_KINDS:
        raise ValueError(f'executor_kind must be one of {EXECUTOR_KINDS}, got {executor_kind!r}')
    if not seconds > 0:
        raise ValueError('seconds must be positive')
    if not isolated:
        return _measure_pingpong_here(executor_kind, seconds, across_processes)
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


def _measure_pingpong_here(executor_kind: str, seconds: float,
                           across_processes: bool = False) -> Dict[str, Any]:
    import rclpy
    from rclpy.task import Future
    global _run_counter
    _run_counter += 1
    tag = f'{os.getpid()}_{_run_counter}_{executor_kind}'

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    executor = None
    pp = None
    echo = None
    try:
        if across_processes:
            echo = subprocess.Popen(
                [sys.executable, '-m', 'gripper_ros.bench.pingpong', '--echo', tag,
                 '--executor', executor_kind, '--seconds', str(seconds + 2 * _MATCH_TIMEOUT_S)],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        executor = _make_executor(executor_kind, context)
        pp = _PingPong(context, tag, echo=not across_processes)
        for node in pp.nodes:
            executor.add_node(node)

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
            'across_processes': across_processes,
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
        if echo is not None:
            echo.terminate()
            try:
                echo.wait(5.0)
            except subprocess.TimeoutExpired:
                echo.kill()
                echo.wait()


def _echo_main(tag: str, executor_kind: str, seconds: float) -> int:
    """Run the echo node alone, for ``seconds`` or until terminated (``across_processes``)."""
    import rclpy
    from rclpy.task import Future
    rclpy.init(args=[])
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    executor = _make_executor(executor_kind, None)
    pp = _PingPong(None, tag, pinger=False)
    executor.add_node(pp.node_b)
    try:
        _spin_until(executor, Future(), seconds)
    except Exception:  # noqa: BLE001 - shut down from the signal handler
        pass
    finally:
        pp.destroy()
        rclpy.try_shutdown()
    return 0


def measure_ring(executor_kind: str, seconds: float, taps: bool = False) -> Dict[str, Any]:
    """Measure the transport floor of one graph tick: the three loop messages round a ring.

    Three nodes in one executor pass the three loop messages (PlantTick, StageReference,
    MotorCommand) round a lockstep ring, as bytes on raw subscriptions with no work in the
    callbacks; ``taps`` adds one more raw subscription on each hop, as a recorder subscribing
    over DDS would (the graph's recorder taps the publishers instead). One lap
    is one tick.
    """
    import rclpy
    from gripper_interfaces.msg import MotorCommand, PlantTick, StageReference
    from rclpy.node import Node
    from rclpy.task import Future
    from gripper_ros.nodes.qos import GRAPH_QOS
    from gripper_ros.wire import COMMAND_LAYOUT, REFERENCE_LAYOUT, TICK_LAYOUT
    global _run_counter
    _run_counter += 1
    tag = f'{os.getpid()}_{_run_counter}'
    layouts = (TICK_LAYOUT, REFERENCE_LAYOUT, COMMAND_LAYOUT)
    types = (PlantTick, StageReference, MotorCommand)
    payloads = [lay.pack(*(0.0 if c in 'd' else 0 for c in _codes(lay))) for lay in layouts]
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    executor = _make_executor(executor_kind, context)
    nodes = [Node(f'bench_ring_{tag}_{i}', context=context) for i in range(3)]
    try:
        topics = [f'bench_ring_{tag}/hop{i}' for i in range(3)]
        pubs = [nodes[i].create_publisher(types[i], topics[i], GRAPH_QOS) for i in range(3)]
        state = {'laps': 0, 'deadline': float('inf'), 'done': Future()}

        def hop(i):
            nxt = (i + 1) % 3
            if nxt:
                return lambda _data: pubs[nxt].publish(payloads[nxt])

            def lap(_data):
                state['laps'] += 1
                if time.perf_counter() >= state['deadline']:
                    state['done'].set_result(True)
                    return
                pubs[0].publish(payloads[0])
            return lap
        subs = [nodes[(i + 1) % 3].create_subscription(types[i], topics[i], hop(i), GRAPH_QOS,
                                                       raw=True) for i in range(3)]
        if taps:
            subs += [nodes[0].create_subscription(types[i], topics[i], lambda _d: None,
                                                  GRAPH_QOS, raw=True) for i in range(3)]
        for node in nodes:
            executor.add_node(node)
        t_end = time.monotonic() + _MATCH_TIMEOUT_S
        while any(sub.get_publisher_count() < 1 for sub in subs) or \
                any(pub.get_subscription_count() < (2 if taps else 1) for pub in pubs):
            if time.monotonic() > t_end:
                raise BenchError('the ring nodes did not discover each other')
            executor.spin_once(timeout_sec=0.01)
        for phase_s in (0.2, seconds):            # warm-up, then the measured phase
            state.update(laps=0, done=Future())
            t0 = time.perf_counter()
            state['deadline'] = t0 + phase_s
            pubs[0].publish(payloads[0])
            _spin_until(executor, state['done'], phase_s + _MATCH_TIMEOUT_S)
            elapsed = time.perf_counter() - t0
            if not state['done'].done():
                raise BenchError(f'the ring stalled after {state["laps"]} laps')
        n = state['laps']
        return {'executor': executor_kind, 'taps': taps, 'ticks': n, 'seconds': elapsed,
                'us_per_tick': elapsed / n * 1e6 if n else float('inf')}
    finally:
        executor.shutdown(timeout_sec=5.0)
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


def _codes(layout) -> str:
    """Return the struct codes of a loop layout's fields, in order (padding left out)."""
    import re
    fmt = layout._reader.format.lstrip('<')
    out = ''
    for count, code in re.findall(r'(\d*)([a-zA-Z?])', fmt):
        if code != 'x':
            out += code * int(count or 1)
    return out


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
    parser.add_argument('--across-processes', action='store_true',
                        help='the echo node in a process of its own')
    parser.add_argument('--echo', metavar='TAG', help=argparse.SUPPRESS)
    return parser


def pingpong_main(args: Optional[Sequence[str]] = None) -> int:
    """``python -m gripper_ros.bench.pingpong``: the ping-pong alone."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    argv = list(sys.argv[1:] if args is None else args)
    argv = rclpy.utilities.remove_ros_args(['bench_pingpong'] + argv)[1:]
    opts = build_pingpong_parser().parse_args(argv)
    if not opts.seconds > 0:
        print('bench_pingpong: error: --seconds must be positive', file=sys.stderr)
        return 2
    if opts.echo:
        return _echo_main(opts.echo, 'single' if opts.executor == 'single' else 'events',
                          opts.seconds)
    kinds: List[str] = list(EXECUTOR_KINDS) if opts.executor == 'both' else [opts.executor]
    results: Dict[str, Dict[str, Any]] = {}
    try:
        print(f'lockstep Float64 ping-pong, {opts.seconds:g} s per executor, '
              f'rmw={rclpy.get_rmw_implementation_identifier()}, '
              f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}", flush=True)
        for kind in kinds:
            results[kind] = measure_pingpong(kind, opts.seconds,
                                             across_processes=opts.across_processes)
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


if __name__ == '__main__':
    sys.exit(pingpong_main())
