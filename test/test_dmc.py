"""Dynamic matrix control (eqs. 17-22) on hand-checkable examples and a first-order plant.

The examples are small; the discrete first-order plant's step response and free response are
known in closed form.
"""
from gripper_ros.core.config import PidGains
from gripper_ros.core.control.dmc import (closed_loop_step_response, dmc_gain, dynamic_matrix,
                                          DynamicMatrixControl)
from gripper_ros.core.control.pid import PID
import numpy as np
import pytest

A_POLE, B_GAIN = 0.5, 0.25          # plant y+ = a y + b u, DC gain b/(1-a) = 0.5
HORIZON = 60                        # a^60 ~ 1e-18: the truncated model is exact to rounding


def first_order_step(a, b, n):
    """a_j = b (1 - a^j) / (1 - a), j = 1..n: unit step response of y+ = a y + b u."""
    j = np.arange(1, n + 1)
    return b * (1.0 - a ** j) / (1.0 - a)


# ------------------------------------------------------------------ eq. 18 / eq. 20
def test_dynamic_matrix_by_hand():
    a = dynamic_matrix([1.0, 2.0, 3.0, 4.0], 2)
    np.testing.assert_array_equal(a, [[1.0, 0.0],
                                      [2.0, 1.0],
                                      [3.0, 2.0],
                                      [4.0, 3.0]])
    a3 = dynamic_matrix([0.1, 0.5, 0.9], 3)
    np.testing.assert_array_equal(a3, [[0.1, 0.0, 0.0], [0.5, 0.1, 0.0], [0.9, 0.5, 0.1]])


def test_dynamic_matrix_is_lower_triangular_toeplitz():
    steps = first_order_step(0.8, 0.3, 12)
    a = dynamic_matrix(steps, 5)
    assert a.shape == (12, 5)
    for i in range(12):
        for m in range(5):
            assert a[i, m] == (steps[i - m] if i >= m else 0.0)


@pytest.mark.parametrize('nu', [0, 5, -1])
def test_dynamic_matrix_rejects_bad_control_horizon(nu):
    with pytest.raises(ValueError):
        dynamic_matrix([1.0, 2.0, 3.0, 4.0], nu)


def test_dmc_gain_is_regularised_least_squares():
    steps = [1.0, 2.0, 3.0, 4.0]
    a = np.array([[1.0, 0.0], [2.0, 1.0], [3.0, 2.0], [4.0, 3.0]])
    lam = 1.001
    expected = np.linalg.inv(a.T @ a + lam * np.eye(2)) @ a.T
    np.testing.assert_allclose(dmc_gain(steps, 2, lam), expected, rtol=1e-12)
    # by hand: A^T A = [[30, 20], [20, 14]]
    np.testing.assert_array_equal(a.T @ a, [[30.0, 20.0], [20.0, 14.0]])


def test_dmc_gain_minimises_eq_17():
    """Eq. 20 is the minimiser of |A du - E|^2 + lambda |du|^2: the gradient vanishes there."""
    rng = np.random.default_rng(1)
    steps = first_order_step(0.9, 0.2, 30)
    a = dynamic_matrix(steps, 4)
    e = rng.normal(size=30)
    lam = 0.3
    du = dmc_gain(steps, 4, lam) @ e
    grad = 2 * a.T @ (a @ du - e) + 2 * lam * du
    np.testing.assert_allclose(grad, 0.0, atol=1e-10)
    cost = np.sum((a @ du - e) ** 2) + lam * np.sum(du ** 2)
    for _ in range(20):
        other = du + 1e-3 * rng.normal(size=4)
        assert np.sum((a @ other - e) ** 2) + lam * np.sum(other ** 2) > cost


@pytest.mark.parametrize('lam', [-0.1, float('nan'), float('inf')])
def test_dmc_gain_rejects_bad_move_suppression(lam):
    with pytest.raises(ValueError):
        dmc_gain([1.0, 2.0], 1, lam)


# ------------------------------------------------------------------ closed loop on a known plant
def simulate(dmc, setpoint, n, b_true=B_GAIN, a_true=A_POLE):
    y, out, corrections, predictions = 0.0, [], [], []
    for _ in range(n):
        corrections.append(y - dmc.prediction[0])      # eq. 22 before the step
        u = dmc.step(setpoint, y)
        predictions.append(dmc.prediction)
        y = a_true * y + b_true * u
        out.append((u, y))
    return np.array(out), np.array(corrections), predictions


def test_perfect_model_tracks_without_offset_and_prediction_equals_plant():
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.1)
    out, corrections, _ = simulate(dmc, 2.0, 150)
    u, y = out[:, 0], out[:, 1]
    assert y[-1] == pytest.approx(2.0, abs=1e-12)
    assert u[-1] == pytest.approx(2.0 * (1 - A_POLE) / B_GAIN, abs=1e-12)   # DC balance
    np.testing.assert_allclose(corrections, 0.0, atol=1e-12)                # eq. 22 -> 0


def test_perfect_model_prediction_is_the_free_response():
    """After a step at time k, prediction[j] = y(k+1+j) with u held: a^(j+1) y_k + a_(j+1) u_k."""
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.1)
    y = 0.0
    for k in range(6):
        u = dmc.step(1.0, y)
        j = np.arange(HORIZON)
        free = A_POLE ** (j + 1) * y + first_order_step(A_POLE, B_GAIN, HORIZON) * u
        np.testing.assert_allclose(dmc.prediction[:HORIZON], free, atol=1e-12)
        y = A_POLE * y + B_GAIN * u


def test_first_move_is_eq_20_on_the_error_of_eq_19():
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    lam = 0.5
    dmc = DynamicMatrixControl(model, 4, lam)
    dmc.reset(0.3, 1.2)                 # at rest: output 0.3 with u = 1.2
    k = dmc_gain(model, 4, lam)
    e = 1.0 - np.full(HORIZON, 0.3)    # r - free prediction (flat at rest)
    assert dmc.step(1.0, 0.3) == pytest.approx(1.2 + k[0] @ e, rel=1e-12)


@pytest.mark.parametrize('gain_ratio', [0.6, 1.5])
def test_model_gain_error_still_removes_offset(gain_ratio):
    """A true plant gain that differs from the model's still leaves no offset.

    Eq. 22's correction settles at the model's steady-state mis-prediction
    r (1 - b_model / b_true) and the output has no offset.
    """
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.5)
    b_true = gain_ratio * B_GAIN
    r = 1.0
    out, corrections, _ = simulate(dmc, r, 300, b_true=b_true)
    u, y = out[:, 0], out[:, 1]
    assert y[-1] == pytest.approx(r, abs=1e-9)
    assert u[-1] == pytest.approx(r * (1 - A_POLE) / b_true, abs=1e-9)
    assert corrections[-1] == pytest.approx(r * (1 - 1 / gain_ratio), abs=1e-9)
    assert abs(corrections[-1]) > 0.1


def test_model_pole_error_still_removes_offset():
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.5)
    a_true = 0.7                         # slower plant, DC gain 0.25 / 0.3
    out, _, _ = simulate(dmc, -0.5, 400, a_true=a_true)
    assert out[-1, 1] == pytest.approx(-0.5, abs=1e-9)
    assert out[-1, 0] == pytest.approx(-0.5 * (1 - a_true) / B_GAIN, abs=1e-9)


def test_limited_output_books_the_move_actually_made():
    """With output limits the prediction still equals the (perfectly modelled) plant."""
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.01, output_limits=(-1.0, 1.5))
    out, corrections, _ = simulate(dmc, 0.6, 80)           # needs u = 1.2 at rest
    u = out[:, 0]
    assert u.max() == 1.5 and u.min() >= -1.0          # the limit was active
    np.testing.assert_allclose(corrections, 0.0, atol=1e-12)
    assert out[-1, 1] == pytest.approx(0.6, abs=1e-9)


def test_per_sample_output_range_is_respected_and_booked():
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.01)
    y = 0.0
    for k in range(60):
        bounds = (-0.2, 0.2 + 0.05 * k)
        correction = y - dmc.prediction[0]
        assert correction == pytest.approx(0.0, abs=1e-12)
        u = dmc.step(1.0, y, bounds)
        assert bounds[0] <= u <= bounds[1]
        y = A_POLE * y + B_GAIN * u
    assert y == pytest.approx(1.0, abs=1e-9)


def test_unreachable_setpoint_holds_at_limit_without_windup():
    model = first_order_step(A_POLE, B_GAIN, HORIZON)
    dmc = DynamicMatrixControl(model, 3, 0.01, output_limits=(-1.0, 1.0))
    y = 0.0
    for _ in range(100):                 # setpoint 2 needs u = 4: unreachable, u pinned at 1
        y = A_POLE * y + B_GAIN * dmc.step(2.0, y)
    assert dmc.last_output == 1.0 and y == pytest.approx(0.5, abs=1e-12)
    us = []
    for _ in range(100):                 # reachable again: leaves the limit on the first sample
        u = dmc.step(0.25, y)
        us.append(u)
        y = A_POLE * y + B_GAIN * u
    assert us[0] < 1.0
    assert y == pytest.approx(0.25, abs=1e-9)


def test_closed_loop_step_response_of_p_loop_is_analytic():
    """P control kc around y+ = a y + b u: y+ = (a - b kc) y + b kc r, a geometric approach."""
    kc = 2.0
    pid = PID(PidGains(kc=kc), 1.0, (-1e9, 1e9))
    state = [0.0]

    def model_step(u):
        state[0] = A_POLE * state[0] + B_GAIN * u
        return state[0]

    resp = closed_loop_step_response(model_step, pid, 20)
    np.testing.assert_allclose(resp, first_order_step(A_POLE - B_GAIN * kc, B_GAIN * kc, 20),
                               rtol=1e-12)


# ------------------------------------------------------------------ braking governor
def test_braking_governor_phases_in_order_on_the_gripper_model():
    """One ACCELERATE run at +limit, one BRAKE run at -braking_v, then DMC for good.

    The forced voltages are exactly those, and a short move still starts by accelerating.
    """
    from gripper_ros.core.config import load_config
    from gripper_ros.core.control.factories import make_plant
    from gripper_ros.core.control.dmc import BrakingGovernor, GovernorPhase

    config = load_config()
    dt = config.position.sample_time_s
    plant = make_plant(config)
    ad, bd = plant.discrete_free_model(dt)
    gov = BrakingGovernor(ad, bd, 24.0, 20.0, 700)
    gov.reset(0.0)
    phases, volts = [], []
    for _ in range(400):
        y = plant.sample().position_m
        v = gov.command(0.1, y)
        phases.append(gov.phase)
        if v is None:
            break
        volts.append(v)
        gov.applied(v)
        plant.step(v, dt)
    order = [p for i, p in enumerate(phases) if i == 0 or p is not phases[i - 1]]
    assert order == [GovernorPhase.ACCELERATE, GovernorPhase.BRAKE, GovernorPhase.DMC]
    n_acc = phases.count(GovernorPhase.ACCELERATE)
    assert volts[:n_acc] == [24.0] * n_acc and set(volts[n_acc:]) == {-20.0}
    # handed over nearly at rest, just short of the setpoint (the DMC finishes the last bit)
    assert 0.098 < plant.sample().position_m <= 0.1
    assert abs(plant.sample().speed_rad_s) < 2.0
