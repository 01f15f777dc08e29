"""What the position and force controller nodes share: the lockstep answer to a reference.

A stage controller takes only the references addressed to it (``loop/position_reference`` or
``loop/force_reference``), each carrying its tick's measurement, and answers each (stage,
stamp) once on ``loop/motor_command``; a repeated reference (the plant still waiting, e.g. a
late peer) gets the same command again. It restarts from the measured state whenever the
supervisor assigns it a new stage. A non-finite measurement or output is never acted on: the
controller holds 0 V and reports it. The bookkeeping and the laws live in
:mod:`gripper_ros.core.control.stages` and :mod:`gripper_ros.core.runtime.lockstep` (no rclpy).

A watchdog (steady clock, parameter ``status_timeout_s``) covers a dead or hung supervisor:
while this controller is the named stage and the supervisor's status heartbeat has been silent
for that long, it publishes one 0 V command for the last tick it knows and logs an error naming
the supervisor. Only time in which the executor demonstrably ran counts. The default (3 s) lies
above the supervisor's own ``tick_timeout_s`` (2 s), so that a stall the supervisor can see ends
as its FAULT first.
"""
from __future__ import annotations

from collections import Counter

from gripper_interfaces.msg import MotorCommand, StageReference, SupervisorStatus
from gripper_ros.core.control.stages import Reference
from gripper_ros.core.runtime.lockstep import FOREIGN, REPEATED, StageSide
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import in_layout, read_status
from gripper_ros.nodes.parameters import ConfigParameters
from gripper_ros.nodes.watchdog import ExecutorSilence
from gripper_ros.wire import (CDR_LITTLE_ENDIAN, COMMAND_LAYOUT, Controller, NODE_PLANT,
                              REFERENCE_LAYOUT, STAGE_NODES, STAGE_REFERENCE_TOPICS,
                              STATUS_HEARTBEAT_S, TOPIC_MOTOR_COMMAND, TOPIC_STATUS, TOPIC_TICK)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType

DEFAULT_STATUS_TIMEOUT_S = 3.0
STATUS_TIMEOUT_RANGE_S = (1.5 * STATUS_HEARTBEAT_S, 600.0)
"""A timeout shorter than the heartbeat would find a live supervisor of a paused or idle graph
silent; half a period more covers a late heartbeat."""
WATCHDOG_PERIOD_S = 0.05


class LockstepController(GripperNode):
    """A stage controller node: its stage's references in, ``loop/motor_command`` out.

    Subclasses name their stage and config section (``class X(LockstepController,
    stage=Controller.FORCE, section='force_control')``), declare their own parameters in
    ``declare_stage_parameters()`` and build their stage (:mod:`gripper_ros.core.control.stages`)
    in ``build_stage(config)``. A gain set at run time is checked at once and takes effect when
    the supervisor next assigns this stage (the law restarts then anyway).
    """

    source: Controller = Controller.NONE
    reference_topic = ''
    section = ''

    def __init_subclass__(cls, stage: Controller, section: str, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.source, cls.section = stage, section
        cls.node_name, cls.reference_topic = STAGE_NODES[stage], STAGE_REFERENCE_TOPICS[stage]

    def __init__(self, **kwargs):
        super().__init__(self.node_name, **kwargs)
        self.parameters = ConfigParameters(self, (self.section,), ('plant',),
                                           on_change=self._on_config_change,
                                           check=self.build_stage)
        self.config = self.parameters.config
        self._next_stage = None                   # built from changed gains, not yet in use
        self.declare_stage_parameters()
        self.declare_parameter(
            'status_timeout_s', DEFAULT_STATUS_TIMEOUT_S, ParameterDescriptor(
                description='wall seconds without the supervisor status heartbeat, while this '
                            'controller is the named stage, before it commands 0 V once; keep '
                            "it above the supervisor's tick_timeout_s",
                floating_point_range=[FloatingPointRange(from_value=STATUS_TIMEOUT_RANGE_S[0],
                                                         to_value=STATUS_TIMEOUT_RANGE_S[1])]))
        self.stage = self.build_stage(self.config)
        self.controller = self.stage.controller
        self.sample_time_s = self.stage.sample_time_s
        self.side = StageSide(self.stage)
        self.commands_published = 0
        self.published: Counter = Counter()       # messages per (relative) topic
        self.nonfinite_answers = 0                # ticks answered with 0 V for want of numbers
        self.watchdog_trips = 0                   # 0 V commands for a silent supervisor
        self.watchdog_message = ''                # the error logged by the last trip
        self._has_ref = False                     # a reference was taken
        self._last_command: bytes | None = None
        self._named = False                       # the supervisor's status names this stage
        self._silence = ExecutorSilence()         # executor-running time without a status
        self._watchdog_tripped = False
        self._pub = self.graph_publisher(MotorCommand, TOPIC_MOTOR_COMMAND)
        self.graph_subscription(StageReference, self.reference_topic, self._on_reference)
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self.create_timer(WATCHDOG_PERIOD_S, self._watchdog,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

    def declare_stage_parameters(self) -> None:
        """Declare the parameters ``build_stage`` reads (the controller kind...)."""

    def build_stage(self, config):
        raise NotImplementedError

    def _on_config_change(self, config, keys, stage) -> None:
        self.config = config
        self._next_stage = stage                 # built by the check, used from the next stage
        self.get_logger().info(f'{", ".join(keys)} changed: in effect from the next stage')

    @property
    def status_timeout_s(self) -> float:
        return self.get_parameter('status_timeout_s').value

    # lockstep ------------------------------------------------------------------
    @property
    def _last_ref(self) -> Reference | None:
        """The newest reference taken (None before the first)."""
        return Reference._make(self.side.reference_record[0].item()) if self._has_ref else None

    def _on_reference(self, data: bytes) -> None:
        if self._next_stage is not None:          # new gains wait for the next stage
            values = REFERENCE_LAYOUT.unpack(data) or \
                REFERENCE_LAYOUT.unpack(in_layout(REFERENCE_LAYOUT, data, StageReference))
            if Reference._make(values).stage_id != self.side.answerer.active_stage:
                self.stage, self._next_stage = self._next_stage, None      # a new stage begins
                self.controller = self.stage.controller
                self.side = StageSide(self.stage)
        side = self.side
        taken = side.take_reference(data)
        if taken == FOREIGN:                      # another encapsulation: the general way
            taken = side.take_reference(in_layout(REFERENCE_LAYOUT, data, StageReference))
        self._has_ref = self._named = True
        if taken == REPEATED:
            if self._last_command is not None:    # asked again: the plant is still waiting
                self._pub.publish(self._last_command)
                self.published[TOPIC_MOTOR_COMMAND] += 1
            return
        if not side.finite[0]:
            self.nonfinite_answers += 1
            ref = self._last_ref
            self.get_logger().error(f'{side.last_answer.reason} at t={ref.stamp_ns} '
                                    f'(measurement {self.stage.measurement(ref)!r}): holding 0 V',
                                    throttle_duration_sec=1.0)
        self._last_command = CDR_LITTLE_ENDIAN + side.command_record.tobytes()
        self._pub.publish(self._last_command)
        self.commands_published += 1
        self.published[TOPIC_MOTOR_COMMAND] += 1

    def _on_status(self, data: bytes) -> None:
        self._named = read_status(data).active_controller == self.source
        self._silence.reset()
        self._watchdog_tripped = False

    # watchdog ------------------------------------------------------------------
    def _watchdog(self) -> None:
        """Named, and the supervisor silent for ``status_timeout_s``: command 0 V once."""
        ref = self._last_ref
        watching = self._named and ref is not None and not self._watchdog_tripped
        silent_s = self._silence.check(counting=watching)
        if not watching or silent_s < self.status_timeout_s:
            return
        self._watchdog_tripped = True
        if self.count_publishers(TOPIC_STATUS) == 0:
            why = f'the supervisor is gone (no publisher on {TOPIC_STATUS})'
        elif NODE_PLANT not in {i.node_name for i in self.get_publishers_info_by_topic(
                self.resolve_topic_name(TOPIC_TICK))}:
            why = f'the supervisor is silent and {NODE_PLANT} is gone (no publisher on ' \
                  f'{TOPIC_TICK})'
        else:
            why = 'the supervisor is silent'
        self.watchdog_message = (
            f'no status from the supervisor for {silent_s:.2f} s of wall time while '
            f'{self.get_name()} was the named stage (grasp {ref.grasp_id}, '
            f't={ref.stamp_ns * 1e-9:.4f} s): {why}; commanding 0 V')
        self.get_logger().error(self.watchdog_message)
        self.watchdog_trips += 1
        # answered: a reference arriving late adds no second command for this tick
        self.side.answerer.answered = (ref.stage_id, ref.stamp_ns)
        self._last_command = COMMAND_LAYOUT.pack(
            ref.stamp_ns, ref.grasp_id, ref.stage_id, ref.revision, int(self.source), ref.phase,
            ref.outcome, ref.running, False, 0.0, self.sample_time_s, 0.0)
        self._pub.publish(self._last_command)
        self.published[TOPIC_MOTOR_COMMAND] += 1
