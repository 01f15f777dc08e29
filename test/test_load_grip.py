"""The load-tracking grip: mu from the incipient slip, slip answered at once, overload said first.

Known answers: fed a stuck pad's Cattaneo-Mindlin displacement while its grip sweeps, the law
finds the pad's mu to the grid's step and sets ``F_sp = k F_load / (2 mu_safety mu)``; a
displacement that runs faster than the slip speed with the pads carrying near mu F raises the
setpoint at once; an object of unknown mass is grasped headless and held through a
pick-and-place with the same bits on every run; an object heavier than 24 V can hold is
declared overloaded before it leaves the pads.
"""
import math

from gripper_ros.apps.common import with_values
from gripper_ros.apps.grip_study import DEFAULT_LIFT_OFF_S
from gripper_ros.core.config import load_config
from gripper_ros.core.control.load_grip import (law_step, make_law, MU_GRID, plan_announce,
                                                PLAN_DTYPE)
from gripper_ros.core.physics.hold import HoldModel, HoldState, Lift, presliding_m
from gripper_ros.studies.grip_runs import simulate_load_grip
from gripper_ros.wire import LiftProfile
import numpy as np
import pytest

BASE = load_config()                                  # the shipped instant lift-off
# the study's arm: the weight passes from the support to the pads over 0.1 s
CONFIG = with_values(BASE, {'contact.lift_off_s': DEFAULT_LIFT_OFF_S})
P = CONFIG.load_grip
K_T = CONFIG.contact.pad_tangential_stiffness_n_per_m
MAX_N = CONFIG.plant.max_force_n
DT_S = CONFIG.force.sample_time_s


NO_PLAN = np.zeros(1, PLAN_DTYPE)                     # the arm announces nothing
NO_POSITION = math.nan                                # the finger's position unread


def law():
    return make_law(P, MAX_N, K_T, DT_S, 0.0, 0.0)


@pytest.mark.parametrize('mu', [0.4, 0.6, 0.9])
def test_mu_is_read_from_the_incipient_slip_and_sets_the_grip(mu):
    g, history, sums = law()
    q = 5.0                                            # each pad's shear: a 10 N load
    for i in range(600):                               # the grip sweeps 30 N -> 14 N
        f = 30.0 - 16.0 * i / 600
        law_step(g[0], history, sums, MU_GRID, i, q, presliding_m(q, f, mu, K_T), f, NO_PLAN,
                 NO_POSITION)
    assert g[0]['estimated'] == 1
    assert g[0]['mu_est'] == pytest.approx(P.mu_safety * mu, abs=0.011)
    # held still from then on, the setpoint comes down to k F_load / (2 mu_est), no faster
    # than the release rate, and stays there
    f = 14.0
    for i in range(600, 3000):
        sp = law_step(g[0], history, sums, MU_GRID, i, q, presliding_m(q, f, mu, K_T), f,
                      NO_PLAN, NO_POSITION)
    assert sp == pytest.approx(max(P.touch_force_n,
                                   P.grip_margin * 2 * q / (2 * g[0]['mu_est'])), rel=1e-12)


def test_a_slip_raises_the_grip_at_once():
    g, history, sums = law()
    f, q = 10.0, 4.0                                   # carrying 0.4 F per pad
    d = presliding_m(q, f, 0.5, K_T)
    for i in range(100):
        before = law_step(g[0], history, sums, MU_GRID, i, q, d, f, NO_PLAN, NO_POSITION)
    window = int(g[0]['window'])
    speed = 4 * P.slip_speed_mps
    for i in range(100, 100 + window + 1):             # the object runs down the pads
        d += speed * DT_S
        sp = law_step(g[0], history, sums, MU_GRID, i, q, d, f, NO_PLAN, NO_POSITION)
    assert g[0]['slipping'] == 1 and g[0]['slips'] == 1
    # mu_est is what the pads carry as it slides (kinetic: a lower bound of mu_s, which
    # betters the conservative start when nothing was measured before)
    assert g[0]['mu_est'] == q / f
    assert sp >= P.grip_margin * f > before            # k times the force, within the window


@pytest.mark.parametrize('announced', [True, False])
def test_after_a_slip_the_grip_holds_over_the_static_friction_the_pads_carried(announced):
    """A grip too light for the fit holds, after a slip, over what the pads carried stuck.

    Stuck, the pads carry up to Q / F = 0.58 (so mu_s >= 0.58); then a slip reads kinetic
    friction, 0.48. Told the arm's motion the law holds, once the object sticks again, at its
    margin over the static bound, mu_safety x 0.58; without, over the kinetic reading (its
    extra is reserve for a load nobody announced).
    """
    g, history, sums = law()
    plan = np.zeros(4, PLAN_DTYPE)
    if announced:
        plan_announce(g, plan, 0, 0.0)                # the arm holds still: planned, no change
    f, mu_s, i = 2.0, 0.6, 0
    for q in np.linspace(0.5, 0.58 * f, 300):          # the load grows, the pads stuck
        law_step(g[0], history, sums, MU_GRID, i, q, presliding_m(q, f, mu_s, K_T), f, plan,
                 NO_POSITION)
        i += 1
    d = presliding_m(0.58 * f, f, mu_s, K_T)
    for _ in range(int(g[0]['window']) + 1):            # it slides: kinetic friction 0.48 F
        d += 4 * P.slip_speed_mps * DT_S
        law_step(g[0], history, sums, MU_GRID, i, 0.48 * f, d, f, plan, NO_POSITION)
        i += 1
    assert g[0]['slipping'] == 1 and g[0]['mu_est'] == pytest.approx(0.48)
    for _ in range(int(g[0]['window'] + g[0]['rest']) + 1):   # stuck again
        law_step(g[0], history, sums, MU_GRID, i, 0.48 * f, d, f, plan, NO_POSITION)
        i += 1
    assert g[0]['slipping'] == 0
    expected = P.mu_safety * 0.58 if announced else 0.48
    assert g[0]['mu_est'] == pytest.approx(expected, rel=1e-12)
    assert g[0]['mu_est'] < mu_s                        # never above what holds


def pick_and_place():
    return Lift(3.0, 0.2, 1.2, LiftProfile.PICK_AND_PLACE)


def test_unknown_mass_held_through_a_pick_and_place_bit_identically():
    runs = [simulate_load_grip(CONFIG, 0.05, 0.6, 0.3, 0.24, pick_and_place(),
                               'load_tracking', decimate=1) for _ in range(2)]
    a, b = runs
    assert a.outcome == 'HOLDING' and math.isnan(a.lost_s)
    assert a.slip_m < 0.5e-3 and a.contact_peak_ratio <= 1.10
    # above the slip limit, and at most k over the kinetic friction (0.8 mu_s here) that a
    # slip shows the law when it cannot measure mu_s
    assert 1.0 < a.mean_margin <= P.grip_margin / 0.8
    assert np.array_equal(a.rows, b.rows) and a.rows.shape[0] > 10_000


def test_the_fixed_laws_stay_selectable_and_the_wrong_mass_loses_it():
    wrong = simulate_load_grip(CONFIG, 0.05, 0.6, 0.3, 0.24, pick_and_place(), 'friction',
                               0.45)
    paper = simulate_load_grip(CONFIG, 0.05, 0.6, 0.5, 0.4, pick_and_place(), 'paper')
    right = simulate_load_grip(CONFIG, 0.05, 0.6, 0.5, 0.4, pick_and_place(), 'friction')
    assert wrong.outcome == 'OBJECT_LOST' and paper.outcome == 'OBJECT_LOST'
    assert right.outcome == 'HOLDING' and right.slip_m == 0.0
    # the friction law's grip: k m (g + A) / (2 mu_s), the mu_s configured
    g = CONFIG.plant.gravity_mps2
    f_sp = CONFIG.supervisor.grip_safety_factor * 0.6 * (g + 3.0) / (
        2 * CONFIG.supervisor.friction_coefficient)
    assert right.rows[-1, 2] == pytest.approx(f_sp)


def test_an_overload_is_said_before_the_object_falls():
    run = simulate_load_grip(CONFIG, 0.05, 2.2, 0.3, 0.24, Lift(0.0, 0.2, 1.0),
                             'load_tracking')
    need_n = 2.2 * CONFIG.plant.gravity_mps2 / (2 * 0.3)
    assert need_n > MAX_N
    assert math.isfinite(run.overload_s)
    assert run.outcome == 'HOLDING' or run.overload_s < run.lost_s
    assert f'{MAX_N:.2f} N at 24 V' in run.note


@pytest.mark.parametrize('announce', [True, False])
def test_a_frictionless_object_is_called_overloaded_before_it_falls(announce):
    """Friction 0 holds nothing, whatever the grip: OVERLOADED is said before the object is out.

    Lifted at once, it slides out of the 20 mm pads in sqrt(2 L / (g + a)). The pads carry no
    shear of it, so the law raises the grip to the most and, the slide not slowing there, says
    so while it is still between them.
    """
    g, a = BASE.plant.gravity_mps2, 3.0
    run = simulate_load_grip(BASE, 0.05, 0.5, 0.0, 0.0, Lift(a, 0.2, 1.0), 'load_tracking',
                             announce=announce)
    assert run.outcome == 'OBJECT_LOST'
    assert run.lost_s == pytest.approx(math.sqrt(2 * BASE.contact.pad_length_m / (g + a)),
                                       abs=2 * DT_S)
    assert math.isfinite(run.overload_s) and run.overload_s < run.lost_s, run.note


@pytest.mark.parametrize('mass, mu, accel', [(2.0, 0.6, 5.0), (0.5, 0.9, 3.0), (1.0, 0.4, 6.0)])
def test_the_instant_slip_bound_is_the_hold_models_own_slide(mass, mu, accel):
    """The least slip of a reacting grip, in closed form, against the hold model integrated.

    The weight lands on the touch and the grip rises at 24 V as the stalled motor's current,
    F(t) = F_24V - (F_24V - F0) exp(-t / tau); the model slides against kinetic friction.
    """
    from gripper_ros.apps.grip_study import instant_slip_bound_m
    tau = BASE.plant.inductance_h / BASE.plant.resistance_ohm
    f0 = P.touch_force_n
    hold = HoldModel(mass, mu, 0.8 * mu, 1.0, BASE.plant.gravity_mps2, Lift(accel, 0.0, 10.0))
    hold.begin(0, mass)
    hold.fire_events(0)
    dt, t = tau / 2000, 0.0
    while hold.state is not HoldState.STUCK or t == 0.0:
        mid = t + 0.5 * dt                                 # the grip at the middle of the piece
        hold.advance(MAX_N - (MAX_N - f0) * math.exp(-mid / tau), dt)
        t += dt
    bound = instant_slip_bound_m(BASE, mass, mu, 0.8 * mu, accel)
    assert hold.slip_m == pytest.approx(bound, rel=1e-4)
    # beyond kinetic friction at 24 V, m (g + A) > 2 mu_k F_24V, the slide never stops
    assert instant_slip_bound_m(BASE, 2.0, 0.4, 0.32, 3.0) == math.inf


def test_grip_study_prints_a_row_per_law_and_refuses_bad_input():
    from gripper_ros.apps.grip_study import main
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(['--masses', '1.2', '--frictions', '0.5', '--instant-masses', '2',
                     '--instant-frictions', '0.6', '--instant-steps', '5']) == 0
    lines = out.getvalue().splitlines()
    for label in ('load-tracking, announced', 'load-tracking, unannounced'):
        row = next(line for line in lines if line.startswith(label))
        cases, lost = row[len(label):].split()[:2]
        assert (cases, lost) == ('6', '0')              # six motions, none lost
    assert sum(line.startswith('friction,') for line in lines) == 2
    # the instant step: a table of its own, the bounds beside it
    instant = lines[next(i for i, line in enumerate(lines) if 'instant steps' in line):]
    row = next(line for line in instant if line.startswith('load-tracking, announced'))
    assert row.split()[2:5] == ['1', '0', '0'] and float(row.split()[5]) == 0.0
    assert any(line.startswith('announced: the weight is unknown') for line in instant)
    assert any(line.startswith('unannounced: the least slip') for line in instant)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(['--masses', '1,nan']) == 2
    assert err.getvalue().count('\n') == 1 and '--masses' in err.getvalue()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(['--lift-off-s', '-1']) == 2
    assert err.getvalue().count('\n') == 1 and '--lift-off-s' in err.getvalue()
