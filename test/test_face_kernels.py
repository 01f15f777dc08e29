"""The Python faces over the compiled records: declared kernels, record copies, message texts.

A node's or a tool's first call of a face must not pay numba's compilation: warm-up compiles
every kernel declared with ``face_kernel`` (physics, control, supervision, the nodes' tick
calls, the compiled loop), and driving each face afterwards, the plant's and the loop's
included, compiles nothing more. A compiled ``copy_fields`` writes what the Python one writes.
Every answering event of the supervisor has one template, and the texts carry the kernel's
numbers.
"""
from __future__ import annotations

import importlib
import math
import pkgutil
import string

from gripper_ros.core.config import load_config
from gripper_ros.core.control.dmc import CascadedMpc
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.pid import AntiWindup, DerivativeOn, PID
from gripper_ros.core.control.stages import (ForceStageController, LockstepAnswerer,
                                             PositionStageController, Reference)
from gripper_ros.core.physics.hold import HoldModel, Lift
from gripper_ros.core.physics.pad_sensor import PadChannel
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.core.records import compile_face_kernels, copy_fields, fields_into, set_fields
from gripper_ros.core.runtime.headless import simulate_grasp, simulate_moves
from gripper_ros.core.runtime.lockstep import PlantSide, StageSide, SupervisorSide
from gripper_ros.core.supervision import machine, messages
from gripper_ros.core.supervision import supervisor as sv
from gripper_ros.core.supervision.requests import MoveRequest, MoveTargets
from gripper_ros.wire import (CDR_LITTLE_ENDIAN, FaultKind, ForceControllerKind,
                              PositionControllerKind)
import numba
import numpy as np

CONFIG = load_config()


def _core_modules() -> list[str]:
    """Return every module of the compiled core (and the identification's compiled replay)."""
    import gripper_ros.core
    names = [m.name for m in pkgutil.walk_packages(gripper_ros.core.__path__, 'gripper_ros.core.')]
    return sorted(n for n in names if not n.endswith('batch_worker')) + [
        'gripper_ros.identify.replay']


def _signatures() -> dict:
    """Return the number of compiled signatures of every kernel of the core."""
    counts = {}
    for name in _core_modules():
        for attr, value in vars(importlib.import_module(name)).items():
            if isinstance(value, numba.core.dispatcher.Dispatcher):
                counts[f'{name}.{attr}'] = len(value.signatures)
    return counts


def _drive_the_plant_and_the_loop() -> None:
    """Run the plant's faces, the sides' tick calls and every mode of the headless loop."""
    plant = make_plant(CONFIG)
    side = PlantSide(plant)
    side.set_object(GraspObject(0.05, 0.0, 0.0, 1.0), lift=Lift(1.0, 0.0, 0.01),
                    fault=(FaultKind.OBJECT_REMOVED, 0.01, 0.0))
    side.step_unpowered(0.001)
    plant.step(1.0, 1e-4)
    plant.object_state
    plant.lift_plan()
    plant.begin_hold(plant.t_ns, 1.0)
    plant.schedule_fault(FaultKind.SENSOR_DROPOUT, plant.t_ns + 1000)
    plant.cancel_fault()
    plant.touch_object()
    plant.sensor.voltage_v(1.0), plant.sensor.resistance_ohm(1.0)
    plant.reset()
    hold = HoldModel(1.0, 0.5, 0.4, 0.02, 9.81, Lift(1.0, 0.0, 0.1))
    hold.begin(0, 1.0)
    hold.fire_events(0), hold.live, hold.load_n, hold.capacity_n(1.0), hold.shear_n(1.0)
    hold.presliding_m(1.0), hold.advance(1.0, 1e-4), hold.drive(0, 1.0), hold.remove()
    PadChannel(CONFIG.pad_sensor.shear, 1e-4).run([0.0, 1.0])
    supervisor = sv.GraspSupervisor(CONFIG.plant, CONFIG.supervisor, sv.load_law(CONFIG))
    sides = (side, SupervisorSide(supervisor), StageSide(PositionStageController(CONFIG)))
    tick = CDR_LITTLE_ENDIAN + side.tick_record.tobytes()
    sides[1].take_tick(tick)
    sides[1].status_published(0, 10_000_000)
    ref = CDR_LITTLE_ENDIAN + sides[1].reference_record.tobytes()
    sides[2].take_reference(ref)
    side.take_command(CDR_LITTLE_ENDIAN + sides[2].command_record.tobytes(), False)
    side.step_due()
    for kwargs in ({}, {'trace': lambda *_: None}, {'trace_state_period_ns': 10_000_000},
                   {'idle_unpowered_s': 0.01, 'announce': True, 'mass_kg': 0.0}):
        simulate_grasp(CONFIG, 0.05, kwargs.pop('mass_kg', 1.0), timeout_s=0.05,
                       lift=Lift(1.0, 0.0, 0.01), **kwargs)
    simulate_moves(CONFIG, [MoveRequest(0.14, speed_mps=0.02, max_effort_n=5.0,
                                        timeout_s=0.02)])


def _drive_every_face() -> None:
    """Call every face method that runs a kernel, as the nodes and the tools do."""
    _drive_the_plant_and_the_loop()
    supervisor = sv.GraspSupervisor(CONFIG.plant, CONFIG.supervisor, sv.load_law(CONFIG))
    supervisor.step(1_000_000, 0.0, 0.0, 0.0)
    supervisor.request_move(MoveTargets(0.1, 0.02, 5.0, 3.6, 0.0, 1e-3))
    supervisor.step(2_000_000, 0.0, 0.0, 0.0, 0.0, 1, 0.0, 0.0)
    supervisor.announce(3_000_000, 1.0)
    supervisor.stop()
    supervisor.request_release()
    supervisor.step(3_000_000, 0.0, 0.0, 0.0)
    supervisor.fault('a test fault')
    assert supervisor.message == 'a test fault'
    ref = Reference(1, 1, 1, 0, 0, 0, 1, 1, 0, 0.01, 0.01, 5.0, 0.0, 0.0, 0.0, 1.0)
    for stage in ([PositionStageController(CONFIG, kind) for kind in PositionControllerKind]
                  + [ForceStageController(CONFIG, kind) for kind in ForceControllerKind]):
        assert LockstepAnswerer(stage).answer(ref).finite
        stage.activate(ref, 0.0)
        stage.compute(ref, 0.0)
        law = stage.controller
        law.reset(*(() if isinstance(law, PID) else (0.0,)))
        if isinstance(law, CascadedMpc):
            law.step(0.01, 0.0)
            law.dmc.reset(0.0, 0.0)
            law.dmc.step(0.01, 0.0, (-1.0, 1.0))
            if law.governor is not None:
                law.governor.reset(0.0)
                law.governor.applied(law.governor.command(0.01, 0.0) or 0.0)
    pid = PID(CONFIG.position.pd, 0.01, (-24.0, 24.0))
    pid.setpoint_range(0.0)
    pid.setpoint_for_output(1.0, 0.0)
    contact = ForceStageController(CONFIG, ForceControllerKind.CONTACT_AWARE).controller
    contact.reset(0.0)
    contact.contact_speed_mps(5.0, 1e-3)
    contact.speed_profile_mps(0.01)
    contact.step(5.0, 0.0, 0.0, 0.01, 0.0)


def test_after_warm_up_no_face_compiles_a_kernel_at_its_first_call():
    """Drive every face after compile_face_kernels: no kernel of their modules compiles again.

    A face that called a kernel with types nobody declared would compile it here, at the
    first tick of a node.
    """
    assert compile_face_kernels() >= 70
    before = _signatures()
    _drive_every_face()
    after = _signatures()
    assert {k: (before[k], n) for k, n in after.items() if n != before[k]} == {}


def test_compiled_copy_fields_and_set_fields_write_what_the_python_ones_write():
    dtype = np.dtype([('tg_a', 'f8'), ('tg_b', 'i8'), ('pend_a', 'f8'), ('pend_b', 'i8'),
                      ('t_ns', 'i8')], align=True)

    @numba.njit
    def take(x):
        s = x[0]
        copy_fields(s, s, ('a', 'b'), 'tg_', 'pend_')
        set_fields(s, ('pend_b', 't_ns'), -1)

    compiled = np.zeros(1, dtype)
    compiled[0]['pend_a'], compiled[0]['pend_b'] = 2.5, 7
    python = compiled.copy()
    take(compiled)
    copy_fields(python[0], python[0], ('a', 'b'), 'tg_', 'pend_')
    set_fields(python[0], ('pend_b', 't_ns'), -1)
    assert compiled.tobytes() == python.tobytes()
    assert compiled[0].tolist() == (2.5, 7, 2.5, -1, -1)


def test_compiled_fields_into_writes_the_named_fields_in_order():
    dtype = np.dtype([('a', 'f8'), ('b', 'i8'), ('c', 'f8')], align=True)

    @numba.njit
    def into(x, out):
        fields_into(out, x[0], ('c', 'a', 'b'))

    record = np.zeros(1, dtype)
    record[0] = (1.5, 7, -2.25)
    out, python = np.zeros(3), np.zeros(3)
    into(record, out)
    fields_into(python, record[0], ('c', 'a', 'b'))
    assert out.tolist() == python.tolist() == [-2.25, 1.5, 7.0]


def test_pid_settings_and_terms_read_the_record():
    pid = PID(CONFIG.position.pd, 0.01, (-24.0, 24.0), DerivativeOn.MEASUREMENT,
              AntiWindup.NONE)
    assert pid.derivative_on is DerivativeOn.MEASUREMENT and pid.anti_windup is AntiWindup.NONE
    assert pid.record[0]['derivative_on_measurement'] == 1 and pid.record[0]['conditional'] == 0
    output = pid.step(0.01, 0.0)                  # kc x 10 mm, inside the limits
    terms = pid.terms
    assert terms.output == output == terms.proportional + terms.integral + terms.derivative
    assert terms.proportional == CONFIG.position.pd.kc * 0.01 and not terms.saturated
    assert pid.step(1.0, 0.0) == 24.0 and pid.terms.saturated


def test_every_answering_event_has_one_template_over_named_numbers():
    """Each event that answers a request has a template; each name it reads is a field or derived.

    An event answers when a transition of the machine gives it an outcome.
    """
    assert sorted(messages.MESSAGES) == sorted(event.name for event in machine.ANSWERS)
    known = set(messages.MESSAGE_DTYPE.names) | set(messages.MESSAGE_VALUES) | {
        'text', 'travel_m', 'voltage_limit_v'}
    for event, template in messages.MESSAGES.items():
        names = {field for _, field, _, _ in string.Formatter().parse(template) if field}
        assert names <= known, (event, names - known)


def test_a_message_carries_the_kernels_numbers_into_its_text():
    """The numbers written by the kernel come out as the template formats them."""
    record = np.zeros(1, messages.MESSAGE_DTYPE)[0]
    record['force_n'], record['force_setpoint_n'], record['position_m'] = 24.8712, 24.87, 0.1234
    assert messages.format_message('HELD', record, CONFIG.plant) == \
        'holding 24.871 N (setpoint 24.870 N) at 0.12340 m'
    record['t_ns'], record['start_ns'], record['position_setpoint_m'] = 2_500_000_000, 0, 0.1
    travel = CONFIG.plant.max_travel_m
    assert messages.format_message('MOVED', record, CONFIG.plant) == (
        f'moved: finger at 0.12340 m (opening {travel - 0.1234:.5f} m, goal '
        f'{travel - 0.1:.5f} m), force 24.871 N, after 2.500 s')
    record['bad_force'], record['force_n'] = True, math.nan
    assert messages.format_message('SENSOR_FAULT', record, CONFIG.plant) == (
        'fault at t=2.5000 s (2.5000 s into the hold): force sensor reads force nan N, voltage '
        '0.0 V (sensor dropout); no controller drives the motor from here on')
