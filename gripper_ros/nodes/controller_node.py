"""What the position and force controller nodes share: the lockstep answer to a tick.

A controller answers tick ``t_k`` once it holds both the supervisor's status for ``t_k`` naming it
active and its own measurement for ``t_k``. It is (re)initialised, bumplessly, whenever it becomes
active for a grasp. A non-finite measurement is never passed on, and a non-finite output is never
published: the controller holds 0 V and reports it.

A status watchdog (steady clock, parameter ``status_timeout_s``) covers a dead or hung
supervisor: while this controller is the active one and no new status has arrived for that long,
it publishes one 0 V command (``hold_s`` as usual) and logs an error naming the supervisor. Only
time in which the executor demonstrably ran counts (a check more than 0.25 s late adds 0.25 s):
after a stall of the whole process, statuses queued behind the watchdog are not mistaken for
silence. The
default (3 s) lies above the supervisor's own ``tick_timeout_s`` (2 s), so that a stall the
supervisor can see (a dead plant or controller) ends as the supervisor's FAULT first and no
controller commands anything after it. The 0 V command is stamped with the tick of the last
status. Normally the controller has answered that tick and the plant has moved on, so the plant
ignores it: simulated time stays where it stopped and the command stands for what a motor driver
would be told. If the tick was still unanswered (its measurement never came), the plant holds
0 V for it, and a late measurement adds no second answer.

The bookkeeping and the control laws live in :mod:`gripper_ros.core.stages` (no rclpy), so
that ``bag_replay --resimulate`` runs exactly the code the nodes run.
"""
from __future__ import annotations

from gripper_interfaces.msg import MotorCommand, SupervisorStatus
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from gripper_ros.core.stages import LockstepAnswerer
from gripper_ros.nodes.common import (GRAPH_QOS, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND, TOPIC_STATUS,
                         ExecutorSilence, time_to_ns)

DEFAULT_STATUS_TIMEOUT_S = 3.0
STATUS_TIMEOUT_RANGE_S = (0.1, 600.0)
WATCHDOG_PERIOD_S = 0.05


class LockstepController(Node):
    """Subclasses set ``source``, ``sample_time_s`` and implement ``activate``/``compute``
    (the nodes delegate both to a stage of :mod:`gripper_ros.core.stages`)."""

    source: int = MotorCommand.SOURCE_NONE

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self._status: SupervisorStatus | None = None
        self._measurement_ns: int | None = None
        self._measurement: float = 0.0
        self._lockstep = LockstepAnswerer(self)   # answers once per (grasp_id, stamp)
        self.sample_time_s = 0.0
        self.commands_published = 0
        self.nonfinite_answers = 0                # ticks answered with 0 V for want of numbers
        self.watchdog_trips = 0                   # 0 V commands for a silent supervisor
        self.watchdog_message = ''                # the error logged by the last trip
        self.declare_parameter(
            'status_timeout_s', DEFAULT_STATUS_TIMEOUT_S, ParameterDescriptor(
                description='wall seconds without a new supervisor status, while this controller '
                            'is active, before it commands 0 V once; keep it above the '
                            "supervisor's tick_timeout_s",
                floating_point_range=[FloatingPointRange(from_value=STATUS_TIMEOUT_RANGE_S[0],
                                                         to_value=STATUS_TIMEOUT_RANGE_S[1])]))
        self._silence = ExecutorSilence()         # executor-running time since the last status
        self._watchdog_tripped = False
        self._pub = self.create_publisher(MotorCommand, TOPIC_MOTOR_COMMAND, GRAPH_QOS)
        self.create_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status, GRAPH_QOS)
        self._command = MotorCommand(source=self.source)
        self.create_timer(WATCHDOG_PERIOD_S, self._watchdog,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def status_timeout_s(self) -> float:
        return self.get_parameter('status_timeout_s').value

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
        self._silence.reset()
        self._watchdog_tripped = False
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
            self.nonfinite_answers += 1
            self.get_logger().error(f'{answer.reason} at t={stamp_ns} (measurement '
                                    f'{self._measurement!r}): holding 0 V',
                                    throttle_duration_sec=1.0)
        self._publish(status, answer.voltage_v, answer.inner_setpoint)

    def _publish(self, status: SupervisorStatus, voltage: float, inner: float) -> None:
        cmd = self._command
        cmd.header.stamp = status.header.stamp
        cmd.grasp_id = status.grasp_id
        cmd.voltage_v = float(voltage)
        cmd.hold_s = self.sample_time_s
        cmd.inner_setpoint = float(inner)
        self._pub.publish(cmd)
        self.commands_published += 1

    # watchdog ------------------------------------------------------------------
    def _watchdog(self) -> None:
        """Active, and the supervisor silent for ``status_timeout_s``: command 0 V once."""
        status = self._status
        watching = not (status is None or status.active_controller != self.source
                        or self._watchdog_tripped)
        silent_s = self._silence.check(counting=watching)
        if not watching or silent_s < self.status_timeout_s:
            return
        self._watchdog_tripped = True
        if self.count_publishers(TOPIC_STATUS) == 0:
            why = f'the supervisor is gone (no publisher on {TOPIC_STATUS})'
        elif 'plant_simulator' not in {i.node_name for i in
                                       self.get_publishers_info_by_topic(TOPIC_JOINT_STATES)}:
            why = (f'the supervisor is silent and plant_simulator is gone (no publisher on '
                   f'{TOPIC_JOINT_STATES})')
        else:
            why = 'the supervisor is silent'
        self.watchdog_message = (
            f'no status from the supervisor for {silent_s:.2f} s of wall time while '
            f'{self.get_name()} was active (grasp {status.grasp_id}, '
            f't={time_to_ns(status.header.stamp) * 1e-9:.4f} s): {why}; commanding 0 V')
        self.get_logger().error(self.watchdog_message)
        self.watchdog_trips += 1
        # this tick counts as answered: a measurement arriving late adds no second command
        self._lockstep.answered = (status.grasp_id, time_to_ns(status.header.stamp))
        self._publish(status, 0.0, 0.0)
