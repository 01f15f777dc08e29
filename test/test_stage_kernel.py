"""The compiled stage entry point ``stage_answer(k, ref, cmd)``, called from compiled code.

It must write exactly the command ``lockstep.StageSide`` builds from the Python answerer (the
headless loop and the nodes), tick for tick, for every kind of stage, and keep the reasons
for a 0 V answer as codes that ``LockstepAnswerer.reason`` turns back into text.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import load_config
from gripper_ros.core.control.stages import (COMMAND_DTYPE, ForceStageController, LockstepAnswerer,
                                             PositionStageController, Reference, REFERENCE_DTYPE,
                                             stage_answer)
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.wire import Controller, Outcome
import numpy as np
import pytest

CONFIG = load_config()


@pytest.mark.parametrize('position, force', [('mpc_pd', 'contact_aware'), ('pd', 'pi'),
                                             ('pid', 'mpc_pi')])
def test_every_stage_kind_answers_its_ticks_and_holds_the_grasp(position, force):
    """Table V's 50 mm, 1.69 kg object, with every kind of stage (the kernels the loop runs).

    Each command echoes its reference's tick, is held for its stage's period (10 ms, 0.1 ms)
    and stays within 24 V; the grasp is HOLDING at F_sp = k m g / (2 mu) = 24.87 N within the
    settle band. The voltages of the shipped and the paper's stages are held bit for bit to the
    interpreted core's recordings by test_recorded_reference.
    """
    seen = {Controller.POSITION: [], Controller.FORCE: []}

    def trace(plant, tick, decision, ref, cmd):
        if ref is not None:
            seen[ref.controller].append((ref, cmd))

    run = simulate_grasp(CONFIG, 0.05, 1.69, position_controller=position,
                         force_controller=force, trace=trace)
    sup = CONFIG.supervisor
    f_sp = sup.grip_safety_factor * 1.69 * CONFIG.plant.gravity_mps2 / (
        2.0 * sup.friction_coefficient)
    assert f'{f_sp:.2f}' == '24.87' and run.force_setpoint_n == pytest.approx(f_sp, rel=1e-12)
    assert run.outcome is Outcome.HOLDING, run.message
    assert abs(run.series.ticks['force_n'][-1] - f_sp) <= sup.force_settle_band_fraction * f_sp
    for source, hold_s in ((Controller.POSITION, 0.01), (Controller.FORCE, 1e-4)):
        pairs = seen[source]
        assert len(pairs) > 10, source
        for ref, cmd in pairs:
            assert (cmd.stamp_ns, cmd.stage_id, cmd.source) == (ref.stamp_ns, ref.stage_id,
                                                                int(source))
            assert cmd.hold_s == pytest.approx(hold_s) and abs(cmd.voltage_v) <= 24.0


def test_stage_answer_answers_each_stamp_once_and_leaves_cmd_untouched():
    stage = PositionStageController(CONFIG, 'pd')
    ref = np.zeros(1, REFERENCE_DTYPE)
    ref[0] = Reference(10, 1, 1, 0, 1, 0, 1, True, False, 0.1, 0.1, 5.0, 0.05, 0.0, 0.0, 0.0)
    cmd = np.zeros(1, COMMAND_DTYPE)
    assert stage_answer(stage.kernel, ref, cmd)
    first = cmd.copy()
    cmd[0]['voltage_v'] = 123.0
    assert not stage_answer(stage.kernel, ref, cmd)
    assert cmd[0]['voltage_v'] == 123.0
    assert first[0]['finite'] and first[0]['hold_s'] == stage.sample_time_s


def test_a_compiled_refusal_keeps_its_reason_text():
    answerer = LockstepAnswerer(ForceStageController(CONFIG, 'contact_aware'))
    ref = Reference(0, 1, 2, 0, 2, 0, 2, True, True, 1e308, -1e308, 5.0, 0.05, 0.0, 4.0, 0.0)
    a = answerer.answer(ref)
    assert (a.voltage_v, a.finite) == (0.0, False)
    assert a.reason == ('control law failed: non-finite input: force_setpoint_n=5.0, '
                        'force_n=4.0, position_m=0.05, face_m=1e+308, width_tolerance_m=inf')
    assert answerer.active_stage is None
    bad = answerer.answer(ref._replace(stamp_ns=1, position_setpoint_m=math.nan,
                                       seed_voltage_v=-math.inf))
    assert bad.reason == 'non-finite reference (position_setpoint_m=nan, seed_voltage_v=-inf)'
