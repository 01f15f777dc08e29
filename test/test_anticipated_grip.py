"""A grip that anticipates the arm's own motion, and OVERLOADED only where 24 V cannot hold.

Known answers, from the physics: two pads hold m (g + a) by static friction while it is at most
their capacity 2 mu_s F_24V. Announced (``arm/planned_acceleration``), the load-tracking grip
holds every motion of the envelope within that capacity with at most 0.5 mm of slip and a mean
margin of at most 1.5 over the slip limit, an instant step without any slip; unannounced, it
loses none of the envelope and says OVERLOADED only where the capacity is short. The plan's
scaling is checked against the ratio (g + a_ahead) / (g + a_now) it must give, its lead against
the plant's own rise at 24 V, and the graph, told over the topic, runs the headless announced
grasp tick for tick.
"""
import math

from gripper_ros.apps.common import with_values
from gripper_ros.apps.grip_study import DEFAULT_LIFT_OFF_S, holdable, KINETIC_SHARE
from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.load_grip import (ANNOUNCED_MARGIN, make_law, plan_announce,
                                                PLAN_DTYPE, plan_load_ratio, PLAN_ROWS,
                                                rise_time_s)
from gripper_ros.core.physics.hold import Lift
from gripper_ros.core.physics.plant import GraspObject
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
DT_S = BASE.force.sample_time_s
TAU_E_S = BASE.plant.inductance_h / BASE.plant.resistance_ohm
M_R = BASE.plant.reflected_mass_kg
BAND = BASE.supervisor.force_settle_band_fraction


def _lift(profile: str, accel: float, hz: float = 0.0, lift_off_s: float = 0.0) -> Lift:
    kinds = {'step': LiftProfile.STEP, 'pick-and-place': LiftProfile.PICK_AND_PLACE,
             'shake': LiftProfile.SHAKE}
    return Lift(accel, 0.2, 1.2, kinds[profile], hz, lift_off_s)


def _rigid_law():
    """Return the shipped law without the shear channel's lag: the pads read the load as is."""
    rec, _, _ = make_law(BASE.load_grip, MAX_N, 0.0, DT_S, 0.0, 0.0, gravity_mps2=G,
                         electrical_time_s=TAU_E_S, reflected_mass_kg=M_R,
                         settle_band=BAND)
    return rec


def test_an_announced_rise_is_asked_for_as_early_as_24_v_needs_to_raise_the_grip():
    """2 kg at mu 0.6, 15 N of grip, a 5 m/s^2 step: the grip asked that long before it.

    The grip it needs, 1.15 m (g + a) / (2 mu), rises on a rigid contact as the motor's current,
    L / R, towards the 24 V stall force; the plan asks for it that long before the step, and
    two samples more.
    """
    rec = _rigid_law()
    plan = np.zeros(PLAN_ROWS, PLAN_DTYPE)
    step_ns = 1_000_000_000
    plan_announce(rec, plan, step_ns, 5.0)
    plan_announce(rec, plan, step_ns + 500_000_000, 0.0)
    g = rec[0]
    load_n, force_n, mu = 2.0 * G, 15.0, 0.6
    need_n = ANNOUNCED_MARGIN * 2.0 * (G + 5.0) / (2 * mu)
    lead_s = TAU_E_S * math.log((MAX_N - force_n) / (MAX_N - (1 - BAND) * need_n)) + 2 * DT_S
    lead_ns = round(lead_s * 1e9)
    assert 0.0 < lead_s < 1e-3                          # well under the 10 ms it used to be

    def ratio(t_ns):
        return plan_load_ratio(g, plan, t_ns, load_n, force_n, ANNOUNCED_MARGIN, mu)

    assert ratio(step_ns - lead_ns - 1) == 1.0          # nothing to raise yet
    assert ratio(step_ns - lead_ns) == pytest.approx((G + 5.0) / G)
    assert g['lead_s'] == pytest.approx(lead_s, abs=1e-9)
    # with no sensor lag the pads read the step as it comes: the ratio is 1 again
    assert ratio(step_ns) == 1.0
    # on a spring the finger must travel the rise: 2 sqrt(rise m_r / (k F_24V)) at the least
    g['stiffness_n_per_m'] = 1e5
    travel_s = 2 * math.sqrt(((1 - BAND) * need_n - force_n) * M_R / (1e5 * MAX_N))
    assert rise_time_s(g, force_n, need_n) == pytest.approx(travel_s, rel=1e-12)
    # a breakpoint at or before a later one replaces the plan from there
    plan_announce(rec, plan, step_ns + 100_000_000, -3.0)
    assert rec[0]['plan_count'] == 2
    assert list(plan[:2]['accel_mps2']) == [5.0, -3.0]


@pytest.mark.parametrize('f0, f1', [(0.7, MAX_N), (15.0, 30.0), (4.0, 6.5)])
def test_the_rise_bound_is_the_plants_own_rise_on_a_rigid_object(f0, f1):
    """The stalled motor's force follows its current, the bound the plant's own answer.

    24 V from a held F0 reaches within the band of F1 in tau_e ln((F_24V - F0) / (F_24V -
    0.98 F1)).
    """
    plant = make_plant(BASE)
    plant.set_object(GraspObject(WIDTH_M, 0.0, 0.0))
    plant.touch_object()
    plant.step(f0 / BASE.plant.stall_force_per_volt_n, 0.05)      # held at F0
    assert plant.sample().force_n == pytest.approx(f0, rel=1e-6)
    dt, t = 1e-7, 0.0
    goal = (1 - BAND) * min(f1, MAX_N)
    while plant.step(BASE.plant.voltage_limit_v, dt).force_n < goal:
        t += dt
    assert t == pytest.approx(rise_time_s(_rigid_law()[0], f0, f1), abs=2 * dt)


def test_the_unannounced_step_of_2_kg_is_held_and_not_called_overloaded():
    """2 kg, mu_s 0.6 / mu_k 0.48, a 5 m/s^2 step at once: 24 V holds 40 N > 29.6 N."""
    lift = _lift('step', 5.0)                      # the shipped instant lift-off
    assert holdable(BASE, 2.0, 0.6, 5.0)
    assert 2 * 0.6 * MAX_N > 2.0 * (G + 5.0)
    run = simulate_load_grip(BASE, WIDTH_M, 2.0, 0.6, 0.48, lift, 'load_tracking')
    assert run.outcome == 'HOLDING' and math.isnan(run.lost_s), run.note
    assert math.isnan(run.overload_s), run.note


INSTANT = [(2.0, 0.6, 5.0), (2.0, 0.4, 3.0), (0.5, 0.9, 3.0), (1.0, 0.9, 6.0),
           (0.5, 0.4, 6.0)]


@pytest.mark.parametrize('mass, mu, accel', INSTANT)
def test_an_announced_instant_step_is_gripped_for_before_it_comes(mass, mu, accel):
    """The whole weight lands at once (the shipped instant lift-off), and nothing slides.

    The pads carry nothing before, so nothing tells the weight: any 24 V holds may come, and
    the grip is at the most when it lands, asked for as early as 24 V needs to raise it there;
    then it comes down to its margin over what the pads read.
    """
    assert holdable(BASE, mass, mu, accel)
    run = simulate_load_grip(BASE, WIDTH_M, mass, mu, KINETIC_SHARE * mu, _lift('step', accel),
                             'load_tracking', announce=True, decimate=1)
    assert run.outcome == 'HOLDING', run.note
    assert run.slip_m == 0.0
    assert 1.0 < run.mean_margin <= MARGIN_AIM
    rows = run.rows
    landed = rows[np.flatnonzero(rows[:, 3] > 0.0)[0]]  # the first tick the pads carry it
    assert landed[1] >= (1 - BAND) * MAX_N             # force: the most, already there
    assert landed[1] >= landed[3] / (2 * mu)           # ... beyond the slip limit


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
