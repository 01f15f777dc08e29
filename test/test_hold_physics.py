"""Holding a lifted object by Coulomb friction on both pads, against closed forms.

The object's slip obeys ``m x'' = m (g + a) - 2 mu_k F`` while it slides and stays put while
``m (g + a) <= 2 mu_s F``; with ``F`` and ``a`` constant the slip is ``x = a_rel t^2 / 2`` and
the object leaves a pad of length ``L`` at ``t = sqrt(2 L / a_rel)``. The grip force is held
exactly constant by a rigid object stalled at a fixed voltage (eq. 13 at steady state: ``F =
1.391 N/V x V``). Every reference value is computed here from these formulas.
"""
import math
from pathlib import Path

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.hold import HoldModel, HoldState, Lift
from gripper_ros.core.physics.plant import ContactState, GraspObject
import numpy as np
import pytest
from scipy.linalg import expm

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
P, C = CONFIG.plant, CONFIG.contact
G = P.gravity_mps2
MU_S, MU_K, PAD_M = C.static_friction, C.kinetic_friction, C.pad_length_m
WIDTH_M = 0.05
STEP_S = 1e-4                     # the force loop's period
STEP_NS = 100_000


def held_plant(volts, mass_kg=1.0, lift=None, **obj):
    """Finger stalled on a rigid object at ``volts``, current settled exactly at V/R."""
    plant = make_plant(CONFIG)
    obj = {'static_friction': MU_S, 'kinetic_friction': MU_K, **obj}    # the configured ones
    plant.set_object(GraspObject(WIDTH_M, mass_kg=mass_kg, **obj), lift=lift)
    plant.touch_object()
    for _ in range(2000):                                 # 0.2 s = 1900 L/R
        plant.step(volts, STEP_S)
    assert plant.sample().current_a == volts / P.resistance_ohm
    return plant


def grip_n(volts):
    return P.torque_constant_n_m_per_a * (volts / P.resistance_ohm) / P.force_lever_m


# ------------------------------------------------------------------ the hold model alone
def model(mass_kg=1.0, lift=None):
    return HoldModel(mass_kg, MU_S, MU_K, PAD_M, G, lift)


def test_model_slides_as_the_closed_form_under_constant_load_and_grip():
    m, a, f = 1.0, 2.0, 3.0                              # load 11.81 N > capacity 3 N
    hold = model(m, Lift(a, 0.0, 10.0))
    hold.begin(0, m)
    hold.fire_events(0)
    a_rel = G + a - 2.0 * MU_K * f / m
    t = 0.0
    for dt in [1e-4, 3.7e-5, 2e-3, 1e-6, 5e-4] * 10:      # uneven pieces: exact for any split
        assert hold.advance(f, dt) is None
        t += dt
        assert hold.state is HoldState.SLIDING
        assert hold.slip_m == pytest.approx(0.5 * a_rel * t * t, rel=1e-12)
        assert hold.slip_speed_mps == pytest.approx(a_rel * t, rel=1e-12)


def test_model_loses_the_object_at_sqrt_2l_over_a_rel():
    m, a, f = 0.5, 1.0, 2.0
    hold = model(m, Lift(a, 0.0, 10.0))
    hold.begin(0, m)
    hold.fire_events(0)
    a_rel = G + a - 2.0 * MU_K * f / m
    t_loss = math.sqrt(2.0 * PAD_M / a_rel)
    assert hold.advance(f, 0.5 * t_loss) is None
    lost_after = hold.advance(f, t_loss)                  # the loss lies inside this interval
    assert lost_after == pytest.approx(0.5 * t_loss, rel=1e-12)
    assert hold.state is HoldState.LOST and hold.slip_m == PAD_M
    assert hold.slip_speed_mps == pytest.approx(a_rel * t_loss, rel=1e-12)
    assert hold.advance(f, 1.0) is None and hold.state is HoldState.LOST


def test_model_decelerates_and_sticks_again_at_the_closed_form_instant():
    m, a, f, lift_s = 1.0, 10.0, 15.0, 0.02
    assert m * (G + a) > 2 * MU_S * f and m * G < 2 * MU_K * f    # slides, then is braked
    hold = model(m, Lift(a, 0.0, lift_s))
    hold.begin(0, m)
    hold.fire_events(0)
    a1 = G + a - 2 * MU_K * f / m
    assert hold.advance(f, lift_s) is None
    hold.fire_events(round(lift_s * 1e9))                 # the lift ends: weight alone
    x1, v1 = 0.5 * a1 * lift_s ** 2, a1 * lift_s
    a2 = G - 2 * MU_K * f / m                             # < 0
    t_stop = -v1 / a2
    assert hold.advance(f, 0.5 * t_stop) is None and hold.state is HoldState.SLIDING
    assert hold.advance(f, t_stop) is None                # stops inside this interval
    assert hold.state is HoldState.STUCK and hold.slip_speed_mps == 0.0
    assert hold.slip_m == pytest.approx(x1 - v1 * v1 / (2 * a2), rel=1e-12)


# ------------------------------------------------------------------ the plant holding it
def test_slip_from_the_lift_instant_follows_the_closed_form_then_the_object_is_lost():
    volts, m, a = 2.0, 1.0, 2.0
    f = grip_n(volts)
    a_rel = G + a - 2 * MU_K * f / m
    assert m * (G + a) > 2 * MU_S * f
    delay_s = 1.23456e-3                                  # not on the 0.1 ms step grid
    plant = held_plant(volts, m, Lift(a, delay_s, 1.0))
    assert plant.sample().force_n == f
    t_hold = plant.t_ns
    plant.begin_hold(t_hold)
    t_lift = t_hold + round(delay_s * 1e9)
    t_loss_s = math.sqrt(2 * PAD_M / a_rel)
    while plant.t_ns + STEP_NS < t_lift + round(t_loss_s * 1e9):
        s = plant.step(volts, STEP_S)
        state = plant.object_state
        t = (s.t_ns - t_lift) * 1e-9
        if t < 0:
            assert state.state is HoldState.RESTING and state.slip_m == 0.0
            assert state.load_n == 0.0
        else:
            assert state.state is HoldState.SLIDING
            assert state.slip_m == pytest.approx(0.5 * a_rel * t * t, rel=1e-9, abs=1e-15)
            assert state.slip_speed_mps == pytest.approx(a_rel * t, rel=1e-9, abs=1e-15)
            assert state.load_n == pytest.approx(m * (G + a), rel=1e-15)
        assert state.capacity_n == pytest.approx(2 * MU_S * f, rel=1e-15)
        assert s.force_n == f and s.contact
    s = plant.step(volts, STEP_S)                         # the loss lies inside this step
    state = plant.object_state
    assert state.state is HoldState.LOST and state.slip_m == PAD_M
    assert abs(state.lost_ns - (t_lift + t_loss_s * 1e9)) <= 1.0
    assert state.load_n == 0.0 and state.capacity_n == 0.0


def test_after_the_loss_the_fingers_close_on_nothing_from_that_instant():
    volts, m, a = 2.0, 1.0, 2.0
    plant = held_plant(volts, m, Lift(a, 0.0, 1.0))
    x_c = plant.contact_position_m
    plant.begin_hold(plant.t_ns)
    while plant.object_state.state is not HoldState.LOST:
        s = plant.step(volts, STEP_S)
    lost_ns = plant.object_state.lost_ns
    assert plant.contact_position_m == P.max_travel_m     # nothing left: fingers would meet
    assert plant.contact_state is ContactState.FREE
    assert s.force_n == 0.0 and not s.contact and s.position_m > x_c
    # free motion from rest at x_c, current V/R, from the loss instant on (eqs. 3, 4, 10)
    a_free = np.array([[-P.resistance_ohm / P.inductance_h,
                        -P.back_emf_v_s_per_rad / P.inductance_h, 0.0],
                       [P.torque_constant_n_m_per_a / P.inertia_kg_m2,
                        -P.damping_n_m_s_per_rad / P.inertia_kg_m2, 0.0],
                       [0.0, P.travel_per_rad_m, 0.0]])
    mat = np.zeros((4, 4))
    mat[:3, :3] = a_free
    mat[0, 3] = volts / P.inductance_h
    phi = expm(mat * (s.t_ns - lost_ns) * 1e-9)
    expected = phi[:3, :3] @ np.array([volts / P.resistance_ohm, 0.0, x_c]) + phi[:3, 3]
    assert s.speed_rad_s == pytest.approx(expected[1], rel=1e-6)
    assert s.position_m == pytest.approx(expected[2], rel=1e-12)
    for _ in range(100):                                  # the finger moves on
        s2 = plant.step(volts, STEP_S)
    assert s2.position_m > s.position_m and s2.force_n == 0.0


def test_a_firm_grip_holds_without_any_slip_through_and_after_the_lift():
    volts, m, a, lift_s = 12.0, 1.0, 2.0, 0.01
    f = grip_n(volts)
    assert m * (G + a) <= 2 * MU_S * f
    plant = held_plant(volts, m, Lift(a, 0.0, lift_s))
    plant.begin_hold(plant.t_ns)
    t_end = plant.t_ns + round(lift_s * 1e9)
    for _ in range(300):
        s = plant.step(volts, STEP_S)
        state = plant.object_state
        assert state.state is HoldState.STUCK and state.slip_m == 0.0
        load = m * (G + a) if s.t_ns <= t_end else m * G      # a(t) = a on [t_lift, t_end]
        assert state.load_n == pytest.approx(load, rel=1e-15)
        assert s.force_n == f


def test_sliding_stops_when_kinetic_friction_exceeds_the_weight_after_the_lift():
    volts, m, a, lift_s = 11.0, 1.0, 10.0, 0.02
    f = grip_n(volts)
    assert m * (G + a) > 2 * MU_S * f and m * G < 2 * MU_K * f
    plant = held_plant(volts, m, Lift(a, 0.0, lift_s))
    plant.begin_hold(plant.t_ns)
    a1, a2 = G + a - 2 * MU_K * f / m, G - 2 * MU_K * f / m
    x1, v1 = 0.5 * a1 * lift_s ** 2, a1 * lift_s
    t_stop = lift_s - v1 / a2
    stuck_at = None
    for _ in range(round((t_stop + 0.05) / STEP_S)):
        plant.step(volts, STEP_S)
        if stuck_at is None and plant.object_state.state is HoldState.STUCK:
            stuck_at = plant.object_state.slip_m
    assert plant.object_state.state is HoldState.STUCK
    assert stuck_at == pytest.approx(x1 - v1 * v1 / (2 * a2), rel=1e-9)
    assert plant.object_state.slip_m == stuck_at and plant.object_state.slip_speed_mps == 0.0


def test_opening_the_fingers_drops_a_lifted_object_in_free_fall():
    volts, m = 12.0, 1.0
    plant = held_plant(volts, m, Lift(0.0, 0.0, 0.0))
    plant.begin_hold(plant.t_ns)
    for _ in range(50):
        plant.step(volts, STEP_S)
    assert plant.object_state.state is HoldState.STUCK
    t_open = plant.t_ns
    while plant.object_state.state is not HoldState.LOST:
        plant.step(-volts, STEP_S)                        # open: the grip force vanishes
    fall_s = (plant.object_state.lost_ns - t_open) * 1e-9
    free_fall_s = math.sqrt(2 * PAD_M / G)                # friction only delays it, briefly
    assert free_fall_s < fall_s < free_fall_s + 1e-3


def test_on_its_support_the_object_never_loads_the_grip():
    plant = held_plant(2.0, 5.0)                          # no lift: it rests forever
    plant.begin_hold(plant.t_ns, 5.0)
    for _ in range(100):
        plant.step(0.0, 0.01)
    state = plant.object_state
    assert state.state is HoldState.RESTING and state.slip_m == 0.0 and state.load_n == 0.0


def test_the_grasps_mass_is_used_when_the_object_gives_none():
    volts, a = 2.0, 2.0
    plant = held_plant(volts, 0.0, Lift(a, 0.0, 1.0))
    plant.begin_hold(plant.t_ns, 0.5)
    plant.step(volts, STEP_S)
    assert plant.object_state.load_n == pytest.approx(0.5 * (G + a), rel=1e-15)
    own = held_plant(volts, 2.0, Lift(a, 0.0, 1.0))      # the object's own mass wins
    own.begin_hold(own.t_ns, 0.5)
    own.step(volts, STEP_S)
    assert own.object_state.load_n == pytest.approx(2.0 * (G + a), rel=1e-15)


def test_per_object_friction_and_pad_length_replace_the_defaults():
    volts, m, a, mu_k, pad_m = 2.0, 1.0, 2.0, 0.2, 0.005
    f = grip_n(volts)
    plant = held_plant(volts, m, Lift(a, 0.0, 1.0), static_friction=0.3,
                       kinetic_friction=mu_k, pad_length_m=pad_m)
    assert plant.object_state.capacity_n == pytest.approx(2 * 0.3 * f, rel=1e-15)
    t0 = plant.t_ns
    plant.begin_hold(t0)
    while plant.object_state.state is not HoldState.LOST:
        plant.step(volts, STEP_S)
    a_rel = G + a - 2 * mu_k * f / m
    assert abs(plant.object_state.lost_ns - t0 - math.sqrt(2 * pad_m / a_rel) * 1e9) <= 1.0


def test_without_a_lift_the_plant_steps_exactly_as_without_a_mass():
    def run(obj, hold):
        plant = make_plant(CONFIG)
        plant.set_object(obj)
        out = []
        for k in range(400):
            if hold and k == 300:
                plant.begin_hold(plant.t_ns, 1.69)
            out.append(plant.step(24.0 if k < 300 else 5.0, 0.01 if k < 300 else STEP_S))
        return out
    assert run(GraspObject(WIDTH_M), False) == run(
        GraspObject(WIDTH_M, mass_kg=1.69, static_friction=MU_S, kinetic_friction=MU_K), True)


def test_two_runs_with_a_slide_and_a_loss_are_bit_identical():
    def run():
        plant = make_plant(CONFIG)
        plant.set_object(plant.configured_friction(GraspObject(WIDTH_M, 1e5, 50.0, mass_kg=0.8)),
                         Lift(3.0, 0.0123, 0.05))
        samples, states = [], []
        for k in range(1500):
            if k == 400:
                plant.begin_hold(plant.t_ns)
            samples.append(plant.step(24.0 if k < 350 else 3.0, 0.01 if k < 350 else STEP_S))
            states.append(plant.object_state)
        return samples, states
    first, second = run(), run()
    assert first == second
    assert {s.state for s in first[1]} >= {HoldState.RESTING, HoldState.SLIDING, HoldState.LOST}


# ------------------------------------------------------------------ bad values
@pytest.mark.parametrize('field, value', [
    ('mass_kg', -1.0), ('mass_kg', math.nan), ('static_friction', -0.1),
    ('kinetic_friction', math.inf), ('pad_length_m', -0.02), ('pad_length_m', math.nan)])
def test_bad_object_values_are_refused_naming_the_field_and_change_nothing(field, value):
    plant = held_plant(2.0)
    before = (plant.sample(), plant.object, plant.object_state)
    with pytest.raises(ValueError, match=field):
        plant.set_object(GraspObject(WIDTH_M, **{field: value}))
    assert (plant.sample(), plant.object, plant.object_state) == before


def test_kinetic_friction_above_static_is_refused():
    plant = make_plant(CONFIG)
    with pytest.raises(ValueError, match='kinetic_friction'):
        plant.set_object(GraspObject(WIDTH_M, static_friction=0.3, kinetic_friction=0.35))
    with pytest.raises(ValueError, match='kinetic_friction'):        # the configured mu_k 0.4
        plant.set_object(GraspObject(WIDTH_M, static_friction=0.3,
                                     kinetic_friction=C.kinetic_friction))
    assert plant.object == GraspObject(0.0)


@pytest.mark.parametrize('grip_v', [2.0, 24.0])
def test_friction_0_is_frictionless_and_the_configured_friction_is_asked_for_apart(grip_v):
    """A frictionless object falls through any grip as the closed form x = (g + a) t^2 / 2.

    Friction 0 is the object's own (none), not the configured one, which
    :meth:`configured_friction` gives instead.
    """
    m, a = 1.0, 2.0
    plant = held_plant(grip_v, m, Lift(a, 0.0, 1.0), static_friction=0.0,
                       kinetic_friction=0.0)
    plant.begin_hold(plant.t_ns)
    t = 0.0
    while plant.object_state.state is not HoldState.LOST:
        plant.step(grip_v, STEP_S)
        t += STEP_S
        state = plant.object_state
        if state.state is HoldState.SLIDING:
            assert state.slip_m == pytest.approx(0.5 * (G + a) * t * t, rel=1e-9)
            assert state.shear_n == 0.0 and state.presliding_m == 0.0
    assert t == pytest.approx(math.sqrt(2 * PAD_M / (G + a)), abs=STEP_S)
    configured = plant.configured_friction(GraspObject(WIDTH_M, static_friction=0.0))
    assert (configured.static_friction, configured.kinetic_friction) == (MU_S, MU_K)


@pytest.mark.parametrize('kwargs, field', [
    ({'acceleration_mps2': -1.0}, 'acceleration_mps2'),
    ({'acceleration_mps2': math.nan}, 'acceleration_mps2'),
    ({'acceleration_mps2': 1.0, 'delay_s': -0.1}, 'delay_s'),
    ({'acceleration_mps2': 1.0, 'duration_s': math.inf}, 'duration_s'),
    ({'acceleration_mps2': 1.0, 'delay_s': 1e4}, 'delay_s'),
    ({'acceleration_mps2': 1.0, 'lift_off_s': -0.1}, 'lift_off_s'),
    ({'acceleration_mps2': 1.0, 'lift_off_s': 11.0}, 'lift_off_s')])
def test_bad_lifts_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Lift(**kwargs)


@pytest.mark.parametrize('t_ns, mass, field', [
    (-1, 1.0, 't_ns'), (1.5, 1.0, 't_ns'), (True, 1.0, 't_ns'),
    (0, -1.0, 'grasp_mass_kg'), (0, math.nan, 'grasp_mass_kg')])
def test_bad_hold_declarations_are_refused_and_change_nothing(t_ns, mass, field):
    plant = held_plant(2.0, 0.0, Lift(2.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=field):
        plant.begin_hold(t_ns, mass)
    a = plant.step(2.0, STEP_S)
    assert plant.object_state.state is HoldState.RESTING and a.force_n == grip_n(2.0)


def test_a_second_hold_after_the_lift_is_refused():
    plant = held_plant(12.0, 1.0, Lift(1.0, 0.0, 0.01))
    plant.begin_hold(plant.t_ns)
    plant.step(12.0, STEP_S)
    with pytest.raises(ValueError, match='off its support'):
        plant.begin_hold(plant.t_ns)
    assert plant.object_state.state is HoldState.STUCK


def test_nothing_to_hold_without_an_object():
    plant = make_plant(CONFIG)
    plant.begin_hold(0, 1.0)
    assert plant.object_state.state is HoldState.NONE


# ------------------------------------------------------------------ the lift-off
def _slide_start_s(hold, f, end_s=1.0, dt_s=STEP_S):
    """Step the model in force-loop periods at grip ``f``: the instant it first slides, or None."""
    t_ns = 0
    while t_ns * 1e-9 < end_s:
        hold.fire_events(t_ns)
        hold.advance(f, dt_s)
        t_ns += STEP_NS
        if hold.state is HoldState.SLIDING:
            return t_ns * 1e-9
    return None


@pytest.mark.parametrize('lift_off_s', [0.05, 0.2])
def test_the_lift_off_passes_the_weight_to_the_pads_linearly(lift_off_s):
    """Over the lift-off the pads carry (t / T_off) m g: it slides from T_off 2 mu_s F / m g."""
    m, f = 1.0, 3.0                                      # 2 mu_s F = 3 N < m g = 9.81 N
    hold = HoldModel(m, MU_S, MU_K, PAD_M, G, Lift(0.0, 0.0, 10.0), lift_off_s=lift_off_s)
    hold.begin(0, m)
    hold.fire_events(0)
    assert hold.load_n < 0.01 * m * G                    # the first piece: a sliver of it
    expected_s = lift_off_s * 2.0 * MU_S * f / (m * G)
    assert _slide_start_s(hold, f) == pytest.approx(expected_s, abs=2 * STEP_S)
    hold.fire_events(round(1e9 * lift_off_s) + STEP_NS)  # past the lift-off: all of it
    assert hold.load_n == m * G


def test_a_grip_above_the_full_weight_never_slides_through_the_lift_off():
    m = 1.0
    f = 1.01 * m * G / (2.0 * MU_S)
    hold = HoldModel(m, MU_S, MU_K, PAD_M, G, Lift(0.0, 0.0, 10.0), lift_off_s=0.1)
    hold.begin(0, m)
    assert _slide_start_s(hold, f, end_s=0.3) is None and hold.slip_m == 0.0


def test_a_zero_lift_off_is_the_instant_lift_bit_for_bit():
    runs = []
    for kwargs in ({}, {'lift_off_s': 0.0}):
        hold = HoldModel(1.0, MU_S, MU_K, PAD_M, G, Lift(2.0, 0.0, 0.05), **kwargs)
        hold.begin(0, 1.0)
        _slide_start_s(hold, 3.0, end_s=0.04)
        runs.append(hold.record.copy())
    for name in runs[0].dtype.names:                    # every field, bit for bit
        assert runs[0][name].tobytes() == runs[1][name].tobytes(), name
    assert runs[0][0]['slip_m'] > 0.0


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_a_bad_lift_off_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match='lift_off_s'):
        HoldModel(1.0, MU_S, MU_K, PAD_M, G, None, lift_off_s=bad)


@pytest.mark.parametrize('lift_off_s, config_s, expected_s', [
    (0.2, 0.0, 0.2), (0.0, 0.05, 0.05), (0.2, 0.05, 0.2), (0.0, 0.0, 0.0)])
def test_a_lifts_own_lift_off_wins_and_0_means_the_configs(lift_off_s, config_s, expected_s):
    """SetObject.lift_off_s (the Lift's) sets the hand-over; 0 leaves contact.lift_off_s."""
    import dataclasses
    config = dataclasses.replace(CONFIG, contact=dataclasses.replace(C, lift_off_s=config_s))
    plant = make_plant(config)
    plant.set_object(plant.configured_friction(GraspObject(WIDTH_M, mass_kg=1.0)),
                     lift=Lift(1.0, 0.0, 1.0, lift_off_s=lift_off_s))
    assert plant.kernel[0]['hold']['lift_off_ns'] == round(expected_s * 1e9)
