"""The compiled stage entry point ``stage_answer(k, ref, cmd)``, called from compiled code.

It must write exactly the command ``lockstep.StageSide`` builds from the Python answerer (the
headless loop and the nodes), tick for tick, for every kind of stage, and keep today's reasons
for a 0 V answer as codes that ``LockstepAnswerer.reason`` turns back into text.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import load_config
from gripper_ros.core.headless import simulate_grasp
from gripper_ros.core.stages import (COMMAND_DTYPE, ForceStageController, LockstepAnswerer,
                                     PositionStageController, Reference, REFERENCE_DTYPE,
                                     stage_answer)
from gripper_ros.wire import Controller
import numba
import numpy as np
import pytest

CONFIG = load_config()


@numba.njit(cache=True)
def _answer_all(k, refs, cmds, answered):
    """Answer every reference in turn from compiled code, as the compiled headless loop does."""
    for i in range(refs.shape[0]):
        answered[i] = stage_answer(k, refs[i:i + 1], cmds[i:i + 1])


@pytest.mark.parametrize('position, force', [('mpc_pd', 'contact_aware'), ('pd', 'pi'),
                                             ('pid', 'mpc_pi')])
def test_stage_answer_writes_the_command_stage_side_builds(position, force):
    seen = {Controller.POSITION: [], Controller.FORCE: []}

    def trace(plant, tick, decision, ref, cmd):
        if ref is not None:
            seen[ref.controller].append((tuple(ref), tuple(cmd)))

    simulate_grasp(CONFIG, 0.05, 1.69, position_controller=position, force_controller=force,
                   trace=trace)
    twins = {Controller.POSITION: PositionStageController(CONFIG, position),
             Controller.FORCE: ForceStageController(CONFIG, force)}
    for source, pairs in seen.items():
        assert pairs
        refs = np.zeros(len(pairs), REFERENCE_DTYPE)
        for i, (ref, _) in enumerate(pairs):
            refs[i] = ref
        cmds = np.zeros(len(pairs), COMMAND_DTYPE)
        answered = np.zeros(len(pairs), np.bool_)
        _answer_all(twins[source].kernel, refs, cmds, answered)
        assert answered.all()
        got = [tuple(float(v) for v in c.item()) for c in cmds]
        assert got == [tuple(float(v) for v in cmd) for _, cmd in pairs]


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


def test_a_compiled_refusal_keeps_todays_reason_text():
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
