"""PD / PI / PID against hand-computed answers.

Sequences, limits, anti-windup, derivative kick, bumpless transfer, setpoint_range and discrete
pole placement against the characteristic polynomial.
"""
import copy
import math

from gripper_ros.core.config import PidGains
from gripper_ros.core.control.pid import (AntiWindup, DerivativeOn,
                                          first_order_pi_by_pole_placement, PID)
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

DT = 0.1
WIDE = (-1e6, 1e6)


def run(pid, pairs):
    return [pid.step(r, y) for r, y in pairs]


# ------------------------------------------------------------------ hand-computed sequences
def test_p_only_sequence():
    pid = PID(PidGains(kc=2.0), DT, WIDE)
    out = run(pid, [(1.0, 0.0), (1.0, 0.5), (1.0, 1.25), (-2.0, 0.0)])
    assert out == pytest.approx([2.0, 1.0, -0.5, -4.0], abs=1e-15)


def test_pi_sequence_backward_rectangle():
    # e = 1, 0.5, -0.25, 0: I = 0.3, 0.45, 0.375, 0.375
    pid = PID(PidGains(kc=2.0, ki=3.0), DT, WIDE)
    out = run(pid, [(1.0, 0.0), (1.0, 0.5), (1.0, 1.25), (1.0, 1.0)])
    assert out == pytest.approx([2.3, 1.45, -0.125, 0.375], abs=1e-12)
    assert pid.terms.integral == pytest.approx(0.375, abs=1e-12)


def test_pi_holds_constant_output_at_zero_error():
    pid = PID(PidGains(kc=5.0, ki=7.0), DT, WIDE)
    pid.step(1.0, 0.0)                                  # I = 0.7
    assert run(pid, [(1.0, 1.0)] * 5) == pytest.approx([0.7] * 5, abs=1e-12)


def test_pd_on_error_sequence():
    # e = 1, 0.5, 0.5, 0: D = 0 (no past), 0.5*(-0.5)/0.1, 0, 0.5*(-0.5)/0.1
    pid = PID(PidGains(kc=2.0, kd=0.5), DT, WIDE, DerivativeOn.ERROR)
    out = run(pid, [(1.0, 0.0), (1.0, 0.5), (1.0, 0.5), (1.0, 1.0)])
    assert out == pytest.approx([2.0, -1.5, 1.0, -2.5], abs=1e-12)


def test_pd_on_measurement_sequence():
    # y = 0, 0.5, 0.5, 1: D = 0, -0.5*0.5/0.1, 0, -0.5*0.5/0.1
    pid = PID(PidGains(kc=2.0, kd=0.5), DT, WIDE, DerivativeOn.MEASUREMENT)
    out = run(pid, [(1.0, 0.0), (1.0, 0.5), (1.0, 0.5), (1.0, 1.0)])
    assert out == pytest.approx([2.0, -1.5, 1.0, -2.5], abs=1e-12)


def test_pid_sequence():
    # kc=1, ki=2, kd=0.05, dt=0.1; e = 1, 0.8, 0.3
    pid = PID(PidGains(kc=1.0, ki=2.0, kd=0.05), DT, WIDE)
    out = run(pid, [(1.0, 0.0), (1.0, 0.2), (1.0, 0.7)])
    i1, i2, i3 = 0.2, 0.36, 0.42
    assert out == pytest.approx([1.0 + i1, 0.8 + i2 + 0.05 * (-0.2) / DT,
                                 0.3 + i3 + 0.05 * (-0.5) / DT], abs=1e-12)


def test_setpoint_weight_scales_proportional_setpoint_only():
    pid = PID(PidGains(kc=2.0, ki=1.0), DT, WIDE, setpoint_weight=0.5)
    # p = 2 (0.5*1 - 0.25) = 0.5; I = 0.1 * (1 - 0.25) = 0.075
    assert pid.step(1.0, 0.25) == pytest.approx(0.575, abs=1e-12)


# ------------------------------------------------------------------ limits and anti-windup
def test_output_limits_clamp():
    pid = PID(PidGains(kc=100.0), DT, (-24.0, 24.0))
    assert pid.step(1.0, 0.0) == 24.0 and pid.terms.saturated
    assert pid.step(-1.0, 0.0) == -24.0 and pid.terms.saturated
    assert pid.step(0.1, 0.0) == pytest.approx(10.0) and not pid.terms.saturated


@pytest.mark.parametrize('kwargs', [
    {'gains': PidGains(kc=1.0), 'dt_s': 0.0, 'output_limits': (-1, 1)},
    {'gains': PidGains(kc=1.0), 'dt_s': math.nan, 'output_limits': (-1, 1)},
    {'gains': PidGains(kc=1.0), 'dt_s': 0.1, 'output_limits': (1, 1)},
    {'gains': PidGains(kc=1.0), 'dt_s': 0.1, 'output_limits': (2, -2)},
    {'gains': PidGains(kc=-1.0), 'dt_s': 0.1, 'output_limits': (-1, 1)},
    {'gains': PidGains(kc=1.0, ki=math.inf), 'dt_s': 0.1, 'output_limits': (-1, 1)},
])
def test_bad_construction_raises(kwargs):
    with pytest.raises(ValueError):
        PID(**kwargs)


def test_non_finite_input_raises_and_keeps_state():
    pid = PID(PidGains(kc=1.0, ki=1.0), DT, WIDE)
    pid.step(1.0, 0.0)
    with pytest.raises(ValueError):
        pid.step(math.nan, 0.0)
    with pytest.raises(ValueError):
        pid.step(1.0, math.inf)
    assert pid.step(1.0, 1.0) == pytest.approx(0.1, abs=1e-15)   # I unchanged at 0.1


def saturate_then_reverse(anti_windup):
    """Error +5 for 10 samples (P alone saturates), then a small negative error."""
    pid = PID(PidGains(kc=1.0, ki=10.0), DT, (-1.0, 1.0), anti_windup=anti_windup)
    sat = run(pid, [(5.0, 0.0)] * 10)
    integral = pid.terms.integral
    after = run(pid, [(0.0, 0.1)] * 3)
    return sat, integral, after


def test_conditional_integration_stops_the_integrator_while_saturated():
    sat, integral, after = saturate_then_reverse(AntiWindup.CONDITIONAL)
    assert sat == [1.0] * 10
    assert integral == 0.0
    # e = -0.1: u = -0.1 + I with I = -0.1, -0.2, -0.3 -> leaves saturation at once
    assert after == pytest.approx([-0.2, -0.3, -0.4], abs=1e-12)


def test_without_anti_windup_the_integrator_winds_up_and_holds_saturation():
    sat, integral, after = saturate_then_reverse(AntiWindup.NONE)
    assert sat == [1.0] * 10
    assert integral == pytest.approx(10 * 10.0 * DT * 5.0)   # 50
    assert after == [1.0, 1.0, 1.0]                          # still pinned at the limit


def test_conditional_integration_still_integrates_out_of_saturation():
    pid = PID(PidGains(kc=1.0, ki=10.0), DT, (-1.0, 1.0))
    run(pid, [(5.0, 0.0)] * 3)
    # saturated high but error negative: integrating (downwards) is allowed
    pid.step(-0.5, 0.0)
    assert pid.terms.integral == pytest.approx(-0.5)


# ------------------------------------------------------------------ derivative kick
@pytest.mark.parametrize('where, kick', [(DerivativeOn.ERROR, True),
                                         (DerivativeOn.MEASUREMENT, False)])
def test_setpoint_step_kicks_only_derivative_on_error(where, kick):
    pid = PID(PidGains(kc=2.0, kd=0.5), DT, WIDE, where)
    assert pid.step(0.0, 0.0) == 0.0
    u = pid.step(1.0, 0.0)               # setpoint step, measurement unchanged
    assert u == pytest.approx(2.0 + (0.5 * 1.0 / DT if kick else 0.0), abs=1e-12)
    assert pid.terms.derivative == pytest.approx(5.0 if kick else 0.0, abs=1e-12)


def test_measurement_change_gives_same_derivative_either_way():
    outs = []
    for where in DerivativeOn:
        pid = PID(PidGains(kc=2.0, kd=0.5), DT, WIDE, where)
        outs.append(run(pid, [(1.0, 0.0), (1.0, 0.3), (1.0, 0.9)]))
    assert outs[0] == pytest.approx(outs[1], abs=1e-12)


# ------------------------------------------------------------------ bumpless transfer
@pytest.mark.parametrize('where', list(DerivativeOn))
def test_bumpless_reset_at_zero_error(where):
    pid = PID(PidGains(kc=3.0, ki=40.0, kd=0.2), DT, (-24.0, 24.0), where)
    run(pid, [(1.0, 0.0)] * 4)           # some unrelated history
    pid.reset(output=7.5, setpoint=0.4, measurement=0.4)
    assert pid.step(0.4, 0.4) == pytest.approx(7.5, abs=1e-12)


@pytest.mark.parametrize('where', list(DerivativeOn))
def test_bumpless_reset_with_error_first_output_is_the_motor_command(where):
    pid = PID(PidGains(kc=3.0, ki=40.0, kd=0.2), DT, (-24.0, 24.0), where)
    pid.reset(output=7.5, setpoint=1.0, measurement=0.2)
    # the integral is seeded with 7.5 - 3*0.8 - 40*0.1*0.8 = 1.9, so that the step that adds
    # ki*dt*e returns the voltage already applied: 2.4 + (1.9 + 3.2) + 0 = 7.5, not 7.5 + 3.2
    assert pid.step(1.0, 0.2) == pytest.approx(7.5, abs=1e-12)
    assert pid.terms.integral == pytest.approx(5.1, abs=1e-12)
    # and the law goes on from there: e = 0.7, P 2.1, I 5.1 + 2.8 = 7.9, D 0.2*(-0.1)/0.1
    assert pid.step(1.0, 0.3) == pytest.approx(2.1 + 7.9 - 0.2, abs=1e-12)


def test_reset_forgets_derivative_and_integral_history():
    pid = PID(PidGains(kc=1.0, ki=1.0, kd=1.0), DT, WIDE)
    run(pid, [(1.0, 0.0), (3.0, -2.0)])
    pid.reset()
    fresh = PID(PidGains(kc=1.0, ki=1.0, kd=1.0), DT, WIDE)
    assert run(pid, [(0.5, 0.1), (0.5, 0.2)]) == run(fresh, [(0.5, 0.1), (0.5, 0.2)])


# ------------------------------------------------------------------ setpoint_range
HISTORY = [(0.05, 0.01), (0.05, 0.02), (0.05, 0.021)]


@pytest.mark.parametrize('where', list(DerivativeOn))
def test_setpoint_range_gives_outputs_exactly_at_the_limits(where):
    pid = PID(PidGains(kc=968.0, kd=364.0), 0.01, (-24.0, 24.0), where)   # Table II PD
    run(pid, HISTORY)
    lo, hi = pid.setpoint_range(0.0215)
    assert lo < hi
    for sp, limit in ((lo, -24.0), (hi, 24.0)):
        probe = copy.deepcopy(pid)
        assert probe.step(sp, 0.0215) == pytest.approx(limit, abs=1e-9)
    mid = copy.deepcopy(pid)
    assert -24.0 < mid.step(0.5 * (lo + hi), 0.0215) < 24.0


@pytest.mark.parametrize('gains, where', [
    (PidGains(kc=653.0, ki=148.0, kd=640.0), DerivativeOn.ERROR),
    (PidGains(kc=653.0, ki=148.0, kd=640.0), DerivativeOn.MEASUREMENT),
    (PidGains(kc=0.29, ki=4877.0), DerivativeOn.ERROR)])
def test_setpoint_range_with_integral_reaches_the_limits_from_inside(gains, where):
    """Just inside the range (1e-9 of its width) the output is within 1e-6 V of each limit."""
    pid = PID(gains, 0.01, (-24.0, 24.0), where)
    run(pid, HISTORY)
    lo, hi = pid.setpoint_range(0.0215)
    margin = 1e-9 * (hi - lo)
    for sp, limit in ((lo + margin, -24.0), (hi - margin, 24.0)):
        probe = copy.deepcopy(pid)
        u = probe.step(sp, 0.0215)
        assert abs(u - limit) < 1e-6 and not probe.terms.saturated


def test_pi_output_is_monotone_in_the_setpoint_across_the_limit():
    """Minimal reproduction: PI kc=1, ki=10, dt=0.1, limits +-1, fresh state, y = 0.

    raw = r + 10*0.1*r = 2r: r = 0.5 gives 1.0; r = 0.5 + 1e-7 gives 0.5000001 (should be 1.0).
    """
    outs = []
    for r in (0.4, 0.5, 0.5 + 1e-7, 0.6, 2.0):
        pid = PID(PidGains(kc=1.0, ki=10.0), DT, (-1.0, 1.0))
        outs.append(pid.step(r, 0.0))
    assert outs[:2] == pytest.approx([0.8, 1.0])
    assert np.all(np.diff(outs) >= 0.0), outs
    assert outs[2:] == [1.0, 1.0, 1.0]


def test_setpoint_range_unbounded_without_setpoint_gain():
    pid = PID(PidGains(kc=1.0, kd=1.0), DT, (-1.0, 1.0), DerivativeOn.MEASUREMENT,
              setpoint_weight=0.0)
    assert pid.setpoint_range(0.0) == (-math.inf, math.inf)


# ------------------------------------------------------------------ pole placement
def closed_loop_matrix(a, b, gains, dt):
    """PI (backward rectangle) around y+ = a y + b u; state (y[k], I[k-1]), derived here."""
    s = gains.kc + gains.ki * dt
    return np.array([[a - b * s, b], [-gains.ki * dt, 1.0]])


@pytest.mark.parametrize('a, b, dt, pole', [
    (math.exp(-1e-4 / (0.238e-3 / 2.32)), 1.391 * (1 - math.exp(-1e-4 / (0.238e-3 / 2.32))),
     1e-4, 0.35),
    (0.9, 0.5, 0.01, 0.5), (0.5, 2.0, 1.0, 0.0), (0.99, 0.01, 0.1, 0.8)])
def test_pole_placement_puts_both_poles_where_asked(a, b, dt, pole):
    gains = first_order_pi_by_pole_placement(a, b, dt, pole)
    char = np.poly(closed_loop_matrix(a, b, gains, dt))
    np.testing.assert_allclose(char, [1.0, -2 * pole, pole ** 2], atol=1e-12)
    np.testing.assert_allclose(np.roots(char), [pole, pole], atol=1e-6)


@pytest.mark.parametrize('pole', [0.2, 0.35, 0.6])
def test_pole_placement_closed_loop_simulation_obeys_the_characteristic_polynomial(pole):
    """Simulate the real PID class on y+ = a y + b u: (q - p)^2 y = (1 - p)^2 r for every k."""
    a, b, dt, r = 0.377, 0.867, 1e-4, 1.0
    gains = first_order_pi_by_pole_placement(a, b, dt, pole)
    pid = PID(gains, dt, WIDE)
    y = [0.0]
    for _ in range(80):
        y.append(a * y[-1] + b * pid.step(r, y[-1]))
    y = np.array(y)
    lhs = y[2:] - 2 * pole * y[1:-1] + pole ** 2 * y[:-2]
    np.testing.assert_allclose(lhs[1:], (1 - pole) ** 2 * r, atol=1e-12)
    assert y[-1] == pytest.approx(r, abs=1e-9)        # integral action: no offset


@pytest.mark.parametrize('pole', [-0.1, 1.0, 1.5])
def test_pole_placement_rejects_poles_outside_unit_interval(pole):
    with pytest.raises(ValueError):
        first_order_pi_by_pole_placement(0.5, 1.0, 0.1, pole)


def test_pole_placement_rejects_pole_needing_negative_kc():
    with pytest.raises(ValueError):
        first_order_pi_by_pole_placement(0.04, 1.0, 0.1, 0.5)   # kc = (0.04 - 0.25)/1 < 0


# ------------------------------------------------------------------ properties
@settings(max_examples=200, deadline=None, derandomize=True)
@given(kc=st.floats(0.0, 1e3), e=st.floats(-1e3, 1e3), y=st.floats(-1e3, 1e3))
def test_p_only_is_clamped_proportional(kc, e, y):
    pid = PID(PidGains(kc=kc), DT, (-24.0, 24.0))
    assert pid.step(y + e, y) == pytest.approx(min(24.0, max(-24.0, kc * ((y + e) - y))),
                                               abs=1e-9)


# ------------------------------------------------------------------ setpoint_for_output
def test_setpoint_for_output_inverts_a_pd_by_hand():
    # PD on measurement, kc 2, kd 3, dt 0.1, last y = 0.0, now y = 0.1:
    # u = 2 (r - 0.1) - 3 (0.1 - 0) / 0.1 = 2 r - 3.2  ->  u = 5 needs r = 4.1
    pid = PID(PidGains(kc=2.0, kd=3.0), DT, (-10.0, 10.0), derivative_on=DerivativeOn.MEASUREMENT)
    pid.step(0.0, 0.0)
    r = pid.setpoint_for_output(5.0, 0.1)
    assert r == pytest.approx(4.1, abs=1e-12)
    assert pid.step(r, 0.1) == pytest.approx(5.0, abs=1e-12)


def test_setpoint_for_output_clamps_to_the_limits():
    pid = PID(PidGains(kc=2.0, ki=1.0), DT, (-1.0, 1.0))
    r = pid.setpoint_for_output(50.0, 0.0)          # beyond the limit: aims at the limit
    assert pid.step(r, 0.0) == pytest.approx(1.0, abs=1e-12)
    only_d_on_measurement = PID(PidGains(kc=0.0, kd=1.0), DT, WIDE,
                                derivative_on=DerivativeOn.MEASUREMENT)
    with pytest.raises(ValueError):                 # no setpoint gives any chosen output
        only_d_on_measurement.setpoint_for_output(1.0, 0.0)
