"""The simulated plant's side of the lockstep loop, without ROS: when it steps, and with what.

The plant publishes the tick of ``stamp_ns``, takes the command for it and steps by the
command's ``hold_s``; with no command to wait for (realtime or a world's /clock, and nobody
commanding, a FAULT, a silent supervisor) it steps one state period at 0 V. Its pacing
(:mod:`gripper_ros.core.runtime.pacing`) says when. :class:`PlantLoop` keeps what decides a
step (a command accepted, a request waiting, nobody commanding) and what the steady chores do
(:meth:`PlantLoop.chore`); the node (``nodes/plant_simulator_node.py``) turns its answers into
publications, timers and log lines. Times are explicit: ``now_s`` is wall (monotonic) seconds,
``*_ns`` simulated nanoseconds.
"""
from __future__ import annotations

import enum

from gripper_ros.core.runtime.lockstep import Command, PlantSide
from gripper_ros.core.runtime.pacing import HELD, Pacing
from gripper_ros.core.runtime.world import busy_reason
from gripper_ros.wire import Controller, REPUBLISH_AFTER_S, TimeMode

STEP_BATCH = 100
"""Unpowered ticks taken in one go before the node yields (a sim/step, a world's time ahead)."""


class Chore(enum.Enum):
    """What a steady housekeeping call asks of the node (:meth:`PlantLoop.chore`)."""

    NONE = 'none'
    RUN = 'run'                  # nobody commands: step on at 0 V
    TIMED_OUT = 'timed out'      # no command for command_timeout_s: 0 V from now, step on
    REPUBLISH = 'republish'      # nobody answered the tick: publish it again (a late peer)


class PlantLoop:
    """The plant's lockstep state: the current tick, the command for it, who drives time."""

    def __init__(self, side: PlantSide, pacing: Pacing, state_period_ns: int,
                 now_s: float) -> None:
        self.side = side
        self.pacing = pacing
        self.fast = pacing.mode is TimeMode.FAST
        self.state_period_ns = state_period_ns
        self._hold_s = side.command_record['hold_s']     # a view: read every tick
        self.pending = False            # a command accepted for the current tick
        self.echoed = False             # a command was ever accepted (its echo counts)
        self.woken = False              # a request is waiting for simulated time
        self.unpowered = pacing.runs_unasked    # nobody commands (yet)
        self.status = None              # the supervisor's last status
        self.stamp_ns = side.tick().stamp_ns    # the current tick's
        self.published_s = now_s        # wall time the current tick was (re)published
        self.first_published_s = now_s  # ... first published

    # ------------------------------------------------------------------ what comes in
    def command_accepted(self) -> None:
        """Count a command accepted for the current tick: the next step is powered."""
        self.pending = self.echoed = True
        self.unpowered = False

    def take_status(self, status) -> None:
        """Take the supervisor's status: the grasp's mass, nobody commanding, a request waiting."""
        previous, self.status = self.status, status
        if previous is None or status.grasp_id != previous.grasp_id:
            if status.mass_kg > 0.0:
                self.side.grasp_mass_kg = status.mass_kg
        if status.active_controller == Controller.NONE and not self.pending:
            self.unpowered = True       # nobody will command: 0 V, when time runs
        if status.pending_request:
            self.woken = True

    def needs_time(self) -> bool:
        """Fast mode: a request waits, or the accepted command's scenario needs time."""
        return self.woken or (self.pending and self.side.command_needs_time())

    # ------------------------------------------------------------------ the step
    def gate(self) -> float | None:
        """Say when the next step may be taken: the pacing's answer (:meth:`Pacing.gate`).

        :data:`~gripper_ros.core.runtime.pacing.HELD` also when there is nothing to step with
        (no command yet, and time does not run without one).
        """
        powered = self.pending
        if not powered and not self.unpowered:
            return HELD
        hold_ns = round(float(self._hold_s[0]) * 1e9) if powered \
            else self.state_period_ns
        return self.pacing.gate(self.stamp_ns, self.stamp_ns + hold_ns, self.needs_time)

    def step(self) -> bool:
        """Take the step :meth:`gate` allowed; say whether the state topics are due."""
        powered = self.pending
        self.woken = self.pending = False
        self.stamp_ns, due = self.side.step_due() if powered else \
            self.side.step_unpowered_due(self.state_period_ns)
        return due

    def published(self, now_s: float) -> None:
        """Note the first publication of the current tick, at wall time ``now_s``."""
        self.published_s = self.first_published_s = now_s

    def republished(self, now_s: float) -> None:
        """Note the current tick published again at ``now_s`` (that is no answer)."""
        self.published_s = now_s

    def chore(self, now_s: float, waiting: bool, command_timeout_s: float) -> Chore:
        """Say what the steady housekeeping does at wall time ``now_s``.

        ``waiting``: a step is already waiting for the pace. Time runs with nobody commanding
        (realtime, /clock); a tick unanswered for ``command_timeout_s`` (republishing it is
        no answer) holds the motor at 0 V from then; one unanswered for
        :data:`~gripper_ros.wire.REPUBLISH_AFTER_S` goes out again.
        """
        if self.pending or self.pacing.paused:
            return Chore.NONE
        runs_unasked = self.pacing.runs_unasked
        if self.unpowered and runs_unasked and not waiting:
            return Chore.RUN
        if runs_unasked and not self.unpowered and self.silent_s(now_s) >= command_timeout_s:
            self.unpowered = True
            return Chore.TIMED_OUT
        if now_s - self.published_s >= REPUBLISH_AFTER_S and not self.unpowered:
            return Chore.REPUBLISH
        return Chore.NONE

    def silent_s(self, now_s: float) -> float:
        """Wall seconds since the current tick was first published, unanswered."""
        return now_s - self.first_published_s

    # ------------------------------------------------------------------ the world
    def busy_reason(self) -> str:
        """Say why the world may not change now ('' when it may): :func:`world.busy_reason`."""
        echo = Command._make(self.side.command_record[0].item()) if self.echoed else None
        return busy_reason(echo, self.status)

    def placed(self) -> None:
        """Forget a command taken for the world before an object was placed; read the tick."""
        self.pending = False
        self.stamp_ns = self.side.tick().stamp_ns

    def start_at(self, world_ns: int) -> None:
        """Start simulated time at a world's first time ``world_ns``, on the state grid."""
        self.side.plant.t_ns = world_ns - world_ns % self.state_period_ns
        self.stamp_ns = self.side.tick().stamp_ns
