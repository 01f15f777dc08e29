"""Supervisor state machine and request validation (no ROS): eq. 23 and the switching rules."""
import math

import pytest

from gripper_ros.config import load_config
from gripper_ros.grasp_logic import (ActiveController, GraspRequest, GraspSupervisor, Outcome,
                                     Phase, RequestError, SwitchCriterion, force_setpoint_n,
                                     validate_request)

CFG = load_config()
P, S = CFG.plant, CFG.supervisor
MS = 1_000_000


def targets(width=0.05, mass=1.69, **kw):
    return validate_request(GraspRequest(width, mass, **kw), P, S)


def test_eq23_and_position_setpoint():
    t = targets(0.05, 1.69, friction_coefficient=0.8, acceleration_mps2=2.0)
    assert t.force_setpoint_n == pytest.approx(0.8 * 1.69 * (9.81 + 2.0))
    assert t.position_setpoint_m == pytest.approx(0.15 - 0.05)
    assert force_setpoint_n(2.0, 0.5, 9.81, 0.0) == pytest.approx(9.81)


def test_defaults_are_resolved_from_config():
    t = targets()
    assert t.friction_coefficient == S.friction_coefficient
    assert t.timeout_s == S.timeout_s


@pytest.mark.parametrize('fields, words', [
    (dict(width_m=math.nan), 'width_m must be a finite'),
    (dict(mass_kg=math.inf), 'mass_kg must be a finite'),
    (dict(width_m=0.0), 'width_m must be in'),
    (dict(width_m=0.15), 'width_m must be in'),
    (dict(mass_kg=0.0), 'mass_kg must be > 0'),
    (dict(friction_coefficient=-1e-9), 'friction_coefficient must be >= 0'),
    (dict(acceleration_mps2=-1.0), 'acceleration_mps2 must be >= 0'),
    (dict(timeout_s=1e9), 'timeout_s must be in'),
    (dict(mass_kg=7.0), 'exceeds the 33.39 N'),            # 0.5*7*9.81 = 34.3 N > 33.39 N
])
def test_bad_requests_are_refused_with_the_reason(fields, words):
    req = dict(width_m=0.05, mass_kg=1.0)
    req.update(fields)
    with pytest.raises(RequestError, match=words):
        validate_request(GraspRequest(**req), P, S)


def test_largest_mass_the_motor_can_hold_is_accepted():
    m_max = P.max_force_n / (S.friction_coefficient * P.gravity_mps2)
    assert targets(mass=m_max * 0.999).force_setpoint_n < P.max_force_n


def start(width=0.05, mass=1.69):
    sup = GraspSupervisor(P, S)
    d = sup.start(targets(width, mass), 0, 0.005)
    assert d.phase is Phase.POSITION and d.active is ActiveController.POSITION
    return sup


def test_switch_on_position_tolerance_exactly_at_2_percent():
    sup = start()
    x_sp = 0.1
    d = sup.step(10 * MS, x_sp * (1 - 0.021), 0.0, 0.005)
    assert d.phase is Phase.POSITION
    d = sup.step(20 * MS, x_sp * (1 - 0.0199), 0.0, 0.005)
    assert d.phase is Phase.FORCE and d.active is ActiveController.FORCE
    assert d.switch_criterion is SwitchCriterion.POSITION_TOLERANCE


def test_switch_on_sensor_voltage_rise_far_from_the_setpoint():
    sup = start()
    d = sup.step(10 * MS, 0.05, 0.0, 0.005 + S.sensor_voltage_threshold_v * 0.99)
    assert d.phase is Phase.POSITION
    d = sup.step(20 * MS, 0.05, 0.3, 0.005 + S.sensor_voltage_threshold_v * 1.01)
    assert d.switch_criterion is SwitchCriterion.SENSOR_VOLTAGE
    assert sup.contact_ns == 20 * MS


def test_holding_after_the_force_stays_in_band_for_the_hold_time():
    sup = start()
    sup.step(10 * MS, 0.0995, 0.0, 0.005)
    f_sp = sup.targets.force_setpoint_n
    hold_ns = int(S.force_settle_hold_s * 1e9)
    t = 20 * MS
    d = sup.step(t, 0.1, f_sp * 1.01, 4.0)
    d = sup.step(t + hold_ns - 100_000, 0.1, f_sp * 1.01, 4.0)
    assert d.phase is Phase.FORCE
    d = sup.step(t + hold_ns, 0.1, f_sp * 0.99, 4.0)
    assert d.outcome is Outcome.HOLDING and d.active is ActiveController.NONE


def test_leaving_the_band_restarts_the_hold_timer():
    sup = start()
    sup.step(10 * MS, 0.0995, 0.0, 0.005)
    f_sp = sup.targets.force_setpoint_n
    hold_ns = int(S.force_settle_hold_s * 1e9)
    sup.step(20 * MS, 0.1, f_sp, 4.0)
    sup.step(21 * MS, 0.1, f_sp * 1.05, 4.0)              # out of the 2 % band
    d = sup.step(20 * MS + hold_ns, 0.1, f_sp, 4.0)
    assert d.phase is Phase.FORCE


def test_no_object_when_the_finger_passes_the_face_without_contact():
    sup = start()
    d = sup.step(10 * MS, 0.1 + S.no_object_margin_m * 1.01, 0.0, 0.005)
    assert d.outcome is Outcome.NO_OBJECT and d.phase is Phase.FAILED


def test_timeout_in_simulated_time():
    sup = start()
    d = sup.step(int(S.timeout_s * 1e9), 0.05, 0.0, 0.005)
    assert d.phase is Phase.POSITION
    d = sup.step(int(S.timeout_s * 1e9) + 10 * MS, 0.05, 0.0, 0.005)
    assert d.outcome is Outcome.TIMEOUT


def test_non_finite_measurement_is_a_fault_and_no_controller_drives():
    sup = start()
    d = sup.step(10 * MS, math.nan, 0.0, 0.005)
    assert d.outcome is Outcome.FAULT and d.active is ActiveController.NONE


def test_stop_and_a_second_start_while_busy():
    sup = start()
    with pytest.raises(RequestError, match='already running'):
        sup.start(targets(), 10 * MS, 0.0)
    d = sup.stop()
    assert d.outcome is Outcome.STOPPED and not sup.busy
    assert sup.start(targets(), 20 * MS, 0.0).phase is Phase.POSITION
