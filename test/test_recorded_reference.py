"""Bags recorded by the interpreted core re-run in closed loop on the compiled core, bit for bit.

``test/data/python_core_bags`` holds four grasps recorded with ``grasp_demo`` (commit e866a85,
before the simulation core was compiled): a Table V object (50 mm, 1.69 kg), a stiff object
(1e5 N/m, 50 N s/m), a lift under the paper's force law that loses the object, and PD + the
paper's PI. Re-run headless without a change (``bag_replay BAG --resimulate --closed-loop``),
every tick, reference, command and object state equals the recording, and so the outcome and
the time of every phase.
"""
from __future__ import annotations

from pathlib import Path

from gripper_ros.bags import rerun
from helpers import assert_rerun_equals_recording
import pytest

BAGS = Path(__file__).resolve().parent / 'data' / 'python_core_bags'
RECORDED = {   # what grasp_demo answered when it recorded them, and the outcome after the hold
    'rigid_w50mm_m1.69kg': ('HOLDING', 'HOLDING'),
    'stiff_1e5_w50mm_m1kg': ('HOLDING', 'HOLDING'),
    'lift_paper_law_lost': ('HOLDING', 'OBJECT_LOST'),
    'pd_pi_w50mm_m1kg': ('HOLDING', 'HOLDING'),
}


@pytest.mark.parametrize('name', sorted(RECORDED))
def test_interpreted_core_bag_reruns_identically_on_the_compiled_core(name):
    w = rerun.whatif(BAGS / name)
    assert not w.record.truncated
    # every tick, reference, command and object state; every figure, the times of contact,
    # of the switch and of the answer among them
    assert_rerun_equals_recording(w)
    r = w.reruns[0]
    assert (r.metrics.outcome, r.metrics.final_outcome) == RECORDED[name]
