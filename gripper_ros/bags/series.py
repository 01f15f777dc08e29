"""A grasp bag as numpy series: the measurement, decision and command of every tick (no rclpy).

Two bag formats are read. Bags of the lockstep protocol (custom_data ``gripper_ros.format`` 2)
hold ``<ns>/loop/tick`` (measurement), ``<ns>/loop/position_reference`` and
``<ns>/loop/force_reference`` (decision), ``<ns>/loop/motor_command`` (command), plus the
state topics. Earlier bags held one tick message per topic under ``/gripper``
(``joint_states``, ``force_sensor``, ``motor_state``, ``supervisor/status``, ``motor_command``
with headers). Both give the same :class:`GraspSeries`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Any

from gripper_ros.bags.reader import Bag, MissingTopicsError, open_bag
from gripper_ros.wire import (COMMAND_LAYOUT, FINGER_JOINT, GRAPH_TOPICS, qualified,
                              REFERENCE_LAYOUT, stamp_ns, TICK_LAYOUT, TOPIC_FORCE_REFERENCE,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_OBJECT_STATE, TOPIC_POSITION_REFERENCE, TOPIC_STATUS,
                              TOPIC_TICK)
import numpy as np

LEGACY_NAMESPACE = 'gripper'
LEGACY_MOTOR_STATE = 'motor_state'
LEGACY_MOTOR_COMMAND = 'motor_command'
"""Topics of a bag recorded before the lockstep protocol that the graph no longer has."""
LEGACY_TOPICS = {
    TOPIC_JOINT_STATES: 'sensor_msgs/msg/JointState',
    TOPIC_FORCE_SENSOR: 'gripper_interfaces/msg/ForceSensor',
    LEGACY_MOTOR_STATE: 'gripper_interfaces/msg/MotorState',
    TOPIC_STATUS: 'gripper_interfaces/msg/SupervisorStatus',
    LEGACY_MOTOR_COMMAND: 'gripper_interfaces/msg/MotorCommand',
}
"""The topics of a bag recorded before the lockstep protocol (all under /gripper)."""

GRASP_TOPICS = GRAPH_TOPICS
"""Relative topic -> type of everything one gripper's graph publishes (what a bag records)."""


def _t_s(msg) -> float:
    """Return a stamped message's time in seconds."""
    return stamp_ns(msg.header.stamp) * 1e-9


@dataclass
class JointSeries:
    """Finger travel from fully open, its speed, contact force, per tick."""

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    contact_force_n: np.ndarray


@dataclass
class SensorSeries:
    """The force sensor per tick."""

    t_s: np.ndarray
    force_n: np.ndarray
    voltage_v: np.ndarray
    peak_force_n: np.ndarray      # largest force since the previous tick (NaN in old bags)


@dataclass
class MotorSeries:
    """Voltage applied over the interval ending at t_s, current, speed."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    speed_rad_s: np.ndarray


@dataclass
class StatusSeries:
    """The supervisor's decision, one row per tick (and its final state after the last)."""

    t_s: np.ndarray
    phase: np.ndarray
    active_controller: np.ndarray
    switch_criterion: np.ndarray
    grasp_id: np.ndarray
    outcome: np.ndarray
    position_setpoint_m: np.ndarray
    force_setpoint_n: np.ndarray
    position_m: np.ndarray
    force_n: np.ndarray
    contact: np.ndarray
    seed_voltage_v: np.ndarray
    stage_id: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    approach_setpoint_m: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class CommandSeries:
    """One row per controller answer."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    source: np.ndarray
    grasp_id: np.ndarray
    hold_s: np.ndarray
    inner_setpoint: np.ndarray
    stage_id: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))


@dataclass
class ObjectSeries:
    """Ground truth of the held object along the pads (empty in bags without it)."""

    t_s: np.ndarray
    state: np.ndarray
    slip_m: np.ndarray
    slip_speed_mps: np.ndarray
    load_n: np.ndarray
    capacity_n: np.ndarray


@dataclass
class GraspSeries:
    """Numpy series of one grasp bag; ``t_s`` everywhere = simulated time of the tick."""

    path: Path
    joint: JointSeries
    sensor: SensorSeries
    motor: MotorSeries
    status: StatusSeries
    command: CommandSeries
    custom_data: dict[str, Any]
    counts: dict[str, int]
    start_ns: int
    end_ns: int
    size_bytes: int
    truncated: bool
    damage: str = ''
    namespace: str = LEGACY_NAMESPACE
    bag_format: int = 1
    objects: ObjectSeries | None = None
    ticks: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    """Format 2: every PlantTick field as an array (what a re-simulation feeds back)."""
    references: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    """Format 2: every StageReference field as an array, in tick order."""
    commands: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    """Format 2: every MotorCommand field as an array, in tick order."""
    absent: frozenset = frozenset()
    """``kind.field`` (kind ``tick``, ``reference``, ``command``) of the loop messages' fields
    the bag's own (older) message types lack: read as 0, never recorded."""

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


def _columns(rows: list[tuple], dtypes: tuple) -> list[np.ndarray]:
    if not rows:
        return [np.zeros(0, dtype=d) for d in dtypes]
    cols = list(zip(*rows))
    return [np.asarray(cols[i], dtype=dtypes[i]) for i in range(len(dtypes))]


def _joint_value(values, index: int) -> float:
    return float(values[index]) if len(values) > index else float('nan')


def bag_namespace(bag: Bag, namespace: str | None = None) -> tuple[int, str]:
    """(format, namespace) of a grasp bag: the recorded ones, or found from its topics.

    MissingTopicsError when the bag holds no gripper's loop (or legacy) topics, or several
    grippers' when ``namespace`` does not choose one.
    """
    info = bag.custom_data_parsed().get('gripper_ros')
    if isinstance(info, dict) and namespace is None and info.get('namespace') is not None:
        namespace = str(info['namespace'])
    found = sorted({t[:-len('/' + TOPIC_TICK)].strip('/') for t in bag.topics
                    if t.endswith('/' + TOPIC_TICK) and bag.topics[t].count})
    legacy = qualified(LEGACY_NAMESPACE, TOPIC_JOINT_STATES) in bag.topics and \
        qualified(LEGACY_NAMESPACE, TOPIC_STATUS) in bag.topics and not found
    if namespace is not None:
        ns = namespace.strip('/')
        if ns in found:
            return 2, ns
        if ns == LEGACY_NAMESPACE and legacy:
            return 1, ns
        raise MissingTopicsError(f'{bag.path}: no gripper in namespace /{ns} (has: '
                                 f'{", ".join("/" + f for f in found) or "none"})')
    if len(found) == 1:
        return 2, found[0]
    if len(found) > 1:
        raise MissingTopicsError(f'{bag.path}: holds several grippers ('
                                 f'{", ".join("/" + f for f in found)}); choose one namespace')
    if legacy:
        return 1, LEGACY_NAMESPACE
    have = ', '.join(sorted(t for t, i in bag.topics.items() if i.count)) or 'none'
    raise MissingTopicsError(f'{bag.path}: not a grasp bag: no <namespace>/{TOPIC_TICK} topic '
                             f'(has: {have})')


def load_grasp_series(bag: Bag | str | os.PathLike,
                      namespace: str | None = None) -> GraspSeries:
    """Load the series of every topic of a grasp bag, of either format.

    Optional topics the bag lacks give empty arrays.
    """
    bag = open_bag(bag)
    fmt, ns = bag_namespace(bag, namespace)
    if fmt == 1:
        return _legacy_series(bag)
    return _lockstep_series(bag, ns)


def _lockstep_series(bag: Bag, ns: str) -> GraspSeries:
    t_tick = qualified(ns, TOPIC_TICK)
    t_refs = {qualified(ns, TOPIC_POSITION_REFERENCE), qualified(ns, TOPIC_FORCE_REFERENCE)}
    t_cmd = qualified(ns, TOPIC_MOTOR_COMMAND)
    t_status = qualified(ns, TOPIC_STATUS)
    t_object = qualified(ns, TOPIC_OBJECT_STATE)
    bag.require_topics([t_tick])
    ticks, refs, cmds, statuses, objects = [], [], [], [], []
    absent: set[str] = set()
    for raw in bag.messages:
        topic = raw.topic
        if topic == t_tick:
            values = TICK_LAYOUT.unpack(raw.data)
            ticks.append(values if values is not None else _fields(
                bag.decode(raw), TICK_LAYOUT.fields, 'tick', absent))
        elif topic in t_refs:
            values = REFERENCE_LAYOUT.unpack(raw.data)
            refs.append(values if values is not None else _fields(
                bag.decode(raw), REFERENCE_LAYOUT.fields, 'reference', absent))
        elif topic == t_cmd:
            values = COMMAND_LAYOUT.unpack(raw.data)
            cmds.append(values if values is not None else _fields(
                bag.decode(raw), COMMAND_LAYOUT.fields, 'command', absent))
        elif topic == t_status:
            m = bag.decode(raw)
            statuses.append((stamp_ns(m.header.stamp), m))
        elif topic == t_object:
            m = bag.decode(raw)
            objects.append((_t_s(m), m.state, m.slip_m, m.slip_speed_mps, m.load_n,
                            m.capacity_n))
    return lockstep_series(bag.path, ns, ticks, refs, cmds, statuses, objects,
                           custom_data=bag.custom_data_parsed(), counts=bag.counts(),
                           start_ns=bag.start_ns, end_ns=bag.end_ns, size_bytes=bag.size_bytes,
                           truncated=bag.truncated, damage=bag.damage, absent=frozenset(absent))


_NO_BAG = {'custom_data': {}, 'counts': {}, 'start_ns': 0, 'end_ns': 0, 'size_bytes': 0,
           'truncated': False}
"""The bag fields of a series that comes from no bag."""


def lockstep_series(path, ns: str, ticks: list[tuple], refs: list[tuple], cmds: list[tuple],
                    statuses: list[tuple], objects: list[tuple], **bag_fields) -> GraspSeries:
    """Build the series of lockstep messages, for bags and grasps re-run without ROS alike.

    ``ticks``, ``refs`` and ``cmds`` are the wire layouts' values (TICK_LAYOUT,
    REFERENCE_LAYOUT, COMMAND_LAYOUT), ``statuses`` (stamp_ns, an object with
    SupervisorStatus's fields), ``objects`` (t_s, state, slip_m, slip_speed_mps, load_n,
    capacity_n); ``bag_fields`` fill the rest of :class:`GraspSeries`. One builder, so that
    both give the same series.
    """
    # a repeated tick (a late peer) once; in tick order (DDS does not order topics)
    ticks = sorted(_unique_by(ticks, _key(TICK_LAYOUT, 'stamp_ns', 'revision')),
                   key=_key(TICK_LAYOUT, 'stamp_ns', 'revision'))
    refs = sorted(_unique_by(refs, _key(REFERENCE_LAYOUT, 'stage_id', 'stamp_ns')),
                  key=_key(REFERENCE_LAYOUT, 'stamp_ns', 'stage_id'))
    cmds = sorted(_unique_by(cmds, _key(COMMAND_LAYOUT, 'stage_id', 'stamp_ns')),
                  key=_key(COMMAND_LAYOUT, 'stamp_ns', 'stage_id'))
    tick = dict(zip(TICK_LAYOUT.fields, _columns(
        ticks, (np.int64,) + (float,) * 8 + (int, int) + (float,) * 4)))
    t_s = tick['stamp_ns'] * 1e-9
    f, i = float, int
    ref = dict(zip(REFERENCE_LAYOUT.fields, _columns(
        refs, (np.int64, i, i, i, i, i, i, bool, bool) + (f,) * 9)))
    switch = _switch_criteria(ref['stamp_ns'], statuses)
    status = StatusSeries(ref['stamp_ns'] * 1e-9, ref['phase'], ref['controller'], switch,
                          ref['grasp_id'], ref['outcome'], ref['position_setpoint_m'],
                          ref['force_setpoint_n'], ref['position_m'], ref['force_n'],
                          ref['contact'], ref['seed_voltage_v'], ref['stage_id'],
                          ref['approach_setpoint_m'])
    status = _with_final_state(status, statuses)
    cmd = dict(zip(COMMAND_LAYOUT.fields, _columns(
        cmds, (np.int64, i, i, i, i, i, i, bool, bool, f, f, f))))
    return GraspSeries(
        path=Path(path),
        joint=JointSeries(t_s, tick['position_m'], tick['velocity_mps'], tick['force_n']),
        sensor=SensorSeries(t_s, tick['force_n'], tick['sensor_voltage_v'],
                            tick['peak_force_n']),
        motor=MotorSeries(t_s, tick['motor_voltage_v'], tick['current_a'], tick['speed_rad_s']),
        status=status,
        command=CommandSeries(cmd['stamp_ns'] * 1e-9, cmd['voltage_v'], cmd['source'],
                              cmd['grasp_id'], cmd['hold_s'], cmd['inner_setpoint'],
                              cmd['stage_id']),
        namespace=ns, bag_format=2,
        objects=ObjectSeries(*_columns(objects, (f, i, f, f, f, f))), ticks=tick,
        references=ref, commands=cmd, **{**_NO_BAG, **bag_fields})


def _key(layout, *names):
    """Make a function of a message's values giving the named fields (de-duplication)."""
    index = tuple(layout.fields.index(n) for n in names)
    return lambda values: tuple(values[i] for i in index)


def _fields(msg, names, kind: str, absent: set) -> tuple:
    """``msg``'s values of ``names``; 0 for a field its (older) type lacks, named in ``absent``."""
    for n in names:
        if not hasattr(msg, n):
            absent.add(f'{kind}.{n}')
    return tuple(getattr(msg, n, 0) for n in names)


def _unique_by(rows: list, key) -> list:
    seen, out = set(), []
    for row in rows:
        k = key(row)
        if k not in seen:
            seen.add(k)
            out.append(row)
    return out


def _switch_criteria(stamps_ns: np.ndarray, statuses: list) -> np.ndarray:
    """Per decision tick, the switch criterion the supervisor's state reported by then."""
    out = np.zeros(len(stamps_ns), dtype=int)
    if not statuses:
        return out
    s_t = np.array([t for t, _ in statuses], dtype=np.int64)
    s_v = np.array([m.switch_criterion for _, m in statuses], dtype=int)
    idx = np.searchsorted(s_t, stamps_ns, side='right') - 1
    valid = idx >= 0
    out[valid] = s_v[idx[valid]]
    return out


def _with_final_state(status: StatusSeries, statuses: list) -> StatusSeries:
    """Append the supervisor's last state when it ended the request after the last reference.

    A FAULT: no stage is named, so no reference carries it.
    """
    if not statuses:
        return status
    t_ns, m = statuses[-1]
    last_t = status.t_s[-1] if status.t_s.size else -np.inf
    if t_ns * 1e-9 < last_t or (status.outcome.size and status.outcome[-1] == m.outcome and
                                status.phase[-1] == m.phase):
        return status
    row = (t_ns * 1e-9, m.phase, m.active_controller, m.switch_criterion, m.grasp_id, m.outcome,
           m.position_setpoint_m, m.force_setpoint_n, m.position_m, m.force_n, bool(m.contact),
           np.nan, m.stage_id, m.approach_setpoint_m)
    cols = [np.append(getattr(status, name), value) for name, value in
            zip(('t_s', 'phase', 'active_controller', 'switch_criterion', 'grasp_id', 'outcome',
                 'position_setpoint_m', 'force_setpoint_n', 'position_m', 'force_n', 'contact',
                 'seed_voltage_v', 'stage_id', 'approach_setpoint_m'), row)]
    return StatusSeries(*cols)


def _legacy_series(bag: Bag) -> GraspSeries:
    """Read a bag recorded before the lockstep protocol: a message per topic per tick."""
    topic = {name: qualified(LEGACY_NAMESPACE, name) for name in LEGACY_TOPICS}
    bag.require_topics([topic[TOPIC_JOINT_STATES], topic[TOPIC_FORCE_SENSOR],
                        topic[TOPIC_STATUS]])
    joint, sensor, motor, status, command = [], [], [], [], []
    for raw in bag.messages:
        if raw.topic == topic[TOPIC_JOINT_STATES]:
            m = bag.decode(raw)
            names = list(m.name)
            idx = names.index(FINGER_JOINT) if FINGER_JOINT in names else 0
            joint.append((_t_s(m), _joint_value(m.position, idx),
                          _joint_value(m.velocity, idx), _joint_value(m.effort, idx)))
        elif raw.topic == topic[TOPIC_FORCE_SENSOR]:
            m = bag.decode(raw)
            sensor.append((_t_s(m), m.force_n, m.voltage_v,
                           getattr(m, 'peak_force_n', float('nan'))))
        elif raw.topic == topic[LEGACY_MOTOR_STATE]:
            m = bag.decode(raw)
            motor.append((_t_s(m), m.voltage_v, m.current_a, m.speed_rad_s))
        elif raw.topic == topic[TOPIC_STATUS]:
            m = bag.decode(raw)
            status.append((_t_s(m), m.phase, m.active_controller, m.switch_criterion,
                           m.grasp_id, m.outcome, m.position_setpoint_m, m.force_setpoint_n,
                           m.position_m, m.force_n, bool(m.contact), m.seed_voltage_v,
                           getattr(m, 'approach_setpoint_m', m.position_setpoint_m)))
        elif raw.topic == topic[LEGACY_MOTOR_COMMAND]:
            m = bag.decode(raw)
            command.append((_t_s(m), m.voltage_v, m.source, m.grasp_id, m.hold_s,
                            m.inner_setpoint))
    f, i = float, int
    st = _columns(status, (f, i, i, i, i, i, f, f, f, f, bool, f, f))
    return GraspSeries(
        path=bag.path,
        joint=JointSeries(*_columns(joint, (f, f, f, f))),
        sensor=SensorSeries(*_columns(sensor, (f, f, f, f))),
        motor=MotorSeries(*_columns(motor, (f, f, f, f))),
        status=StatusSeries(*st[:12], stage_id=st[4].copy(), approach_setpoint_m=st[12]),
        command=CommandSeries(*_columns(command, (f, f, i, i, f, f))),
        custom_data=bag.custom_data_parsed(), counts=bag.counts(), start_ns=bag.start_ns,
        end_ns=bag.end_ns, size_bytes=bag.size_bytes, truncated=bag.truncated,
        damage=bag.damage, namespace=LEGACY_NAMESPACE, bag_format=1)
