"""bench_realtime: whether the simulated gripper keeps the wall clock's pace, at what CPU cost.

    ros2 run gripper_ros bench_realtime                  # idle 5 s, grasp, hold 5 s
    ros2 run gripper_ros bench_realtime --seconds 10 --no-record --json
    ros2 run gripper_ros bench_realtime --per-node       # one process per node
    ros2 run gripper_ros bench_realtime --launch         # via ros2 launch (one process)
    ros2 run gripper_ros bench_realtime --use-sim-time   # on a world's /clock at the wall's pace
    ros2 run gripper_ros bench_realtime --foxglove       # without, then with a Foxglove client
    ros2 run gripper_ros bench_realtime --split          # the holding graph's CPU, by part

``grasp_demo --serve`` runs in a child process, exactly as a user starts it (realtime time,
real-time factor 1, bags per grasp unless ``--no-record``); with ``--per-node`` the launch
file's node executables (``wire.LAUNCHED_NODES``) run one process each, started with the
arguments ``launch_ros`` gives them (no bags; the graph of
``ros2 launch gripper_ros gripper.launch.py per_node:=true``); with
``--launch`` the child is ``ros2 launch gripper_ros gripper.launch.py`` itself (with
``--per-node``: ``per_node:=true``) in a process group of its own, every process of the group
counted, stopped as Ctrl-C stops it (SIGINT to the group). With ``--use-sim-time [PACE]`` the
graph runs with ``use_sim_time`` on the /clock of a world (``gripper_ros.bench.world_clock``,
as Gazebo publishes it, in a process of its own, not counted) at ``PACE`` of the wall clock's
(default 1): the RTF to aim at is then ``PACE``. From this process, over
DDS, the benchmark watches ``/clock``, ``joint_states`` and ``sim/status`` and reads the
child's CPU time from /proc, in two windows of ``--seconds`` wall seconds each:

- idle: no request; the position stage holds the open fingers (10 ms ticks);
- holding: after a grasp of the 0.1 m / 0.75 kg object of Table V answered HOLDING, the force
  loop holding it (0.1 ms ticks).

For each window: the achieved real-time factor (simulated seconds per wall second, from the
stamps of ``joint_states``; 1.0 is the aim, and the plant never runs ahead of the wall
clock), the rates of ``/clock`` and ``joint_states`` against ``state_rate_hz``, the plant's own
figure from ``sim/status``, and the child's CPU time as a share of one core (summed over the
node processes with ``--per-node``, over the launch group with ``--launch``).

``--foxglove`` measures ``grasp_demo --serve`` three times in one run: as above, then serving the
live view (``--foxglove``) to Foxglove's own client library through both windows, watching the
topics of the shipped layout (viewers/gripper.foxglove.json), then every topic
(``test/interop/live_client.mjs``: ``@foxglove/ws-protocol``, every message decoded, from the
npm packages scripts/setup.sh installs in ``build/interop``; ``--foxglove-client`` names another
command, given the URL and ``--topics T1,T2``). It prints each, the CPU the live view adds and
what the client got.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Dict, Optional, Sequence

from gripper_ros.bench.common import (call, group_pids, process_cpu_s, reap, ros2_launch_command,
                                      run_bench, SpunNode)
from gripper_ros.bench.pingpong import BenchError
from gripper_ros.nodes import LAUNCHED_MODULES
from gripper_ros.wire import DEFAULT_STATE_RATE_HZ

GRASP = (0.10, 0.75)                   # Table V's third object: the longest force stage
_UP_TIMEOUT_S = 30.0


class _Watcher:
    """Counts and stamps of the streams a ROS system would use, seen from another process."""

    def __init__(self, namespace: str) -> None:
        from gripper_interfaces.msg import SimStatus
        from gripper_interfaces.srv import Grasp, SetObject
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger
        from gripper_ros.nodes.loop_io import joint_state_template
        from gripper_ros.nodes.qos import GRAPH_QOS, SERVICE_QOS
        from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, namespace_prefix,
                                      SERVICE_GRASP, SERVICE_RELEASE, SERVICE_SET_OBJECT,
                                      TOPIC_CLOCK, TOPIC_JOINT_STATES, TOPIC_SIM_STATUS,
                                      qualified)
        self.spun = SpunNode('bench_realtime_watcher')
        self.node = self.spun.node
        self._lock = threading.Lock()
        self.clock_count = 0
        self.joint_count = 0
        self.joint_first_last_ns: list = [None, None]
        self.sim_rtf: list = []
        prefix = namespace_prefix(namespace)        # the graph's default names
        self._joint_layout = joint_state_template(prefix + FINGER_JOINT, prefix + FRAME_BASE)
        self.node.create_subscription(Clock, TOPIC_CLOCK, self._on_clock, GRAPH_QOS, raw=True)
        self.joint_sub = self.node.create_subscription(
            JointState, qualified(namespace, TOPIC_JOINT_STATES), self._on_joint, GRAPH_QOS,
            raw=True)
        self.node.create_subscription(SimStatus, qualified(namespace, TOPIC_SIM_STATUS),
                                      self._on_sim_status, GRAPH_QOS)
        self.grasp = self.node.create_client(Grasp, qualified(namespace, SERVICE_GRASP),
                                             qos_profile=SERVICE_QOS)
        self.release = self.node.create_client(Trigger, qualified(namespace, SERVICE_RELEASE))
        self.set_object = self.node.create_client(SetObject,
                                                  qualified(namespace, SERVICE_SET_OBJECT))
        self.spun.start()

    def _on_clock(self, _data: bytes) -> None:
        with self._lock:
            self.clock_count += 1

    def _on_joint(self, data: bytes) -> None:
        values = self._joint_layout.unpack(data)
        if values is None:
            from rclpy.serialization import deserialize_message
            from sensor_msgs.msg import JointState
            msg = deserialize_message(data, JointState)
            values = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        t_ns = values[0] * 1_000_000_000 + values[1]
        with self._lock:
            self.joint_count += 1
            if self.joint_first_last_ns[0] is None:
                self.joint_first_last_ns[0] = t_ns
            self.joint_first_last_ns[1] = t_ns

    def _on_sim_status(self, msg) -> None:
        with self._lock:
            self.sim_rtf.append(msg.real_time_factor)

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            return {'clock': self.clock_count, 'joint': self.joint_count,
                    'joint_ns': self.joint_first_last_ns[1], 'sim_rtf': len(self.sim_rtf)}

    def call(self, client, request, timeout_s: float):
        return call(client, request, timeout_s)

    def close(self) -> None:
        self.spun.close()


PER_NODE_MODULES = tuple(LAUNCHED_MODULES.values())
"""The node executables the launch file starts, one process each."""


def _process_name(pid: int) -> str:
    """Name a serving process as a user would: its program, or for Python its module."""
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as f:
            argv = [a.decode(errors='replace') for a in f.read().split(b'\0') if a]
    except OSError:
        return str(pid)
    words = [os.path.basename(a) for a in argv[:4] if not a.startswith('-')]
    if words and words[0].startswith('python'):
        words = words[1:]
    if len(argv) > 1 and argv[1] == '-m':
        words = [argv[2].rsplit('.', 1)[-1]]
    return ' '.join(words[:2]) or str(pid)


def _window(watcher: _Watcher, pids: Sequence[int], seconds: float) -> Dict[str, Any]:
    """Streams, simulated time and CPU (summed over ``pids``) over ``seconds`` of wall time."""
    first = {pid: process_cpu_s(pid) for pid in pids}
    a, t0 = watcher.snapshot(), time.perf_counter()
    time.sleep(seconds)
    b, t1 = watcher.snapshot(), time.perf_counter()
    wall = t1 - t0
    shares = {pid: (process_cpu_s(pid) - first[pid]) / wall for pid in pids}
    with watcher._lock:
        sim_rtf = watcher.sim_rtf[a['sim_rtf']:b['sim_rtf']]
    sim_s = (b['joint_ns'] - a['joint_ns']) * 1e-9 if a['joint_ns'] and b['joint_ns'] else 0.0
    return {'wall_s': wall, 'sim_s': sim_s, 'rtf': sim_s / wall,
            'clock_hz': (b['clock'] - a['clock']) / wall,
            'joint_states_hz': (b['joint'] - a['joint']) / wall,
            'plant_reported_rtf': min(sim_rtf) if sim_rtf else float('nan'),
            'cpu_share': sum(shares.values()),
            'cpu_share_by_process': {f'{_process_name(pid)} ({pid})': share
                                     for pid, share in shares.items()}}


def _commands(namespace: str, output: str, record: bool, per_node: bool,
              launch: bool = False, sim_time: bool = False,
              live: bool = False) -> list[list[str]]:
    """Return the command line of each child: grasp_demo --serve, one per node, or ros2 launch.

    ``sim_time``: every node with ``use_sim_time``; ``live``: grasp_demo serves the live view.
    """
    if launch:
        return [ros2_launch_command(namespace, per_node) +
                (['use_sim_time:=true'] if sim_time else [])]
    if per_node:
        return [[sys.executable, '-m', f'gripper_ros.nodes.{module}', '--ros-args', '-r',
                 f'__ns:=/{namespace}', '--log-level', 'warn'] +
                (['-p', 'use_sim_time:=true'] if sim_time else [])
                for module in PER_NODE_MODULES]
    cmd = [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve', '--namespace',
           namespace, '--output', output, '--ros-args', '--log-level', 'warn']
    if not record:
        cmd.insert(-3, '--no-record')
    if sim_time:
        cmd.insert(-3, '--use-sim-time')
    if live:
        cmd[-3:-3] = ['--foxglove', '0']
    return [cmd]


LIVE_URL = re.compile(r'Foxglove live view at (ws://\S+)')


def default_client() -> list[str]:
    """Return the command of Foxglove's client library as the tests run it (BenchError if none)."""
    repo = Path(__file__).resolve().parents[2]
    script, modules = repo / 'test' / 'interop' / 'live_client.mjs', repo / 'build' / 'interop'
    node = shutil.which('node')
    if node is None or not script.is_file() or not (modules / 'node_modules').is_dir():
        raise BenchError('--foxglove needs node and the npm packages scripts/setup.sh installs in '
                         'build/interop (or --foxglove-client COMMAND)')
    target = modules / script.name          # node resolves the packages beside the script
    shutil.copyfile(script, target)
    return [node, str(target)]


def shipped_layout_topics() -> list[str]:
    """Return the topics of the installed Foxglove layout, relative to its gripper's namespace."""
    from ament_index_python.packages import get_package_share_directory
    from gripper_ros.nodes.live_view import layout_topics
    from gripper_ros.wire import DEFAULT_NAMESPACE
    path = Path(get_package_share_directory('gripper_ros')) / 'viewers' / 'gripper.foxglove.json'
    prefix = f'/{DEFAULT_NAMESPACE}/'
    return [t.removeprefix(prefix) for t in layout_topics(json.loads(path.read_text()))]


class _LiveClient:
    """A Foxglove client watching every topic of the live view at ``url``."""

    def __init__(self, command: list[str], url: str, topics: Optional[list[str]], log) -> None:
        extra = ['--topics', ','.join(topics)] if topics else []
        self.proc = subprocess.Popen([*command, url, *extra], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=log, text=True)
        line = self.proc.stdout.readline()
        if not line.startswith('subscribed'):
            self.proc.kill()
            raise BenchError(f'the Foxglove client did not subscribe: {line.strip()!r}')

    def stop(self) -> Dict[str, Any]:
        """Stop it (SIGTERM); return its report, JSON (live_client.mjs)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=60)
        try:
            return json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            raise BenchError(f'the Foxglove client printed no report: {out[-300:]!r}') from None


def measure(seconds: float, record: bool, per_node: bool = False,
            launch: bool = False, world_pace: float = 0.0,
            client: Optional[list[str]] = None,
            topics: Optional[list[str]] = None) -> Dict[str, Any]:
    """Idle and holding windows of a ``grasp_demo --serve`` child, the node children, or launch.

    ``world_pace`` > 0: on the /clock of a world at that pace (``use_sim_time``).
    ``client``: serve the live view to this command (given the URL) through both windows,
    watching ``topics`` (relative names; None: every one).
    """
    from gripper_interfaces.srv import Grasp, SetObject
    from std_srvs.srv import Trigger
    from gripper_ros.wire import Outcome
    namespace = f'bench_realtime_{os.getpid()}'
    record = record and not (per_node or launch)
    with tempfile.TemporaryDirectory(prefix='bench_realtime_') as tmp:
        log = open(os.path.join(tmp, 'stderr.log'), 'w+')    # never a full pipe that blocks
        printed = open(os.path.join(tmp, 'stdout.log'), 'w+')
        children = [subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=printed,
                                     stderr=log, text=True, start_new_session=launch)
                    for cmd in _commands(namespace, tmp, record, per_node, launch,
                                         world_pace > 0.0, client is not None)]
        pids = [child.pid for child in children]
        world = None
        if world_pace > 0.0:              # not one of the gripper's: its CPU is not counted
            world = subprocess.Popen([sys.executable, '-m', 'gripper_ros.bench.world_clock',
                                      '--pace', repr(world_pace)], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=log)
        watcher = viewer = None
        try:
            watcher = _Watcher(namespace)
            deadline = time.monotonic() + _UP_TIMEOUT_S
            while not (watcher.grasp.service_is_ready() and watcher.set_object.service_is_ready()
                       and watcher.snapshot()['joint'] > 10):
                for child in children:
                    if child.poll() is not None:
                        log.seek(0)
                        raise BenchError(f'{child.args[2]} exited ({child.returncode}): '
                                         f'{log.read().strip()[-300:]}')
                if time.monotonic() > deadline:
                    raise BenchError('grasp_demo --serve did not come up')
                time.sleep(0.05)
            time.sleep(0.5)
            if client is not None:
                printed.seek(0)
                url = LIVE_URL.search(printed.read())
                if url is None:
                    raise BenchError('grasp_demo --serve --foxglove said no URL')
                from gripper_ros.wire import qualified
                viewer = _LiveClient(client, url.group(1),
                                     topics and [qualified(namespace, t) for t in topics], log)
            if launch:                        # launch and every process it started
                pids = group_pids(children[0].pid)
            idle = _window(watcher, pids, seconds)
            placed = watcher.call(watcher.set_object, SetObject.Request(width_m=GRASP[0]), 30.0)
            if not placed.success:
                raise BenchError(f'set_object: {placed.message}')
            t0 = time.perf_counter()
            while True:       # one process per node: refused until the supervisor heard all
                response = watcher.call(watcher.grasp, Grasp.Request(width_m=GRASP[0],
                                                                     mass_kg=GRASP[1]), 120.0)
                if response.outcome != Outcome.REFUSED or time.monotonic() > deadline:
                    break
                time.sleep(0.2)
                t0 = time.perf_counter()
            grasp_wall_s = time.perf_counter() - t0
            if response.outcome != Outcome.HOLDING:
                raise BenchError(f'the grasp ended {Outcome(response.outcome).name}: '
                                 f'{response.message}')
            time.sleep(1.0)                  # the serve bag closes 0.5 s after the answer
            holding = _window(watcher, pids, seconds)
            watcher.call(watcher.release, Trigger.Request(), 60.0)
            result = {'record': record, 'per_node': per_node, 'launch': launch,
                      'world_pace': world_pace, 'processes': len(pids), 'seconds': seconds,
                      'state_rate_hz': DEFAULT_STATE_RATE_HZ,
                      'grasp': {'width_m': GRASP[0], 'mass_kg': GRASP[1],
                                'wall_s': grasp_wall_s},
                      'idle': idle, 'holding': holding}
            if viewer is not None:
                result['foxglove_client'] = _client_summary(viewer.stop())
            return result
        finally:
            if viewer is not None and viewer.proc.poll() is None:
                viewer.proc.kill()
                viewer.proc.wait()
            if watcher is not None:
                watcher.close()
            for child in children:
                if child.poll() is None:
                    if launch:
                        os.killpg(child.pid, signal.SIGINT)
                    else:
                        child.send_signal(signal.SIGINT)
            for child in children:
                reap(child, 15.0, group=launch)
            if world is not None:
                world.send_signal(signal.SIGINT)
                reap(world, 15.0)
            log.close()
            printed.close()


def _client_summary(report: Dict[str, Any]) -> Dict[str, Any]:
    """Return what the client got: per topic, messages decoded and their rate (its wall time)."""
    topics = {}
    for topic, e in report['topics'].items():
        span_s = ((e['last_wall_ms'] or 0) - (e['first_wall_ms'] or 0)) * 1e-3
        topics[topic] = {'decoded': e['decoded'], 'failed': e['failed'],
                         'hz': (e['decoded'] - 1) / span_s if span_s > 0 else 0.0}
    return {'protocol': report['protocol'], 'errors': report['errors'], 'topics': topics,
            'watched': sorted(t for t, e in report['topics'].items() if e['decoded'])}


def format_report(r: Dict[str, Any]) -> str:
    if r.get('launch'):
        graph = (f'ros2 launch gripper_ros gripper.launch.py '
                 f'per_node:={"true" if r["per_node"] else "false"} '
                 f'({r["processes"]} processes with launch)')
    elif r.get('per_node'):
        graph = (f'the {len(PER_NODE_MODULES)} nodes, one process each '
                 '(as the launch file starts them)')
    else:
        graph = f"grasp_demo --serve{'' if r['record'] else ' --no-record'}"
    pace = r.get('world_pace') or 0.0
    timing = f"use_sim_time, on a world's /clock at {pace:g} x the wall clock's pace" if pace \
        else 'realtime, real-time factor 1'
    lines = [f'bench_realtime: {graph} '
             f"({timing}, state_rate_hz {r['state_rate_hz']:g}) watched "
             f"from another process, {r['seconds']:g} s per window; CPU: the serving "
             'process(es), share of one core', '',
             f'{"window":>8s} {"RTF":>6s} {"plant RTF":>9s} {"/clock Hz":>10s} '
             f'{"joint_states Hz":>15s} {"CPU share":>9s}']
    for name in ('idle', 'holding'):
        w = r[name]
        lines.append(f'{name:>8s} {w["rtf"]:6.3f} {w["plant_reported_rtf"]:9.3f} '
                     f'{w["clock_hz"]:10.1f} {w["joint_states_hz"]:15.1f} '
                     f'{w["cpu_share"]:9.2f}')
    for name in ('idle', 'holding'):
        shares = r[name].get('cpu_share_by_process', {})
        if len(shares) > 1:
            lines.append(f'{name:>8s} CPU share by process: ' + ', '.join(
                f'{process} {share:.2f}' for process, share in
                sorted(shares.items(), key=lambda kv: -kv[1])))
    g = r['grasp']
    lines.append('')
    lines.append(f'grasp of {g["width_m"]:g} m / {g["mass_kg"]:g} kg answered HOLDING after '
                 f'{g["wall_s"]:.2f} s of wall time')
    lines.append(f'RTF: simulated s per wall s from the joint_states stamps (aim '
                 f'{pace or 1.0:g}, never above); plant RTF: the lowest sim/status figure in the '
                 'window')
    client = r.get('foxglove_client')
    if client is not None:
        rates = ', '.join(f'{t} {c["hz"]:.0f} Hz' for t, c in sorted(client['topics'].items())
                          if c['hz'] >= 1.0)
        decoded = sum(c['decoded'] for c in client['topics'].values())
        failed = sum(c['failed'] for c in client['topics'].values())
        lines.append(f'Foxglove client ({client["protocol"]}), {len(client["watched"])} '
                     'topics, from before the idle window to after the holding one: '
                     f'{decoded} messages decoded, {failed} failed; {rates}')
    return '\n'.join(lines)


def format_comparison(off: Dict[str, Any], layout: Dict[str, Any], every: Dict[str, Any]) -> str:
    """Return the three reports and the CPU the live view adds in each window."""
    lines = ['without the live view:', format_report(off)]
    for title, on in (("a Foxglove client watching the shipped layout's topics", layout),
                      ('a Foxglove client watching every topic', every)):
        added = [f'{name}: {on[name]["cpu_share"] - off[name]["cpu_share"]:+.2f} of a core '
                 f'({off[name]["cpu_share"]:.2f} -> {on[name]["cpu_share"]:.2f}), RTF '
                 f'{off[name]["rtf"]:.3f} -> {on[name]["rtf"]:.3f}' for name in ('idle',
                                                                                 'holding')]
        lines += ['', f'with the live view and {title}:', format_report(on), '',
                  'the live view adds: ' + '; '.join(added)]
    return '\n'.join(lines)


def main(args: Optional[Sequence[str]] = None) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    p = argparse.ArgumentParser(prog='bench_realtime', description=__doc__.splitlines()[0])
    p.add_argument('--seconds', type=float, default=5.0,
                   help='wall seconds per window (default 5)')
    p.add_argument('--no-record', dest='record', action='store_false',
                   help='serve without recording bags')
    p.add_argument('--per-node', action='store_true',
                   help=f"run the launch file's {len(PER_NODE_MODULES)} nodes as a process each, "
                        'as it does (no bags)')
    p.add_argument('--launch', action='store_true',
                   help='run ros2 launch gripper_ros gripper.launch.py (with --per-node: '
                        'per_node:=true); needs the ros2 command')
    p.add_argument('--use-sim-time', type=float, nargs='?', const=1.0, default=0.0,
                   metavar='PACE', help='every node on the /clock of a world at PACE x the wall '
                                        "clock's pace (default 1), as Gazebo publishes it")
    p.add_argument('--foxglove', action='store_true',
                   help='grasp_demo --serve without, then with the live view and a Foxglove '
                        'client watching every topic')
    p.add_argument('--foxglove-client', default=None, metavar='COMMAND',
                   help='the client to run (given the URL; default: test/interop/'
                        'live_client.mjs with node)')
    p.add_argument('--split', action='store_true',
                   help='the one-process graph in this process, holding: its CPU a tick, split '
                        'by part (gripper_ros.bench.holding_split)')
    p.add_argument('--json', action='store_true', help='print JSON instead of the table')
    opts = p.parse_args(list(sys.argv[1:] if args is None else args))
    if not (0.5 <= opts.seconds <= 600.0):
        print('bench_realtime: error: --seconds must be in [0.5, 600]', file=sys.stderr)
        return 2
    if opts.use_sim_time and not 0.01 <= opts.use_sim_time <= 10.0:
        print('bench_realtime: error: --use-sim-time PACE must be in [0.01, 10]',
              file=sys.stderr)
        return 2
    if opts.foxglove and (opts.per_node or opts.launch or opts.use_sim_time):
        print('bench_realtime: error: --foxglove measures grasp_demo --serve (not with '
              '--per-node, --launch or --use-sim-time)', file=sys.stderr)
        return 2
    if opts.split and (opts.per_node or opts.launch or opts.use_sim_time or opts.foxglove):
        print('bench_realtime: error: --split measures the one-process graph in this process '
              '(not with --per-node, --launch, --use-sim-time or --foxglove)', file=sys.stderr)
        return 2
    return run_bench('bench_realtime', lambda: _run(opts))


def _run(opts: argparse.Namespace) -> int:
    """Measure what ``opts`` asks for and print it."""
    if opts.split:
        from gripper_ros.bench.holding_split import format_split, measure_split
        split = measure_split(opts.seconds)
        print(json.dumps(split, indent=2) if opts.json else format_split(split))
        return 0
    if opts.foxglove:
        client = shlex.split(opts.foxglove_client) if opts.foxglove_client else \
            default_client()
        shown = shipped_layout_topics()
        off = measure(opts.seconds, opts.record)
        layout = measure(opts.seconds, opts.record, client=client, topics=shown)
        every = measure(opts.seconds, opts.record, client=client)
        print(json.dumps({'off': off, 'layout': layout, 'every': every}, indent=2)
              if opts.json else format_comparison(off, layout, every))
        return 0
    report = measure(opts.seconds, opts.record, opts.per_node, opts.launch, opts.use_sim_time)
    print(json.dumps(report, indent=2) if opts.json else format_report(report))
    return 0


if __name__ == '__main__':
    sys.exit(main())
