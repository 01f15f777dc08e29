"""The supervisor's state machine is the table docs/ARCHITECTURE.md shows, and runs by it.

``machine.TRANSITIONS`` is what the compiled machine reads; the page shows the same rows. Real
runs (a Table V grasp held and then lost under a lift, moves that reach their goal and stall on
an object, a release) change state only along a row of that table, reporting the row's phase and
outcome; every state the table names is reached from the first one.
"""
from __future__ import annotations

from pathlib import Path
import re

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.stages import ForceStageController, PositionStageController
from gripper_ros.core.physics.hold import Lift
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.core.runtime.lockstep import PlantSide, StageSide, SupervisorSide
from gripper_ros.core.supervision import machine
from gripper_ros.core.supervision.machine import Event, KEEP, State, TABLE, TRANSITIONS
from gripper_ros.core.supervision.requests import (GraspRequest, MoveRequest, validate_move,
                                                   validate_request)
from gripper_ros.core.supervision.supervisor import GraspSupervisor, load_law
from gripper_ros.wire import Controller, Outcome, Phase

CONFIG = load_config()
ARCHITECTURE = Path(__file__).resolve().parents[1] / 'docs' / 'ARCHITECTURE.md'


def test_architecture_md_shows_the_table_the_machine_reads():
    text = ARCHITECTURE.read_text()
    shown = re.search(r'<!-- transitions: machine.transitions_table\(\) -->\n(.*?)\n'
                      r'<!-- end of transitions -->', text, re.S)
    assert shown is not None, 'docs/ARCHITECTURE.md has no transitions table'
    assert shown.group(1) == machine.transitions_table()


def test_every_event_that_sets_an_outcome_has_its_message_template():
    """An outcome is its code, the row that reaches it and its template: none is left out.

    Each event whose row reports an outcome has a template in ``messages.MESSAGES``, and every
    template is such an event's (a template no row reaches is a dead one).
    """
    from gripper_ros.core.supervision.messages import MESSAGES
    answering = {row[1].name for row in TRANSITIONS if row[4] not in (KEEP, Outcome.UNKNOWN)}
    assert answering == set(MESSAGES)


def test_every_state_is_reached_from_the_first_and_every_answer_leaves_a_request_done():
    reached, frontier = {State.UNDRIVEN}, [State.UNDRIVEN]
    while frontier:
        state = frontier.pop()
        for event in Event:
            after = TABLE[state, event, machine.T_NEXT]
            if after != KEEP and State(after) not in reached:
                reached.add(State(after))
                frontier.append(State(after))
    assert reached == set(State)
    running = {State.APPROACH, State.SQUEEZE, State.SETTLED, State.RELEASE, State.MOVE}
    for _, event, after, _, outcome, _ in TRANSITIONS:
        if outcome not in (KEEP, Outcome.UNKNOWN):
            assert after not in running, event.name


def _rows_between(before: State, after: State) -> list[tuple]:
    """Return the (phase, outcome) each row from ``before`` to ``after`` reports."""
    return [(row[machine.T_PHASE], row[machine.T_OUTCOME]) for row in TABLE[before]
            if row[machine.T_NEXT] == after]


def _assert_along_the_table(trail: list[tuple]) -> list[State]:
    """Check each change of state in ``trail`` ((state, phase, outcome) a tick) is a row."""
    states = [trail[0][0]]
    for (a, phase_a, outcome_a), (b, phase, outcome) in zip(trail, trail[1:]):
        if a == b:
            continue
        rows = _rows_between(a, b)
        assert rows, f'{a.name} -> {b.name} is no transition of the table'
        assert any(p in (KEEP, phase) and o in (KEEP, outcome) and (p != KEEP or phase == phase_a)
                   and (o != KEEP or outcome == outcome_a) for p, o in rows), \
            (a.name, b.name, phase.name, outcome.name, rows)
        states.append(b)
    return states


def test_a_grasp_held_and_then_lost_under_a_lift_runs_along_the_table():
    trail = []

    def trace(plant, tick, decision, ref, cmd):
        trail.append((decision.state, decision.phase, decision.outcome))

    result = simulate_grasp(CONFIG, 0.05, 1.0, object_mass_kg=1.0, lift=Lift(20.0, 0.05, 0.3),
                            hold_s=0.5, trace=trace)
    assert (result.answer, result.outcome) == (Outcome.HOLDING, Outcome.OBJECT_LOST)
    states = _assert_along_the_table(trail)
    assert states == [State.IDLE, State.APPROACH, State.SQUEEZE, State.SETTLED, State.HOLD,
                      State.IDLE]


def _run_requests(requests, object_width_m: float) -> list[tuple]:
    """Run requests one after another as the graph in fast mode does; each tick's state."""
    plant = make_plant(CONFIG)
    side = PlantSide(plant)
    side.set_object(GraspObject(object_width_m, 0.0, 0.0))
    supervisor = GraspSupervisor(CONFIG.plant, CONFIG.supervisor, load_law(CONFIG))
    decide = SupervisorSide(supervisor).decide
    stages = {Controller.POSITION: StageSide(PositionStageController(CONFIG)),
              Controller.FORCE: StageSide(ForceStageController(CONFIG))}
    tick = side.tick()
    _, ref = decide(tick)
    trail = []
    while True:
        trail.append((supervisor.state, supervisor.phase, supervisor.outcome))
        cmd = stages[Controller(ref.controller)].answer(ref)
        side.accept(cmd)
        if not side.needs_time(cmd):
            if not requests:
                return trail
            requests.pop(0)(supervisor, tick.stamp_ns)
        tick = side.step(cmd)
        _, ref = decide(tick)


def test_moves_a_grasp_and_a_release_run_along_the_table():
    plant, sup = CONFIG.plant, CONFIG.supervisor
    grasp = validate_request(GraspRequest(0.05, 1.0), plant, sup, CONFIG.load_grip)
    trail = _run_requests([
        lambda s, t: s.request_move(validate_move(MoveRequest(0.12, 0.05), plant, sup), t),
        lambda s, t: s.request_move(validate_move(MoveRequest(0.02, 0.05, 5.0), plant, sup),
                                    t),
        lambda s, t: s.stop(),
        lambda s, t: s.request_release(after_ns=t),
        lambda s, t: s.request_grasp(grasp, 1.0, t),
        lambda s, t: s.request_release(after_ns=t)], 0.05)
    states = _assert_along_the_table(trail)
    assert states == [State.IDLE, State.MOVE, State.IDLE, State.MOVE, State.PRESSING,
                      State.IDLE, State.RELEASE, State.IDLE, State.APPROACH, State.SQUEEZE,
                      State.SETTLED, State.HOLD, State.RELEASE, State.IDLE]
    assert trail[-1][1:] == (Phase.DONE, Outcome.RELEASED)
