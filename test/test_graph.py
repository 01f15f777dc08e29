"""The node graph over real DDS in one process: paper objects, determinism, refusals, bags.

Four rclpy nodes under one EventsExecutor, real service calls, real MCAP bags.
"""
import math
import time

from gripper_ros.bags.reader import read_bag
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.core.config import load_config
from gripper_ros.core.series import seconds
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.nodes.services import wait_until
from gripper_ros.studies.paper import PAPER_OBJECTS
from gripper_ros.wire import (COMMAND_LAYOUT, Controller, DEFAULT_NAMESPACE, DESCRIPTION_TOPICS,
                              GRAPH_TOPICS,
                              LOOP_LAYOUTS, LOOP_TOPICS, Outcome, Phase, qualified,
                              REFERENCE_LAYOUT, SwitchCriterion, TICK_LAYOUT,
                              TOPIC_FORCE_REFERENCE, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                              TOPIC_POSITION_REFERENCE, TOPIC_TICK)
from helpers import step_into_phase, tf_as_robot_state_publisher, within_claimed_peak
import numpy as np
import pytest

CONFIG = load_config()
L_LS = CONFIG.plant.max_travel_m
V_LIMIT = CONFIG.plant.voltage_limit_v
EXACT_M = 1e-9
"""A rigid object stops the finger at its face: the answer is exact up to rounding."""
EXACT_REL = 1e-9
"""The force stage holds a rigid object at F_sp exactly when it answers HOLDING."""
RECORDED = {qualified(DEFAULT_NAMESPACE, t) for t in GRAPH_TOPICS}
DESCRIBED = {qualified(DEFAULT_NAMESPACE, t) for t in DESCRIPTION_TOPICS}
"""robot_description, /tf_static and /tf: in a bag, not counted by the loop's nodes."""
IDLE_TICK_NS = round(CONFIG.position.sample_time_s * 1e9)
"""A request starts one tick after the one it arrived at: the idle hold's position tick."""


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        yield g


@pytest.fixture(scope='module')
def paper_runs(graph, tmp_path_factory):
    out = tmp_path_factory.mktemp('bags')
    return [recorded_grasp(graph, out / f'object_{i}', w, m)
            for i, (w, m) in enumerate(PAPER_OBJECTS, 1)]


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_paper_object_is_held_at_its_width_and_force(paper_runs, index):
    width, mass = PAPER_OBJECTS[index]
    run = paper_runs[index]
    r = run.response
    assert r.success and r.outcome == Outcome.HOLDING, r.message
    setpoint = L_LS - width
    assert r.position_setpoint_m == pytest.approx(setpoint)
    assert r.final_position_m == pytest.approx(setpoint, abs=EXACT_M)   # at the rigid face
    sup = CONFIG.supervisor                      # friction law: each pad holds mu_s F
    f_sp = sup.grip_safety_factor * mass * CONFIG.plant.gravity_mps2 / (
        2 * sup.friction_coefficient)
    assert r.force_setpoint_n == pytest.approx(f_sp)
    assert r.final_force_n == pytest.approx(f_sp, rel=EXACT_REL)


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_paper_object_bag_voltage_limit_and_single_switch(paper_runs, index):
    series = load_grasp_series(paper_runs[index].bag_dir)
    assert np.all(np.abs(series.ticks['motor_voltage_v']) <= V_LIMIT + 1e-12)
    assert np.all(np.abs(series.commands['voltage_v']) <= V_LIMIT + 1e-12)
    criteria = series.decisions['switch_criterion']
    switches = np.flatnonzero(np.diff(criteria) != 0)
    assert len(switches) == 1 and criteria[-1] != SwitchCriterion.NONE


def _loop_messages(bag, topic, layout):
    """Per tick (stamp_ns), the distinct messages of one loop topic, as dicts by field name.

    A reference or command repeated for a late peer is the same message again: kept once.
    """
    out = {}
    for raw in bag.messages:
        if raw.topic == qualified(DEFAULT_NAMESPACE, topic):
            values = layout.as_dict(layout.unpack(raw.data))
            rows = out.setdefault(values['stamp_ns'], [])
            if values not in rows:
                rows.append(values)
    return out


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_each_tick_applies_the_command_of_the_controller_the_supervisor_named(paper_runs,
                                                                              index):
    """Tick by tick, on the wire, the motor is driven by the controller the supervisor named.

    The one reference for tick t names a controller (on that controller's topic); the one
    command for t comes from it, in the same stage; the plant's next tick, ``hold_s`` later,
    reports that source and that voltage as applied. The named controller is the position
    stage until one switch, the force stage after.
    """
    bag = read_bag(paper_runs[index].bag_dir)
    ticks = _loop_messages(bag, TOPIC_TICK, TICK_LAYOUT)
    topics = {Controller.POSITION: TOPIC_POSITION_REFERENCE,
              Controller.FORCE: TOPIC_FORCE_REFERENCE}
    references = {}
    for controller, topic in topics.items():
        for stamp, rows in _loop_messages(bag, topic, REFERENCE_LAYOUT).items():
            assert all(r['controller'] == controller for r in rows), (topic, stamp)
            references.setdefault(stamp, []).extend(rows)
    commands = _loop_messages(bag, TOPIC_MOTOR_COMMAND, COMMAND_LAYOUT)
    stamps = sorted(ticks)
    assert stamps == sorted(references) == sorted(commands)
    assert all(len(rows) == 1 for table in (ticks, references, commands)
               for rows in table.values())
    named = []
    for stamp in stamps:
        (ref,), (cmd,) = references[stamp], commands[stamp]
        assert cmd['source'] == ref['controller'], stamp
        assert (cmd['stage_id'], cmd['grasp_id']) == (ref['stage_id'], ref['grasp_id']), stamp
        named.append(ref['controller'])
    for before, after in zip(stamps, stamps[1:]):          # the first tick's command was idle's
        (cmd,), (tick,) = commands[before], ticks[after]
        assert after - before == round(cmd['hold_s'] * 1e9), before
        assert tick['applied_source'] == cmd['source'], after
        assert tick['motor_voltage_v'] == cmd['voltage_v'], after
    switch = named.index(Controller.FORCE)
    assert switch > 0 and named == [Controller.POSITION] * switch + \
        [Controller.FORCE] * (len(named) - switch)


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_bag_holds_every_published_message_and_decodes(paper_runs, index):
    run = paper_runs[index]
    bag = read_bag(run.bag_dir)
    assert not bag.truncated
    assert set(bag.counts()) == RECORDED | DESCRIBED
    assert {t: n for t, n in bag.counts().items() if t in RECORDED} == run.published
    js = qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES)
    tf, expected = tf_as_robot_state_publisher(bag)          # as robot_state_publisher
    assert tf == expected and len(tf) >= run.published[js] // 5, (tf[:3], expected[:3])
    assert all(n > 0 for n in run.published.values())
    layouts = {qualified(DEFAULT_NAMESPACE, t): LOOP_LAYOUTS[msgtype]
               for t, msgtype in LOOP_TOPICS.items()}
    for topic in RECORDED:                       # every message decodes, by the bag's schema
        decoded = list(bag.iter_decoded(topic))
        assert len(decoded) == run.published[topic]
        if topic in layouts:                     # to the numbers the nodes packed
            layout = layouts[topic]
            for raw, msg in decoded:
                assert tuple(getattr(msg, f) for f in layout.fields) == \
                    layout.unpack(raw.data), topic


def test_same_request_twice_gives_identical_series(graph, tmp_path):
    runs = [recorded_grasp(graph, tmp_path / f'run_{k}', 0.05, 1.69) for k in range(2)]
    a, b = (load_grasp_series(r.bag_dir) for r in runs)
    # simulated time runs on across grasps: compare tick times relative to each grasp's start
    t_a = np.round((a.t_s - a.t_s[0]) * 1e9).astype(np.int64)
    t_b = np.round((b.t_s - b.t_s[0]) * 1e9).astype(np.int64)
    assert np.array_equal(t_a, t_b)
    assert np.array_equal(a.ticks['position_m'], b.ticks['position_m'])
    assert np.array_equal(a.ticks['force_n'], b.ticks['force_n'])
    assert np.array_equal(a.commands['voltage_v'], b.commands['voltage_v'])


BAD_REQUESTS = [
    {'width_m': math.nan, 'mass_kg': 1.0},
    {'width_m': math.inf, 'mass_kg': 1.0},
    {'width_m': 0.05, 'mass_kg': -math.inf},
    {'width_m': 0.0, 'mass_kg': 1.0},
    {'width_m': -0.01, 'mass_kg': 1.0},
    {'width_m': L_LS, 'mass_kg': 1.0},
    {'width_m': 0.05, 'mass_kg': -1.0},
    {'width_m': 0.05, 'mass_kg': 1.0, 'friction_coefficient': -0.5},
    {'width_m': 0.05, 'mass_kg': 1.0, 'timeout_s': math.nan},
    {'width_m': 0.05, 'mass_kg': 50.0},   # 1.5*50*9.81/(2*0.5) = 736 N > 33.4 N at 24 V
]


@pytest.mark.parametrize('request_fields', BAD_REQUESTS)
def test_bad_request_is_refused_with_a_message_and_nothing_moves(graph, request_fields):
    before = graph.plant.ticks_published
    r = graph.grasp(**request_fields)
    assert not r.success
    assert r.outcome == Outcome.REFUSED
    assert r.message.startswith('refused: ') and len(r.message) > len('refused: ')
    assert graph.plant.ticks_published == before


def test_force_beyond_the_motor_names_the_numbers(graph):
    r = graph.grasp(0.05, 50.0)
    # friction law: 1.5 x 50 kg x 9.81 m/s^2 / (2 x 0.5) = 735.75 N
    assert '735.75 N' in r.message and 'friction law' in r.message and '33.39 N' in r.message


def test_request_while_grasping_is_refused_and_next_one_succeeds(graph):
    """The first grasp is held in its position stage (paused, stepped) while the second comes."""
    graph.set_object(0.05)
    assert graph.wait_still()
    assert graph.pause().success
    first = graph.grasp_async(0.05, 1.69)
    try:
        assert wait_until(lambda: graph.supervisor.logic.pending, 10.0)
        step_into_phase(graph, Phase.POSITION, ticks_into=5)
        busy = graph.grasp(0.05, 1.69)
    finally:
        assert graph.resume().success
    assert busy.outcome == Outcome.REFUSED and 'grasp is running' in busy.message
    assert wait_until(first.done, 120.0)
    assert first.result().success
    graph.set_object(0.10)
    assert graph.grasp(0.10, 0.75).success


def test_no_object_between_the_fingers_ends_in_no_object(graph):
    graph.set_object(0.0)                        # nothing there: the fingers would meet
    r = graph.grasp(0.05, 1.69)
    assert not r.success and r.outcome == Outcome.NO_OBJECT, r.message
    assert 'without contact' in r.message
    margin = CONFIG.supervisor.no_object_margin_m
    assert (L_LS - 0.05) + margin < r.final_position_m < L_LS
    graph.set_object(0.05)
    assert graph.grasp(0.05, 1.69).success


def test_stop_ends_the_running_grasp_and_the_next_one_succeeds(graph):
    from std_srvs.srv import Trigger
    stop = graph.client_node.create_client(Trigger, 'stop')
    assert stop.wait_for_service(timeout_sec=5)
    graph.set_object(0.0)                        # a held object is released first
    refused = graph.call(stop, Trigger.Request(), 5)
    assert not refused.success and 'nothing to stop' in refused.message
    graph.set_object(0.01)
    assert graph.wait_still()
    assert graph.pause().success                 # stopped at a known tick of the approach
    pending = graph.grasp_async(0.01, 1.27)
    try:
        assert wait_until(lambda: graph.supervisor.logic.pending, 10.0)
        step_into_phase(graph, Phase.POSITION, ticks_into=20)
        assert graph.call(stop, Trigger.Request(), 5).success
    finally:
        assert graph.resume().success
    assert wait_until(pending.done, 30.0)
    r = pending.result()
    assert r.outcome == Outcome.STOPPED and not r.success
    assert graph.wait_still()
    frozen = graph.plant.ticks_published
    time.sleep(0.2)
    assert graph.plant.ticks_published == frozen          # fast time: nothing needs time now
    assert graph.supervisor.logic.active == 1              # the position stage holds the finger
    graph.set_object(0.01)
    assert graph.grasp(0.01, 1.27).success


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_headless_simulation_reproduces_the_graph_bit_for_bit(paper_runs, index):
    """The headless loop runs the same logic without ROS: identical series to the bag's."""
    from gripper_ros.core.runtime.headless import simulate_grasp
    width, mass = PAPER_OBJECTS[index]
    series = load_grasp_series(paper_runs[index].bag_dir)
    start_ns = int(series.decisions['stamp_ns'][0])
    h = simulate_grasp(CONFIG, width, mass, start_ns=start_ns - IDLE_TICK_NS)
    assert h.outcome == Outcome(paper_runs[index].response.outcome)
    assert h.start_ns == start_ns
    # the bag starts with the grasp's first tick; the idle tick before it was not recorded
    assert np.array_equal(h.series.ticks['stamp_ns'][1:], series.ticks['stamp_ns'])
    assert np.array_equal(h.series.ticks['position_m'][1:], series.ticks['position_m'])
    assert np.array_equal(h.series.ticks['force_n'][1:], series.ticks['force_n'])
    assert np.array_equal(h.series.ticks['motor_voltage_v'][1:], series.ticks['motor_voltage_v'])


@pytest.mark.parametrize('index', range(len(PAPER_OBJECTS)))
def test_position_stage_in_the_graph_is_the_controller_step_run(paper_runs, index):
    """The node graph's MPC-PD gives the numeric core's step response, tick for tick.

    test_position_limit holds the step run's figures to the targets; here the graph follows it
    up to the switch, and the voltage never leaves +-24 V.
    """
    from gripper_ros.core.control.factories import make_position_controller
    from gripper_ros.wire import PositionControllerKind
    from gripper_ros.studies.step_runs import position_step
    width, _ = PAPER_OBJECTS[index]
    setpoint = L_LS - width
    series = load_grasp_series(paper_runs[index].bag_dir)
    start_s = seconds(series.decisions)[0]
    switch_s = start_s + paper_runs[index].response.switch_time_s
    ticks = series.t_s <= switch_s + 1e-12                 # the 10 ms position stage
    t_graph = series.t_s[ticks] - start_s
    x_graph = series.ticks['position_m'][ticks]
    assert t_graph.size > 50
    step = position_step(CONFIG, make_position_controller(CONFIG, PositionControllerKind.MPC_PD),
                         setpoint, horizon_s=t_graph[-1] + 0.01)
    k = np.rint(t_graph / CONFIG.position.sample_time_s).astype(int)
    np.testing.assert_allclose(x_graph, step.output[k], rtol=0, atol=1e-12)
    assert np.all(np.abs(series.ticks['motor_voltage_v'][ticks]) <= V_LIMIT)


def test_stiff_object_in_the_graph_no_spike_and_bit_identical_to_headless(graph, tmp_path):
    """A stiff (1e5 N/m) object through the live graph: held without a force spike.

    The recorded series equal the headless run that contact_sweep uses.
    """
    from gripper_ros.core.runtime.headless import simulate_grasp
    run = recorded_grasp(graph, tmp_path / 'stiff', 0.05, 1.0, stiffness_n_per_m=1e5,
                         damping_n_s_per_m=50.0)
    assert run.response.success and run.response.outcome == Outcome.HOLDING, \
        run.response.message
    series = load_grasp_series(run.bag_dir)
    f_sp = run.response.force_setpoint_n
    assert within_claimed_peak(np.max(series.ticks['peak_force_n']) / f_sp)
    assert np.all(np.abs(series.ticks['motor_voltage_v']) <= V_LIMIT)
    start_ns = int(series.decisions['stamp_ns'][0])
    h = simulate_grasp(CONFIG, 0.05, 1.0, stiffness_n_per_m=1e5, damping_n_s_per_m=50.0,
                       start_ns=start_ns - IDLE_TICK_NS)
    assert np.array_equal(h.series.ticks['position_m'][1:], series.ticks['position_m'])
    assert np.array_equal(h.series.ticks['force_n'][1:], series.ticks['force_n'])


def test_width_tolerance_through_the_service_meets_a_wider_object_at_the_setpoint(graph, tmp_path):
    """Request 50 mm +- 12 mm, place a 62 mm object: it is held at its real face.

    The position stage stops short of the widest face (status approach_setpoint_m) and the
    object is met with at most F_sp.
    """
    run = recorded_grasp(graph, tmp_path / 'wider', 0.05, 1.69, width_tolerance_m=0.012,
                         object_width_m=0.062)
    r = run.response
    assert r.success and r.outcome == Outcome.HOLDING, r.message
    assert r.final_width_m == pytest.approx(0.062, abs=1e-6)
    series = load_grasp_series(run.bag_dir)
    assert within_claimed_peak(np.max(series.ticks['peak_force_n']) / r.force_setpoint_n)
    grasp = np.isin(series.decisions['phase'], (Phase.POSITION, Phase.FORCE))
    assert set(np.round(series.decisions['approach_setpoint_m'][grasp], 9)) == \
        {round(L_LS - 0.05 - 0.012, 9)}
    assert graph.grasp(0.05, 1.69, width_tolerance_m=math.nan).outcome == Outcome.REFUSED
