"""RMS error, % overshoot and 2 % settling time against closed-form step responses."""
import math

from gripper_ros.studies.metrics import (percent_overshoot, rms_error, SETTLING_BAND,
                                         settling_time, step_metrics)
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from scipy.optimize import brentq


def first_order(tau, dt, t_end, y0=0.0, r=1.0):
    t = np.arange(0.0, t_end, dt)
    return t, r + (y0 - r) * np.exp(-t / tau)


def second_order(zeta, wn, t):
    """Return the unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), 0 < zeta < 1."""
    wd = wn * math.sqrt(1 - zeta ** 2)
    phi = math.acos(zeta)
    return 1 - np.exp(-zeta * wn * t) / math.sqrt(1 - zeta ** 2) * np.sin(wd * t + phi)


def second_order_settling(zeta, wn, band=0.02):
    """Last instant |y - 1| = band, found on the analytic response (extrema at k pi / wd)."""
    wd = wn * math.sqrt(1 - zeta ** 2)
    phi = math.acos(zeta)
    err = lambda t: 1.0 - float(second_order(zeta, wn, np.array([t]))[0])  # noqa: E731
    k = 1
    while abs(err((k + 1) * math.pi / wd)) > band:
        k += 1
    t_ext = k * math.pi / wd                     # last extremum outside the band
    t_zero = ((k + 1) * math.pi - phi) / wd      # next zero of the error
    return brentq(lambda t: abs(err(t)) - band, t_ext, t_zero, xtol=1e-14)


# ------------------------------------------------------------------ first order
@pytest.mark.parametrize('tau, dt', [(0.5, 1e-3), (1.0, 1e-2), (1e-4, 1e-7)])
def test_first_order_settling_is_tau_ln_50(tau, dt):
    t, y = first_order(tau, dt, 10 * tau)
    ts = settling_time(t, y, 1.0)
    exact = tau * math.log(50.0)
    assert exact <= ts <= exact + dt * (1 + 1e-9)


def test_first_order_has_no_overshoot():
    t, y = first_order(0.5, 1e-3, 5.0)
    assert percent_overshoot(y, 1.0) == 0.0


def test_first_order_rms_is_geometric_series():
    tau, dt, n = 0.5, 1e-3, 4000
    t, y = first_order(tau, dt, n * dt)
    q = math.exp(-2 * dt / tau)
    exact = math.sqrt((1 - q ** n) / ((1 - q) * n))          # mean of exp(-2 k dt / tau)
    assert rms_error(y, 1.0) == pytest.approx(exact, rel=1e-10)
    # and, for dt -> 0, the continuous-time RMS sqrt(tau (1 - e^(-2T/tau)) / (2T))
    cont = math.sqrt(tau * (1 - math.exp(-2 * n * dt / tau)) / (2 * n * dt))
    assert rms_error(y, 1.0) == pytest.approx(cont, rel=2 * dt / tau)


def test_downward_first_order_step():
    tau, dt = 0.2, 1e-4
    t, y = first_order(tau, dt, 3.0, y0=5.0, r=2.0)
    ts = settling_time(t, y, 2.0, initial=5.0)
    assert tau * math.log(50.0) <= ts <= tau * math.log(50.0) + dt * (1 + 1e-9)
    assert percent_overshoot(y, 2.0, initial=5.0) == 0.0
    m = step_metrics(t, y, 2.0, initial=5.0)
    assert m.settling_time_s == ts and m.overshoot_pct == 0.0


# ------------------------------------------------------------------ second order
@pytest.mark.parametrize('zeta, wn', [(0.2, 10.0), (0.5, 3.0), (0.65, 100.0)])
def test_second_order_overshoot_and_settling(zeta, wn):
    wd = wn * math.sqrt(1 - zeta ** 2)
    dt = (math.pi / wd) / 2000                   # the peak time pi/wd falls on sample 2000
    t = np.arange(0.0, 12.0 / (zeta * wn), dt)
    y = second_order(zeta, wn, t)
    overshoot = math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2)) * 100
    assert percent_overshoot(y, 1.0) == pytest.approx(overshoot, rel=1e-9)
    ts_exact = second_order_settling(zeta, wn)
    assert ts_exact <= settling_time(t, y, 1.0) <= ts_exact + dt * (1 + 1e-9)


def test_second_order_scaled_and_offset_step():
    zeta, wn = 0.3, 5.0
    wd = wn * math.sqrt(1 - zeta ** 2)
    dt = (math.pi / wd) / 1000
    t = np.arange(0.0, 8.0, dt)
    y = 0.04 + (0.1 - 0.04) * second_order(zeta, wn, t)     # 0.04 -> 0.1
    overshoot = math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2)) * 100
    assert percent_overshoot(y, 0.1, initial=0.04) == pytest.approx(overshoot, rel=1e-8)
    ts = settling_time(t, y, 0.1, initial=0.04)
    assert second_order_settling(zeta, wn) <= ts <= second_order_settling(zeta, wn) + dt * 1.001


def test_settling_start_time_offsets_the_answer():
    t, y = first_order(0.5, 1e-3, 5.0)
    t_shift = t + 2.0
    plain = settling_time(t, y, 1.0)
    assert settling_time(t_shift, y, 1.0) == pytest.approx(plain, abs=1e-12)
    assert settling_time(t_shift, y, 1.0, start_s=0.0) == pytest.approx(plain + 2.0, abs=1e-12)


def test_band_argument():
    t, y = first_order(1.0, 1e-3, 10.0)
    assert SETTLING_BAND == 0.02
    ts5 = settling_time(t, y, 1.0, band=0.05)
    assert math.log(20.0) <= ts5 <= math.log(20.0) + 1e-3 * (1 + 1e-9)


# ------------------------------------------------------------------ edge cases
def test_never_settles_is_inf():
    t = np.linspace(0.0, 10.0, 1001)
    assert settling_time(t, 1.0 + 0.5 * np.sin(3 * t), 1.0) == math.inf
    t, y = first_order(1.0, 1e-2, 2.0)          # record ends at 13.5 % error
    assert settling_time(t, y, 1.0) == math.inf
    assert step_metrics(t, y, 1.0).settling_time_s == math.inf


def test_only_last_sample_inside_band_is_settled_there():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    assert settling_time(t, [0.0, 1.5, 0.5, 1.0], 1.0) == 3.0


def test_already_settled_is_zero():
    t = np.linspace(0.0, 1.0, 11)
    assert settling_time(t, np.full(11, 1.01), 1.0) == 0.0


@pytest.mark.parametrize('call', [
    lambda: rms_error([], 1.0),
    lambda: settling_time([], [], 1.0),
    lambda: step_metrics([], [], 1.0),
    lambda: settling_time([0.0, 1.0], [1.0], 1.0),
    lambda: settling_time(np.zeros((2, 2)), np.zeros((2, 2)), 1.0),
    lambda: percent_overshoot([1.0, 2.0], 1.0, initial=1.0)])
def test_bad_series_raise_value_error(call):
    with pytest.raises(ValueError):
        call()


def test_rms_by_hand():
    assert rms_error([0.0, 2.0, 1.0, 1.0], 1.0) == pytest.approx(math.sqrt(0.5), rel=1e-15)


# ------------------------------------------------------------------ properties
@settings(max_examples=100, deadline=None, derandomize=True)
@given(offset=st.floats(-1e3, 1e3), n=st.integers(1, 50))
def test_rms_of_constant_error_is_its_magnitude(offset, n):
    assert rms_error(np.full(n, 3.0 + offset), 3.0) == pytest.approx(
        abs(offset), rel=1e-12, abs=1e-12)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(scale=st.floats(1e-3, 1e3), shift=st.floats(-1e3, 1e3))
def test_overshoot_and_settling_invariant_under_affine_rescaling(scale, shift):
    t = np.linspace(0.0, 6.0, 601)
    y = second_order(0.4, 4.0, t)
    base = (percent_overshoot(y, 1.0), settling_time(t, y, 1.0))
    ys = shift + scale * y
    got = (percent_overshoot(ys, shift + scale, shift), settling_time(t, ys, shift + scale, shift))
    assert got[0] == pytest.approx(base[0], rel=1e-6)
    assert got[1] == pytest.approx(base[1], abs=1e-12)
