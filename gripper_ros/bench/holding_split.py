"""bench_realtime --split: where the CPU of the one-process graph goes while it holds an object.

    ros2 run gripper_ros bench_realtime --split --seconds 10

The graph ``ros2 launch gripper_ros gripper.launch.py`` starts by default (one process, realtime
at real-time factor 1, the loop topics on the intra-process bus), built in this process as
``gripper_graph`` builds it, holds the 0.1 m / 0.75 kg object of Table V (the force stage's
0.1 ms ticks, ten thousand a second) twice: plain, for the process's CPU time a tick (from
/proc), then with every part of a tick timed by the wrappers of
:mod:`gripper_ros.bench.breakdown` (each part's own wall time, what it calls counted where it
belongs) and the timers' callbacks besides. The pacing's sleep is timed too and left out (it
is no CPU). The CPU time less the parts is what no wrapper sees: the executor's dispatch of
tasks, timers and events, its timer thread, DDS's threads, the kernel's sleeps and wakes. No
process outside watches, so joint_states and sim/status go over DDS only if one is matched;
``bench_realtime --launch`` watches them from another process.
"""
from __future__ import annotations

import contextlib
import os
import time
from typing import Any, Dict, List

from gripper_ros.bench import breakdown

GRASP = (0.10, 0.75)                   # Table V's third object: the longest force stage
SLEEP = 'pacing sleep (wall, no CPU)'
TIMERS = 'timers (polls, housekeeping, watchdogs)'
GROUPS = (*breakdown.GROUPS[:-1], TIMERS, breakdown.REST)


def _timer_parts():
    """(owner, attribute, part) of each steady timer's callback in the graph."""
    from gripper_ros.nodes import controller_node, plant_simulator_node, services, supervisor_node
    polls = getattr(services, 'DeferredPolls', None)   # (a tree before one poll timer a node)
    return [(polls, '_poll', 'deferred services poll') if polls is not None else
            (services.DeferredService, '_poll', 'deferred service poll'),
            (plant_simulator_node.PlantSimulatorNode, '_housekeeping', 'plant _housekeeping'),
            (supervisor_node.SupervisorNode, '_watchdog', 'supervisor _watchdog'),
            (supervisor_node.SupervisorNode, '_heartbeat', 'supervisor _heartbeat'),
            (controller_node.LockstepController, '_watchdog', 'stage _watchdog')]


@contextlib.contextmanager
def _timed_timers(profile: breakdown.Profile, groups: Dict[str, str]):
    """Wrap the timers' callbacks (before the graph is built: a timer keeps what it was given)."""
    saved = []
    for owner, attribute, part in _timer_parts():
        original = owner.__dict__[attribute]
        saved.append((owner, attribute, original))
        setattr(owner, attribute, profile.wrap(part, original))
        groups[part] = TIMERS
    try:
        yield
    finally:
        for owner, attribute, original in saved:
            setattr(owner, attribute, original)


def _time_the_sleep(pacing, profile: breakdown.Profile, stack: contextlib.ExitStack) -> None:
    """Time the pacing's sleep in place (a tree before ``RealtimePacing.sleep``: its module's)."""
    if hasattr(pacing, 'sleep'):
        pacing.sleep = profile.wrap(SLEEP, pacing.sleep)
        return
    import types
    from gripper_ros.core.runtime import pacing as module
    timed = types.ModuleType('time')
    timed.__dict__.update(time.__dict__)
    timed.sleep = profile.wrap(SLEEP, time.sleep)
    module.time = timed
    stack.callback(setattr, module, 'time', time)


def _window(graph, seconds: float, profile: breakdown.Profile | None) -> Dict[str, float]:
    from gripper_ros.bench.common import process_cpu_s
    pid = os.getpid()
    wall0, cpu0 = time.monotonic(), process_cpu_s(pid)
    ticks0, sim0 = graph.plant.ticks_published, graph.sim_time_ns
    if profile is not None:
        profile.reset()
        profile.enabled = True
    time.sleep(seconds)
    if profile is not None:
        profile.enabled = False
    wall_s, cpu_s = time.monotonic() - wall0, process_cpu_s(pid) - cpu0
    ticks = graph.plant.ticks_published - ticks0
    return {'wall_s': wall_s, 'cpu_s': cpu_s, 'ticks': ticks,
            'cpu_us_per_tick': cpu_s / max(ticks, 1) * 1e6, 'cpu_share': cpu_s / wall_s,
            'rtf': (graph.sim_time_ns - sim0) * 1e-9 / wall_s}


def measure_split(seconds: float) -> Dict[str, Any]:
    """Every figure of the split (see the module docstring), one run."""
    import rclpy
    from gripper_ros.bench.observer import quiet_loggers
    from gripper_ros.bench.pingpong import BenchError
    from gripper_ros.nodes.graph import GraphOptions, GripperGraph
    from gripper_ros.wire import TimeMode
    out: Dict[str, Any] = {'grasp': {'width_m': GRASP[0], 'mass_kg': GRASP[1]},
                           'seconds': seconds}
    profile = breakdown.Profile()
    for name in ('plain', 'instrumented'):
        with contextlib.ExitStack() as stack:
            groups: Dict[str, str] = {}
            if name == 'instrumented':
                groups = stack.enter_context(breakdown.instrumented(profile))
                stack.enter_context(_timed_timers(profile, groups))
            context = rclpy.Context()
            rclpy.init(args=[], context=context)
            stack.callback(context.try_shutdown)
            quiet_loggers()
            graph = GripperGraph(GraphOptions(time_mode=TimeMode.REALTIME.parameter,
                                              namespace=f'bench_split_{name}'), context=context)
            stack.callback(graph.close)
            if name == 'instrumented':
                _time_the_sleep(graph.plant.pacing, profile, stack)
                groups[SLEEP] = SLEEP
            placed = graph.set_object(GRASP[0])
            if not placed.success:
                raise BenchError(f'set_object: {placed.message}')
            held = graph.grasp(*GRASP, wall_timeout_s=120.0)
            if not held.success:
                raise BenchError(f'the grasp did not hold: {held.message}')
            out[name] = _window(graph, seconds, profile if name == 'instrumented' else None)
            if name == 'instrumented':
                out['parts'] = _parts(profile, groups, out[name])
    return out


def _parts(profile: breakdown.Profile, groups: Dict[str, str],
           run: Dict[str, float]) -> List[dict]:
    ticks = max(run['ticks'], 1)
    rows = [{'part': part, 'group': groups.get(part, breakdown.OTHER_CALLBACKS),
             'us_per_tick': ns / ticks * 1e-3, 'calls_per_tick': profile.calls[part] / ticks}
            for part, ns in profile.own_ns.items()]
    seen_us = sum(r['us_per_tick'] for r in rows if r['group'] != SLEEP)
    rows.append({'part': '(CPU time in no wrapper)', 'group': breakdown.REST,
                 'us_per_tick': run['cpu_us_per_tick'] - seen_us, 'calls_per_tick': 0.0})
    order = (*GROUPS, SLEEP)
    return sorted(rows, key=lambda r: (order.index(r['group']), -r['us_per_tick']))


def format_split(r: Dict[str, Any]) -> str:
    """Return the split as a table: per group, then per part."""
    plain, inst = r['plain'], r['instrumented']
    lines = [f'bench_realtime --split: one-process graph, realtime, holding '
             f'{r["grasp"]["width_m"]:g} m / {r["grasp"]["mass_kg"]:g} kg, '
             f'{r["seconds"]:g} s a window',
             f'plain: {plain["cpu_us_per_tick"]:.1f} us of CPU a tick, '
             f'{plain["cpu_share"]:.3f} of a core, RTF {plain["rtf"]:.3f} '
             f'({plain["ticks"]} ticks)',
             f'instrumented: {inst["cpu_us_per_tick"]:.1f} us a tick, {inst["cpu_share"]:.3f} of '
             f'a core, RTF {inst["rtf"]:.3f} (the wrappers cost '
             f'{inst["cpu_us_per_tick"] - plain["cpu_us_per_tick"]:+.1f} us)',
             '', f'{"instrumented tick, by group":<48s} {"us/tick":>8s} {"share":>7s}']
    by_group: Dict[str, float] = {}
    for row in r['parts']:
        by_group[row['group']] = by_group.get(row['group'], 0.0) + row['us_per_tick']
    for group in GROUPS:
        us = by_group.get(group, 0.0)
        lines.append(f'{group:<48s} {us:8.2f} {us / inst["cpu_us_per_tick"]:7.1%}')
    lines += ['', f'{"part":<34s} {"group":<44s} {"us/tick":>8s} {"calls/tick":>10s}']
    for row in r['parts']:
        lines.append(f'{row["part"]:<34s} {row["group"]:<44s} {row["us_per_tick"]:8.2f} '
                     f'{row["calls_per_tick"]:10.2f}')
    return '\n'.join(lines)
