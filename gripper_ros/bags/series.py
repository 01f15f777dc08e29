"""A grasp bag as numpy series: the measurement, decision and command of every tick (no rclpy)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from gripper_ros.bags.reader import Bag, open_bag
from gripper_ros.wire import (FINGER_JOINT, GRAPH_TOPICS, TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES,
                              TOPIC_MOTOR_COMMAND, TOPIC_MOTOR_STATE, TOPIC_STATUS)

REQUIRED_GRASP_TOPICS = (TOPIC_JOINT_STATES, TOPIC_FORCE_SENSOR, TOPIC_STATUS)
"""Without these a bag cannot be analysed as a grasp."""

GRASP_TOPICS = GRAPH_TOPICS
"""Topic -> type of everything a grasp run publishes (what the recorder records by default)."""

def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


@dataclass
class JointSeries:
    """/gripper/joint_states: finger travel from fully open, its speed, contact force."""

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    contact_force_n: np.ndarray


@dataclass
class SensorSeries:
    """/gripper/force_sensor."""

    t_s: np.ndarray
    force_n: np.ndarray
    voltage_v: np.ndarray
    peak_force_n: np.ndarray      # largest force since the previous sample (NaN in older bags)


@dataclass
class MotorSeries:
    """/gripper/motor_state: voltage applied over the interval ending at t_s."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    speed_rad_s: np.ndarray


@dataclass
class StatusSeries:
    """/gripper/supervisor/status, one row per tick."""

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


@dataclass
class CommandSeries:
    """/gripper/motor_command, one row per controller answer."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    source: np.ndarray
    grasp_id: np.ndarray
    hold_s: np.ndarray
    inner_setpoint: np.ndarray


@dataclass
class GraspSeries:
    """Numpy series of one grasp bag; ``t_s`` everywhere = simulated time of header stamps."""

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

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


def _columns(rows: list[tuple], n: int, dtypes: tuple) -> list[np.ndarray]:
    if not rows:
        return [np.zeros(0, dtype=d) for d in dtypes]
    cols = list(zip(*rows))
    return [np.asarray(cols[i], dtype=dtypes[i]) for i in range(n)]


def _joint_value(values, index: int) -> float:
    return float(values[index]) if len(values) > index else float('nan')


def load_grasp_series(bag: Bag | str | os.PathLike,
                      required: Iterable[str] = REQUIRED_GRASP_TOPICS) -> GraspSeries:
    """Series of every graph topic of a grasp bag (missing optional topics give empty arrays)."""
    bag = open_bag(bag)
    bag.require_topics(required)
    joint, sensor, motor, status, command = [], [], [], [], []
    for raw in bag.messages:
        if raw.topic == TOPIC_JOINT_STATES:
            m = bag.decode(raw)
            names = list(m.name)
            idx = names.index(FINGER_JOINT) if FINGER_JOINT in names else 0
            joint.append((_stamp_ns(m) * 1e-9, _joint_value(m.position, idx),
                          _joint_value(m.velocity, idx), _joint_value(m.effort, idx)))
        elif raw.topic == TOPIC_FORCE_SENSOR:
            m = bag.decode(raw)
            sensor.append((_stamp_ns(m) * 1e-9, m.force_n, m.voltage_v,
                           getattr(m, 'peak_force_n', float('nan'))))
        elif raw.topic == TOPIC_MOTOR_STATE:
            m = bag.decode(raw)
            motor.append((_stamp_ns(m) * 1e-9, m.voltage_v, m.current_a, m.speed_rad_s))
        elif raw.topic == TOPIC_STATUS:
            m = bag.decode(raw)
            status.append((_stamp_ns(m) * 1e-9, m.phase, m.active_controller, m.switch_criterion,
                           m.grasp_id, m.outcome, m.position_setpoint_m, m.force_setpoint_n,
                           m.position_m, m.force_n, bool(m.contact), m.seed_voltage_v))
        elif raw.topic == TOPIC_MOTOR_COMMAND:
            m = bag.decode(raw)
            command.append((_stamp_ns(m) * 1e-9, m.voltage_v, m.source, m.grasp_id, m.hold_s,
                            m.inner_setpoint))
    f, i = float, int
    return GraspSeries(
        path=bag.path,
        joint=JointSeries(*_columns(joint, 4, (f, f, f, f))),
        sensor=SensorSeries(*_columns(sensor, 4, (f, f, f, f))),
        motor=MotorSeries(*_columns(motor, 4, (f, f, f, f))),
        status=StatusSeries(*_columns(status, 12, (f, i, i, i, i, i, f, f, f, f, bool, f))),
        command=CommandSeries(*_columns(command, 6, (f, f, i, i, f, f))),
        custom_data=bag.custom_data_parsed(), counts=bag.counts(), start_ns=bag.start_ns,
        end_ns=bag.end_ns, size_bytes=bag.size_bytes, truncated=bag.truncated,
        damage=bag.damage)
