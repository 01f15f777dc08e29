"""A grip that anticipates the arm's own motion, and OVERLOADED only where 24 V cannot hold.

Known answers, from the physics: two pads hold m (g + a) by static friction while it is at most
their capacity 2 mu_s F_24V. Announced (``arm/planned_acceleration``), the load-tracking grip
holds every motion of the envelope within that capacity with at most 0.5 mm of slip and a mean
margin of at most 1.5 over the slip limit; unannounced, it loses none of them and says
OVERLOADED only where the capacity is short. The plan's scaling is checked against the ratio
(g + a_ahead) / (g + a_now) it must give, and the graph, told over the topic, runs the headless
announced grasp tick for tick.
"""
import math

from gripper_ros.apps.common import with_values
from gripper_ros.apps.grip_study import DEFAULT_LIFT_OFF_S, holdable, KINETIC_SHARE
from gripper_ros.core.config import load_config
from gripper_ros.core.control.load_grip import (ANTICIPATION_S, make_law, plan_announce,
                                                PLAN_DTYPE, plan_load_ratio, PLAN_ROWS)
from gripper_ros.core.physics.hold import Lift
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.studies.grip_runs import simulate_load_grip
from gripper_ros.wire import LiftProfile, Outcome
import numpy as np
import pytest

BASE = load_config()
CONFIG = with_values(BASE, {'contact.lift_off_s': DEFAULT_LIFT_OFF_S})   # the study's arm
G = BASE.plant.gravity_mps2
MAX_N = BASE.plant.max_force_n
WIDTH_M = 0.05
SLIP_AIM_M = 0.5e-3
MARGIN_AIM = 1.5


def _lift(profile: str, accel: float, hz: float = 0.0, lift_off_s: float = 0.0) -> Lift:
    kinds = {'step': LiftProfile.STEP, 'pick-and-place': LiftProfile.PICK_AND_PLACE,
             'shake': LiftProfile.SHAKE}
    return Lift(accel, 0.2, 1.2, kinds[profile], hz, lift_off_s)


def test_the_plan_raises_the_load_ahead_by_the_ratio_of_the_accelerations():
    rec, _, _ = make_law(BASE.load_grip, MAX_N, 0.0, 1e-4, 0.0, 0.0, gravity_mps2=G)
    plan = np.zeros(PLAN_ROWS, PLAN_DTYPE)
    step_ns = 1_000_000_000
    plan_announce(rec, plan, step_ns, 5.0)
    plan_announce(rec, plan, step_ns + 500_000_000, 0.0)
    g = rec[0]
    lead_ns = round(ANTICIPATION_S * 1e9)
    assert plan_load_ratio(g, plan, step_ns - lead_ns - 1) == 1.0        # nothing comes yet
    assert plan_load_ratio(g, plan, step_ns - lead_ns) == pytest.approx((G + 5.0) / G)
    # with no sensor lag the pads read the step as it comes: the ratio is 1 again
    assert plan_load_ratio(g, plan, step_ns) == 1.0
    # a breakpoint at or before a later one replaces the plan from there
    plan_announce(rec, plan, step_ns + 100_000_000, -3.0)
    assert rec[0]['plan_count'] == 2
    assert list(plan[:2]['accel_mps2']) == [5.0, -3.0]


def test_the_unannounced_step_of_2_kg_is_held_and_not_called_overloaded():
    """2 kg, mu_s 0.6 / mu_k 0.48, a 5 m/s^2 step at once: 24 V holds 40 N > 29.6 N."""
    lift = _lift('step', 5.0)                      # the shipped instant lift-off
    assert holdable(BASE, 2.0, 0.6, 5.0)
    assert 2 * 0.6 * MAX_N > 2.0 * (G + 5.0)
    run = simulate_load_grip(BASE, WIDTH_M, 2.0, 0.6, 0.48, lift, 'load_tracking')
    assert run.outcome == 'HOLDING' and math.isnan(run.lost_s), run.note
    assert math.isnan(run.overload_s), run.note


@pytest.mark.parametrize('announce', [True, False])
def test_overloaded_is_said_before_the_fall_where_24_v_cannot_hold(announce):
    """2 kg at mu_s 0.4 through a 5 m/s^2 step: 26.7 N of capacity against 29.6 N."""
    assert not holdable(CONFIG, 2.0, 0.4, 5.0)
    run = simulate_load_grip(CONFIG, WIDTH_M, 2.0, 0.4, KINETIC_SHARE * 0.4,
                             _lift('step', 5.0), 'load_tracking', announce=announce)
    assert math.isfinite(run.overload_s), run.outcome
    assert run.outcome == 'HOLDING' or run.overload_s < run.lost_s


ENVELOPE = [(2.0, 0.6, 'pick-and-place', 6.0, 0.0), (2.0, 0.9, 'step', 5.0, 0.0),
            (1.0, 0.4, 'shake', 3.0, 2.0), (1.0, 0.9, 'pick-and-place', 6.0, 0.0),
            (0.2, 0.4, 'pick-and-place', 3.0, 0.0)]


@pytest.mark.parametrize('mass, mu, profile, accel, hz', ENVELOPE)
def test_announced_motions_within_24_v_are_held_closely(mass, mu, profile, accel, hz):
    assert holdable(CONFIG, mass, mu, accel)
    announced = simulate_load_grip(CONFIG, WIDTH_M, mass, mu, KINETIC_SHARE * mu,
                                   _lift(profile, accel, hz), 'load_tracking', announce=True)
    assert announced.outcome == 'HOLDING', announced.note
    assert announced.slip_m <= SLIP_AIM_M
    assert 1.0 < announced.mean_margin <= MARGIN_AIM
    assert math.isnan(announced.overload_s)
    unannounced = simulate_load_grip(CONFIG, WIDTH_M, mass, mu, KINETIC_SHARE * mu,
                                     _lift(profile, accel, hz), 'load_tracking')
    assert unannounced.outcome == 'HOLDING' and math.isnan(unannounced.overload_s)


def test_the_graph_told_over_the_topic_grips_as_the_headless_announced_grasp():
    lift = _lift('pick-and-place', 6.0, lift_off_s=DEFAULT_LIFT_OFF_S)
    obj = {'object_mass_kg': 2.0, 'static_friction': 0.6, 'kinetic_friction': 0.48}
    with GripperGraph.in_own_context() as graph:
        placed = graph.set_object(
            WIDTH_M, mass_kg=2.0, static_friction=0.6, kinetic_friction=0.48,
            lift_acceleration_mps2=lift.acceleration_mps2, lift_delay_s=lift.delay_s,
            lift_duration_s=lift.duration_s, lift_profile=int(lift.profile),
            lift_off_s=lift.lift_off_s, announce_lift=True)
        assert placed.success, placed.message
        r = graph.grasp(WIDTH_M, 0.0)
        assert r.outcome == Outcome.HOLDING, r.message
        assert graph.wait_still(timeout_s=120.0)
        start_ns = graph.supervisor.logic.start_ns
        plan = graph.supervisor.logic.plan
        state = graph.plant.plant.object_state
        breakpoints = graph.supervisor.plan_breakpoints
        overload_ns = graph.supervisor.logic.overload_ns
    # the pick-and-place's seven breakpoints and its end, stamped from the lift's start
    assert breakpoints == 8 and plan.size == 8
    assert list(plan['accel_mps2']) == [6.0, 0.0, -6.0, 0.0, -6.0, 0.0, 6.0, 0.0]
    assert state.lost_ns is None and state.slip_m <= SLIP_AIM_M and overload_ns is None
    h = simulate_grasp(BASE, WIDTH_M, 0.0, lift=lift, start_ns=start_ns - round(
        BASE.position.sample_time_s * 1e9), announce=True, **obj)
    assert h.start_ns == start_ns
    assert h.slip_m == state.slip_m                # the same ticks: the plan came in time
