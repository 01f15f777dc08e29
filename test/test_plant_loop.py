"""The simulated plant's loop and world set-up without ROS: the rules the plant node follows.

Known answers a user of ``sim/set_object`` and of a realtime graph meets: the world may not
change while a grasp or release runs or an object is held (the supervisor's newest word, its
status or the last command's echo, decides); time runs on at 0 V while nobody commands, a tick
unanswered for ``command_timeout_s`` holds the motor at 0 V, one unanswered for
REPUBLISH_AFTER_S goes out again; the arm announces a lift once per grasp, as its hold begins.
"""
from collections import namedtuple

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.runtime.arm import LiftAnnouncer
from gripper_ros.core.runtime.lockstep import Command, PlantSide
from gripper_ros.core.runtime.pacing import HELD, make_pacing
from gripper_ros.core.runtime.plant_loop import Chore, PlantLoop
from gripper_ros.core.runtime.world import busy_reason
from gripper_ros.wire import Outcome, Phase, REPUBLISH_AFTER_S, TimeMode
import pytest

Status = namedtuple('Status', 'grasp_id stage_id running pending_request phase outcome')


def _echo(grasp_id, stage_id, running, phase=Phase.FORCE, outcome=Outcome.UNKNOWN):
    return Command(stamp_ns=0, grasp_id=grasp_id, stage_id=stage_id, revision=0, source=0,
                   phase=phase, outcome=outcome, running=running, finite=1, voltage_v=0.0,
                   hold_s=0.0001, inner_setpoint=0.0)


def test_the_world_is_busy_while_a_grasp_runs_or_an_object_is_held():
    assert busy_reason(None, None) == ''
    assert busy_reason(_echo(1, 2, 1), None) == 'a grasp or release is running'
    held = Status(1, 3, 0, 0, Phase.HOLDING, Outcome.HOLDING)
    assert busy_reason(_echo(1, 2, 1), held) == 'an object is held (release or stop first)'
    # the echo of a later stage is the newer word: the status before it no longer counts
    assert busy_reason(_echo(1, 4, 0, Phase.IDLE), held) == ''
    waiting = Status(2, 0, 0, 1, Phase.IDLE, Outcome.UNKNOWN)
    assert busy_reason(None, waiting) == 'a grasp or release is running'
    released = Status(2, 5, 0, 0, Phase.IDLE, Outcome.RELEASED)
    assert busy_reason(_echo(1, 4, 1), released) == ''


def _loop(mode):
    side = PlantSide(make_plant(load_config()))
    return PlantLoop(side, make_pacing(mode, side.plant.t_ns), 10_000_000, now_s=100.0)


def test_realtime_runs_on_at_0_v_and_times_out_a_silent_supervisor():
    loop = _loop(TimeMode.REALTIME)
    assert loop.unpowered and loop.chore(100.0, False, 1.0) is Chore.RUN
    assert loop.chore(100.0, True, 1.0) is Chore.NONE          # a step already waits
    loop.command_accepted()
    assert not loop.unpowered and loop.chore(101.0, False, 1.0) is Chore.NONE    # answered
    loop.step()
    loop.published(200.0)
    assert loop.chore(200.0 + REPUBLISH_AFTER_S, False, 1.0) is Chore.REPUBLISH
    loop.republished(200.0 + REPUBLISH_AFTER_S)                 # no answer: still silent
    assert loop.chore(200.9, False, 1.0) is Chore.NONE
    assert loop.chore(201.0, False, 1.0) is Chore.TIMED_OUT and loop.unpowered
    assert loop.chore(201.0, False, 1.0) is Chore.RUN


def test_fast_mode_waits_for_a_command_and_steps_by_its_hold():
    loop = _loop(TimeMode.FAST)
    assert not loop.unpowered and loop.gate() is HELD            # nothing to step with
    assert loop.chore(1e6, False, 1.0) is Chore.REPUBLISH        # a late peer gets it again
    t0 = loop.stamp_ns
    loop.side.step_unpowered_due(0)                              # no change of the world
    loop.unpowered = True                                        # nobody commands
    assert loop.gate() == pytest.approx(float('inf'))            # fast: nothing needs time
    loop.woken = True                                            # a request waits
    assert loop.gate() == 0.0
    loop.step()
    assert loop.stamp_ns == t0 + 10_000_000 and not loop.woken


def test_the_arm_announces_a_lift_once_a_grasp_as_its_hold_begins():
    arm = LiftAnnouncer()
    assert not arm.due(0)                                        # nothing asked
    arm.arm(True, -1)
    assert not arm.due(-1)                                       # no hold begun
    assert arm.due(3) and not arm.due(3) and arm.announced == 1
    assert arm.due(4) and arm.announced == 2
    arm.arm(False, 4)
    assert not arm.due(5)
