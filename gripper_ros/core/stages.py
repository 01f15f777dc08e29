"""What a controller node does with one lockstep tick, without rclpy (nodes and re-simulation).

The position and force controller nodes are thin: they pair the supervisor's status for tick
``t_k`` with their own measurement for ``t_k`` and publish the answer. Everything else lives
here, so that ``bag_replay --resimulate`` (:mod:`gripper_ros.bags.resimulate`) runs the very same code
on recorded measurements and gets bit-identical commands:

- :class:`PositionStageController`: MPC-PD (or PD / PID), reset from rest at the measured
  position whenever it takes over.
- :class:`ForceStageController`: PI (or MPC-PI), seeded bumplessly from the status'
  ``seed_voltage_v``, its output capped before contact at ``approach_force_margin`` x F_sp /
  (N per V) and released once the status reports contact.
- :class:`LockstepAnswerer`: the per-tick bookkeeping of a node (answer each (grasp, stamp)
  once, (re)activate on a new grasp or after another controller was active, hold 0 V on a
  non-finite measurement or status number without touching the control law's state, and
  hold 0 V on a non-finite output or a law that refuses its inputs, re-initialising the law
  at the next good tick).

A *status* here is anything with the fields of ``gripper_interfaces/msg/SupervisorStatus`` that
are read (``active_controller``, ``grasp_id``, ``position_setpoint_m``, ``force_setpoint_n``,
``seed_voltage_v``, ``contact``): the rclpy message, a rosbags-decoded one, or a test double.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Protocol

from gripper_ros.core.config import ConfigError, GripperConfig
from gripper_ros.wire import Controller
from gripper_ros.core.controllers import (ForceControllerKind, PositionControllerKind, make_force_controller,
                          make_position_controller)

SOURCE_POSITION = Controller.POSITION
SOURCE_FORCE = Controller.FORCE

DEFAULT_POSITION_CONTROLLER = PositionControllerKind.MPC_PD
DEFAULT_FORCE_CONTROLLER = ForceControllerKind.CONTACT_AWARE
DEFAULT_APPROACH_FORCE_MARGIN = 1.0


class StatusLike(Protocol):
    active_controller: int
    grasp_id: int
    position_setpoint_m: float
    force_setpoint_n: float
    seed_voltage_v: float
    contact: bool


def parse_kind(kind_cls: type[enum.Enum], value, name: str = 'controller'):
    """``value`` as a member of ``kind_cls``; ConfigError naming the parameter otherwise."""
    if isinstance(value, kind_cls):
        return value
    try:
        return kind_cls(value)
    except ValueError:
        raise ConfigError(f'parameter "{name}" must be one of '
                          f'{[k.value for k in kind_cls]}, got {value!r}') from None


def approach_setpoint(status: StatusLike) -> float:
    """The position stage's target: ``approach_setpoint_m`` (the widest object's face); bags
    recorded before it existed carry only ``position_setpoint_m``."""
    return getattr(status, 'approach_setpoint_m', status.position_setpoint_m)


class PositionStageController:
    """The position controller node's control law (10 ms, Table II)."""

    source = SOURCE_POSITION

    def __init__(self, config: GripperConfig,
                 kind: PositionControllerKind | str = DEFAULT_POSITION_CONTROLLER):
        self.config = config
        self.kind = parse_kind(PositionControllerKind, kind)
        self.controller = make_position_controller(config, self.kind)
        self.sample_time_s = config.position.sample_time_s

    def activate(self, status: StatusLike, measurement: float) -> None:
        """Start from rest at the measured position with the motor off."""
        if self.kind is PositionControllerKind.MPC_PD:
            self.controller.reset(measurement, 0.0)
        else:
            self.controller.reset(0.0, measurement=measurement)

    def compute(self, status: StatusLike, measurement: float) -> tuple[float, float]:
        """(voltage_v, inner_setpoint) for this tick."""
        setpoint = approach_setpoint(status)
        voltage = self.controller.step(setpoint, measurement)
        inner = getattr(self.controller, 'last_inner_setpoint', setpoint)
        return voltage, inner


class ForceStageController:
    """The force controller node's control law (force sampling time, bumpless, approach cap)."""

    source = SOURCE_FORCE

    def __init__(self, config: GripperConfig,
                 kind: ForceControllerKind | str = DEFAULT_FORCE_CONTROLLER,
                 approach_force_margin: float = DEFAULT_APPROACH_FORCE_MARGIN):
        margin = float(approach_force_margin)
        if not (math.isfinite(margin) and margin >= 0.0):
            raise ConfigError(f'approach_force_margin must be finite and >= 0, got {margin!r}')
        self.config = config
        self.kind = parse_kind(ForceControllerKind, kind)
        self.approach_margin = margin
        self.controller = make_force_controller(config, self.kind)
        self.contact_aware = self.kind is ForceControllerKind.CONTACT_AWARE
        self._pi = None if self.contact_aware else (
            self.controller.inner if self.kind is ForceControllerKind.MPC_PI
            else self.controller)
        self._full_limits = None if self.contact_aware else self._pi.output_limits
        self.sample_time_s = config.force.sample_time_s
        self._contact = False

    @property
    def capped(self) -> bool:
        """True while the pre-contact cap is in force (PI / MPC-PI; the contact-aware stage
        caps its approach itself, at the feed-forward)."""
        return not self._contact and self.approach_margin > 0.0 and not self.contact_aware

    def activate(self, status: StatusLike, measurement: float) -> None:
        self._contact = False
        if self.contact_aware:       # speed-shaped approach from where the finger is now
            self.controller.reset(status.position_m)
            return
        self._apply_limits(status)
        if self.kind is ForceControllerKind.MPC_PI:
            self.controller.reset(measurement, status.seed_voltage_v)
        else:
            self.controller.reset(status.seed_voltage_v, status.force_setpoint_n, measurement)

    def _apply_limits(self, status: StatusLike) -> None:
        low, high = self._full_limits
        if not self._contact and self.approach_margin > 0.0:
            cap = (self.approach_margin * status.force_setpoint_n
                   / self.config.plant.stall_force_per_volt_n)
            high = min(high, cap)
        self._pi.output_limits = (low, high)

    def compute(self, status: StatusLike, measurement: float) -> tuple[float, float]:
        """(voltage_v, inner_setpoint) for this tick; the cap is released at first contact."""
        if self.contact_aware:
            face_m = status.position_setpoint_m
            voltage = self.controller.step(status.force_setpoint_n, measurement,
                                           status.position_m, face_m,
                                           max(face_m - approach_setpoint(status), 0.0))
            return voltage, status.force_setpoint_n
        if not self._contact and status.contact:
            self._contact = True
            self._apply_limits(status)
        voltage = self.controller.step(status.force_setpoint_n, measurement)
        inner = getattr(self.controller, 'last_inner_setpoint', status.force_setpoint_n)
        return voltage, inner


STATUS_NUMBERS = ('position_setpoint_m', 'force_setpoint_n', 'seed_voltage_v', 'position_m')
"""The status fields a stage computes with; a non-finite one is never acted on."""


@dataclass(frozen=True)
class TickAnswer:
    """A controller's answer to one tick (what goes into MotorCommand)."""

    voltage_v: float
    inner_setpoint: float
    finite: bool = True        # False: a measurement or output was not finite, 0 V is held
    reason: str = ''           # why 0 V is held ('' when finite)


class LockstepAnswerer:
    """The lockstep bookkeeping of one controller around a stage (anything with ``source``,
    ``activate(status, measurement)`` and ``compute(status, measurement)``).

    Call :meth:`on_status` with EVERY status (also those naming another controller), then
    :meth:`answer` with the status of tick ``stamp_ns`` that names this controller and the
    measurement of the same tick.
    """

    def __init__(self, stage):
        self.stage = stage
        self.answered: tuple[int, int] | None = None    # (grasp_id, stamp) last answered
        self.active_grasp: int | None = None

    def on_status(self, status: StatusLike) -> None:
        if status.active_controller != self.stage.source:
            self.active_grasp = None

    def answer(self, status: StatusLike, stamp_ns: int, measurement: float) -> TickAnswer | None:
        """The command for this tick, or None when this (grasp, stamp) was answered already."""
        key = (status.grasp_id, stamp_ns)
        if key == self.answered:
            return None
        self.answered = key
        if not math.isfinite(measurement):
            return TickAnswer(0.0, 0.0, finite=False, reason='non-finite measurement')
        bad = [f'{name}={getattr(status, name)!r}' for name in STATUS_NUMBERS
               if not math.isfinite(getattr(status, name))]
        if bad:
            return TickAnswer(0.0, 0.0, finite=False,
                              reason=f'non-finite status ({", ".join(bad)})')
        try:
            if self.active_grasp != status.grasp_id:
                self.stage.activate(status, measurement)
                self.active_grasp = status.grasp_id
            voltage, inner = self.stage.compute(status, measurement)
        except (ValueError, ArithmeticError) as exc:    # a law that refuses its numbers
            self.active_grasp = None
            return TickAnswer(0.0, 0.0, finite=False, reason=f'control law failed: {exc}')
        if not (math.isfinite(voltage) and math.isfinite(inner)):
            # the law's state is no longer trustworthy: start afresh at the next finite tick
            self.active_grasp = None
            return TickAnswer(0.0, 0.0, finite=False,
                              reason=f'non-finite output (voltage {voltage!r}, inner setpoint '
                                     f'{inner!r})')
        return TickAnswer(voltage, inner)
