"""Recorded grasps re-run in closed loop: bit for bit, or within a stated tolerance if older.

``test/data/reference_bags`` holds five grasps recorded with ``grasp_demo --time-mode fast`` by
the present core, whose results are the same bits on every CPU (docs/ARCHITECTURE.md): a Table V
object (50 mm, 1.69 kg), a stiff object (1e5 N/m, 50 N s/m), a lift under the paper's force law
that loses the object, PD + the paper's PI, and an unknown-mass pick-and-place under the
load-tracking grip (pad sensors with their noise, the lift-off). Re-run headless without a
change (``bag_replay BAG --resimulate --closed-loop``), every tick, reference, command and object
state equals the recording bit for bit, and so the outcome and the time of every phase.

``test/data/python_core_bags`` holds four grasps recorded by the interpreted core (commit e866a85)
on an AVX-512 machine, whose linear algebra took that CPU's BLAS kernels. Their bits cannot be
given again anywhere else; they re-run with the same outcome, phases, event times and every
integer field exact, and every float within ``rerun.RECORDING_TOLERANCE`` of its full scale.
"""
from __future__ import annotations

import copy
from dataclasses import asdict
import math
from pathlib import Path

from gripper_ros.bags import rerun
from helpers import assert_rerun_equals_recording
import numpy as np
import pytest

DATA = Path(__file__).resolve().parent / 'data'
REFERENCE = {   # what grasp_demo answered when it recorded them, and the outcome after the hold
    'rigid_w50mm_m1.69kg': ('HOLDING', 'HOLDING'),
    'stiff_1e5_w50mm_m1kg': ('HOLDING', 'HOLDING'),
    'lift_paper_law_lost': ('HOLDING', 'OBJECT_LOST'),
    'pd_pi_w50mm_m1kg': ('HOLDING', 'HOLDING'),
    'load_tracking_pick_and_place': ('HOLDING', 'HOLDING'),
}
INTERPRETED = {k: v for k, v in REFERENCE.items() if k != 'load_tracking_pick_and_place'}
EVENT_FIGURES = ('grasp_start_s', 'grasp_end_s', 'time_to_contact_s', 'switch_time_s',
                 'hold_s', 'lost_at_s', 'loss_detected_s', 'overload_said_s')
FIGURE_RELATIVE_TOLERANCE = 1e-6


@pytest.mark.parametrize('name', sorted(REFERENCE))
def test_a_reference_bag_reruns_bit_for_bit(name):
    w = rerun.whatif(DATA / 'reference_bags' / name)
    assert not w.record.truncated
    assert_rerun_equals_recording(w)
    r = w.reruns[0]
    assert (r.metrics.outcome, r.metrics.final_outcome) == REFERENCE[name]


@pytest.mark.parametrize('name', sorted(INTERPRETED))
def test_an_interpreted_core_bag_reruns_with_its_outcome_and_events_and_within_tolerance(name):
    w = rerun.whatif(DATA / 'python_core_bags' / name)
    assert not w.record.truncated
    r = w.reruns[0]
    assert r.agreement == '', r.agreement
    assert (r.metrics.outcome, r.metrics.final_outcome) == INTERPRETED[name]
    recorded, again = asdict(w.recorded), asdict(r.metrics)
    skip = {'bag', 'pad_shear_max_n'}        # the bag's messages have no pad readings
    for key, value in recorded.items():
        if key in skip:
            continue
        new = again[key]
        if key in EVENT_FIGURES or not isinstance(value, float):
            assert new == value or (isinstance(value, float) and math.isnan(value) and
                                    math.isnan(new)), key
        elif math.isfinite(value):
            assert new == pytest.approx(value, rel=FIGURE_RELATIVE_TOLERANCE, abs=1e-12), key
        else:
            assert repr(new) == repr(value), key


def test_the_tolerance_passes_an_ulp_and_finds_what_is_beyond_it_or_in_an_integer():
    """Within tolerance: a 1-ulp force; beyond: 2e-6 of full scale, or a phase changed at all."""
    w = rerun.whatif(DATA / 'reference_bags' / 'rigid_w50mm_m1.69kg')
    new, start = w.reruns[0].series, w.record.grasp_start_ns

    def within(edit) -> str:
        rec = copy.deepcopy(w.record.series)
        edit(rec)
        return rerun.series_difference(rec, new, start, tolerance=rerun.RECORDING_TOLERANCE)

    force = w.record.series.ticks['force_n']
    k = int(np.flatnonzero(force > 0)[0])
    full_scale = float(np.abs(force).max())
    assert within(lambda r: r.ticks['force_n'].__setitem__(
        k, np.nextafter(force[k], np.inf))) == ''
    text = within(lambda r: r.ticks['force_n'].__setitem__(k, force[k] + 2e-6 * full_scale))
    assert text.startswith('tick force_n differs first at') and 'beyond 1e-06' in text
    phase = w.record.series.references['phase']
    text = within(lambda r: r.references['phase'].__setitem__(-1, phase[-1] + 1))
    assert text.startswith('reference phase differs first at'), text
