"""bench_graph --breakdown: where one lockstep tick of the one-process graph spends its time.

    ros2 run gripper_ros bench_graph --breakdown --objects 2 --record

The graph of ``grasp_demo`` (one executor thread) grasps the Table V objects twice in ONE run:
plain (the in-run baseline of the tick's cost, beside a bare ping-pong and the ring floor of
:mod:`gripper_ros.bench.pingpong`), and with every part of a tick timed by wrappers put on the
classes and modules before the graph is built: the three loop callbacks' own Python, the
compiled call each makes of a message (numba included), the in-process hand-off of the graph's
topics (publish, queue, drain), the state topics' Python, rclpy's ``publish`` (DDS) per topic,
the recording tap, and the other subscriptions. A part's time is its own (exclusive: what it
calls is counted where it belongs); what no wrapper sees is the executor's dispatch of tasks
and events, rclpy's take and DDS delivery. The wrappers cost a little themselves: the
instrumented tick is reported beside the plain one.
"""
from __future__ import annotations

from collections import defaultdict
import contextlib
import functools
from pathlib import Path
import tempfile
import threading
import time
from typing import Any, Callable, Dict, List, Sequence

LOOP_CALLBACKS = 'loop callbacks (own Python)'
KERNELS = 'compiled calls of the loop nodes'
HAND_OFF = 'in-process hand-off (publish, queue, drain)'
STATE_TOPICS = 'state topics (own Python)'
PUBLISH_LOOP = 'rclpy publish: loop messages'
PUBLISH_STATE = 'rclpy publish: state topics'
RECORDING = 'recording tap'
OTHER_CALLBACKS = 'other subscriptions (status, observer)'
REST = 'executor dispatch, rclpy take, DDS (no wrapper)'
GROUPS = (LOOP_CALLBACKS, KERNELS, HAND_OFF, STATE_TOPICS, PUBLISH_LOOP, PUBLISH_STATE,
          RECORDING, OTHER_CALLBACKS, REST)
"""The shares a tick is split into, in the report's order."""


class Profile:
    """Exclusive wall time and calls per named part, from wrappers (thread-safe enough).

    Each thread keeps a stack of the parts it is in; a part's time, less its children's, is
    added to it, so the parts add up to the time spent inside any of them.
    """

    def __init__(self) -> None:
        self.own_ns: Dict[str, int] = defaultdict(int)
        self.calls: Dict[str, int] = defaultdict(int)
        self.enabled = False
        self._local = threading.local()

    def reset(self) -> None:
        self.own_ns.clear()
        self.calls.clear()

    def wrap(self, name: str | Callable[..., str], fn: Callable) -> Callable:
        """Return ``fn`` timed as ``name`` (or ``name(*args)`` for a name chosen per call)."""
        clock = time.perf_counter_ns
        local = self._local

        @functools.wraps(fn)
        def timed(*args, **kwargs):
            if not self.enabled:
                return fn(*args, **kwargs)
            stack = getattr(local, 'stack', None)
            if stack is None:
                stack = local.stack = []
            stack.append(0)                 # the children's time, so far
            start = clock()
            try:
                return fn(*args, **kwargs)
            finally:
                spent = clock() - start
                children = stack.pop()
                part = name(*args) if callable(name) else name
                self.own_ns[part] += spent - children
                self.calls[part] += 1
                if stack:
                    stack[-1] += spent
        return timed


def _parts():
    """(owner, attribute, part name, group) of everything a tick does that is timed."""
    from gripper_ros.core.physics import plant
    from gripper_ros.nodes import (controller_node, intra_process, plant_simulator_node,
                                   recording, supervisor_node)
    from gripper_ros.bench.observer import PhaseObserver
    Plant, Sup = plant_simulator_node.PlantSimulatorNode, supervisor_node.SupervisorNode
    Stage = controller_node.LockstepController
    Bus = intra_process.IntraProcessBus
    return [(Plant, '_on_command', 'plant _on_command', LOOP_CALLBACKS),
            (Plant, '_try_step', 'plant _try_step', LOOP_CALLBACKS),
            (Plant, '_publish_tick', 'plant _publish_tick', LOOP_CALLBACKS),
            (Sup, '_on_tick', 'supervisor _on_tick', LOOP_CALLBACKS),
            (Stage, '_on_reference', 'stage _on_reference', LOOP_CALLBACKS),
            (intra_process.GraphPublisher, 'publish', 'GraphPublisher.publish', HAND_OFF),
            (Bus, 'post', 'IntraProcessBus.post', HAND_OFF),
            (Bus, '_drain', 'IntraProcessBus._drain', HAND_OFF),
            (Plant, '_publish_state', 'plant _publish_state', STATE_TOPICS),
            (Sup, '_publish_status', 'supervisor _publish_status', STATE_TOPICS),
            (Plant, '_on_status', 'plant _on_status', OTHER_CALLBACKS),
            (Stage, '_on_status', 'stage _on_status', OTHER_CALLBACKS),
            (PhaseObserver, '_on_status', 'observer _on_status', OTHER_CALLBACKS),
            (recording.GraphTap, '_on_message', 'GraphTap._on_message', RECORDING),
            (plant, '_object_state', '_object_state', STATE_TOPICS)]


@contextlib.contextmanager
def instrumented(profile: Profile):
    """Put the wrappers in place (before a graph is built) and take them away after.

    The loop nodes' compiled calls are bound when their nodes are built
    (``lockstep.entry_point``): each is timed under its kernel's name.
    """
    from gripper_ros.core.runtime import lockstep
    from rclpy.publisher import Publisher
    groups: Dict[str, str] = {}
    saved = []
    for owner, attribute, part, group in _parts():
        original = owner.__dict__[attribute]
        saved.append((owner, attribute, original))
        setattr(owner, attribute, profile.wrap(part, original))
        groups[part] = group
    original_entry_point = lockstep.entry_point

    def timed_entry_point(kernel, *args):
        groups[kernel.__name__] = KERNELS
        return profile.wrap(kernel.__name__, original_entry_point(kernel, *args))
    saved.append((lockstep, 'entry_point', original_entry_point))
    lockstep.entry_point = timed_entry_point

    def publish_part(publisher, *_):
        topic = publisher.topic_name
        part = f'publish {topic.rsplit("/", 1)[-1]}'
        if part not in groups:
            groups[part] = PUBLISH_LOOP if '/loop/' in topic else PUBLISH_STATE
        return part
    original_publish = Publisher.publish
    Publisher.publish = profile.wrap(publish_part, original_publish)
    try:
        yield groups
    finally:
        Publisher.publish = original_publish
        for owner, attribute, original in saved:
            setattr(owner, attribute, original)


def _grasps(graph, objects: Sequence[tuple], record: bool, tmp: Path,
            profile: Profile | None, released: bool = False) -> Dict[str, float]:
    """Grasp each object (released between, recorded as grasp_demo records with ``record``).

    Only the grasps are timed (and profiled): the release before each is not.
    """
    from gripper_ros.bench.pingpong import BenchError
    from gripper_ros.nodes.recording import recorded_grasp
    wall_s, ticks = 0.0, 0
    for i, (width_m, mass_kg) in enumerate(objects, 1):
        if i > 1 or released:
            graph.release()
            graph.wait_still()
        before = graph.plant.ticks_published
        if profile is not None:
            profile.enabled = True
        start = time.perf_counter()
        if record:
            run = recorded_grasp(graph, tmp / f'grasp_{i}', width_m, mass_kg,
                                 wall_timeout_s=120.0)
            if run.recording_error:
                raise BenchError(f'recording: {run.recording_error}')
        else:
            placed = graph.set_object(width_m)
            if not placed.success:
                raise BenchError(f'set_object({width_m:g}): {placed.message}')
            graph.grasp(width_m, mass_kg, wall_timeout_s=120.0)
            graph.wait_still()
        wall_s += time.perf_counter() - start
        if profile is not None:
            profile.enabled = False
        ticks += graph.plant.ticks_published - before
    return {'wall_s': wall_s, 'ticks': ticks, 'us_per_tick': wall_s / ticks * 1e6}


def measure_breakdown(executor_kind: str, objects: Sequence[tuple], record: bool,
                      pingpong_s: float) -> Dict[str, Any]:
    """Every figure of the breakdown (see the module docstring), one run."""
    import rclpy
    from gripper_ros.bench.observer import PhaseObserver, quiet_loggers
    from gripper_ros.bench.pingpong import measure_pingpong, measure_ring
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.nodes.process import ExecutorKind
    out: Dict[str, Any] = {'executor': executor_kind, 'record': record,
                           'objects': [list(o) for o in objects]}
    out['pingpong'] = measure_pingpong(executor_kind, pingpong_s)
    out['ring'] = measure_ring(executor_kind, pingpong_s)
    profile = Profile()
    for name, prof in (('plain', None), ('instrumented', profile)):
        with contextlib.ExitStack() as stack:
            groups = stack.enter_context(instrumented(profile)) if prof else {}
            context = rclpy.Context()
            rclpy.init(args=[], context=context)
            stack.callback(context.try_shutdown)
            quiet_loggers()
            graph = GripperGraph(GraphOptions(executor=ExecutorKind(executor_kind),
                                              namespace=f'bench_breakdown_{name}'),
                                 context=context)
            stack.callback(graph.close)
            observer = PhaseObserver(graph.client_node, graph.namespace, None,
                                     time.process_time, lambda: None)
            observer.arm(0.0)
            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix='breakdown_')))
            _grasps(graph, objects[:1], record, tmp / 'warm_up', None)   # not timed
            out[name] = _grasps(graph, objects, record, tmp / 'timed', prof, released=True)
        if prof:
            out['parts'] = _shares(profile, groups, out[name])
    return out


def _shares(profile: Profile, groups: Dict[str, str], run: Dict[str, float]) -> List[dict]:
    ticks = run['ticks']
    total_ns = run['wall_s'] * 1e9
    rows = [{'part': part, 'group': groups.get(part, OTHER_CALLBACKS),
             'us_per_tick': ns / ticks * 1e-3, 'calls_per_tick': profile.calls[part] / ticks,
             'share': ns / total_ns} for part, ns in profile.own_ns.items()]
    seen_ns = sum(profile.own_ns.values())
    rows.append({'part': '(not in any wrapper)', 'group': REST,
                 'us_per_tick': (total_ns - seen_ns) / ticks * 1e-3, 'calls_per_tick': 0.0,
                 'share': (total_ns - seen_ns) / total_ns})
    return sorted(rows, key=lambda r: (GROUPS.index(r['group']), -r['us_per_tick']))


def format_breakdown(r: Dict[str, Any]) -> str:
    """Return the breakdown as a table: per group, then per part."""
    plain, inst = r['plain'], r['instrumented']
    ping = r['pingpong']['us_per_round_trip']
    ring = r['ring']['us_per_tick']
    lines = [f'bench_graph --breakdown: executor {r["executor"]}, '
             f'{"recorded" if r["record"] else "not recorded"}, objects {r["objects"]}',
             f'ping-pong {ping:.1f} us a round (baseline); ring floor {ring:.1f} us = '
             f'{ring / ping:.2f}x',
             f'tick, plain: {plain["us_per_tick"]:.1f} us = {plain["us_per_tick"] / ping:.2f}x '
             f'the ping-pong ({plain["ticks"]} ticks); instrumented: '
             f'{inst["us_per_tick"]:.1f} us = {inst["us_per_tick"] / plain["us_per_tick"]:.2f}x '
             "plain (the wrappers' own cost)",
             '', f'{"share of an instrumented tick":<48s} {"us/tick":>8s} {"share":>7s}']
    by_group: Dict[str, float] = defaultdict(float)
    for row in r['parts']:
        by_group[row['group']] += row['us_per_tick']
    for group in GROUPS:
        us = by_group.get(group, 0.0)
        lines.append(f'{group:<48s} {us:8.2f} {us / inst["us_per_tick"]:7.1%}')
    lines += ['', f'{"part":<34s} {"group":<44s} {"us/tick":>8s} {"calls/tick":>10s} '
                  f'{"share":>7s}']
    for row in r['parts']:
        lines.append(f'{row["part"]:<34s} {row["group"]:<44s} {row["us_per_tick"]:8.2f} '
                     f'{row["calls_per_tick"]:10.2f} {row["share"]:7.1%}')
    return '\n'.join(lines)
