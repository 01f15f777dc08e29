"""What the position and force controller nodes share: the lockstep answer to a tick.

A controller answers tick ``t_k`` once it holds both the supervisor's status for ``t_k`` naming it
active and its own measurement for ``t_k``. It is (re)initialised, bumplessly, whenever it becomes
active for a grasp. A non-finite measurement is never passed on: the controller holds 0 V and
reports it.
"""
from __future__ import annotations

import math

from gripper_interfaces.msg import MotorCommand, SupervisorStatus
from rclpy.node import Node

from .ros_common import GRAPH_QOS, TOPIC_MOTOR_COMMAND, TOPIC_STATUS, time_to_ns


class LockstepController(Node):
    """Subclasses set ``source``, ``sample_time_s`` and implement ``activate``/``compute``."""

    source: int = MotorCommand.SOURCE_NONE

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self._status: SupervisorStatus | None = None
        self._measurement_ns: int | None = None
        self._measurement: float = 0.0
        self._answered: tuple[int, int] | None = None   # (grasp_id, stamp) last answered
        self._active_grasp: int | None = None
        self.sample_time_s = 0.0
        self.commands_published = 0
        self._pub = self.create_publisher(MotorCommand, TOPIC_MOTOR_COMMAND, GRAPH_QOS)
        self.create_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status, GRAPH_QOS)
        self._command = MotorCommand(source=self.source)

    # subclasses ----------------------------------------------------------------
    def activate(self, status: SupervisorStatus, measurement: float) -> None:
        """Called when this controller takes over (new grasp or stage switch)."""
        raise NotImplementedError

    def compute(self, status: SupervisorStatus, measurement: float) -> tuple[float, float]:
        """Return (voltage_v, inner_setpoint) for this tick."""
        raise NotImplementedError

    # lockstep ------------------------------------------------------------------
    def _on_status(self, msg: SupervisorStatus) -> None:
        self._status = msg
        if msg.active_controller != self.source:
            self._active_grasp = None
        self._try_answer()

    def on_measurement(self, stamp_ns: int, value: float) -> None:
        self._measurement_ns = stamp_ns
        self._measurement = value
        self._try_answer()

    def _try_answer(self) -> None:
        status = self._status
        if status is None or status.active_controller != self.source:
            return
        stamp_ns = time_to_ns(status.header.stamp)
        if self._measurement_ns != stamp_ns:
            return
        key = (status.grasp_id, stamp_ns)
        if key == self._answered:
            return
        self._answered = key
        value = self._measurement
        if not math.isfinite(value):
            self.get_logger().error(f'non-finite measurement {value!r} at t={stamp_ns}: '
                                    'holding 0 V', throttle_duration_sec=1.0)
            voltage, inner = 0.0, 0.0
        else:
            if self._active_grasp != status.grasp_id:
                self.activate(status, value)
                self._active_grasp = status.grasp_id
            voltage, inner = self.compute(status, value)
        cmd = self._command
        cmd.header.stamp = status.header.stamp
        cmd.grasp_id = status.grasp_id
        cmd.voltage_v = float(voltage)
        cmd.hold_s = self.sample_time_s
        cmd.inner_setpoint = float(inner)
        self._pub.publish(cmd)
        self.commands_published += 1
