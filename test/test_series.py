"""One grasp's time series (core/series.py): a headless grasp keeps what a bag holds.

- The supervisor's decisions are its references, each with the switch criterion its status
  reported by then; a FAULT, which names no stage, ends them with the supervisor's last state.
- bag_analyze reads a headless grasp's series as it reads a bag: its figures are the
  supervisor's own instants and answers.
"""
from __future__ import annotations

import math

from gripper_ros.bags.analyze import analyze_series
from gripper_ros.core.config import load_config
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.wire import FaultKind, Outcome, SwitchCriterion
import numpy as np
import pytest

CONFIG = load_config()
STATE_PERIOD_NS = 10_000_000


def test_decisions_carry_the_switch_criterion_from_the_switch_on():
    h = simulate_grasp(CONFIG, 0.05, 1.69, hold_s=0.1, trace_state_period_ns=STATE_PERIOD_NS)
    assert h.answer is Outcome.HOLDING and h.switch_criterion is not SwitchCriterion.NONE
    d, refs = h.series.decisions, h.series.references
    assert d.size == refs.size                    # no FAULT: one decision a reference
    for name in ('stamp_ns', 'phase', 'outcome', 'grasp_id', 'stage_id', 'force_setpoint_n'):
        assert np.array_equal(d[name], refs[name]), name
    assert np.array_equal(d['active_controller'], refs['controller'])
    after = d['stamp_ns'] >= h.switch_ns
    assert np.all(d['switch_criterion'][after] == h.switch_criterion)
    assert np.all(d['switch_criterion'][~after] == SwitchCriterion.NONE)


def test_a_fault_ends_the_decisions_with_the_supervisors_last_state():
    h = simulate_grasp(CONFIG, 0.05, 1.0, fault=(FaultKind.SENSOR_DROPOUT, 0.05, 0.0),
                       trace_state_period_ns=STATE_PERIOD_NS)
    assert h.outcome is Outcome.FAULT
    d, refs = h.series.decisions, h.series.references
    assert d.size == refs.size + 1
    assert np.array_equal(d['stamp_ns'][:-1], refs['stamp_ns'])
    assert np.all(d['outcome'][:-1] != Outcome.FAULT)
    last = d[-1]
    assert last['outcome'] == Outcome.FAULT and last['stamp_ns'] > refs['stamp_ns'][-1]
    assert math.isnan(last['seed_voltage_v'])     # no reference carried it: no seed


def test_bag_analysis_of_a_headless_series_gives_the_supervisors_instants():
    h = simulate_grasp(CONFIG, 0.05, 1.69, hold_s=0.2, trace_state_period_ns=STATE_PERIOD_NS)
    m = analyze_series(h.series, CONFIG.plant.voltage_limit_v)
    assert (m.outcome, m.final_outcome) == (h.answer.name, h.outcome.name)
    assert m.switch_criterion == h.switch_criterion.name
    assert m.grasp_start_s == h.start_ns * 1e-9
    assert m.switch_time_s == pytest.approx((h.switch_ns - h.start_ns) * 1e-9, abs=1e-12)
    assert m.grasp_end_s - m.grasp_start_s == pytest.approx(h.time_to_answer_s, abs=1e-12)
    assert m.hold_s == pytest.approx((h.end_ns - h.answer_ns) * 1e-9, abs=1e-12)
    assert m.force_setpoint_n == h.force_setpoint_n
