"""What a stage controller node does with one lockstep tick, without rclpy.

The position and force controller nodes are thin: each takes the supervisor's
``StageReference`` for tick ``t_k`` (it carries that tick's measurement) and publishes the
answer. Everything else lives here, so that the headless loop (:mod:`gripper_ros.core.headless`)
and ``bag_replay --resimulate`` run the very same code and get bit-identical commands:

- :class:`PositionStageController`: MPC-PD (or PD / PID), restarted from rest at the measured
  position whenever it takes over a stage; its voltage capped at the reference's
  ``voltage_limit_v`` (a move's effort limit) when that is set.
- :class:`ForceStageController`: the contact-aware force stage (or the paper's PI / MPC-PI,
  seeded bumplessly from ``seed_voltage_v`` and capped before contact at
  ``approach_force_margin`` x F_sp / (N per V)).
- :class:`LockstepAnswerer`: the per-tick bookkeeping of a node: answer each (stage, stamp)
  once, restart the law on a new stage, hold 0 V on a non-finite measurement or reference
  number without touching the law's state, and hold 0 V on a non-finite output or a law that
  refuses its inputs, restarting the law at the next good tick.

A *reference* is anything with the fields of ``gripper_interfaces/msg/StageReference``:
:data:`Reference` (built from the message's bytes), the rclpy message, or a test double.
"""
from __future__ import annotations

from collections import namedtuple
import enum
import math

from gripper_ros.core.config import ConfigError, GripperConfig
from gripper_ros.core.controllers import (ForceControllerKind, make_force_controller,
                                          make_position_controller, PositionControllerKind)
from gripper_ros.wire import Controller, REFERENCE_LAYOUT

SOURCE_POSITION = Controller.POSITION
SOURCE_FORCE = Controller.FORCE

DEFAULT_POSITION_CONTROLLER = PositionControllerKind.MPC_PD
DEFAULT_FORCE_CONTROLLER = ForceControllerKind.CONTACT_AWARE
DEFAULT_APPROACH_FORCE_MARGIN = 1.0

Reference = namedtuple('Reference', REFERENCE_LAYOUT.fields, defaults=(0.0, 0.0))
"""One StageReference's fields, in message order (``Reference._make(values)``); the last two,
a move's ``speed_limit_mps`` and ``voltage_limit_v``, default to 0 (no limit)."""


def parse_kind(kind_cls: type[enum.Enum], value, name: str = 'controller'):
    """Return ``value`` as a member of ``kind_cls``; ConfigError naming the parameter if not."""
    if isinstance(value, kind_cls):
        return value
    try:
        return kind_cls(value)
    except ValueError:
        raise ConfigError(f'parameter "{name}" must be one of '
                          f'{[k.value for k in kind_cls]}, got {value!r}') from None


class PositionStageController:
    """The position controller node's control law (10 ms, Table II), with a move's limits.

    A reference's ``voltage_limit_v`` and ``speed_limit_mps`` (> 0; 0 = none) cap the voltage
    that drives the finger towards its setpoint: at ``voltage_limit_v`` (the stall voltage of
    a move's effort), and at what keeps the speed below ``speed_limit_mps`` on the exact
    first-order model of the finger's speed (``position_control.speed_limit_pole``). The
    voltage away from the setpoint (braking) keeps the plant's limit. The cap is the output
    limit of the PD / PID (the inner PD of the MPC-PD, whose DMC then keeps within it, and the
    braking governor's accelerating voltage), so that every loop books the voltage applied.
    """

    source = SOURCE_POSITION

    def __init__(self, config: GripperConfig,
                 kind: PositionControllerKind | str = DEFAULT_POSITION_CONTROLLER):
        self.config = config
        self.kind = parse_kind(PositionControllerKind, kind)
        self.controller = make_position_controller(config, self.kind)
        self.sample_time_s = config.position.sample_time_s
        self.reference_numbers = REFERENCE_NUMBERS + LIMIT_NUMBERS
        mpc = self.kind is PositionControllerKind.MPC_PD
        self._pid = self.controller.inner if mpc else self.controller
        self._governor = self.controller.governor if mpc else None
        plant = config.plant
        self._full_v = plant.voltage_limit_v
        self._limits = self._full_limits = (-self._full_v, self._full_v)
        # speed one sample on: a v + (1 - a) k_v u; the cap u puts it at v_lim - pole (v_lim - v)
        a = math.exp(-self.sample_time_s / plant.mechanical_time_constant_s)
        pole = config.position.speed_limit_pole
        gain = 1.0 / ((1.0 - a) * plant.free_speed_per_volt_mps)
        self._speed_gain_v_per_mps = ((1.0 - pole) * gain, (a - pole) * gain)

    def voltage_cap_v(self, ref, toward_speed_mps: float) -> float:
        """Return the most voltage towards the setpoint this tick.

        ``toward_speed_mps`` is the finger's speed towards the setpoint.
        """
        cap = self._full_v
        if ref.voltage_limit_v > 0.0:
            cap = min(cap, ref.voltage_limit_v)
        limit = ref.speed_limit_mps
        if limit > 0.0:
            k_limit, k_speed = self._speed_gain_v_per_mps
            cap = min(cap, max(0.0, k_limit * limit - k_speed * toward_speed_mps))
        return cap

    def _apply_limits(self, ref, measurement: float) -> None:
        """Set this tick's output limits (only a move's reference changes them)."""
        if ref.voltage_limit_v == 0.0 and ref.speed_limit_mps == 0.0:
            limits = self._full_limits
        elif ref.approach_setpoint_m >= measurement:
            limits = (-self._full_v, self.voltage_cap_v(ref, ref.velocity_mps))
        else:
            limits = (-self.voltage_cap_v(ref, -ref.velocity_mps), self._full_v)
        if limits != self._limits:
            self._limits = limits
            self._pid.output_limits = limits
            if self._governor is not None:
                self._governor.limit_v = min(-limits[0], limits[1])

    @staticmethod
    def measurement(ref) -> float:
        """Return what this stage controls, from the tick's reference: the finger position."""
        return ref.position_m

    def activate(self, ref, measurement: float) -> None:
        """Start from rest at the measured position with the motor off."""
        self._apply_limits(ref, measurement)
        if self.kind is PositionControllerKind.MPC_PD:
            self.controller.reset(measurement, 0.0)
        else:
            self.controller.reset(0.0, measurement=measurement)

    def compute(self, ref, measurement: float) -> tuple[float, float]:
        """Return (voltage_v, inner_setpoint) for this tick."""
        self._apply_limits(ref, measurement)
        setpoint = ref.approach_setpoint_m
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
        """Tell whether the pre-contact cap is in force.

        Only for PI / MPC-PI: the contact-aware stage caps its approach itself, at the
        feed-forward.
        """
        return not self._contact and self.approach_margin > 0.0 and not self.contact_aware

    @staticmethod
    def measurement(ref) -> float:
        """Return what this stage controls, from the tick's reference: the gripping force."""
        return ref.force_n

    def activate(self, ref, measurement: float) -> None:
        """Restart: the contact-aware approach from where the finger is, or the PI seeded."""
        self._contact = False
        if self.contact_aware:       # speed-shaped approach from where the finger is now
            self.controller.reset(ref.position_m)
            return
        self._apply_limits(ref)
        if self.kind is ForceControllerKind.MPC_PI:
            self.controller.reset(measurement, ref.seed_voltage_v)
        else:
            self.controller.reset(ref.seed_voltage_v, ref.force_setpoint_n, measurement)

    def _apply_limits(self, ref) -> None:
        low, high = self._full_limits
        if not self._contact and self.approach_margin > 0.0:
            cap = (self.approach_margin * ref.force_setpoint_n
                   / self.config.plant.stall_force_per_volt_n)
            high = min(high, cap)
        self._pi.output_limits = (low, high)

    def compute(self, ref, measurement: float) -> tuple[float, float]:
        """Return (voltage_v, inner_setpoint) for this tick; the cap ends at first contact."""
        if self.contact_aware:
            face_m = ref.position_setpoint_m
            voltage = self.controller.step(ref.force_setpoint_n, measurement, ref.position_m,
                                           face_m, max(face_m - ref.approach_setpoint_m, 0.0))
            return voltage, ref.force_setpoint_n
        if not self._contact and ref.contact:
            self._contact = True
            self._apply_limits(ref)
        voltage = self.controller.step(ref.force_setpoint_n, measurement)
        inner = getattr(self.controller, 'last_inner_setpoint', ref.force_setpoint_n)
        return voltage, inner


REFERENCE_NUMBERS = ('position_setpoint_m', 'approach_setpoint_m', 'force_setpoint_n',
                     'seed_voltage_v', 'position_m')
"""The reference fields a stage computes with; a non-finite one is never acted on."""
LIMIT_NUMBERS = ('speed_limit_mps', 'voltage_limit_v')
"""... and the position stage's limits (a stage's ``reference_numbers`` name all it uses)."""


class TickAnswer(namedtuple('TickAnswer', 'voltage_v inner_setpoint finite reason',
                            defaults=(True, ''))):
    """A controller's answer to one tick (what goes into MotorCommand).

    ``finite`` False means a measurement or output was not finite and 0 V is held, ``reason``
    says why.
    """

    __slots__ = ()


class LockstepAnswerer:
    """The lockstep bookkeeping of one controller around a stage.

    A stage is anything with ``source``, ``measurement(ref)``, ``activate(ref, measurement)``
    and ``compute(ref, measurement)``. Call :meth:`answer` with every reference addressed to
    this controller.
    """

    def __init__(self, stage):
        self.stage = stage
        self.numbers = getattr(stage, 'reference_numbers', REFERENCE_NUMBERS)
        self.answered: tuple[int, int] | None = None    # (stage_id, stamp) last answered
        self.active_stage: int | None = None            # the stage the law was started for

    def answer(self, ref) -> TickAnswer | None:
        """Return the command for this tick, or None when this (stage, stamp) was answered."""
        key = (ref.stage_id, ref.stamp_ns)
        if key == self.answered:
            return None
        self.answered = key
        measurement = self.stage.measurement(ref)
        if not math.isfinite(measurement):
            return TickAnswer(0.0, 0.0, finite=False, reason='non-finite measurement')
        for name in self.numbers:
            if not math.isfinite(getattr(ref, name)):
                bad = [f'{n}={getattr(ref, n)!r}' for n in self.numbers
                       if not math.isfinite(getattr(ref, n))]
                return TickAnswer(0.0, 0.0, finite=False,
                                  reason=f'non-finite reference ({", ".join(bad)})')
        try:
            if self.active_stage != ref.stage_id:
                self.stage.activate(ref, measurement)
                self.active_stage = ref.stage_id
            voltage, inner = self.stage.compute(ref, measurement)
        except (ValueError, ArithmeticError) as exc:    # a law that refuses its numbers
            self.active_stage = None
            return TickAnswer(0.0, 0.0, finite=False, reason=f'control law failed: {exc}')
        if not (math.isfinite(voltage) and math.isfinite(inner)):
            # the law's state is no longer trustworthy: start afresh at the next finite tick
            self.active_stage = None
            return TickAnswer(0.0, 0.0, finite=False,
                              reason=f'non-finite output (voltage {voltage!r}, inner setpoint '
                                     f'{inner!r})')
        return TickAnswer(voltage, inner)
