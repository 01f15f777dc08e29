"""Setting up the simulated world, without ROS: when it may change, and what a request places.

``sim/set_object`` (``nodes/plant_simulator_node.py``) asks :func:`busy_reason` first, then
builds the placement from the request with :func:`placement` and says what it did with
:func:`placed_message`. A request is anything with a ``gripper_interfaces/SetObject`` request's
fields.
"""
from __future__ import annotations

from typing import NamedTuple

from gripper_ros.core.physics.plant import check_fault, GraspObject, GripperPlant, Lift
from gripper_ros.core.runtime.lockstep import Command
from gripper_ros.wire import Outcome, Phase


def busy_reason(echo: Command | None, status) -> str:
    """Say why the world may not be changed now ('' when it may).

    The supervisor's newest word on it counts: its ``status`` (a SupervisorStatus's numbers),
    or ``echo``, the last command's, whichever is later by (grasp, stage).
    """
    state = echo
    if status is not None and (echo is None or (status.grasp_id, status.stage_id) >=
                               (echo.grasp_id, echo.stage_id)):
        state = status
    if state is None:
        return ''
    if state.running or getattr(state, 'pending_request', 0):
        return 'a grasp or release is running'
    if state.phase == Phase.HOLDING and state.outcome in (Outcome.HOLDING, Outcome.OVERLOADED):
        return 'an object is held (release or stop first)'
    return ''


class Placement(NamedTuple):
    """What a set-object request places: the object, its lift, its fault, whether announced."""

    obj: GraspObject
    lift: Lift | None
    fault: tuple            # (FaultKind, seconds after the next grasp's start, time constant)
    announce_lift: bool     # the simulated arm announces the lift as the hold begins


def placement(request, plant: GripperPlant) -> Placement:
    """Build the placement ``request`` asks for (ValueError or TypeError: refused)."""
    obj = GraspObject(request.width_m, request.stiffness_n_per_m, request.damping_n_s_per_m,
                      request.mass_kg, request.static_friction, request.kinetic_friction,
                      request.pad_length_m)
    if request.default_friction:
        if request.static_friction or request.kinetic_friction:
            raise ValueError(
                f'default_friction asks for the configured friction; static_friction '
                f'and kinetic_friction must then be 0, got {request.static_friction!r} '
                f'and {request.kinetic_friction!r}')
        obj = plant.configured_friction(obj)
    lift = Lift(request.lift_acceleration_mps2, request.lift_delay_s, request.lift_duration_s,
                request.lift_profile, request.lift_frequency_hz, request.lift_off_s) \
        if request.lift_duration_s > 0.0 else None
    kind, tau = check_fault(request.fault, request.fault_at_s, request.fault_time_constant_s,
                            obj.rigid)
    return Placement(obj, lift, (kind, request.fault_at_s, tau),
                     bool(request.announce_lift) and lift is not None)


def placed_message(placed: Placement, plant: GripperPlant) -> str:
    """Say what was placed: the object's width, where contact begins, the fault armed."""
    kind, at_s, _ = placed.fault
    message = (f'object width {placed.obj.width_m:g} m, contact at '
               f'{plant.contact_position_m:.4f} m')
    if kind.value:
        message += f'; fault {kind.name} {at_s:g} s after the start of the next grasp'
    return message
