"""Plant (eqs. 1-13, exact ZOH, contact) and FSR sensor against analytic answers.

Every reference quantity here is derived in this file from the paper's equations and the
Table I numbers of config/gripper.yaml (their one home), never read back from the plant under
test.
"""
import copy
import math
from pathlib import Path

from gripper_ros.core.config import ForceSensorParams, load_config, object_contact
from gripper_ros.core.physics.force_sensor import FsrVoltageDivider
from gripper_ros.core.physics.plant import (check_fault, ContactState, FaultKind, GraspObject,
                                            GripperPlant)
import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import cont2discrete, lsim

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
P = CONFIG.plant

# Table I (SI units), as config/gripper.yaml holds it.
J, B_M, N_RATIO, R, L = (P.inertia_kg_m2, P.damping_n_m_s_per_rad, P.gear_ratio,
                         P.resistance_ohm, P.inductance_h)
PITCH, KT, KB, ETA, L_LS = (P.pitch_m, P.torque_constant_n_m_per_a, P.back_emf_v_s_per_rad,
                            P.efficiency, P.max_travel_m)
RHO = PITCH / (2 * math.pi)                    # eq. 10
LEVER = ETA * PITCH * N_RATIO                  # eq. 12
TAU_E = L / R
STALL_N_PER_V = KT / (LEVER * R)               # DC gain of eq. 13 = 1.391 N/V
FREE_MPS_PER_V = KT / (B_M * R + KT * KB) * RHO  # DC gain of eq. 9 times p/2pi


def continuous_free_model():
    """Return x' = A x + B e for x = [i_a, omega, x_finger], straight from eqs. 3, 4 and 10."""
    a = np.array([[-R / L, -KB / L, 0.0],          # eq. 4
                  [KT / J, -B_M / J, 0.0],         # eq. 3
                  [0.0, RHO, 0.0]])                # eq. 10
    b = np.array([[1.0 / L], [0.0], [0.0]])
    return a, b


def free_response_from_rest(volts, t):
    """[i, omega, x] after holding ``volts`` for ``t`` from rest (x = 0), exactly."""
    a, b = continuous_free_model()
    m = np.zeros((4, 4))
    m[:3, :3] = a
    m[:3, 3] = b[:, 0] * volts
    return expm(m * t)[:3, 3]


def make_plant(contact=None):
    return GripperPlant(P, FsrVoltageDivider(CONFIG.force_sensor), contact)


_MOVING = []


def moving_plant():
    """Return a plant 2 cm into its travel and moving (prepared once, copied per test)."""
    if not _MOVING:
        plant = make_plant()
        for _ in range(60):
            plant.step(24.0, 0.01)
        _MOVING.append(plant)
    return copy.deepcopy(_MOVING[0])


def state_of(plant):
    s = plant.sample()
    return (s.t_ns, s.position_m, s.velocity_mps, s.force_n, s.current_a, s.speed_rad_s,
            s.voltage_v, plant.contact_state, plant.object)


def run_until_contact(plant, voltage, dt=0.01, max_steps=2000):
    for _ in range(max_steps):
        before = plant.sample()
        s = plant.step(voltage, dt)
        if plant.contact_state in (ContactState.RIGID_OBJECT, ContactState.COMPLIANT_OBJECT):
            return before, s
    raise AssertionError('no contact')


# ------------------------------------------------------------------ transfer functions
def test_position_transfer_function_is_eq_11():
    num, den = make_plant().position_transfer_function()
    for s in (1j, 3.0 + 40j, -5.0 + 0.5j, 1e4j, 250.0):
        eq11 = KT * PITCH / (2 * math.pi * s * ((J * s + B_M) * (L * s + R) + KT * KB))
        assert np.polyval(num, s) / np.polyval(den, s) == pytest.approx(eq11, rel=1e-12)


def test_force_transfer_function_is_eq_13():
    num, den = make_plant().force_transfer_function()
    for s in (0.0, 1j, 1e4 + 3e3j, -100.0):
        eq13 = KT / (ETA * PITCH * N_RATIO * (L * s + R))   # N2/N1 = 1/gear ratio
        assert np.polyval(num, s) / np.polyval(den, s) == pytest.approx(eq13, rel=1e-12)
    assert np.polyval(num, 0.0) / np.polyval(den, 0.0) == pytest.approx(1.391, abs=5e-4)


def test_position_poles_are_eigenvalues_of_the_state_model():
    num, den = make_plant().position_transfer_function()
    poles = np.sort_complex(np.roots(den))
    a, _ = continuous_free_model()
    eig = np.sort_complex(np.linalg.eigvals(a))
    np.testing.assert_allclose(poles, eig, rtol=1e-9, atol=1e-9)
    # one integrator (position), two real stable electromechanical poles
    assert np.sum(np.abs(eig) < 1e-9) == 1
    assert np.all(np.abs(eig.imag) < 1e-9) and np.all(eig.real <= 1e-9)


def test_force_pole_is_minus_r_over_l():
    _, den = make_plant().force_transfer_function()
    np.testing.assert_allclose(np.roots(den), [-R / L], rtol=1e-12)


def test_state_model_reproduces_eq_11_frequency_response():
    a, b = continuous_free_model()
    c = np.array([[0.0, 0.0, 1.0]])
    num, den = make_plant().position_transfer_function()
    for w in (0.3, 3.0, 300.0, 3e4):
        s = 1j * w
        g_ss = (c @ np.linalg.solve(s * np.eye(3) - a, b))[0, 0]
        assert g_ss == pytest.approx(np.polyval(num, s) / np.polyval(den, s), rel=1e-9)


# ------------------------------------------------------------------ free motion
def test_long_constant_voltage_reaches_dc_speed_of_eq_9():
    # 1 V for 15 s: ~13 mechanical time constants, 4.3 cm of the 15 cm travel.
    plant = make_plant()
    for _ in range(1500):
        s = plant.step(1.0, 0.01)
    assert plant.contact_state is ContactState.FREE
    assert s.velocity_mps == pytest.approx(FREE_MPS_PER_V * 1.0, rel=1e-5)
    assert s.speed_rad_s * RHO == pytest.approx(s.velocity_mps, rel=1e-12)
    assert P.free_speed_per_volt_mps == pytest.approx(FREE_MPS_PER_V, rel=1e-12)
    # at steady speed the armature current only covers viscous damping: k_t i = b omega (eq. 3)
    assert KT * s.current_a == pytest.approx(B_M * s.speed_rad_s, rel=1e-5)


def test_free_position_matches_eq_11_step_response():
    """Constant voltage from rest at x = 0: the position is the step response of eq. 11."""
    volts = 2.0
    t = np.linspace(0.0, 3.0, 301)
    num = [KT * PITCH / (2 * math.pi)]
    den = np.polymul(np.polyadd(np.polymul([J, B_M], [L, R]), [KT * KB]), [1.0, 0.0])
    _, x_ref, _ = lsim((num, den), np.full_like(t, volts), t)
    plant = make_plant()
    x = [plant.sample().position_m]
    for _ in range(t.size - 1):
        x.append(plant.step(volts, 0.01).position_m)
    np.testing.assert_allclose(x, x_ref, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize('dt', [1e-5, 1e-4, 0.01, 0.5])
def test_discrete_free_model_is_exact_zoh(dt):
    a, b = continuous_free_model()
    ad, bd = make_plant().discrete_free_model(dt)
    ad_ref, bd_ref, *_ = cont2discrete((a, b, np.eye(3), np.zeros((3, 1))), dt, method='zoh')
    np.testing.assert_allclose(ad, ad_ref, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(bd, bd_ref[:, 0], rtol=1e-10, atol=1e-16)
    np.testing.assert_allclose(ad, expm(a * dt), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize('dt', [1e-4, 0.01, 0.25])
def test_discretisation_composes(dt):
    plant = make_plant()
    ad1, bd1 = plant.discrete_free_model(dt)
    ad2, bd2 = plant.discrete_free_model(2 * dt)
    np.testing.assert_allclose(ad1 @ ad1, ad2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ad1 @ bd1 + bd1, bd2, rtol=1e-12, atol=1e-18)


def test_two_steps_of_dt_equal_one_of_two_dt_in_simulation():
    plant = moving_plant()
    assert plant.contact_state is ContactState.FREE
    twice, once = copy.deepcopy(plant), copy.deepcopy(plant)
    twice.step(-2.0, 0.004)
    a = twice.step(-2.0, 0.004)
    b = once.step(-2.0, 0.008)
    assert a.t_ns == b.t_ns
    for name in ('position_m', 'velocity_mps', 'current_a'):
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-12, abs=1e-15)


def test_discrete_force_model_is_zoh_of_eq_13():
    for dt in (1e-6, 1e-4, 1e-3):
        a, b = make_plant().discrete_force_model(dt)
        assert a == pytest.approx(math.exp(-dt * R / L), rel=1e-14)
        assert b == pytest.approx(STALL_N_PER_V * (1 - math.exp(-dt * R / L)), rel=1e-12)


# ------------------------------------------------------------------ rigid contact (eq. 12/13)
def test_force_step_on_rigid_object_is_first_order_of_eq_13():
    volts = 5.0
    plant = make_plant()
    plant.set_object(GraspObject(width_m=0.05))
    plant.touch_object()
    t = 0.0
    for dt in (1e-5, 2e-5, 3e-5, 5e-5, 1e-4, 2e-4, 1e-3):   # irregular holds, exact at each
        s = plant.step(volts, dt)
        t += dt
        expected = STALL_N_PER_V * volts * (1 - math.exp(-t * R / L))
        assert s.force_n == pytest.approx(expected, rel=1e-9)
        assert s.position_m == L_LS - 0.05 and s.velocity_mps == 0.0 and s.contact


def test_stall_force_at_24_volts():
    assert P.max_force_n == pytest.approx(33.39, abs=0.01)
    plant = make_plant()
    assert P.stall_force_per_volt_n == pytest.approx(STALL_N_PER_V, rel=1e-12)
    plant.set_object(GraspObject(width_m=0.02))
    plant.touch_object()
    s = plant.step(24.0, 0.01)            # 97 electrical time constants
    assert s.force_n == pytest.approx(33.39, abs=0.01)
    s = plant.step(100.0, 0.01)           # clipped to the 24 V supply
    assert s.voltage_v == 24.0
    assert s.force_n == pytest.approx(33.39, abs=0.01)


def test_rigid_contact_stops_finger_holds_then_releases_on_reverse_voltage():
    plant = make_plant()
    plant.set_object(GraspObject(width_m=0.05))
    before, s = run_until_contact(plant, 12.0)
    x_c = L_LS - 0.05
    assert s.position_m == x_c and s.velocity_mps == 0.0
    # perfectly inelastic: the motor's kinetic energy at impact is lost
    assert plant.impact_energy_lost_j == pytest.approx(
        0.5 * J * (before.velocity_mps / RHO) ** 2, rel=0.02)
    for _ in range(20):                   # stays, force settles to the stall force
        s = plant.step(12.0, 0.01)
        assert s.position_m == x_c and s.velocity_mps == 0.0
    assert s.force_n == pytest.approx(12.0 * STALL_N_PER_V, rel=1e-9)
    assert s.contact and s.sensor_voltage_v > 4.0
    # reverse: the current i = 12/R decays towards -12/R and crosses zero after tau ln 2;
    # until then the finger is held and the force follows the current
    t_leave = TAU_E * math.log(2.0)
    t_reverse_ns = plant.t_ns
    hold_ns = round(0.9 * t_leave * 1e9)            # the plant holds whole nanoseconds
    s = plant.step(-12.0, hold_ns * 1e-9)
    assert s.position_m == x_c
    assert s.force_n == pytest.approx(
        KT / LEVER * 12.0 / R * (2.0 * math.exp(-hold_ns * 1e-9 / TAU_E) - 1.0), rel=1e-9)
    s = plant.step(-12.0, 0.1 * t_leave + 0.01)
    assert s.force_n == 0.0 and not s.contact
    assert plant.contact_state is ContactState.FREE
    assert s.position_m < x_c and s.velocity_mps < 0.0
    # from then on it is free motion from rest (i = 0, omega = 0): the step response of eq. 11
    times = [(s.t_ns - t_reverse_ns) * 1e-9]
    xs = [s.position_m]
    for _ in range(30):
        s = plant.step(-12.0, 0.01)
        times.append((s.t_ns - t_reverse_ns) * 1e-9)
        xs.append(s.position_m)
    x_ref = [free_response_from_rest(-12.0, t - t_leave)[2] for t in times]
    np.testing.assert_allclose(xs, x_c + np.array(x_ref), rtol=0, atol=1e-9)
    assert xs[-1] < x_c - 0.001


def test_no_object_fingers_meet_at_full_travel():
    plant = make_plant()
    run_until_contact(plant, 24.0)
    s = plant.step(24.0, 0.01)
    assert s.position_m == L_LS and s.force_n == pytest.approx(33.39, abs=0.01)


# ------------------------------------------------------------------ compliant contact
def test_compliant_contact_steady_force_is_stall_force_and_penetration_f_over_k():
    # k = 4e6 N/m, c = 9e4 N s/m: about critically damped at the motor, decay rate ~85 1/s
    k, c, volts = 4e6, 9e4, 6.0
    plant = make_plant()
    plant.set_object(GraspObject(width_m=0.05, stiffness_n_per_m=k, damping_n_s_per_m=c))
    plant.touch_object()
    s = plant.step(volts, 0.25)
    force = volts * STALL_N_PER_V          # k_t i = lever F with i = V/R at rest
    assert s.force_n == pytest.approx(force, rel=1e-5)
    assert s.position_m - (L_LS - 0.05) == pytest.approx(force / k, rel=1e-5)
    assert abs(s.velocity_mps) < 1e-8 and s.contact


def test_compliant_contact_from_free_motion_default_contact_params():
    plant = make_plant(object_contact(4e6, 9e4))       # the default object is compliant
    assert plant.object.stiffness_n_per_m == 4e6 and not plant.object.rigid
    plant.set_object(GraspObject(width_m=0.14, stiffness_n_per_m=4e6, damping_n_s_per_m=9e4))
    run_until_contact(plant, 24.0)
    assert plant.contact_state is ContactState.COMPLIANT_OBJECT
    s = plant.step(8.0, 0.25)
    assert s.force_n == pytest.approx(8.0 * STALL_N_PER_V, rel=1e-4)
    depth = s.position_m - (L_LS - 0.14)
    assert depth == pytest.approx(8.0 * STALL_N_PER_V / 4e6, rel=1e-4)
    # Kelvin-Voigt: reported force = k d + c d'
    assert s.force_n == pytest.approx(4e6 * depth + 9e4 * s.velocity_mps, rel=1e-9)


# ------------------------------------------------------------------ open stop, time, inputs
def test_open_end_stop_holds_with_negative_voltage():
    plant = make_plant()
    s = plant.step(-24.0, 0.2)
    assert s.position_m == 0.0 and s.velocity_mps == 0.0 and s.force_n == 0.0
    assert plant.contact_state is ContactState.OPEN_STOP
    assert s.current_a == pytest.approx(-24.0 / R, rel=1e-9)   # stalled: i = V/R


def test_time_is_integer_nanoseconds_and_exact():
    plant = make_plant()
    for _ in range(10000):
        plant.step(0.0, 1e-4)
    assert isinstance(plant.t_ns, int) and plant.t_ns == 1_000_000_000
    for _ in range(3000):
        s = plant.step(-1.0, 0.01)       # 0.01 is not a binary fraction
    assert s.t_ns == 31_000_000_000 and s.t_s == pytest.approx(31.0, rel=1e-15)
    s = plant.step(0.0, 1.0e-9)
    assert s.t_ns == 31_000_000_001


@pytest.mark.parametrize('voltage, duration', [
    (float('nan'), 0.01), (float('inf'), 0.01), (-float('inf'), 0.01),
    (1.0, 0.0), (1.0, -0.01), (1.0, float('nan')), (1.0, float('inf')), (1.0, 1e-12)])
def test_bad_step_raises_and_leaves_state_unchanged(voltage, duration):
    plant = moving_plant()
    before = state_of(plant)
    with pytest.raises(ValueError):
        plant.step(voltage, duration)
    assert state_of(plant) == before


@pytest.mark.parametrize('obj', [
    GraspObject(width_m=-0.01), GraspObject(width_m=0.150), GraspObject(width_m=0.2),
    GraspObject(width_m=float('nan')), GraspObject(width_m=0.05, stiffness_n_per_m=-1.0),
    GraspObject(width_m=0.05, damping_n_s_per_m=float('inf')),
    GraspObject(width_m=0.145)])          # the finger is already past 0.005 m
def test_bad_object_raises_and_leaves_state_unchanged(obj):
    plant = moving_plant()
    assert plant.sample().position_m > 0.005
    before = state_of(plant)
    with pytest.raises(ValueError):
        plant.set_object(obj)
    assert state_of(plant) == before


# ------------------------------------------------------------------ force sensor (FSR divider)
SENSOR = FsrVoltageDivider(CONFIG.force_sensor)
SP = CONFIG.force_sensor


def test_sensor_formula():
    for force in (0.25, 1.0, 4.0, 33.0):
        r_fsr = SP.fsr_resistance_at_1n_ohm / force
        expected = SP.supply_v * SP.measuring_resistor_ohm / (SP.measuring_resistor_ohm + r_fsr)
        assert SENSOR.voltage_v(force) == pytest.approx(expected, rel=1e-12)
    assert SENSOR.voltage_v(1.0) == pytest.approx(2.5, rel=1e-12)   # R_fsr = R_m at 1 N
    assert SENSOR.voltage_v(4.0) == pytest.approx(4.0, rel=1e-12)


def test_sensor_near_zero_below_activation_and_jumps_above_threshold():
    below = [SENSOR.voltage_v(f) for f in (0.0, 0.1, 0.199)]
    assert max(below) < 0.01 and max(below) == min(below)
    at = SENSOR.voltage_v(SP.activation_force_n)
    assert at == pytest.approx(5.0 * 1e4 / (1e4 + 1e4 / 0.2), rel=1e-12)   # 0.833 V
    assert at > CONFIG.supervisor.sensor_voltage_threshold_v
    assert SENSOR.activation_step_v == pytest.approx(at - below[0], rel=1e-12)


def test_sensor_monotone_in_force():
    forces = np.linspace(0.0, 40.0, 4001)
    v = np.array([SENSOR.voltage_v(f) for f in forces])
    assert np.all(np.diff(v) >= 0.0)
    assert np.all(np.diff(v[forces > SP.activation_force_n]) > 0.0)
    assert v[-1] < SP.supply_v


def test_sensor_open_resistance_is_a_ceiling():
    sensor = FsrVoltageDivider(ForceSensorParams(5.0, 1e4, 1e4, 1e5, 0.01))
    # just above activation 1e4/0.02 = 5e5 ohm would exceed the open circuit: capped
    assert sensor.resistance_ohm(0.02) == 1e5
    assert sensor.voltage_v(0.02) == sensor.voltage_v(0.0)


def test_plant_sample_reports_sensor_voltage_of_its_force():
    plant = make_plant()
    plant.set_object(GraspObject(width_m=0.05))
    plant.touch_object()
    assert plant.sample().sensor_voltage_v == SENSOR.voltage_v(0.0)
    s = plant.step(2.0, 1e-3)
    assert s.sensor_voltage_v == pytest.approx(SENSOR.voltage_v(s.force_n), rel=1e-12)


# ------------------------------------------------------------------ fault injection


def gripping_plant(volts=8.0, width=0.05):
    """Finger at rest on a rigid object, current settled at ``volts / R`` (force 1.391 N/V)."""
    plant = make_plant()
    plant.set_object(GraspObject(width))
    plant.touch_object()
    for _ in range(50):                                   # 5 ms = 48 L/R: current settled
        plant.step(volts, 1e-4)
    return plant


def test_removal_fires_at_its_exact_instant_inside_a_step_then_free_motion():
    volts, t_split = 8.0, 0.37e-3
    plant = gripping_plant(volts)
    i0 = plant.sample().current_a
    x_c = plant.contact_position_m
    plant.schedule_fault(FaultKind.OBJECT_REMOVED, plant.t_ns + round(t_split * 1e6) * 1000)
    s = plant.step(volts, 1e-3)
    # analytic: current of the stalled motor (eq. 13) up to the fault, then free motion
    i_f = volts / R + (i0 - volts / R) * math.exp(-t_split / TAU_E)
    a, b = continuous_free_model()
    m = np.zeros((4, 4))
    m[:3, :3] = a
    m[:3, 3] = b[:, 0] * volts
    phi = expm(m * (1e-3 - t_split))
    expected = phi[:3, :3] @ np.array([i_f, 0.0, x_c]) + phi[:3, 3]
    assert s.current_a == pytest.approx(expected[0], rel=1e-9)
    assert s.speed_rad_s == pytest.approx(expected[1], rel=1e-9)
    assert s.position_m == pytest.approx(expected[2], rel=1e-12)
    assert s.position_m > x_c and s.force_n == 0.0 and not s.contact
    assert plant.fired_faults == [(FaultKind.OBJECT_REMOVED, plant.t_ns - 1_000_000
                                   + round(t_split * 1e9))]
    assert plant.contact_position_m == L_LS                 # nothing left: fingers would meet


def test_slipping_object_force_decays_exponentially_then_the_object_is_gone():
    volts, tau = 8.0, 0.004
    plant = gripping_plant(volts)
    f_0 = plant.sample().force_n
    assert f_0 == pytest.approx(STALL_N_PER_V * volts, rel=1e-6)
    x_c = plant.contact_position_m
    t_f = plant.t_ns
    plant.schedule_fault(FaultKind.OBJECT_SLIPPING, t_f, tau)
    for k in range(1, 3 * 40 + 1):                         # 3 tau in 0.1 ms steps
        s = plant.step(volts, 1e-4)
        assert s.force_n == pytest.approx(f_0 * math.exp(-k * 1e-4 / tau), rel=1e-9)
        assert s.contact
    assert plant.contact_state is ContactState.SLIPPING
    assert s.position_m > x_c                               # the finger advanced: face receded
    assert plant.contact_position_m == pytest.approx(s.position_m, abs=1e-12)
    for _ in range(2 * 40 + 1):                            # past 4.6 tau: below 1 % of F_0
        s = plant.step(volts, 1e-4)
    assert s.force_n == 0.0 and not s.contact and plant.contact_state is ContactState.FREE


def test_slip_with_the_motor_pushing_less_than_the_capacity_stays_stalled():
    plant = gripping_plant(8.0)
    f_0 = plant.sample().force_n
    plant.schedule_fault(FaultKind.OBJECT_SLIPPING, plant.t_ns, 0.004)
    plant.step(0.0, 0.002)                                  # motor off: the current decays
    s = plant.sample()
    cap = f_0 * math.exp(-0.5)
    motor = f_0 * math.exp(-0.002 / TAU_E)                  # eq. 13, zero input
    assert motor < cap and s.force_n == pytest.approx(motor, rel=1e-9)
    assert plant.contact_state is ContactState.RIGID_OBJECT and s.velocity_mps == 0.0


def test_sensor_dropout_reads_nan_and_leaves_the_mechanics_alone():
    a, b = gripping_plant(8.0), gripping_plant(8.0)
    a.schedule_fault(FaultKind.SENSOR_DROPOUT, a.t_ns + 250_000)
    for _ in range(2):
        sa, sb = a.step(5.0, 1e-4), b.step(5.0, 1e-4)
        assert math.isfinite(sa.force_n) and sa.voltage_v == sb.voltage_v
    sa, sb = a.step(5.0, 1e-4), b.step(5.0, 1e-4)
    assert math.isnan(sa.force_n) and math.isnan(sa.sensor_voltage_v)
    assert math.isnan(sa.peak_force_n)
    assert (sa.position_m, sa.current_a, sa.contact) == (sb.position_m, sb.current_a, sb.contact)
    a.set_object(GraspObject(0.05))                         # a new object: the sensor works again
    assert a.sample().force_n == b.sample().force_n and not a.sensor_dropped_out
    assert a.fired_faults == [] and a.scheduled_fault is None


def test_a_cancelled_fault_never_fires():
    plant = gripping_plant(8.0)
    plant.schedule_fault(FaultKind.OBJECT_REMOVED, plant.t_ns + 100_000)
    plant.cancel_fault()
    s = plant.step(8.0, 1e-3)
    assert s.force_n > 0.0 and plant.fired_faults == []


@pytest.mark.parametrize('kind, at_s, tau, rigid, words', [
    (9, 0.1, 0.0, True, 'unknown fault'),
    (FaultKind.OBJECT_REMOVED, -0.1, 0.0, True, 'fault_at_s'),
    (FaultKind.OBJECT_REMOVED, math.nan, 0.0, True, 'fault_at_s'),
    (FaultKind.OBJECT_SLIPPING, 0.1, -1.0, True, 'fault_time_constant_s'),
    (FaultKind.OBJECT_SLIPPING, 0.1, 0.0, False, 'rigid objects only'),
])
def test_bad_fault_requests_are_refused(kind, at_s, tau, rigid, words):
    with pytest.raises(ValueError, match=words):
        check_fault(kind, at_s, tau, rigid)
    assert check_fault(FaultKind.OBJECT_SLIPPING, 0.5, 0.0) == (FaultKind.OBJECT_SLIPPING, 0.01)
