"""A grasp of unknown mass (``mass_kg`` 0): the supervisor's load-tracking grip, headless and live.

The supervisor runs the law (core/control/load_grip.py) each tick on the pads' readings the tick
carries. Known answers: the same request twice gives the same bits; the graph gives the headless
run's ticks, pad readings included; a 0.6 kg object (mu_s 0.5) is held through a +-3 m/s^2
pick-and-place with at most 0.5 mm of slip (the issue's bound); a 2.2 kg object on mu_s 0.3
needs 2.2 x 9.81 / (2 x 0.3) = 36.0 N at rest, more than the 33.39 N of 24 V, and the overload
is answered, with both numbers, before the plant loses the object.
"""
import math
from pathlib import Path
import threading
import time

from gripper_interfaces.msg import SupervisorStatus
from gripper_ros.bags.analyze import analyze_series
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.core.config import load_config
from gripper_ros.core.physics.hold import Lift
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.studies.grip_runs import simulate_load_grip
from gripper_ros.wire import (LiftProfile, Outcome, Phase, REFERENCE_LAYOUT, TOPIC_OUTCOME,
                              TOPIC_STATUS)
import numpy as np
import pytest

CONFIG = load_config()
WIDTH_M = 0.05
IDLE_TICK_NS = round(CONFIG.position.sample_time_s * 1e9)
"""A request starts one tick after the one it arrived at: the idle hold's position tick."""
SLIP_BOUND_M = 0.5e-3
MATCH_WAIT_S = 10.0                              # discovery on a loaded machine
PADS = ('pad1_shear_n', 'pad2_shear_n', 'pad1_displacement_m', 'pad2_displacement_m')
OLD_BAG = Path(__file__).resolve().parent / 'data' / 'python_core_bags' / 'lift_paper_law_lost'

HELD = {'object_mass_kg': 0.6, 'static_friction': 0.5, 'kinetic_friction': 0.4}
PICK = Lift(3.0, 0.2, 1.0, LiftProfile.PICK_AND_PLACE)
HEAVY = {'object_mass_kg': 2.2, 'static_friction': 0.3, 'kinetic_friction': 0.24}
HANG = Lift(0.0, 0.2, 1.0)                       # lifted off its support; its weight alone


def _lift_fields(lift: Lift) -> dict:
    """Return the SetObject fields of ``lift``."""
    return {'lift_acceleration_mps2': lift.acceleration_mps2, 'lift_delay_s': lift.delay_s,
            'lift_duration_s': lift.duration_s, 'lift_profile': int(lift.profile),
            'lift_frequency_hz': lift.frequency_hz}


def _set_object_fields(obj: dict, lift: Lift) -> dict:
    return {'mass_kg': obj['object_mass_kg'], 'static_friction': obj['static_friction'],
            'kinetic_friction': obj['kinetic_friction'], **_lift_fields(lift)}


@pytest.fixture(scope='module')
def headless_pick():
    return simulate_grasp(CONFIG, WIDTH_M, 0.0, lift=PICK, **HELD)


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        yield g


def test_unknown_mass_is_held_through_a_pick_and_place_and_bit_identical(headless_pick):
    h = headless_pick
    assert h.answer is Outcome.HOLDING and h.outcome is Outcome.HOLDING, h.message
    assert h.force_setpoint_n == CONFIG.load_grip.touch_force_n        # the request's
    assert h.lost_ns is None and h.overload_ns is None
    assert h.slip_m <= SLIP_BOUND_M
    lifted = h.series.ticks['stamp_ns'] > h.answer_ns
    # the grip followed the load: above the touch once lifted, and at most what 24 V holds
    assert np.max(h.series.ticks['force_n'][lifted]) > 2 * CONFIG.load_grip.touch_force_n
    assert np.max(h.series.ticks['force_n']) <= CONFIG.plant.max_force_n * (1 + 1e-9)
    # the pads read the load (about half the weight each) while held, exactly 0 before
    before = h.series.ticks['stamp_ns'] <= h.answer_ns
    for name in PADS:
        series = h.series.ticks[name]
        assert np.all(np.isfinite(series)) and np.all(series[before] == 0.0), name
    weight_share_n = 0.5 * HELD['object_mass_kg'] * CONFIG.plant.gravity_mps2
    assert np.max(h.series.ticks['pad1_shear_n'][lifted]) > 0.5 * weight_share_n
    again = simulate_grasp(CONFIG, WIDTH_M, 0.0, lift=PICK, **HELD)
    for name in h.series.ticks.dtype.names:
        assert np.array_equal(h.series.ticks[name], again.series.ticks[name]), name
    assert np.array_equal(h.series.tick_states['phase'], again.series.tick_states['phase'])
    assert (again.outcome, again.slip_m, again.end_ns) == (h.outcome, h.slip_m, h.end_ns)


def test_the_study_holds_with_the_load_tracking_grip_the_graph_runs(headless_pick):
    """grip_study's load-tracking case is the mass-0 grasp of the supervisor, row for row."""
    run = simulate_load_grip(CONFIG, WIDTH_M, HELD['object_mass_kg'], HELD['static_friction'],
                             HELD['kinetic_friction'], PICK, decimate=1,
                             after_s=CONFIG.contact.after_lift_s,
                             seed=CONFIG.sensor_noise.seed)
    h = headless_pick
    assert run.outcome == 'HOLDING' and run.slip_m == h.slip_m
    held = h.series.ticks['stamp_ns'] >= h.answer_ns
    assert np.array_equal(run.rows[:, 0], h.series.ticks['stamp_ns'][held])
    assert np.array_equal(run.rows[:, 1], h.series.ticks['force_n'][held])
    assert np.array_equal(run.rows[:, 2], h.series.tick_states['force_setpoint_n'][held])


def test_the_graph_runs_the_unknown_mass_grasp_tick_for_tick_as_headless(graph, tmp_path,
                                                                         headless_pick):
    run = recorded_grasp(graph, tmp_path / 'unknown_mass', WIDTH_M, 0.0,
                         object_mass_kg=HELD['object_mass_kg'],
                         static_friction=HELD['static_friction'],
                         kinetic_friction=HELD['kinetic_friction'], **_lift_fields(PICK))
    assert run.response.outcome == Outcome.HOLDING, run.response.message
    assert run.response.force_setpoint_n == CONFIG.load_grip.touch_force_n
    series = load_grasp_series(run.bag_dir)
    assert not series.absent                      # every tick field recorded, the pads' too
    start_ns = int(series.decisions['stamp_ns'][0])
    h = simulate_grasp(CONFIG, WIDTH_M, 0.0, lift=PICK, start_ns=start_ns - IDLE_TICK_NS,
                       **HELD)
    assert h.start_ns == start_ns
    # the bag starts with the grasp's first tick; the idle tick before it was not recorded
    assert np.array_equal(h.series.ticks['stamp_ns'][1:], series.ticks['stamp_ns'])
    for name in ('position_m', 'force_n', *PADS):
        assert np.array_equal(h.series.ticks[name][1:], series.ticks[name]), name
    # and it is the run of the first test, shifted in time
    ticks, pick = h.series.ticks, headless_pick.series.ticks
    assert np.array_equal(ticks['force_n'], pick['force_n'])
    assert np.array_equal(ticks['pad1_displacement_m'], pick['pad1_displacement_m'])
    m = analyze_series(series)
    assert m.pad_shear_max_n == np.max(0.5 * (ticks['pad1_shear_n'] + ticks['pad2_shear_n']))
    assert math.isnan(m.overload_said_s)


def test_a_bag_recorded_before_the_pad_readings_still_reads():
    """Its PlantTick has no pad fields (the bag's own schema): they read 0, named absent.

    Its StageReference also predates the reference's motion (the servo's feed-forward): read as
    the layout's defaults, named absent.
    """
    series = load_grasp_series(OLD_BAG)
    later = {'reference.approach_velocity_mps', 'reference.approach_acceleration_mps2'}
    assert all(name.split('.')[1] in REFERENCE_LAYOUT.tuple._field_defaults for name in later)
    assert series.absent == {f'tick.{name}' for name in PADS} | later
    assert series.ticks['stamp_ns'].size > 1000
    for name in PADS:
        assert series.ticks[name].shape == series.ticks['stamp_ns'].shape
        assert np.all(series.ticks[name] == 0.0)
    m = analyze_series(series)
    assert m.final_outcome == 'OBJECT_LOST' and math.isnan(m.pad_shear_max_n)


class _Outcomes:
    """What a robot program sees of a grasp: every status and every latched outcome."""

    def __init__(self, node):
        self._lock = threading.Lock()
        self.statuses: list[SupervisorStatus] = []
        self.outcomes: list[SupervisorStatus] = []
        self._subs = [node.create_subscription(SupervisorStatus, TOPIC_STATUS,
                                               self._keep(self.statuses), GRAPH_QOS),
                      node.create_subscription(SupervisorStatus, TOPIC_OUTCOME,
                                               self._keep(self.outcomes), LATCHED_QOS)]
        self._node = node
        deadline_s = time.monotonic() + MATCH_WAIT_S         # as a robot program waits
        while any(sub.get_publisher_count() < 1 for sub in self._subs):
            assert time.monotonic() < deadline_s, 'the graph never matched a subscriber'
            time.sleep(0.005)

    def _keep(self, into):
        def keep(msg):
            with self._lock:
                into.append(msg)
        return keep

    def close(self):
        for sub in self._subs:
            self._node.destroy_subscription(sub)


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec


def test_an_overload_is_answered_with_its_numbers_before_the_object_falls(graph):
    placed = graph.set_object(WIDTH_M, **_set_object_fields(HEAVY, HANG))
    assert placed.success, placed.message
    seen = _Outcomes(graph.client_node)
    try:
        r = graph.grasp(WIDTH_M, 0.0)
        assert r.outcome == Outcome.HOLDING, r.message
        assert graph.wait_still()
    finally:
        seen.close()
    lost_ns = graph.plant.plant.object_state.lost_ns             # the plant's ground truth
    assert lost_ns is not None
    said_ns = []
    for where in (seen.statuses, seen.outcomes):
        said = [m for m in where if m.grasp_id == r.grasp_id and
                m.outcome == Outcome.OVERLOADED]
        assert said, [(m.outcome, m.message) for m in where]
        first = said[0]
        assert first.phase == Phase.HOLDING and _stamp_ns(first) < lost_ns
        need_n = float(first.message.split(' N of grip')[0].rsplit(' ', 1)[1])
        assert need_n > CONFIG.plant.max_force_n
        assert f'the most 24 V holds is {CONFIG.plant.max_force_n:.2f} N' in first.message
        said_ns.append(_stamp_ns(first))
    assert said_ns[0] == said_ns[1]
    last = [m for m in seen.outcomes if m.grasp_id == r.grasp_id][-1]
    assert last.outcome == Outcome.OBJECT_LOST
    # headless says the same at the same instant: the very same kernels
    start_ns = min(_stamp_ns(m) for m in seen.statuses
                   if m.grasp_id == r.grasp_id and m.phase == Phase.POSITION)
    h = simulate_grasp(CONFIG, WIDTH_M, 0.0, lift=HANG, start_ns=start_ns - IDLE_TICK_NS,
                       **HEAVY)
    assert h.outcome is Outcome.OBJECT_LOST
    assert (h.overload_ns, h.lost_ns) == (said_ns[0], lost_ns)
    assert h.overload_limit_n == CONFIG.plant.max_force_n < h.overload_need_n


def test_the_plant_reads_no_pads_without_a_held_object():
    h = simulate_grasp(CONFIG, WIDTH_M, 1.0)                        # never lifted
    assert h.outcome is Outcome.HOLDING
    for name in PADS:
        assert np.all(h.series.ticks[name] == 0.0), name
