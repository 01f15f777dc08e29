"""The compiled headless loop and the batch engine over the cores (no ROS).

- The compiled loop and the same kernels driven tick by tick from Python (``trace=``) give the
  same series, bit for bit, and the same answer.
- The compiled loop's trace (``trace_state_period_ns``) keeps every tick, reference and command
  a ``trace=`` callback is given, field for field.
- ``simulate_grasps`` gives, for every case, what ``simulate_grasp`` gives in this process,
  whatever the number of worker processes; a refused request comes back as its RequestError;
  ``summarize`` runs in the worker and only its result comes back; summarized cases in one
  process reuse the rows a case before left free, and give the same bytes; so does a traced
  grasp (a closed-loop re-run's) that follows them.
- Bad ``jobs`` are refused.
"""
from __future__ import annotations

from gripper_ros.core.config import load_config
from gripper_ros.core.runtime import headless
from gripper_ros.core.runtime.headless import map_cases, simulate_grasp, simulate_grasps
from gripper_ros.core.supervision.requests import RequestError
from gripper_ros.wire import Outcome
import numpy as np
import pytest

CONFIG = load_config()
CASES = [
    {'width_m': 0.14, 'mass_kg': 0.5, 'hold_s': 0.05},
    {'width_m': 0.12, 'mass_kg': 1.0, 'stiffness_n_per_m': 1e5, 'damping_n_s_per_m': 50.0},
    {'width_m': 0.13, 'mass_kg': 50.0},                    # beyond what 24 V can hold: refused
    {'width_m': 0.14, 'mass_kg': 0.3, 'object_width_m': 0.0},          # nothing there
    {'width_m': 0.125, 'mass_kg': 0.8, 'position_controller': 'pd', 'force_controller': 'pi'},
]


def _same(a, b) -> bool:
    """Tell whether two grasps answered the same with every field of every tick the same."""
    return a.outcome is b.outcome and a.answer_ns == b.answer_ns and a.message == b.message \
        and all(np.array_equal(x[n], y[n], equal_nan=True)
                for x, y in ((a.series.ticks, b.series.ticks),
                             (a.series.tick_states, b.series.tick_states))
                for n in x.dtype.names)


def _outcome_and_ticks(case: dict, result):
    """Summary made in the worker (module level: it is pickled)."""
    if isinstance(result, RequestError):
        return 'refused'
    return result.outcome.name, len(result.series.ticks)


def test_compiled_loop_equals_the_kernels_driven_from_python():
    ticks = []
    for case in (CASES[1], CASES[4]):
        compiled = simulate_grasp(CONFIG, **case)
        traced = simulate_grasp(CONFIG, **case, trace=lambda *args: ticks.append(args[1]))
        assert compiled.outcome is Outcome.HOLDING
        assert _same(compiled, traced)
        assert [t.stamp_ns for t in ticks] == compiled.series.ticks['stamp_ns'].tolist()
        ticks.clear()


def test_the_compiled_trace_keeps_what_a_trace_callback_is_given():
    seen = {'ticks': [], 'references': [], 'commands': []}

    def trace(plant, tick, decision, ref, cmd):
        seen['ticks'].append(tuple(tick))
        if ref is not None:
            seen['references'].append(tuple(ref))
            seen['commands'].append(tuple(cmd))
    for case in (CASES[1], {**CASES[0], 'idle_unpowered_s': 0.01}):
        simulate_grasp(CONFIG, **case, trace=trace)
        kept = simulate_grasp(CONFIG, **case, trace_state_period_ns=10_000_000).series
        for name, rows in seen.items():
            assert getattr(kept, name).tolist() == rows, name
            rows.clear()
        assert kept.statuses.size and kept.objects.size
    with pytest.raises(ValueError, match='exclusive'):
        simulate_grasp(CONFIG, **CASES[0], trace=trace, trace_state_period_ns=1)


@pytest.mark.parametrize('jobs', [1, 2])
def test_a_batch_gives_what_each_grasp_gives_alone(jobs):
    results = simulate_grasps(CONFIG, CASES, jobs=jobs)
    assert len(results) == len(CASES)
    for case, result in zip(CASES, results):
        if case['mass_kg'] == 50.0:
            assert isinstance(result, RequestError) and 'exceeds' in str(result)
            continue
        assert _same(result, simulate_grasp(CONFIG, **case))
    assert [r.outcome for r in results if not isinstance(r, RequestError)] == \
        [Outcome.HOLDING, Outcome.HOLDING, Outcome.NO_OBJECT, Outcome.HOLDING]


def test_summaries_come_back_in_the_order_of_the_cases():
    summaries = simulate_grasps(CONFIG, CASES, jobs=2, summarize=_outcome_and_ticks)
    assert summaries[2] == 'refused'
    assert summaries == [_outcome_and_ticks(c, simulate_grasp(CONFIG, **c))
                         if c['mass_kg'] != 50.0 else 'refused' for c in CASES]


def _ticks_digest(case: dict, result):
    """Summarize every tick's numbers (as a sweep's summary reads them all)."""
    if isinstance(result, RequestError):
        return 'refused'
    return [result.series.ticks[n].tobytes() for n in result.series.ticks.dtype.names]


def _force_rows(case: dict, result):
    """Summarize by a view of the grasp's rows (kept: the rows must stay as they are)."""
    return None if isinstance(result, RequestError) else result.series.ticks['force_n']


def test_summarized_grasps_in_one_process_give_what_each_gives_alone():
    """A summarized case writes into the rows the one before left free, and only then.

    Each summary is the same bytes as the grasp's alone (the longer hold first: the next ones
    write into bigger, used rows); a summary that keeps a view of its rows keeps them intact
    through the cases after it.
    """
    cases = [dict(CASES[0], hold_s=0.5)] + CASES
    summaries = simulate_grasps(CONFIG, cases, jobs=1, summarize=_ticks_digest)
    assert summaries == [_ticks_digest(c, simulate_grasp(CONFIG, **c))
                         if c['mass_kg'] != 50.0 else 'refused' for c in cases]
    kept = simulate_grasps(CONFIG, cases, jobs=1, summarize=_force_rows)
    for case, rows in zip(cases, kept):
        if rows is not None:
            assert np.array_equal(rows, simulate_grasp(CONFIG, **case).series.ticks['force_n'],
                                  equal_nan=True)


def test_a_traced_grasp_after_a_summarized_batch_keeps_every_message():
    """A traced grasp (a closed-loop re-run's) that writes into rows a batch left free.

    Its ticks start in the spare rows, longer than its first trace rows would be: every
    message is kept as in the same grasp traced first in the process, byte for byte.
    """
    case = dict(CASES[1], trace_state_period_ns=10_000_000)
    alone = simulate_grasp(CONFIG, **case).series
    simulate_grasps(CONFIG, [dict(CASES[0], hold_s=2.0)], jobs=1, summarize=_outcome_and_ticks)
    assert headless._SPARE_ROWS, 'the batch left no rows free: nothing is tested'
    after = simulate_grasp(CONFIG, **case).series
    for name in ('ticks', 'references', 'commands', 'statuses', 'objects'):
        assert getattr(after, name).tobytes() == getattr(alone, name).tobytes(), name
    assert alone.statuses.size and alone.objects.size


@pytest.mark.parametrize('jobs', [0, -1, 1.5, 10 ** 6])
def test_bad_jobs_are_refused(jobs):
    with pytest.raises(ValueError, match=r'jobs must be a whole number in \[1, '):
        map_cases(abs, [1, 2, 3], jobs=jobs)
