"""The three sides of one lockstep tick, shared by the nodes and the headless loop (no rclpy).

Each tick ``t_k``: the plant measures (:class:`Tick`), the supervisor decides and sends a
:class:`Reference` to the stage it names, that stage answers with a :class:`Command`, and the
plant holds the command's voltage for its ``hold_s``. The nodes move these tuples over DDS as
bytes (:mod:`gripper_ros.wire` layouts); :mod:`gripper_ros.core.headless` hands them over
directly. Both call exactly the code below, so a headless grasp equals the graph's tick for tick.
"""
from __future__ import annotations

from collections import namedtuple
import math

from gripper_ros.core.plant import GraspObject, GripperPlant, PlantSample
from gripper_ros.core.stages import LockstepAnswerer, Reference
from gripper_ros.core.supervisor import Decision, GraspSupervisor
from gripper_ros.wire import COMMAND_LAYOUT, Controller, FaultKind, Outcome, Phase, TICK_LAYOUT

Tick = namedtuple('Tick', TICK_LAYOUT.fields)
"""One PlantTick's fields, in message order."""
Command = namedtuple('Command', COMMAND_LAYOUT.fields)
"""One MotorCommand's fields, in message order."""

MAX_HOLD_S = 1.0
"""A command held longer than this is refused as malformed."""


def tick_of(sample: PlantSample, revision: int, applied_source: int) -> Tick:
    """Return the tick message of a plant sample."""
    return Tick(sample.t_ns, sample.position_m, sample.velocity_mps, sample.force_n,
                sample.peak_force_n, sample.sensor_voltage_v, sample.voltage_v,
                sample.current_a, sample.speed_rad_s, applied_source, revision)


def command_problem(cmd: Command) -> str:
    """Why the plant must refuse ``cmd`` ('' when it is usable)."""
    if not math.isfinite(cmd.voltage_v):
        return f'voltage {cmd.voltage_v!r} V is not finite'
    if not (math.isfinite(cmd.hold_s) and 0.0 < cmd.hold_s <= MAX_HOLD_S):
        return f'hold {cmd.hold_s!r} s is not in (0, {MAX_HOLD_S:g}] s'
    if cmd.source not in (Controller.POSITION, Controller.FORCE):
        return f'source {cmd.source!r} is no stage controller'
    return ''


class PlantSide:
    """The plant's share of a tick: the measurement, the command's echo, the step.

    The echo of each accepted command tells the plant, at that exact tick, what the supervisor
    decided: a scheduled fault is armed when a grasp starts (its first command), and the hold
    clock of a lift starts when the grasp is answered HOLDING.
    """

    def __init__(self, plant: GripperPlant):
        self.plant = plant
        self.revision = 0                   # +1 on every change of the simulated world
        self.applied_source = Controller.NONE
        self.grasp_mass_kg = 0.0            # the requested mass of the grasp (from its status)
        self._fault: tuple[FaultKind, float, float] | None = None   # (kind, at_s, tau) to arm
        self._fault_grasp: int | None = None
        self._echo_grasp = 0                # grasp id of the last accepted command
        self._hold_begun_for: int | None = None

    def tick(self) -> Tick:
        return tick_of(self.plant.sample(), self.revision, self.applied_source)

    def set_object(self, obj: GraspObject, open_fingers: bool = False,
                   fault: tuple[FaultKind, float, float] | None = None, **hold) -> None:
        """Place ``obj`` (ValueError and nothing changes when refused).

        ``fault`` (kind, seconds after the next grasp's start, time constant) is armed when
        that grasp starts.
        """
        saved = self.plant.snapshot()
        try:
            if open_fingers:
                self.plant.reset(open_fingers=True)
            self.plant.set_object(obj, **hold)
        except ValueError:
            self.plant.restore(saved)           # refused: the plant is as it was
            raise
        self._fault = None if fault is None or fault[0] is FaultKind.NONE else fault
        self._fault_grasp = None
        self._hold_begun_for = None
        self.applied_source = Controller.NONE
        self.revision += 1

    def accept(self, cmd: Command) -> None:
        """React to the decision ``cmd`` echoes, at the tick it answers."""
        if cmd.grasp_id != self._echo_grasp:
            self._echo_grasp = cmd.grasp_id
            if self._fault is not None and cmd.phase == Phase.POSITION:
                kind, at_s, tau = self._fault
                self._fault = None
                self._fault_grasp = cmd.grasp_id
                self.plant.schedule_fault(kind, cmd.stamp_ns + round(at_s * 1e9), tau)
        if cmd.outcome != Outcome.UNKNOWN and self.plant.scheduled_fault is not None and \
                cmd.grasp_id == self._fault_grasp:
            self.plant.cancel_fault()            # the grasp ended before its fault fired
        if cmd.phase == Phase.HOLDING and cmd.outcome == Outcome.HOLDING and \
                self._hold_begun_for != cmd.grasp_id:
            self._hold_begun_for = cmd.grasp_id
            try:
                self.plant.begin_hold(cmd.stamp_ns, self.grasp_mass_kg)
            except ValueError:
                pass            # the object left its support in an earlier hold: no new lift

    def needs_time(self, cmd: Command) -> bool:
        """Tell whether simulated time must go on after ``cmd`` in fast mode.

        It must for a request in progress, or a hold scenario (a lift) still to be played out.
        """
        return bool(cmd.running) or self.plant.scenario_in_progress()

    def step(self, cmd: Command) -> Tick:
        """Hold the command's voltage for its ``hold_s``; the next tick."""
        self.applied_source = cmd.source
        return tick_of(self.plant.step(cmd.voltage_v, cmd.hold_s), self.revision, cmd.source)

    def step_unpowered(self, duration_s: float) -> Tick:
        """No command came: the motor is held at 0 V (a driver's command timeout)."""
        self.applied_source = Controller.NONE
        return tick_of(self.plant.step(0.0, duration_s), self.revision, Controller.NONE)


class SupervisorSide:
    """The supervisor's share of a tick: decide, and address the reference to one stage."""

    def __init__(self, supervisor: GraspSupervisor):
        self.supervisor = supervisor
        self._seed_v = 0.0

    def decide(self, tick: Tick) -> tuple[Decision, Reference | None]:
        """Return the decision for ``tick`` and the reference to the stage it names (or None).

        The reference relays the tick's measurement as read, a non-finite one included (the
        stage then holds 0 V); the seed voltage is the last finite applied one, since no
        measurement of the stage depends on it.
        """
        d = self.supervisor.step(tick.stamp_ns, tick.position_m, tick.force_n,
                                 tick.sensor_voltage_v, tick.velocity_mps, tick.revision)
        if math.isfinite(tick.motor_voltage_v):
            self._seed_v = tick.motor_voltage_v
        if d.active is Controller.NONE:
            return d, None
        return d, Reference(tick.stamp_ns, d.grasp_id, d.stage_id, tick.revision,
                            int(d.phase), int(d.outcome), int(d.active), d.running, d.contact,
                            d.position_setpoint_m, d.approach_setpoint_m, d.force_setpoint_n,
                            tick.position_m, tick.velocity_mps, tick.force_n, self._seed_v,
                            d.speed_limit_mps, d.voltage_limit_v)


class StageSide:
    """A stage controller's share of a tick: answer each reference once."""

    def __init__(self, stage):
        self.stage = stage
        self.answerer = LockstepAnswerer(stage)
        self.last_answer = None                 # the TickAnswer of the last command

    def answer(self, ref: Reference) -> Command | None:
        """Return the command for ``ref``, or None when that (stage, stamp) was answered."""
        a = self.answerer.answer(ref)
        if a is None:
            return None
        self.last_answer = a
        return Command(ref.stamp_ns, ref.grasp_id, ref.stage_id, ref.revision,
                       int(self.stage.source), ref.phase, ref.outcome, ref.running, a.finite,
                       a.voltage_v, self.stage.sample_time_s, a.inner_setpoint)
