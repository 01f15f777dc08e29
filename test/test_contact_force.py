"""The contact-aware force stage against closed-form answers and the plant (no ROS).

Known answers: the stall force per volt is eq. 13's DC gain, so the feed-forward alone holds
F_sp on any object; the reflected mass, the spring mode's natural frequency and the free impact
peak follow from Table I and the object; the contact speed is designed from them, the damping
gain places the closed loop's damping ratio exactly, and the loop time constant keeps the speed
servo's per-sample gain at its bound for the most damped object of a stiffness.
"""
import dataclasses
import math

from gripper_ros.core.config import load_config
from gripper_ros.core.control.contact_force import ContactForceController, impact_factor
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.plant import GraspObject
import numpy as np
import pytest

CONFIG = load_config()
PLANT = CONFIG.plant
TUNING = CONFIG.force.contact_aware
DT = CONFIG.force.sample_time_s
# Table I seen from the finger: the motor inertia and damping through the lead screw
M_R = PLANT.inertia_kg_m2 / (PLANT.force_lever_m * PLANT.travel_per_rad_m)


def _controller(**changes):
    return ContactForceController(PLANT, dataclasses.replace(TUNING, **changes), DT)


def _damping(k, zeta):
    """Return c for a damping ratio taken against the contact mode with the reflected mass."""
    return 2.0 * zeta * math.sqrt(k * M_R)


def test_reflected_mass_and_the_contact_speed_from_table_one():
    c = _controller()
    assert c.reflected_mass_kg == pytest.approx(545.8, abs=0.1)
    assert c.reflected_damping_n_s_per_m == pytest.approx(485.2, abs=0.1)
    alpha = TUNING.impact_force_fraction / (
        impact_factor(TUNING.design_damping_ratio)
        * math.sqrt(TUNING.design_stiffness_n_per_m * M_R))
    assert c.contact_speed_mps(5.0) == pytest.approx(alpha * 5.0, rel=1e-12)
    assert c.time_constant_s == pytest.approx(1.0 / (alpha * TUNING.design_stiffness_n_per_m))
    # the reference is continuous at contact: v_c = F_sp / (k_d tau)
    assert c.speed_profile_mps(5.0 / TUNING.design_stiffness_n_per_m) == pytest.approx(
        c.contact_speed_mps(5.0), rel=1e-12)


@pytest.mark.parametrize('zeta', [0.0, 0.01, 0.1, 0.3, 0.5, 0.7, 1.0])
def test_impact_factor_bounds_the_free_impact_peak(zeta):
    """Check the impact factor against the closed-form impact.

    A unit mass meets a Kelvin-Voigt contact at unit speed (omega_n = 1): the force
    x + 2 zeta x' peaks at most at max(1, 2 zeta), exactly so at zeta 0 and >= 0.5.
    """
    t = np.linspace(0.0, 10.0, 200001)
    wd = math.sqrt(1.0 - zeta * zeta) if zeta < 1.0 else 0.0
    if zeta < 1.0:
        x = np.exp(-zeta * t) * np.sin(wd * t) / wd
        xd = np.exp(-zeta * t) * (np.cos(wd * t) - zeta * np.sin(wd * t) / wd)
    else:
        x, xd = t * np.exp(-t), (1.0 - t) * np.exp(-t)
    peak = float(np.max(x + 2.0 * zeta * xd))
    assert peak <= impact_factor(zeta) + 1e-9
    if zeta == 0.0 or zeta >= 0.5:
        assert peak == pytest.approx(impact_factor(zeta), rel=1e-6)


def test_feedforward_is_the_stall_voltage_of_the_setpoint():
    c = _controller()
    c.reset(0.1)
    v = c.step(7.0, 7.0, 0.1, 0.1)               # in contact, at rest, no error
    assert v == pytest.approx(7.0 / PLANT.stall_force_per_volt_n, rel=1e-12)
    assert c.terms.in_contact and c.terms.damping_v == 0.0 and c.terms.force_v == 0.0


def test_approach_never_exceeds_the_feedforward_and_brakes_freely():
    c = _controller()
    c.reset(0.099)
    ff = 5.0 / PLANT.stall_force_per_volt_n
    assert c.step(5.0, 0.0, 0.099, 0.1) == pytest.approx(ff)       # 1 mm short, at rest: capped
    # now moving at 20 mm/s where the braking profile allows about 7.7 mm/s: brake hard
    v = c.step(5.0, 0.0, 0.099 + 0.02 * DT, 0.1)
    assert c.terms.speed_ref_mps == pytest.approx(
        c.speed_profile_mps(0.001 - 0.02 * DT) + c.contact_speed_mps(5.0), rel=1e-12)
    assert c.terms.speed_ref_mps < 0.01
    assert v == pytest.approx(-PLANT.voltage_limit_v)


def test_speed_profile_is_linear_then_a_braking_parabola_joined_smoothly():
    c = _controller()
    tau, a = c.time_constant_s, TUNING.braking_deceleration_mps2
    r0 = a * tau * tau
    assert c.speed_profile_mps(0.5 * r0) == pytest.approx(0.5 * r0 / tau, rel=1e-12)
    assert c.speed_profile_mps(r0) == pytest.approx(a * tau, rel=1e-12)
    assert c.speed_profile_mps(r0 * (1 + 1e-9)) == pytest.approx(a * tau, rel=1e-6)
    r = 0.01
    assert c.speed_profile_mps(r) == pytest.approx(math.sqrt(2 * a * (r - r0 / 2)), rel=1e-12)
    assert c.speed_profile_mps(-r) == -c.speed_profile_mps(r)
    # deceleration v dv/dr along the parabola is a
    h = 1e-7
    slope = (c.speed_profile_mps(r + h) - c.speed_profile_mps(r - h)) / (2 * h)
    assert c.speed_profile_mps(r) * slope == pytest.approx(a, rel=1e-5)


@pytest.mark.parametrize('k', [1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8])
def test_damping_gain_places_the_closed_loop_damping_ratio(k):
    """Closed form: m_r s^2 + (D + c_r) s + k (1 + K Kp) + D / tau_k, D = K_stall Kv."""
    c = _controller()
    tau = c.loop_time_constant_s(k)
    kv = c.damping_gain_for(k, tau)
    d = PLANT.stall_force_per_volt_n * kv
    spring = k * (1 + PLANT.stall_force_per_volt_n * TUNING.force_gain_v_per_n) + d / tau
    zeta = (d + c.reflected_damping_n_s_per_m) / (2 * math.sqrt(spring * M_R))
    assert kv < TUNING.max_damping_v_s_per_m
    assert zeta == pytest.approx(TUNING.damping_ratio, rel=1e-9)


@pytest.mark.parametrize('k', [1e2, 1e3, 1e4, 1e5])
def test_loop_time_constant_holds_the_servo_sample_gain_for_the_most_damped_object(k):
    """Check tau_k against its defining quadratic.

    tau_k solves 4 dt / tau_k (1 + c / (k tau_k)) = servo_sample_gain with c / k =
    2 zeta_d sqrt(m_r / k), where that is longer than tau; stiffer objects get tau.
    """
    c = _controller()
    tau_k = c.loop_time_constant_s(k)
    b = 2 * TUNING.design_damping_ratio * math.sqrt(M_R / k)
    assert tau_k > c.time_constant_s
    assert 4 * DT / tau_k * (1 + b / tau_k) == pytest.approx(TUNING.servo_sample_gain, rel=1e-9)
    assert c.loop_time_constant_s(TUNING.design_stiffness_n_per_m) == c.time_constant_s


def test_open_loop_spring_mode_matches_the_closed_form():
    """Without control the stiff object rings at omega_n = sqrt(k / m_r).

    That is the reason the rigid loop's PI cannot hold a compliant object.
    """
    k = 1e5
    omega = math.sqrt(k / M_R)
    plant = make_plant(CONFIG)
    plant.set_object(GraspObject(0.05, k, 0.0))
    plant.touch_object()
    v = 1.0
    f = []
    for _ in range(int(2.0 / 1e-3)):
        f.append(plant.step(v, 1e-3).force_n)
    f = np.array(f)
    peaks = [i for i in range(1, f.size - 1) if f[i - 1] < f[i] >= f[i + 1]]
    period = (peaks[1] - peaks[0]) * 1e-3
    assert period == pytest.approx(2 * math.pi / omega, rel=0.02)
    assert f.max() > 1.8 * PLANT.stall_force_per_volt_n * v          # ~2x: lightly damped


def _hold(k, c_damp, force_n, gap_m, speed_mps, seconds, tuning_changes=None):
    """Let the stage take over with the finger ``gap_m`` short of the face at ``speed_mps``.

    Returns (peak force, final force, voltages, peak force over the first sample of contact).
    """
    plant = make_plant(CONFIG)
    face = 0.1
    plant.set_object(GraspObject(PLANT.max_travel_m - face, k, c_damp))
    ctrl = _controller(**(tuning_changes or {}))
    # bring the finger to the start condition with the free model
    s = plant.sample()
    while s.position_m < face - gap_m - 0.02:
        s = plant.step(24.0, 1e-3)
    while s.position_m < face - gap_m:
        s = plant.step(24.0 if s.velocity_mps < speed_mps else -24.0, 1e-4)
    ctrl.reset(s.position_m)
    peak, impact, touched = 0.0, 0.0, None
    volts = []
    for n in range(int(seconds / DT)):
        v = ctrl.step(force_n, s.force_n, s.position_m, face)
        volts.append(v)
        s = plant.step(v, DT)
        peak = max(peak, s.peak_force_n)
        if touched is None and s.force_n > 0.0:
            touched = n
        if touched == n:
            impact = s.peak_force_n
    return peak, s.force_n, np.array(volts), impact


ENVELOPE_CORNERS = [('rigid', 0.0, 0.0), ('1e2 N/m zeta 0.01', 1e2, 0.01),
                    ('1e4 N/m zeta 1', 1e4, 1.0), ('1e6 N/m zeta 0.01', 1e6, 0.01),
                    ('1e8 N/m zeta 0.01', 1e8, 0.01), ('1e8 N/m zeta 1', 1e8, 1.0)]


@pytest.mark.parametrize('name,k,zeta', ENVELOPE_CORNERS)
@pytest.mark.parametrize('force_n', [0.5, 5.0])
def test_no_spike_across_the_stiffness_envelope(name, k, zeta, force_n):
    """Hand over 1 mm short at 1.5 mm/s, as the position stage does.

    The peak stays within 1.10 x F_sp, the force ends within 2 %, the voltage within +-24 V.
    The time allowed covers the approach, a soft object's compression and a damped object's
    creep (c / k).
    """
    creep_s = _damping(k, zeta) / k if k else 0.0
    seconds = (6.0 if k and k < 1e3 else 1.0) + 10.0 * creep_s
    peak, final, volts, _ = _hold(k, _damping(k, zeta), force_n, 1e-3, 1.5e-3, seconds)
    assert peak <= 1.10 * force_n
    assert final == pytest.approx(force_n, rel=0.02)
    assert np.all(np.abs(volts) <= PLANT.voltage_limit_v)


def test_the_design_object_is_met_with_the_designed_impact():
    """Meet the stiffest, most damped object of the design at v_c.

    Its damper alone puts c v_c = impact_force_fraction x F_sp on it at first touch, whatever
    the motor does next.
    """
    k, zeta = TUNING.design_stiffness_n_per_m, TUNING.design_damping_ratio
    _, _, _, impact = _hold(k, _damping(k, zeta), 5.0, 1e-3, 1.5e-3, 1.0)
    assert impact == pytest.approx(TUNING.impact_force_fraction * 5.0, rel=0.05)


def test_without_the_damper_bound_on_tau_k_a_soft_damped_object_makes_the_servo_chatter():
    """Show why loop_time_constant_s bounds tau_k (the control case).

    With tau_k = tau on a 1e3 N/m, zeta 1 object the damper feeds the speed back through the
    force 140 times over and the sampled servo chatters between the rails; with the bound it
    compresses the object smoothly.
    """
    k, c_damp = 1e3, _damping(1e3, 1.0)
    _, _, volts, _ = _hold(k, c_damp, 0.5, 1e-3, 1.5e-3, 4.0)
    _, _, volts_fast, _ = _hold(k, c_damp, 0.5, 1e-3, 1.5e-3, 4.0,
                                {'servo_sample_gain': 1e9})
    assert np.sum(np.abs(volts_fast) >= PLANT.voltage_limit_v) > 100
    assert np.sum(np.abs(volts) >= PLANT.voltage_limit_v) == 0


def test_the_rigid_loops_pi_would_spike_on_the_stiff_object():
    """Hand the stiff object over to the paper-style PI instead (the control case).

    With our rigid gains it overshoots many times over, which is what this stage exists to
    prevent.
    """
    from gripper_ros.core.control.factories import make_force_controller
    from gripper_ros.wire import ForceControllerKind
    plant = make_plant(CONFIG)
    plant.set_object(GraspObject(PLANT.max_travel_m - 0.1, 1e5, 50.0))
    plant.touch_object()
    pi = make_force_controller(CONFIG, ForceControllerKind.PI)
    s = plant.sample()
    peak = 0.0
    for _ in range(int(1.0 / DT)):
        s = plant.step(pi.step(5.0, s.force_n), DT)
        peak = max(peak, s.peak_force_n)
    assert peak > 2.0 * 5.0


def test_integral_trims_a_wrong_stall_gain_only_at_rest():
    """Model error: the plant's motor is 20 % weaker than the controller believes.

    The feed-forward alone would hold 0.8 F_sp on a rigid object; the trim restores F_sp.
    """
    weak = dataclasses.replace(PLANT,
                               torque_constant_n_m_per_a=0.8 * PLANT.torque_constant_n_m_per_a)
    plant = make_plant(dataclasses.replace(CONFIG, plant=weak))
    plant.set_object(GraspObject(PLANT.max_travel_m - 0.1))
    plant.touch_object()
    ctrl = _controller(integral_gain_v_per_n_s=20.0)
    s = plant.sample()
    ctrl.reset(s.position_m)
    for _ in range(int(1.0 / DT)):
        s = plant.step(ctrl.step(5.0, s.force_n, s.position_m, s.position_m), DT)
    assert s.force_n == pytest.approx(5.0, rel=0.01)
    assert ctrl.terms.integral_v > 0.0


@pytest.mark.parametrize('bad', ['force_setpoint_n', 'force_n', 'position_m', 'face_m',
                                 'width_tolerance_m'])
def test_non_finite_input_is_refused_and_changes_nothing(bad):
    c = _controller()
    c.reset(0.1)
    args = {'force_setpoint_n': 5.0, 'force_n': 0.0, 'position_m': 0.1, 'face_m': 0.1,
            'width_tolerance_m': 0.0}
    args[bad] = math.nan
    with pytest.raises(ValueError, match=bad):
        c.step(**args)
    assert c.step(5.0, 0.0, 0.1, 0.1) == c.step(5.0, 0.0, 0.1, 0.1)   # speed still 0


def test_within_a_tolerance_the_band_is_crossed_at_the_band_speed():
    """Beyond the widest face the reference is the band's speed.

    With the band designed for a softer object it is faster by sqrt(k_d / k_band).
    """
    c = _controller()
    c.reset(0.097)
    c.step(5.0, 0.0, 0.097, 0.1, 0.004)              # 1 mm past the widest face (96 mm)
    assert c.terms.speed_ref_mps == pytest.approx(c.contact_speed_mps(5.0), rel=1e-12)
    soft = _controller(band_design_stiffness_n_per_m=1e4)
    assert soft.contact_speed_mps(5.0, 0.004) == pytest.approx(
        100.0 * soft.contact_speed_mps(5.0), rel=1e-12)


def test_within_a_tolerance_the_stiffness_estimate_starts_at_the_band_design():
    """At first touch the loop assumes the stiffest object it was designed to meet.

    That is k_d at an exact width, the band design stiffness within a tolerance, so that the
    speed reference does not drop below the band speed at contact.
    """
    soft = _controller(band_design_stiffness_n_per_m=1e4)
    for tol, k_cap in ((0.0, TUNING.design_stiffness_n_per_m), (0.001, 1e4)):
        soft.reset(0.1)
        soft.step(5.0, 1e-3, 0.1, 0.1, tol)                      # touched here
        assert soft.terms.stiffness_n_per_m == TUNING.design_stiffness_n_per_m   # no travel yet
        soft.step(5.0, 1e-3, 0.1 + 1e-12, 0.1, tol)              # 1 pm in, 1 mN: ~1e9 N/m
        assert soft.terms.in_contact and soft.terms.stiffness_n_per_m == k_cap
        tau_k = soft.loop_time_constant_s(k_cap)
        assert soft.terms.speed_ref_mps == pytest.approx(
            soft.speed_profile_mps((5.0 - 1e-3) / k_cap, tau_k), rel=1e-12)
        assert soft.terms.speed_ref_mps >= soft.contact_speed_mps(5.0 - 1e-3, tol)


def test_a_rigid_face_within_a_softer_band_design_is_still_met_at_the_setpoint():
    """No travel after the touch is rigid contact, whatever the band: k_d's loop.

    Its speed reference is a small force gain on the stalled motor; a band loop would drive it
    into the rail.
    """
    plant = make_plant(CONFIG)
    plant.set_object(GraspObject(PLANT.max_travel_m - 0.1))
    plant.touch_object()
    ctrl = _controller(band_design_stiffness_n_per_m=1e4)
    s = plant.sample()
    ctrl.reset(s.position_m)
    peak = 0.0
    for _ in range(int(0.05 / DT)):
        s = plant.step(ctrl.step(0.5, s.force_n, s.position_m, 0.1 + 0.001, 0.001), DT)
        peak = max(peak, s.peak_force_n)
    assert peak <= 1.10 * 0.5 and s.force_n == pytest.approx(0.5, rel=1e-3)


def test_past_the_narrowest_face_untouched_it_drives_at_the_feedforward_not_a_crawl():
    """No object (or a narrower one): beyond the narrowest face the motor gets V_ff.

    The speed reference no longer applies and the motor gets exactly the stall voltage of F_sp,
    so NO_OBJECT comes in a fraction of a second; a touching finger (any force) keeps its force
    loop.
    """
    c = _controller()
    c.reset(0.1005)
    ff = 5.0 / PLANT.stall_force_per_volt_n
    assert c.step(5.0, 0.0, 0.1005, 0.1) == pytest.approx(ff)
    assert c.step(5.0, 0.0, 0.1005 + 0.005 * DT, 0.1) == pytest.approx(ff)   # 5 mm/s: no brake
    banded = _controller()                                # within a 1 mm tolerance: brakes
    banded.reset(0.1005)
    assert banded.step(5.0, 0.0, 0.1005 + 0.005 * DT, 0.1, 0.001) == -PLANT.voltage_limit_v
    touching = _controller()
    touching.reset(0.1005)
    touching.step(5.0, 0.01, 0.1005, 0.1)
    assert touching.terms.in_contact
    assert touching.step(5.0, 0.01, 0.1005 + 0.005 * DT, 0.1) < 0.0          # brakes


def test_no_object_is_found_quickly():
    from gripper_ros.core.runtime.headless import simulate_grasp
    g = simulate_grasp(CONFIG, 0.05, 0.42, object_width_m=0.0)     # F_sp 6.18 N
    assert g.outcome.name == 'NO_OBJECT'
    # a crawl at the contact speed over the no-object margin would take margin / v_c
    crawl_s = CONFIG.supervisor.no_object_margin_m / _controller().contact_speed_mps(
        g.force_setpoint_n)
    assert crawl_s > 100.0
    assert (g.end_ns - g.switch_ns) * 1e-9 < 0.01 * crawl_s


def _ramp(k, c_damp, rate_n_per_s, tuning_changes=None):
    """Settle on the object at 2 N, then raise the setpoint at ``rate_n_per_s`` for 0.5 s.

    Returns (force error at the ramp's end, peak over the setpoint during and after it).
    """
    plant = make_plant(CONFIG)
    face = 0.1
    plant.set_object(GraspObject(PLANT.max_travel_m - face, k, c_damp))
    ctrl = _controller(**(tuning_changes or {}))
    s = plant.sample()
    while s.position_m < face - 1e-3 - 0.02:
        s = plant.step(24.0, 1e-3)
    while s.position_m < face - 1e-3:
        s = plant.step(24.0 if s.velocity_mps < 1.5e-3 else -24.0, 1e-4)
    ctrl.reset(s.position_m)
    start_n = 2.0
    for _ in range(int(3.0 / DT)):                       # touch and settle at the start
        s = plant.step(ctrl.step(start_n, s.force_n, s.position_m, face), DT)
    overshoot = 0.0
    ramp_samples = int(0.5 / DT)
    for n in range(ramp_samples + int(1.0 / DT)):
        sp = start_n + rate_n_per_s * DT * min(n + 1, ramp_samples)
        s = plant.step(ctrl.step(sp, s.force_n, s.position_m, face), DT)
        overshoot = max(overshoot, s.peak_force_n - sp)
        if n + 1 == ramp_samples:
            lag_n = sp - s.force_n
    return lag_n, overshoot


@pytest.mark.parametrize('k', [1e4, 1e5])
def test_a_moving_setpoint_is_followed_without_the_loops_lag_or_a_spike(k):
    """A ramp's rate over the spring leads the speed reference.

    Without it the first-order loop trails a ramp by rate x its time constant; with it the
    force is on the ramp at its end, and passes the final setpoint by no more than 10 %.
    """
    rate = 20.0                                          # N/s: 2 N -> 12 N in 0.5 s
    c_damp = _damping(k, 0.5)
    lag, overshoot = _ramp(k, c_damp, rate)
    # a filter of 1e9 s never lets the rate through: the loop alone
    lag_off, _ = _ramp(k, c_damp, rate, {'setpoint_rate_time_constant_s': 1e9})
    assert abs(lag) < 0.2 * lag_off
    assert overshoot <= 0.10 * (2.0 + 0.5 * rate)
