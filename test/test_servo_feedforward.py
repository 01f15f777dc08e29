"""The position servo's feed-forward and setpoint estimate, against closed forms.

The feed-forward voltage is the free finger's model inverted (paper eqs. 1-11, Table I): held
over each 10 ms sample of the exact zero-order-hold plant it keeps the finger on a trajectory
with no feedback at all (a constant acceleration: exactly to second order in the sample over
the mechanical time constant); at constant speed it is that speed over the free speed per volt. The
stream's fit is a weighted least-squares cubic: setpoints of any cubic, at any instants, give
its velocity and acceleration exactly. The reference between setpoints is the closed form of
the newest setpoint's motion, then of braking at what 24 V gives at rest.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.control.servo_feedforward import (feedforward_gains, feedforward_v,
                                                        new_stream, stream_changing,
                                                        stream_reference, stream_sample)
import numpy as np
import pytest

CONFIG = load_config()
P = CONFIG.plant
S = CONFIG.supervisor
DT_S = CONFIG.position.sample_time_s
MEMORY_S = S.servo_fit_memory_s
WINDOW_S = S.servo_rate_window_s
TRAVEL_M = P.max_travel_m
MS = 1_000_000


def test_the_gains_are_the_free_speed_per_volt_and_the_mechanical_time_constant():
    k_v, k_a = feedforward_gains(P)
    assert 1.0 / k_v == pytest.approx(P.free_speed_per_volt_mps, rel=1e-12)
    # k_a / k_v = (R J + L b) / (R b + k_t k_b): tau_m with the armature's L b added
    assert k_a / k_v == pytest.approx(
        P.mechanical_time_constant_s + P.inductance_h * P.damping_n_m_s_per_rad
        / (P.resistance_ohm * P.damping_n_m_s_per_rad
           + P.torque_constant_n_m_per_a * P.back_emf_v_s_per_rad), rel=1e-12)
    assert feedforward_v(k_v, k_a, 0.04, 0.0, DT_S) == \
        pytest.approx(0.04 / P.free_speed_per_volt_mps)


def _follow_open_loop(trajectory, seconds: float):
    """Drive the exact ZOH plant with the feed-forward alone; return the worst position error."""
    k_v, k_a = feedforward_gains(P)
    ad, bd = make_plant(CONFIG).discrete_free_model(DT_S)
    x0, v0, a0 = trajectory(0.0)
    omega = v0 / P.travel_per_rad_m           # the trajectory's own state at t = 0
    current = (P.inertia_kg_m2 * a0 / P.travel_per_rad_m
               + P.damping_n_m_s_per_rad * omega) / P.torque_constant_n_m_per_a
    state = np.array([current, omega, x0])
    worst = 0.0
    for k in range(round(seconds / DT_S)):
        _, v, a = trajectory(k * DT_S)
        state = ad @ state + bd * feedforward_v(k_v, k_a, v, a, DT_S)
        worst = max(worst, abs(state[2] - trajectory((k + 1) * DT_S)[0]))
    return worst


def test_feed_forward_alone_keeps_the_exact_plant_on_a_constant_acceleration():
    """A position 0.01 + a t^2 / 2 for 3 s: no feedback, 300 zero-order holds, within 1 um."""
    a = 0.012
    worst = _follow_open_loop(lambda t: (0.01 + 0.5 * a * t * t, a * t, a), 3.0)
    assert worst < 1e-6, worst


def test_feed_forward_alone_keeps_the_exact_plant_at_constant_speed_from_a_start():
    """0.035 m/s from 0.02 m: k_v v held, the exact ZOH plant stays on x0 + v t within 1 nm."""
    worst = _follow_open_loop(lambda t: (0.02 + 0.035 * t, 0.035, 0.0), 3.0)
    assert worst < 1e-9, worst


@pytest.mark.parametrize('instants_ms', [list(range(0, 200, 10)),
                                         [0, 10, 10, 30, 40, 40, 40, 70, 80, 100, 130, 140],
                                         [0, 10, 30, 20, 40, 60, 50, 70, 100, 80, 90, 110]])
def test_the_fit_gives_a_cubic_s_velocity_and_acceleration_exactly(instants_ms):
    """Setpoints of x = c0 + c1 t + c2 t^2 + c3 t^3 at regular, bunched or reordered instants.

    Reordered: each sampled ahead by a period that varies (a FollowJointTrajectory server's
    ``now + period``, the period measured from the samples it got), so one may be older than the
    one before; the newest stays the reference's base.
    """
    c0, c1, c2, c3 = 0.05, 0.03, -0.02, 0.04
    servo = new_stream(P)
    for t_ms in instants_ms:
        t = t_ms * 1e-3
        stream_sample(servo, t_ms * MS, c0 + t * (c1 + t * (c2 + t * c3)), math.nan, math.nan,
                      MEMORY_S, WINDOW_S)
    t = max(instants_ms) * 1e-3
    assert servo[0]['velocity_mps'] == pytest.approx(c1 + t * (2 * c2 + 3 * c3 * t), rel=1e-7)
    assert servo[0]['acceleration_mps2'] == pytest.approx(2 * c2 + 6 * c3 * t, rel=1e-6)
    assert (servo[0]['t_ns'], servo[0]['position_m']) == (
        max(instants_ms) * MS, pytest.approx(c0 + t * (c1 + t * (c2 + t * c3)), abs=1e-15))


def test_given_velocity_and_acceleration_are_taken_as_given():
    servo = new_stream(P)
    stream_sample(servo, 0, 0.05, 0.02, -0.01, MEMORY_S, WINDOW_S)
    assert (servo[0]['velocity_mps'], servo[0]['acceleration_mps2']) == (0.02, -0.01)


def test_the_reference_moves_on_then_brakes_to_rest_then_stands_at_the_setpoint():
    """Closed forms: x + v t + a t^2 / 2 for the window; then braking at D = 24 V / k_a."""
    x, v, a = 0.05, 0.02, 0.01
    servo = new_stream(P)
    stream_sample(servo, 0, x, v, a, MEMORY_S, WINDOW_S)
    d = P.voltage_limit_v / feedforward_gains(P)[1]
    t = 0.5 * WINDOW_S
    assert stream_reference(servo, round(t * 1e9), WINDOW_S, 0.0, 0.05, TRAVEL_M) == \
        pytest.approx((x + v * t + 0.5 * a * t * t, v + a * t, a), rel=1e-12)
    x_w, v_w = x + v * WINDOW_S + 0.5 * a * WINDOW_S ** 2, v + a * WINDOW_S
    t = 0.5 * v_w / d                          # halfway through braking
    assert stream_reference(servo, round((WINDOW_S + t) * 1e9), WINDOW_S, 0.0, 0.05,
                            TRAVEL_M) == pytest.approx((x_w + v_w * t - 0.5 * d * t * t,
                                                        v_w - d * t, -d), rel=1e-6)
    stop_s = WINDOW_S + v_w / d
    assert stream_reference(servo, round((stop_s + 0.001) * 1e9), WINDOW_S, 0.0, 0.05,
                            TRAVEL_M) == (x, 0.0, 0.0)
    # the speed limit caps it, the travel bounds it
    assert stream_reference(servo, 0, WINDOW_S, 0.0, 0.01, TRAVEL_M)[1] == 0.01
    stream_sample(servo, 1, TRAVEL_M - 1e-4, 0.05, 0.0, MEMORY_S, WINDOW_S)
    assert stream_reference(servo, 100 * MS, WINDOW_S, 0.0, 0.05, TRAVEL_M) == (TRAVEL_M, 0.0, 0.0)


def test_a_setpoint_the_motor_cannot_reach_in_time_restarts_the_estimate():
    """A stream at 0.03 m/s, then 20 mm on in 10 ms (2 m/s): a jump, velocity unknown again."""
    servo = new_stream(P)
    for k in range(10):
        stream_sample(servo, k * 10 * MS, 0.05 + 0.0003 * k, math.nan, math.nan, MEMORY_S,
                      WINDOW_S)
    assert servo[0]['velocity_mps'] == pytest.approx(0.03, rel=1e-9)
    stream_sample(servo, 100 * MS, 0.073, math.nan, math.nan, MEMORY_S, WINDOW_S)
    assert (servo[0]['velocity_mps'], servo[0]['acceleration_mps2']) == (0.0, 0.0)
    assert stream_reference(servo, 110 * MS, WINDOW_S, 0.0, 0.05, TRAVEL_M) == (0.073, 0.0, 0.0)


def test_a_stream_changes_while_new_setpoints_come_and_a_repeat_stands():
    servo = new_stream(P)
    stream_sample(servo, 0, 0.05, math.nan, math.nan, MEMORY_S, WINDOW_S)
    stream_sample(servo, 10 * MS, 0.0503, math.nan, math.nan, MEMORY_S, WINDOW_S)
    stream_sample(servo, 20 * MS, 0.0503, 0.0, 0.0, MEMORY_S, WINDOW_S)   # the same again
    assert stream_reference(servo, 30 * MS, WINDOW_S, 0.0, 0.05, TRAVEL_M) == (0.0503, 0.0, 0.0)
    assert stream_changing(servo, round((0.01 + WINDOW_S) * 1e9), WINDOW_S)
    assert not stream_changing(servo, round((0.01 + WINDOW_S) * 1e9) + 1, WINDOW_S)
