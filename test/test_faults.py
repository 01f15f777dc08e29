"""Faults on the live graph: dead nodes mid-grasp, non-finite measurements in the loop.

Real DDS, the real EventsExecutor, real service calls; nodes are killed with
GripperGraph.kill_node (removed and destroyed on the executor thread, as if their process died).
Non-finite numbers are published by a probe node of the test on the measurement topics with the
stamp of the tick the plant is publishing (the probe runs in the plant's publish, just before its
joint state, so the supervisor decides that tick on the probe's number). Every float field of
every message on every graph topic is checked by a watcher node.

The controller stage logic's 0 V hold on NaN / inf is also tested without ROS, first.
"""
from collections import Counter
import math
import threading
import time
from types import SimpleNamespace

from gripper_ros.core.config import load_config
from gripper_ros.core.control.stages import (ForceStageController, LockstepAnswerer,
                                             PositionStageController, Reference, SOURCE_FORCE,
                                             SOURCE_POSITION)
import pytest

CONFIG = load_config()
BAD_VALUES = [math.nan, math.inf, -math.inf]
BAD_IDS = ['nan', '+inf', '-inf']


# ====================================================================== stage logic, no ROS
def _ref(source, stamp_ns, measurement, stage_id=1, position_sp=0.05, force_sp=3.0,
         contact=False, seed=1.0, position=0.049, **bad):
    """Build a stage reference; ``bad`` overrides fields with non-finite numbers."""
    values = {'stamp_ns': stamp_ns, 'grasp_id': 1, 'stage_id': stage_id, 'revision': 0,
              'phase': 1, 'outcome': 0, 'controller': int(source), 'running': True,
              'contact': contact, 'position_setpoint_m': position_sp,
              'approach_setpoint_m': position_sp, 'force_setpoint_n': force_sp,
              'position_m': measurement if source == SOURCE_POSITION else position,
              'velocity_mps': 0.0, 'force_n': measurement if source == SOURCE_FORCE else 0.0,
              'seed_voltage_v': seed}
    values.update(bad)
    return Reference(**values)


def _stage(source):
    return (PositionStageController(CONFIG) if source == SOURCE_POSITION
            else ForceStageController(CONFIG))


def _measurements(source):
    # finger travel (m) for the position stage, gripping force (N) for the force stage
    return [0.0, 0.001, 0.003, 0.006, 0.01] if source == SOURCE_POSITION else \
        [0.0, 0.5, 1.2, 2.0, 2.6]


@pytest.mark.parametrize('source', [SOURCE_POSITION, SOURCE_FORCE], ids=['position', 'force'])
@pytest.mark.parametrize('bad', BAD_VALUES, ids=BAD_IDS)
@pytest.mark.parametrize('at', [0, 2], ids=['first_tick', 'mid_run'])
def test_stage_holds_zero_volts_on_a_non_finite_measurement_and_is_left_untouched(
        source, bad, at):
    """The bad tick is answered with exactly 0 V, and the law is not stepped.

    So every later answer equals that of a run that never saw the bad tick.
    """
    values = _measurements(source)
    dt_ns = 10_000_000
    clean, hit = LockstepAnswerer(_stage(source)), LockstepAnswerer(_stage(source))
    clean_answers, hit_answers = [], []
    for k, value in enumerate(values):
        if k == at:
            bad_answer = hit.answer(_ref(source, k * dt_ns, bad, contact=k >= 3))
            assert bad_answer.voltage_v == 0.0 and bad_answer.inner_setpoint == 0.0
            assert not bad_answer.finite and 'non-finite measurement' in bad_answer.reason
            assert hit.answer(_ref(source, k * dt_ns, bad)) is None   # each tick answered once
            continue
        clean_answers.append(clean.answer(_ref(source, k * dt_ns, value, contact=k >= 3)))
        hit_answers.append(hit.answer(_ref(source, k * dt_ns, value, contact=k >= 3)))
    assert hit_answers == clean_answers
    assert all(a.finite and math.isfinite(a.voltage_v) and math.isfinite(a.inner_setpoint)
               for a in hit_answers)


@pytest.mark.parametrize('source', [SOURCE_POSITION, SOURCE_FORCE], ids=['position', 'force'])
@pytest.mark.parametrize('bad', BAD_VALUES, ids=BAD_IDS)
@pytest.mark.parametrize('field', ['position_setpoint_m', 'approach_setpoint_m',
                                   'force_setpoint_n', 'seed_voltage_v'])
def test_stage_is_not_driven_by_a_non_finite_reference_number(source, bad, field):
    """A corrupted reference (setpoint or seed voltage) is not acted on: 0 V, law untouched."""
    clean, hit = LockstepAnswerer(_stage(source)), LockstepAnswerer(_stage(source))
    m = _measurements(source)
    assert hit.answer(_ref(source, 0, m[0])) == clean.answer(_ref(source, 0, m[0]))
    a = hit.answer(_ref(source, 10_000_000, m[1], **{field: bad}))
    assert (a.voltage_v, a.inner_setpoint, a.finite) == (0.0, 0.0, False)
    assert 'non-finite reference' in a.reason and field in a.reason
    assert hit.answer(_ref(source, 20_000_000, m[2])) == \
        clean.answer(_ref(source, 20_000_000, m[2]))


@pytest.mark.parametrize('bad', BAD_VALUES, ids=BAD_IDS)
def test_stage_never_outputs_a_non_finite_voltage(bad):
    """A non-finite output is never passed on: 0 V, and the law starts afresh next tick."""
    stage = _stage(SOURCE_POSITION)
    answerer = LockstepAnswerer(stage)
    assert answerer.answer(_ref(SOURCE_POSITION, 0, 0.0)).finite
    gains = stage.state[0]['pid']
    kc = float(gains['kc'])
    gains['kc'] = bad                      # a law whose output goes bad at one tick
    a = answerer.answer(_ref(SOURCE_POSITION, 10_000_000, 0.0))
    assert (a.voltage_v, a.inner_setpoint, a.finite) == (0.0, 0.0, False)
    assert 'non-finite output' in a.reason or 'control law failed' in a.reason
    assert answerer.active_stage is None   # re-initialised after the bad output
    gains['kc'] = kc
    assert answerer.answer(_ref(SOURCE_POSITION, 20_000_000, 0.0)).finite
    assert answerer.active_stage == 1


@pytest.mark.parametrize('bad', BAD_VALUES, ids=BAD_IDS)
def test_stage_on_a_non_finite_measurement_before_activation_activates_later(bad):
    """A stage whose first tick is bad: 0 V, and it activates on the first good tick."""
    answerer = LockstepAnswerer(_stage(SOURCE_POSITION))
    assert answerer.answer(_ref(SOURCE_POSITION, 0, bad)).voltage_v == 0.0
    assert answerer.active_stage is None
    good = answerer.answer(_ref(SOURCE_POSITION, 10_000_000, 0.0))
    assert good.finite and answerer.active_stage == 1


# ====================================================================== the live graph
rclpy = pytest.importorskip('rclpy')
from gripper_ros.bags.schema import import_message_class  # noqa: E402, I100 (block after skip)
from gripper_ros.nodes.graph import GraphOptions, GripperGraph  # noqa: E402
from gripper_ros.nodes.process import load_bound_s  # noqa: E402
from gripper_ros.nodes.qos import GRAPH_QOS  # noqa: E402
from gripper_ros.nodes.services import wait_until  # noqa: E402
from gripper_ros.wire import (Controller, DEFAULT_NAMESPACE, GRAPH_TOPICS,  # noqa: E402
                              Outcome, Phase, qualified, TICK_LAYOUT, TOPIC_MOTOR_COMMAND,
                              TOPIC_STATUS, TOPIC_TICK)
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402

from helpers import in_phase, step_into_phase, TickHook  # noqa: E402, I100

TOPICS = {qualified(DEFAULT_NAMESPACE, t): ty for t, ty in GRAPH_TOPICS.items()}
TICKS, COMMANDS, STATUS = (qualified(DEFAULT_NAMESPACE, t) for t in
                           (TOPIC_TICK, TOPIC_MOTOR_COMMAND, TOPIC_STATUS))


def _float_fields(msg, prefix=''):
    """(field path, value) for every float in ``msg``, nested messages and arrays included."""
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        path = f'{prefix}{name}'
        if isinstance(value, float):
            yield path, value
        elif hasattr(value, 'get_fields_and_field_types'):
            yield from _float_fields(value, path + '.')
        elif not isinstance(value, (str, bytes)) and hasattr(value, '__len__'):
            for i, item in enumerate(value):
                if isinstance(item, float):
                    yield f'{path}[{i}]', item
                elif hasattr(item, 'get_fields_and_field_types'):
                    yield from _float_fields(item, f'{path}[{i}].')


def _stamp(msg) -> int:
    if hasattr(msg, 'stamp_ns'):
        return msg.stamp_ns
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


class Watcher(Node):
    """Subscribes to every graph topic; keeps every non-finite float and every motor command."""

    def __init__(self, context):
        super().__init__('fault_watcher', context=context)
        self.lock = threading.Lock()
        self.nonfinite = []        # (topic, field, stamp_ns, value)
        self.commands = []         # (wall, stamp_ns, source, voltage_v, hold_s)
        self.motor_voltages = []   # applied voltage, every tick
        self.counts = dict.fromkeys(TOPICS, 0)
        self.readers = [self.create_subscription(import_message_class(msgtype), topic,
                                                 lambda msg, t=topic: self._on(t, msg), GRAPH_QOS)
                        for topic, msgtype in TOPICS.items()]

    def matched(self) -> bool:
        """Tell whether every reader has matched its topic's writer."""
        return all(r.get_publisher_count() >= 1 for r in self.readers)

    def _on(self, topic, msg):
        stamp = _stamp(msg)
        with self.lock:
            self.counts[topic] += 1
            for field, value in _float_fields(msg):
                if not math.isfinite(value):
                    self.nonfinite.append((topic, field, stamp, value))
            if topic == COMMANDS:
                self.commands.append((time.monotonic(), stamp, msg.source, msg.voltage_v,
                                      msg.hold_s))
            elif topic == TICKS:
                self.motor_voltages.append(msg.motor_voltage_v)

    def snapshot(self):
        with self.lock:
            return list(self.nonfinite), list(self.commands), list(self.motor_voltages)

    def seen(self) -> dict:
        """Return how many messages each topic has brought so far."""
        with self.lock:
            return dict(self.counts)


class LiveGraph:
    """A graph of its own (one at a time on this domain) with a watcher."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.graph = GripperGraph(GraphOptions(), context=self.context)
        self.watcher = Watcher(self.context)
        self.graph.add_node(self.watcher)
        assert wait_until(self.watcher.matched, 10.0), 'the watcher matched no graph writer'
        self._mark = (self.published(), self.watcher.seen())

    def published(self) -> Counter:
        """Count the messages the graph published, per topic the watcher reads."""
        g = self.graph
        counts = g.run_in_executor(g.published_counts, 10.0)
        return Counter({qualified(g.namespace, t): n for t, n in counts.items()})

    def mark(self) -> None:
        """Count from here in :meth:`delivered`."""
        self._mark = (self.published(), self.watcher.seen())

    def delivered(self, timeout_s: float = 30.0) -> bool:
        """Wait until the watcher has each message the graph published since :meth:`mark`.

        DDS delivers a writer's messages in order: the counts agree once the last one is in.
        The bound scales with the machine's load (the watcher's thread shares the process).
        """
        published, seen = self._mark

        def caught_up() -> bool:
            now_published, now_seen = self.published(), self.watcher.seen()
            return all(now_seen[t] - seen[t] >= now_published[t] - published[t] for t in TOPICS)
        return wait_until(caught_up, load_bound_s(timeout_s), step_s=0.02)

    def start_grasp(self, width_m=0.10, mass_kg=0.75, timeout_s=0.0, paused=False):
        """Place the object and ask for the grasp (``paused``: simulated time held first)."""
        assert self.graph.set_object(width_m).success
        assert self.graph.wait_still()
        if paused:
            assert self.graph.pause().success
        return self.graph.grasp_async(width_m, mass_kg, timeout_s)

    def close(self, pending=None):
        if pending is not None:
            self.graph.forget(pending)
        self.graph.close()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def live():
    g = LiveGraph()
    yield g
    g.close()


# ---------------------------------------------------------------------- dead nodes
def test_dead_plant_mid_grasp_ends_in_fault_naming_it_and_nothing_commands_after(live):
    g = live.graph
    sup_timeout = g.supervisor.tick_timeout_s
    hook = TickHook(g, in_phase(g, Phase.POSITION), silence=True)   # hung mid-approach
    pending = live.start_grasp()
    try:
        assert hook.fired.wait(30.0)
        plant = g.plant
        g.kill_node(plant)
        killed_at = time.monotonic()
        last_tick_ns = plant.plant.t_ns
        assert wait_until(pending.done, load_bound_s(sup_timeout + 5.0))
        detected_s = time.monotonic() - killed_at
        r = pending.result()
        # the watchdogs of both controllers would fire status_timeout_s after their last status
        quiet_until = killed_at + max(g.position.status_timeout_s,
                                      g.force.status_timeout_s) + 0.5
        time.sleep(max(0.0, quiet_until - time.monotonic()))
        _nonfinite, commands, _ = live.watcher.snapshot()
    finally:
        live.close(pending)
    print(f'\ndead plant detected after {detected_s:.3f} s wall: {r.message}')
    assert r.outcome == Outcome.FAULT and not r.success
    assert 'plant_simulator' in r.message
    # the tick watchdog's (it counts only time in which its executor ran: load_bound_s)
    assert detected_s < load_bound_s(sup_timeout + 2.0), detected_s
    after = [c for c in commands if c[0] > killed_at]
    # at most the answer to the plant's last tick can still be in flight; nothing later
    assert all(c[1] <= last_tick_ns for c in after), after
    assert len(after) <= 1, after
    assert g.position.watchdog_trips == 0 and g.force.watchdog_trips == 0


@pytest.fixture(scope='module')
def stall_run():
    """Stall the whole process mid-grasp for longer than every watchdog's timeout.

    The stall is a 3.5 s callback on the executor thread, queued at the 21st tick of the
    position stage; references and ticks are queued behind it.
    """
    lg = LiveGraph()
    g = lg.graph
    pending = None
    try:
        assert g.position.status_timeout_s < 3.5 and g.supervisor.tick_timeout_s < 3.5
        hook = TickHook(g, in_phase(g, Phase.POSITION),
                        then=lambda: g.executor.create_task(lambda: time.sleep(3.5)))
        pending = lg.start_grasp()
        assert hook.fired.wait(30.0)                   # mid-approach, at a known tick
        assert wait_until(pending.done, 60.0)
        return SimpleNamespace(response=pending.result(),
                               trips=g.position.watchdog_trips + g.force.watchdog_trips)
    finally:
        lg.close(pending)


def test_executor_stall_trips_no_watchdog_and_the_grasp_holds(stall_run):
    """Statuses and ticks queued behind the stall are not silence.

    No controller commands 0 V, and the supervisor's tick watchdog (which also counts only time
    in which the executor ran) does not end the grasp as FAULT.
    """
    print(f'\nafter a 3.5 s executor stall: {Outcome(stall_run.response.outcome).name}: '
          f'{stall_run.response.message}')
    assert stall_run.trips == 0
    assert stall_run.response.outcome == Outcome.HOLDING, stall_run.response.message


STAGE_LEAD_S = {Phase.POSITION: 0.0, Phase.FORCE: 1.5}
"""Simulated seconds stepped at once before the stage is looked for tick by tick: a 0.1 m grasp
from open fingers runs its position stage from 0.01 s to 1.92 s of simulated time."""


@pytest.mark.parametrize('phase', [Phase.POSITION, Phase.FORCE], ids=['position', 'force'])
def test_dead_supervisor_mid_grasp_active_controller_falls_to_zero_volts(live, phase):
    g = live.graph
    controller = g.position if phase is Phase.POSITION else g.force
    source, name = controller.source, controller.get_name()
    timeout_s = controller.status_timeout_s
    pending = live.start_grasp(paused=True)     # stepped into the stage: a known moment
    try:
        assert wait_until(lambda: g.supervisor.logic.pending, 10.0)
        step_into_phase(g, phase, 20, STAGE_LEAD_S[phase])   # the stage's loop is running
        g.kill_node(g.supervisor)
        killed_at = time.monotonic()
        assert wait_until(lambda: controller.watchdog_trips >= 1,
                          load_bound_s(timeout_s + 5.0))
        assert wait_until(lambda: any(c[0] > killed_at and c[3] == 0.0
                                      for c in live.watcher.snapshot()[1]), 2.0)
        time.sleep(0.5)    # a second 0 V command (or anything else) would show up here
        nonfinite, commands, _ = live.watcher.snapshot()
    finally:
        live.close(pending)
    zero = [c for c in commands if c[0] > killed_at and c[3] == 0.0]
    detected_s = zero[0][0] - killed_at
    print(f'\ndead supervisor ({phase.name}): 0 V from {name} after '
          f'{detected_s:.3f} s wall: {controller.watchdog_message}')
    last = commands[-1]
    assert last[2] == source and last[3] == 0.0 and last[4] == controller.sample_time_s
    assert detected_s < load_bound_s(timeout_s + 2.0), detected_s   # the status watchdog's
    assert len(zero) == 1 and controller.watchdog_trips == 1
    other = g.force if controller is g.position else g.position
    assert other.watchdog_trips == 0
    assert 'supervisor' in controller.watchdog_message
    assert not nonfinite


# ---------------------------------------------------------------------- non-finite measurements
class Injection:
    """Stands in for the plant's tick publisher, corrupting one tick.

    The first tick for which ``when()`` holds is published with ``field`` replaced by ``value``
    (the plant's sensor read that), the rest as they are.
    """

    FIELDS = {'position': 'position_m', 'force': 'force_n', 'voltage': 'motor_voltage_v'}

    def __init__(self, graph, field, value, when):
        self.plant, self.field, self.value, self.when = graph.plant, field, value, when
        self.stamp_ns = None
        self._real = self.plant._tick_pub
        self.plant._tick_pub = self

    def publish(self, data):
        if self.stamp_ns is None and self.when():
            values = dict(zip(TICK_LAYOUT.fields, TICK_LAYOUT.unpack(data)))
            values[self.FIELDS[self.field]] = self.value
            self.stamp_ns = values['stamp_ns']
            data = TICK_LAYOUT.pack(*values.values())
        self._real.publish(data)

    def remove(self):
        self.plant._tick_pub = self._real


CASES = [(field, phase, value) for field, phase in [('position', Phase.POSITION),
                                                    ('force', Phase.POSITION),
                                                    ('force', Phase.FORCE)]
         for value in BAD_VALUES]
CASE_IDS = [f'{f}-{p.name.lower()}-{v}' for f, p, v in CASES]


@pytest.fixture(scope='module')
def injected_runs():
    """One graph, one grasp per case, each corrupted at one tick mid-grasp."""
    lg = LiveGraph()
    runs = []
    g = lg.graph
    try:
        for field, phase, value in CASES:
            inj = Injection(g, field, value, in_phase(g, phase))
            lg.mark()
            before = lg.watcher.snapshot()
            r = g.grasp(0.10, 0.75, wall_timeout_s=60.0) if g.set_object(0.10).success \
                else None
            inj.remove()
            ticks_at_end = g.plant.ticks_published
            commands_at_end = g.position.commands_published + g.force.commands_published
            still = g.wait_still()
            assert lg.delivered(), 'the watcher missed messages of the graph'
            after = lg.watcher.snapshot()
            runs.append(SimpleNamespace(
                field=field, phase=phase, value=value, response=r, stamp_ns=inj.stamp_ns,
                nonfinite=after[0][len(before[0]):], commands=after[1][len(before[1]):],
                motor_voltages=after[2][len(before[2]):],
                quiet=(still and g.plant.ticks_published == ticks_at_end and
                       g.position.commands_published + g.force.commands_published
                       == commands_at_end)))
        # the graph still grasps after all that
        runs.append(g.grasp(0.10, 0.75, wall_timeout_s=60.0)
                    if g.set_object(0.10).success else None)
    finally:
        lg.close()
    return runs


@pytest.mark.parametrize('index', range(len(CASES)), ids=CASE_IDS)
def test_non_finite_measurement_ends_the_grasp_in_fault_and_no_voltage_goes_bad(
        injected_runs, index):
    run = injected_runs[index]
    r = run.response
    assert run.stamp_ns is not None, 'the injection point was never reached'
    assert r.outcome == Outcome.FAULT and not r.success, r.message
    assert repr(run.value) in r.message, r.message
    assert f't={run.stamp_ns * 1e-9:.4f}' in r.message, r.message
    # nothing of the corrupted tick or later was commanded; the motor never saw a bad number
    assert run.commands and all(c[1] < run.stamp_ns for c in run.commands)
    assert all(math.isfinite(c[3]) and math.isfinite(c[4]) for c in run.commands)
    assert run.motor_voltages and all(math.isfinite(v) for v in run.motor_voltages)
    assert run.quiet            # after FAULT nothing drives, and fast time stands still
    # the corrupted tick is the only message with a non-finite number (the FAULT names no
    # stage, so no reference relays it)
    assert [(n[0], n[2]) for n in run.nonfinite] == [(TICKS, run.stamp_ns)], run.nonfinite


def test_no_status_or_answer_carries_a_non_finite_number(injected_runs):
    bad = []
    for run in injected_runs[:len(CASES)]:
        bad += [n for n in run.nonfinite if n[0] == STATUS]
        r = run.response
        bad += [(f, getattr(r, f)) for f in ('final_position_m', 'final_width_m',
                                             'final_force_n')
                if not math.isfinite(getattr(r, f))]
    assert not bad, bad[:6]


def test_graph_grasps_normally_after_the_injected_faults(injected_runs):
    r = injected_runs[-1]
    assert r is not None and r.outcome == Outcome.HOLDING, r and r.message


# ---------------------------------------------------------------------- a bad reading at rest
IDLE_CASES = [(field, value) for field in ('position', 'force') for value in BAD_VALUES]
IDLE_IDS = [f'{f}-{v}' for f, v in IDLE_CASES]


@pytest.fixture(scope='module')
def idle_runs():
    """Make the tick the graph rests on after set_object read a non-finite number.

    A grasp and a release are then requested on it.
    """
    lg = LiveGraph()
    g = lg.graph
    runs = []
    try:
        for field, value in IDLE_CASES:
            inj = Injection(g, field, value, lambda: True)
            lg.mark()
            before = lg.watcher.snapshot()
            held = g.position.nonfinite_answers
            assert g.set_object(0.10).success
            assert wait_until(lambda: g.position.nonfinite_answers > held or
                              field != 'position', 5.0)
            inj.remove()
            g.wait_still()
            ticks = g.plant.ticks_published
            r = g.grasp(0.10, 0.75, timeout_s=0.3, wall_timeout_s=60.0)
            moved = g.plant.ticks_published - ticks
            released = g.release(60)                     # on the same bad reading
            assert g.wait_still() and lg.delivered(), 'the graph did not come to rest'
            after = lg.watcher.snapshot()
            runs.append(SimpleNamespace(
                field=field, value=value, t0=inj.stamp_ns, response=r, released=released,
                nonfinite=after[0][len(before[0]):], commands=after[1][len(before[1]):],
                motor_voltages=after[2][len(before[2]):],
                nonfinite_answers=g.position.nonfinite_answers - held, ticks=moved))
    finally:
        lg.close()
    return runs


@pytest.mark.parametrize('index', range(len(IDLE_CASES)), ids=IDLE_IDS)
def test_bad_reading_at_rest_never_reaches_the_motor(idle_runs, index):
    """The position stage holding the fingers answers a bad position with 0 V.

    Only the tick and the reference that relays it carry the bad number, never a status or a
    command.
    """
    run = idle_runs[index]
    assert all(math.isfinite(c[3]) and math.isfinite(c[4]) for c in run.commands)
    assert all(math.isfinite(v) for v in run.motor_voltages)
    at_t0 = [c for c in run.commands if c[1] == run.t0]
    assert at_t0, run.commands                       # the tick of the bad reading is answered
    if run.field == 'position':                      # the position stage acts on it: 0 V
        assert all(c[3] == 0.0 for c in at_t0), at_t0
    assert run.nonfinite_answers == (1 if run.field == 'position' else 0)
    carriers = {n[0].rsplit('/', 1)[1] for n in run.nonfinite if n[2] == run.t0}
    assert carriers <= {'tick', 'position_reference'}, run.nonfinite
    assert all(n[2] == run.t0 for n in run.nonfinite), run.nonfinite


@pytest.mark.parametrize('index', range(len(IDLE_CASES)), ids=IDLE_IDS)
def test_grasp_on_a_bad_reading_at_rest_is_refused_and_nothing_moves(idle_runs, index):
    run = idle_runs[index]
    r = run.response
    assert r.outcome == Outcome.REFUSED and not r.success, r.message
    assert repr(run.value) in r.message, r.message
    assert ('finger position' if run.field == 'position' else 'force sensor') in r.message
    assert run.ticks == 0
    if run.field == 'position':                # nor does a release open on a bad position
        assert not run.released.success and 'finger position' in run.released.message, \
            run.released.message
    else:                                      # the release needs no force sensor
        assert run.released.success, run.released.message
    assert all(math.isfinite(getattr(r, f)) for f in ('final_position_m', 'final_width_m',
                                                      'final_force_n'))


# ---------------------------------------------------------------------- a bad applied voltage
@pytest.fixture(scope='module')
def motor_runs():
    """Make the applied voltage the plant reports read non-finite for one position-stage tick.

    That voltage is the stage's bumpless seed; the reference carries the last finite one.
    """
    lg = LiveGraph()
    g = lg.graph
    runs = []
    try:
        for value in BAD_VALUES:
            inj = Injection(g, 'voltage', value, in_phase(g, Phase.POSITION))
            lg.mark()
            before = lg.watcher.snapshot()
            held = g.position.nonfinite_answers
            assert g.set_object(0.10).success
            r = g.grasp(0.10, 0.75, timeout_s=0.5, wall_timeout_s=60.0)
            inj.remove()
            assert g.wait_still() and lg.delivered(), 'the graph did not come to rest'
            after = lg.watcher.snapshot()
            runs.append(SimpleNamespace(
                value=value, response=r, stamp_ns=inj.stamp_ns,
                nonfinite=after[0][len(before[0]):], commands=after[1][len(before[1]):],
                held=g.position.nonfinite_answers - held))
    finally:
        lg.close()
    return runs


@pytest.mark.parametrize('index', range(len(BAD_VALUES)), ids=BAD_IDS)
def test_non_finite_applied_voltage_is_not_relayed(motor_runs, index):
    """The reference carries the last finite applied voltage as its seed.

    The position controller answers that tick as usual (no 0 V hold) and every command stays
    finite.
    """
    run = motor_runs[index]
    assert run.stamp_ns is not None, 'the injection point was never reached'
    at_tick = [c for c in run.commands if c[1] == run.stamp_ns]
    assert len(at_tick) == 1 and at_tick[0][2] == Controller.POSITION
    assert run.held == 0
    assert all(math.isfinite(c[3]) and math.isfinite(c[4]) for c in run.commands)
    assert any(c[1] > run.stamp_ns for c in run.commands)       # the loop went on
    assert [(n[0], n[2]) for n in run.nonfinite] == [(TICKS, run.stamp_ns)], run.nonfinite
