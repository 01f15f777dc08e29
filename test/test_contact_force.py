"""The contact-aware force stage against closed-form answers and the plant (no ROS).

Known answers: the stall force per volt is eq. 13's DC gain, so the feed-forward alone holds
F_sp on any object; the spring mode's natural frequency and damping follow from Table I and the
stiffness; the damping gain places that mode's damping ratio exactly.
"""
import dataclasses
import math

from gripper_ros.core.config import load_config
from gripper_ros.core.contact_force import ContactForceController
from gripper_ros.core.controllers import make_plant
from gripper_ros.core.plant import GraspObject
import numpy as np
import pytest

CONFIG = load_config()
PLANT = CONFIG.plant
TUNING = CONFIG.force.contact_aware
DT = CONFIG.force.sample_time_s


def _controller(**changes):
    return ContactForceController(PLANT, dataclasses.replace(TUNING, **changes), DT)


def test_feedforward_is_the_stall_voltage_of_the_setpoint():
    c = _controller()
    c.reset(0.1)
    v = c.step(7.0, 7.0, 0.1, 0.1)               # in contact, at rest, no error
    assert v == pytest.approx(7.0 / PLANT.stall_force_per_volt_n, rel=1e-12)
    assert c.terms.force_v == 0.0 and c.terms.damping_v == 0.0


def test_approach_never_exceeds_the_feedforward_and_brakes_freely():
    c = _controller()
    c.reset(0.099)
    ff = 5.0 / PLANT.stall_force_per_volt_n
    assert c.step(5.0, 0.0, 0.099, 0.1) == pytest.approx(ff)       # 1 mm short, at rest: capped
    # now moving at 20 mm/s where the reference is gap / tau + v_min = 10.15 mm/s: brake hard
    v = c.step(5.0, 0.0, 0.099 + 0.02 * DT, 0.1)
    assert c.terms.speed_ref_mps == pytest.approx(
        (0.001 - 0.02 * DT) / TUNING.approach_time_constant_s
        + TUNING.contact_speed_mps_per_n * 5.0, rel=1e-9)
    assert v == pytest.approx(-PLANT.voltage_limit_v)


def test_damping_gain_places_the_spring_mode_damping_ratio():
    """Closed form: J s^2 + (b_m + Kv k_t rho / R) s + k lever rho (1 + K_stall Kp) = 0."""
    c = _controller(max_damping_v_s_per_m=1e9)
    kp = TUNING.force_gain_v_per_n
    for k in (1e3, 1e4, 1e5):
        kv = c.damping_gain_for(k, kp)
        spring = k * PLANT.force_lever_m * PLANT.travel_per_rad_m * (
            1 + PLANT.stall_force_per_volt_n * kp)
        damping = PLANT.damping_n_m_s_per_rad + kv * (
            PLANT.torque_constant_n_m_per_a / PLANT.resistance_ohm * PLANT.travel_per_rad_m)
        zeta = damping / (2 * math.sqrt(spring * PLANT.inertia_kg_m2))
        assert zeta == pytest.approx(TUNING.damping_ratio, rel=1e-12)
    assert c.damping_gain_for(math.inf, kp) == 1e9


def test_open_loop_spring_mode_matches_the_closed_form():
    """Without control the stiff object rings at omega_n = sqrt(k lever rho / J).

    That is the reason the rigid loop's PI cannot hold a compliant object.
    """
    k = 1e5
    omega = math.sqrt(k * PLANT.force_lever_m * PLANT.travel_per_rad_m / PLANT.inertia_kg_m2)
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


def _hold(k, c_damp, force_n, gap_m, speed_mps, seconds=8.0):
    """Finger ``gap_m`` short of the face, moving at ``speed_mps``; the stage takes over."""
    plant = make_plant(CONFIG)
    face = 0.1
    plant.set_object(GraspObject(PLANT.max_travel_m - face, k, c_damp))
    ctrl = _controller()
    # bring the finger to the start condition with the free model: run it at a steady voltage
    s = plant.sample()
    while s.position_m < face - gap_m - 0.02:
        s = plant.step(24.0, 1e-3)
    while s.position_m < face - gap_m:
        target = speed_mps
        s = plant.step(24.0 if s.velocity_mps < target else -24.0, 1e-4)
    ctrl.reset(s.position_m)
    peak = 0.0
    volts = []
    for _ in range(int(seconds / DT)):
        v = ctrl.step(force_n, s.force_n, s.position_m, face)
        volts.append(v)
        s = plant.step(v, DT)
        peak = max(peak, s.peak_force_n)
    return peak, s.force_n, np.array(volts)


@pytest.mark.parametrize('name,k,c', [('rigid', 0.0, 0.0), ('stiff', 1e5, 50.0),
                                      ('soft', 1e3, 5.0)])
@pytest.mark.parametrize('force_n', [0.5, 14.7])
def test_no_spike_on_rigid_stiff_or_soft_objects(name, k, c, force_n):
    """From 1 mm short at 1.5 mm/s (what the position stage hands over): no spike.

    The peak stays within 1.10 x F_sp, the force ends within 2 %, the voltage within +-24 V.
    """
    peak, final, volts = _hold(k, c, force_n, 1e-3, 1.5e-3)
    assert peak <= 1.10 * force_n
    assert final == pytest.approx(force_n, rel=0.02)
    assert np.all(np.abs(volts) <= PLANT.voltage_limit_v)


def test_the_rigid_loops_pi_would_spike_on_the_stiff_object():
    """The control: the same hand-over into the paper-style PI overshoots many times over.

    The PI (our rigid gains) on the stiff object: what this stage exists to prevent.
    """
    from gripper_ros.core.controllers import ForceControllerKind, make_force_controller
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


def test_non_finite_input_is_refused():
    c = _controller()
    with pytest.raises(ValueError):
        c.step(5.0, math.nan, 0.1, 0.1)


def test_past_the_expected_face_untouched_it_drives_at_the_feedforward_not_a_crawl():
    """No object (or a narrower one): NO_OBJECT comes in a fraction of a second.

    Beyond the face the speed reference no longer applies and the motor gets exactly the stall
    voltage of F_sp; a touching finger (any force) keeps the crawl.
    """
    c = _controller()
    c.reset(0.1005)
    ff = 5.0 / PLANT.stall_force_per_volt_n
    assert c.step(5.0, 0.0, 0.1005, 0.1) == pytest.approx(ff)
    assert c.step(5.0, 0.0, 0.1005 + 0.005 * DT, 0.1) == pytest.approx(ff)   # 5 mm/s: no brake
    touching = _controller()
    touching.reset(0.1005)
    touching.step(5.0, 0.01, 0.1005, 0.1)
    assert touching.step(5.0, 0.01, 0.1005 + 0.005 * DT, 0.1) < 0.0          # brakes to v_min


def test_no_object_is_found_quickly():
    from gripper_ros.core.headless import simulate_grasp
    g = simulate_grasp(CONFIG, 0.05, 0.42, object_width_m=0.0)     # F_sp 6.18 N
    assert g.outcome.name == 'NO_OBJECT'
    # a crawl at the contact speed over the no-object margin would take margin / v_min
    crawl_s = CONFIG.supervisor.no_object_margin_m / (
        TUNING.contact_speed_mps_per_n * g.force_setpoint_n)
    assert crawl_s > 10.0
    assert (g.end_ns - g.switch_ns) * 1e-9 < 0.1 * crawl_s       # measured 0.66 s
