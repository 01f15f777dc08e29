"""What the position and force controller nodes share: the lockstep answer to a tick.

A controller answers tick ``t_k`` once it holds both the supervisor's status for ``t_k`` naming it
active and its own measurement for ``t_k``. It is (re)initialised, bumplessly, whenever it becomes
active for a grasp. A non-finite measurement is never passed on: the controller holds 0 V and
reports it.

The bookkeeping and the control laws live in :mod:`gripper_ros.controller_logic` (no rclpy), so
that ``bag_replay --resimulate`` runs exactly the code the nodes run.
"""
from __future__ import annotations

from gripper_interfaces.msg import MotorCommand, SupervisorStatus
from rclpy.node import Node

from .controller_logic import LockstepAnswerer
from .ros_common import GRAPH_QOS, TOPIC_MOTOR_COMMAND, TOPIC_STATUS, time_to_ns


class LockstepController(Node):
    """Subclasses set ``source``, ``sample_time_s`` and implement ``activate``/``compute``
    (the nodes delegate both to a stage of :mod:`gripper_ros.controller_logic`)."""

    source: int = MotorCommand.SOURCE_NONE

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self._status: SupervisorStatus | None = None
        self._measurement_ns: int | None = None
        self._measurement: float = 0.0
        self._lockstep = LockstepAnswerer(self)   # answers once per (grasp_id, stamp)
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
        self._lockstep.on_status(msg)
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
        answer = self._lockstep.answer(status, stamp_ns, self._measurement)
        if answer is None:
            return
        if not answer.finite:
            self.get_logger().error(f'non-finite measurement {self._measurement!r} at '
                                    f't={stamp_ns}: holding 0 V', throttle_duration_sec=1.0)
        voltage, inner = answer.voltage_v, answer.inner_setpoint
        cmd = self._command
        cmd.header.stamp = status.header.stamp
        cmd.grasp_id = status.grasp_id
        cmd.voltage_v = float(voltage)
        cmd.hold_s = self.sample_time_s
        cmd.inner_setpoint = float(inner)
        self._pub.publish(cmd)
        self.commands_published += 1
