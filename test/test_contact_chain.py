"""Flexible fingers and Hertz pads in series with the object: known answers, no ROS.

Closed forms: at rest the chain carries the motor's stall force ``K_stall e`` (eq. 13) and the
finger has travelled ``2 F / k_f + 2 (F / k_p)^(2/3) + F / k_o`` past the object's face; a pad
alone gives force rising as the 3/2 power of its compression (Hertz). Limits: with both keys 0
the plant is the paper's (a rigid grip's force is the armature's RL transient, eqs. 12-13, and a
Kelvin-Voigt object compresses by F / k_o); with a finger far stiffer than the object it converges
to the Kelvin-Voigt contact. The contact stage keeps its no-spike claim on the chain kinds.
"""
import dataclasses
import math

from gripper_ros.core.config import ConfigError, default_config_path, load_config, parse_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.contact_chain import (cantilever_stiffness_n_per_m,
                                                    chain_compression_m, chain_solve,
                                                    hertz_pad_stiffness_n_per_m1_5, PRINTED_FINGER,
                                                    RUBBER_DOME_PAD)
from gripper_ros.core.physics.plant import GraspObject
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.studies.sweep_runs import finger_cases, finger_kinds, sweep
import numpy as np
import pytest
import yaml

CONFIG = load_config()
K_FINGER = cantilever_stiffness_n_per_m(**PRINTED_FINGER)
K_PAD = hertz_pad_stiffness_n_per_m1_5(**RUBBER_DOME_PAD)
WIDTH_M = 0.05
SETTLE_S = 60.0                 # the motor damps the chain at about 0.45 1/s: 60 s is 1e-11
STEP_S = 1e-2


def chain_config(finger_n_per_m: float, pad_n_per_m1_5: float):
    contact = dataclasses.replace(CONFIG.contact, finger_stiffness_n_per_m=finger_n_per_m,
                                  pad_normal_stiffness_n_per_m1_5=pad_n_per_m1_5)
    return dataclasses.replace(CONFIG, contact=contact)


def settle(config, voltage_v: float, stiffness_n_per_m: float = 0.0,
           damping_n_s_per_m: float = 0.0):
    """Hold ``voltage_v`` on an object touched at rest until the chain is still; (plant, last)."""
    plant = make_plant(config)
    plant.set_object(GraspObject(WIDTH_M, stiffness_n_per_m, damping_n_s_per_m))
    plant.touch_object()
    for _ in range(round(SETTLE_S / STEP_S)):
        sample = plant.step(voltage_v, STEP_S)
    return plant, sample


def test_the_textbook_stiffnesses():
    """3 E I / L^3 and 4/3 E* sqrt(R), worked by hand for the sweep's finger and pad."""
    assert K_FINGER == pytest.approx(3 * 3.5e9 * (0.02 * 0.01 ** 3 / 12) / 0.06 ** 3, rel=1e-12)
    assert K_FINGER == pytest.approx(8.1e4, rel=1e-3)
    assert K_PAD == pytest.approx(4 / 3 * 3e6 / 0.75 * math.sqrt(0.02), rel=1e-12)


@pytest.mark.parametrize('compliance', [0.0, 1e-9, 2.5e-5, 1e-2])
def test_the_solver_meets_the_closed_form_over_six_decades_of_travel(compliance):
    """chain_solve's force, put back into the closed form, gives the travel it was asked."""
    for travel_m in np.geomspace(1e-9, 1e-2, 25):
        for guess in (0.0, 1e-12, travel_m, 1.0):
            force, pad_m = chain_solve(travel_m, compliance, K_PAD, guess)
            assert force == pytest.approx(K_PAD * pad_m ** 1.5, rel=1e-12)
            assert 2 * (force / K_PAD) ** (2 / 3) + compliance * force == pytest.approx(
                travel_m, rel=1e-10)
    assert chain_solve(0.0, compliance, K_PAD, 0.0) == (0.0, 0.0)
    assert chain_solve(-1e-3, compliance, K_PAD, 1e-3) == (0.0, 0.0)


@pytest.mark.parametrize('finger,pad,k_o,c_o', [
    (K_FINGER, 0.0, 0.0, 0.0),
    (0.0, K_PAD, 0.0, 0.0),
    (K_FINGER, K_PAD, 0.0, 0.0),
    (K_FINGER, K_PAD, 1e5, 2e4),
])
def test_at_rest_the_chain_carries_the_stall_force_at_the_closed_form_compression(
        finger, pad, k_o, c_o):
    """Hold 12 V: F = K_stall e (eq. 13), x - x_c = 2F/k_f + 2(F/k_p)^(2/3) + F/k_o."""
    voltage_v = 12.0
    plant, sample = settle(chain_config(finger, pad), voltage_v, k_o, c_o)
    force_n = CONFIG.plant.stall_force_per_volt_n * voltage_v
    assert sample.velocity_mps == pytest.approx(0.0, abs=1e-9)
    assert sample.force_n == pytest.approx(force_n, rel=1e-6)
    travel_m = sample.position_m - plant.contact_position_m
    assert travel_m == pytest.approx(chain_compression_m(sample.force_n, finger, pad, k_o),
                                     rel=1e-9)
    assert travel_m > chain_compression_m(sample.force_n, 0.0, 0.0, k_o) + 1e-5   # it bends


def test_a_pad_alone_stiffens_as_hertz_says():
    """Two voltages 4x apart: the pad's compression grows 4^(2/3) = 2.52x, not 4x."""
    (plant, low), (_, high) = settle(chain_config(0.0, K_PAD), 4.0), \
        settle(chain_config(0.0, K_PAD), 16.0)
    x_c = plant.contact_position_m
    ratio = (high.position_m - x_c) / (low.position_m - x_c)
    assert high.force_n / low.force_n == pytest.approx(4.0, rel=1e-6)
    assert ratio == pytest.approx(4.0 ** (2 / 3), rel=1e-6)


def test_with_both_keys_zero_a_rigid_grip_is_the_armature_rl_transient():
    """Keys 0, a rigid object touched at rest, V held: the finger stays at the face (x = x_c).

    With omega = 0 the armature is an RL circuit, i = V/R (1 - exp(-R t / L)), and the force is
    eq. 12 on that current: F(t) = K_stall V (1 - exp(-R t / L)), to the stall force (eq. 13).
    """
    assert CONFIG.contact.finger_stiffness_n_per_m == 0.0
    assert CONFIG.contact.pad_normal_stiffness_n_per_m1_5 == 0.0
    p = CONFIG.plant
    voltage_v, dt_s = 6.0, 1e-4
    plant = make_plant(CONFIG)
    plant.set_object(GraspObject(WIDTH_M, 0.0, 0.0))
    plant.touch_object()
    x_c = plant.contact_position_m
    t0_ns = plant.step(0.0, dt_s).t_ns
    for _ in range(round(5 * p.inductance_h / p.resistance_ohm / dt_s) + 1):
        sample = plant.step(voltage_v, dt_s)
        t_s = (sample.t_ns - t0_ns) * 1e-9
        rl = 1.0 - math.exp(-p.resistance_ohm * t_s / p.inductance_h)
        assert sample.position_m == pytest.approx(x_c, abs=1e-12)
        assert sample.current_a == pytest.approx(voltage_v / p.resistance_ohm * rl, rel=1e-9)
        assert sample.force_n == pytest.approx(p.stall_force_per_volt_n * voltage_v * rl,
                                               rel=1e-9)
    assert rl > 0.99


def test_with_both_keys_zero_a_compliant_object_compresses_by_f_over_k():
    """Keys 0, a 1e5 N/m object held at 12 V: F = K_stall V (eq. 13), x - x_c = F / k_o."""
    k_o = 1e5
    plant, sample = settle(CONFIG, 12.0, k_o, 2e4)
    force_n = CONFIG.plant.stall_force_per_volt_n * 12.0
    assert sample.force_n == pytest.approx(force_n, rel=1e-6)
    assert sample.position_m - plant.contact_position_m == pytest.approx(force_n / k_o,
                                                                         rel=1e-6)


def test_a_finger_far_stiffer_than_the_object_converges_to_the_kelvin_voigt_contact():
    """k_f = 1e11 N/m on a 1e5 N/m object: the Kelvin-Voigt grasp (keys 0) within 1e-5 of F_sp.

    The chain's integrator (trapezoidal load, backward-Euler damper) against the exact ZOH.
    """
    reference = simulate_grasp(CONFIG, WIDTH_M, 1.0, stiffness_n_per_m=1e5,
                               damping_n_s_per_m=50.0, hold_s=0.05)
    chain = simulate_grasp(chain_config(1e11, 0.0), WIDTH_M, 1.0, stiffness_n_per_m=1e5,
                           damping_n_s_per_m=50.0, hold_s=0.05)
    assert chain.outcome == reference.outcome
    reference_n, chain_n = reference.series.ticks['force_n'], chain.series.ticks['force_n']
    n = min(len(reference_n), len(chain_n))
    assert np.max(np.abs(chain_n[:n] - reference_n[:n])) < (
        1e-5 * reference.force_setpoint_n)
    assert chain.peak_contact_force_n == pytest.approx(reference.peak_contact_force_n, rel=1e-5)


def test_the_contact_stage_keeps_its_claim_on_flexible_fingers_and_pads():
    """contact_sweep --fingers' corners: every chain kind held, none over 1.10 x F_sp."""
    cases, _ = finger_cases(CONFIG, widths=(0.005, 0.14), masses=(0.1, None), band=False)
    rows = sweep(CONFIG, cases, hold_s=0.2, jobs=2, rest_floors=False)
    assert {r.finger for r in rows} == {name for name, _, _ in finger_kinds()}
    assert {r.stiffness_n_per_m for r in rows} == {0.0, 1e2, 1e4, 1e6, 1e8}
    assert len(rows) == len(cases)
    for r in rows:
        assert r.outcome == 'HOLDING' and r.peak_ratio <= 1.10, r


def test_a_negative_stiffness_is_refused_naming_the_key():
    data = yaml.safe_load(open(default_config_path(), encoding='utf-8'))
    for key in ('finger_stiffness_n_per_m', 'pad_normal_stiffness_n_per_m1_5'):
        bad = {**data, 'contact': {**data['contact'], key: -1.0}}
        with pytest.raises(ConfigError, match=f'contact.{key}'):
            parse_config(bad)
    absent = {**data, 'contact': {k: v for k, v in data['contact'].items() if k not in (
        'finger_stiffness_n_per_m', 'pad_normal_stiffness_n_per_m1_5')}}
    contact = parse_config(absent).contact
    assert contact.finger_stiffness_n_per_m == contact.pad_normal_stiffness_n_per_m1_5 == 0.0
