"""A grasp bag as numpy series: the measurement, decision and command of every tick (no rclpy).

Two bag formats are read. Bags of the lockstep protocol (custom_data ``gripper_ros.format`` 2)
hold ``<ns>/loop/tick`` (measurement), ``<ns>/loop/position_reference`` and
``<ns>/loop/force_reference`` (decision), ``<ns>/loop/motor_command`` (command), plus the
state topics. Earlier bags held one tick message per topic under ``/gripper``
(``joint_states``, ``force_sensor``, ``motor_state``, ``supervisor/status``, ``motor_command``
with headers). Both give the same :class:`gripper_ros.core.series.GraspSeries`.
"""
from __future__ import annotations

import math
import os

from gripper_ros.bags.reader import Bag, MissingTopicsError, open_bag
from gripper_ros.core.series import GraspSeries, OBJECT_ROW, rows, STATUS_ROW
from gripper_ros.wire import (COMMAND_LAYOUT, FINGER_JOINT, GRAPH_TOPICS, qualified,
                              REFERENCE_LAYOUT, stamp_ns, TICK_LAYOUT, TOPIC_FORCE_REFERENCE,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_OBJECT_STATE, TOPIC_POSITION_REFERENCE, TOPIC_STATUS,
                              TOPIC_TICK)

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
            statuses.append(_status_row(m))
        elif topic == t_object:
            m = bag.decode(raw)
            objects.append((stamp_ns(m.header.stamp), m.state, m.slip_m, m.slip_speed_mps,
                            m.load_n, m.capacity_n))
    # a repeated message (a late peer) once; in tick order (DDS does not order topics)
    ticks = sorted(_unique_by(ticks, _key(TICK_LAYOUT, 'stamp_ns', 'revision')),
                   key=_key(TICK_LAYOUT, 'stamp_ns', 'revision'))
    refs = sorted(_unique_by(refs, _key(REFERENCE_LAYOUT, 'stage_id', 'stamp_ns')),
                  key=_key(REFERENCE_LAYOUT, 'stamp_ns', 'stage_id'))
    cmds = sorted(_unique_by(cmds, _key(COMMAND_LAYOUT, 'stage_id', 'stamp_ns')),
                  key=_key(COMMAND_LAYOUT, 'stamp_ns', 'stage_id'))
    return GraspSeries(rows(TICK_LAYOUT.dtype, ticks), rows(REFERENCE_LAYOUT.dtype, refs),
                       rows(COMMAND_LAYOUT.dtype, cmds), rows(STATUS_ROW, statuses),
                       rows(OBJECT_ROW, objects), namespace=ns, bag_format=2,
                       absent=frozenset(absent), **_bag_fields(bag))


def _bag_fields(bag: Bag) -> dict:
    """Return what a series says of the bag it was read from."""
    return {'path': bag.path, 'custom_data': bag.custom_data_parsed(), 'counts': bag.counts(),
            'start_ns': bag.start_ns, 'end_ns': bag.end_ns, 'size_bytes': bag.size_bytes,
            'truncated': bag.truncated, 'damage': bag.damage}


def _status_row(m) -> tuple:
    """Return a SupervisorStatus message as a :data:`STATUS_ROW`.

    A message type without a stage id or an approach setpoint (an older bag's) gives the grasp
    id and the position setpoint.
    """
    return (stamp_ns(m.header.stamp), m.phase, m.active_controller, m.switch_criterion,
            m.grasp_id, m.outcome, m.position_setpoint_m, m.force_setpoint_n, m.position_m,
            m.force_n, bool(m.contact), getattr(m, 'stage_id', m.grasp_id),
            getattr(m, 'approach_setpoint_m', m.position_setpoint_m),
            getattr(m, 'pending_request', 0), math.nan)


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


def _unique_by(values: list, key) -> list:
    seen, out = set(), []
    for row in values:
        k = key(row)
        if k not in seen:
            seen.add(k)
            out.append(row)
    return out


LEGACY_TICK_FIELDS = ('peak_force_n', 'applied_source', 'revision', 'pad1_shear_n',
                      'pad2_shear_n', 'pad1_displacement_m', 'pad2_displacement_m')
"""The tick fields a bag recorded before the lockstep protocol has no message for."""


def _legacy_series(bag: Bag) -> GraspSeries:
    """Read a bag recorded before the lockstep protocol: a message per topic per tick.

    Its joint, force-sensor and motor messages of one stamp make that stamp's tick; each
    supervisor status is the decision of its tick, and the motor commands are the commands.
    """
    topic = {name: qualified(LEGACY_NAMESPACE, name) for name in LEGACY_TOPICS}
    bag.require_topics([topic[TOPIC_JOINT_STATES], topic[TOPIC_FORCE_SENSOR],
                        topic[TOPIC_STATUS]])
    joint, sensor, motor, status, command = [], {}, {}, [], []
    peak_recorded = False
    for raw in bag.messages:
        if raw.topic == topic[TOPIC_JOINT_STATES]:
            m = bag.decode(raw)
            names = list(m.name)
            idx = names.index(FINGER_JOINT) if FINGER_JOINT in names else 0
            joint.append((stamp_ns(m.header.stamp), _joint_value(m.position, idx),
                          _joint_value(m.velocity, idx)))
        elif raw.topic == topic[TOPIC_FORCE_SENSOR]:
            m = bag.decode(raw)
            peak_recorded = peak_recorded or hasattr(m, 'peak_force_n')
            sensor[stamp_ns(m.header.stamp)] = (m.force_n, m.voltage_v,
                                                getattr(m, 'peak_force_n', float('nan')))
        elif raw.topic == topic[LEGACY_MOTOR_STATE]:
            m = bag.decode(raw)
            motor[stamp_ns(m.header.stamp)] = (m.voltage_v, m.current_a, m.speed_rad_s)
        elif raw.topic == topic[TOPIC_STATUS]:
            m = bag.decode(raw)
            status.append(m)
        elif raw.topic == topic[LEGACY_MOTOR_COMMAND]:
            m = bag.decode(raw)
            command.append((stamp_ns(m.header.stamp), m.grasp_id, 0, 0, m.source, 0, 0, 0, 1,
                            m.voltage_v, m.hold_s, m.inner_setpoint))
    nan3 = (math.nan,) * 3
    ticks = [(t_ns, position_m, velocity_mps, force_n, peak_force_n, sensor_voltage_v,
              motor_voltage_v, current_a, speed_rad_s, 0, 0, 0.0, 0.0, 0.0, 0.0)
             for t_ns, position_m, velocity_mps in joint
             for force_n, sensor_voltage_v, peak_force_n in [sensor.get(t_ns, nan3)]
             for motor_voltage_v, current_a, speed_rad_s in [motor.get(t_ns, nan3)]]
    statuses = [_status_row(m) for m in status]
    refs = [(t_ns, grasp_id, grasp_id, 0, phase, outcome, controller, 0, contact, position_sp,
             approach_sp, force_sp, position_m, 0.0, force_n, m.seed_voltage_v, 0.0, 0.0, 0.0,
             0.0)
            for m, (t_ns, phase, controller, _, grasp_id, outcome, position_sp, force_sp,
                    position_m, force_n, contact, _, approach_sp, _, _) in zip(status, statuses)]
    absent = {f'tick.{n}' for n in LEGACY_TICK_FIELDS[int(peak_recorded):]} | {
        f'reference.{n}' for n in ('revision', 'running', 'velocity_mps', 'speed_limit_mps',
                                   'voltage_limit_v', 'approach_velocity_mps',
                                   'approach_acceleration_mps2')} | {
        f'command.{n}' for n in ('stage_id', 'revision', 'phase', 'outcome', 'running',
                                 'finite')}
    if not motor:
        absent |= {f'tick.{n}' for n in ('motor_voltage_v', 'current_a', 'speed_rad_s')}
    return GraspSeries(rows(TICK_LAYOUT.dtype, ticks), rows(REFERENCE_LAYOUT.dtype, refs),
                       rows(COMMAND_LAYOUT.dtype, command), rows(STATUS_ROW, statuses),
                       namespace=LEGACY_NAMESPACE, bag_format=1, absent=frozenset(absent),
                       **_bag_fields(bag))
