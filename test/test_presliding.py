"""Cattaneo-Mindlin pre-sliding on the pads, against its closed forms and Coulomb's.

A pad of initial tangential stiffness ``k_t`` under normal force ``F`` and shear ``Q`` moves the
object by ``delta = 3 mu_s F / (2 k_t) [1 - (1 - Q / (mu_s F))^(2/3)]`` (Johnson, Contact
Mechanics, eq. 7.58 written with the initial stiffness); its compliance is ``(1 / k_t) (1 - Q /
(mu_s F))^(-1/3)``. Rigid pads (``k_t = 0``) and ``k_t -> inf`` are the Coulomb law, and gross
slip keeps its closed forms ``x = a_rel t^2 / 2`` and loss at ``sqrt(2 L / a_rel)``.
"""
import math
from pathlib import Path

from gripper_ros.core.config import load_config
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.hold import HoldModel, HoldState, Lift, presliding_m
from gripper_ros.core.physics.plant import GraspObject
import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_config(REPO / 'config' / 'gripper.yaml')
G = CONFIG.plant.gravity_mps2
C = CONFIG.contact
MU_S, MU_K, PAD_M = C.static_friction, C.kinetic_friction, C.pad_length_m
K_T = C.pad_tangential_stiffness_n_per_m


def lifted(mass_kg, accel_mps2, k_t=K_T):
    hold = HoldModel(mass_kg, MU_S, MU_K, PAD_M, G, Lift(accel_mps2, 0.0, 10.0), k_t)
    hold.begin(0, mass_kg)
    hold.fire_events(0)
    return hold


def closed_form_m(q_n, f_n, k_t=K_T):
    return 1.5 * MU_S * f_n / k_t * (1.0 - (1.0 - q_n / (MU_S * f_n)) ** (2.0 / 3.0))


def test_config_gives_the_pads_a_finite_tangential_stiffness():
    assert K_T == 6.0e4


@pytest.mark.parametrize('ratio', [0.05, 0.3, 0.6, 0.9, 0.99])
def test_stuck_object_moves_by_the_cattaneo_mindlin_curve(ratio):
    m, a = 1.0, 2.0
    q = 0.5 * m * (G + a)                            # each pad carries half the load
    f = q / (MU_S * ratio)
    hold = lifted(m, a)
    assert hold.advance(f, 1e-3) is None and hold.state is HoldState.STUCK
    assert hold.shear_n(f) == pytest.approx(q, rel=1e-15)
    assert hold.presliding_m(f) == pytest.approx(closed_form_m(q, f), rel=1e-12)
    assert hold.slip_m == 0.0                        # no gross slip below the limit


def test_compliance_grows_without_bound_as_the_shear_nears_the_limit():
    f = 20.0
    limit = MU_S * f
    compliance = []
    for ratio in (0.1, 0.5, 0.9, 0.99, 0.999):
        q, dq = ratio * limit, 1e-7 * limit
        slope = (presliding_m(q + dq, f, MU_S, K_T) - presliding_m(q - dq, f, MU_S, K_T)) / \
            (2 * dq)
        assert slope == pytest.approx((1.0 - ratio) ** (-1.0 / 3.0) / K_T, rel=1e-5)
        compliance.append(slope)
    assert compliance == sorted(compliance) and compliance[-1] > 9.0 / K_T
    # at the onset of gross slip the pad has moved the object by 3 mu_s F / (2 k_t)
    assert presliding_m(limit, f, MU_S, K_T) == 1.5 * limit / K_T
    assert presliding_m(-0.5 * limit, f, MU_S, K_T) == -presliding_m(0.5 * limit, f, MU_S, K_T)


def test_initial_slope_is_the_pad_stiffness_and_stiff_pads_tend_to_coulomb():
    f, q = 20.0, 1e-6
    assert presliding_m(q, f, MU_S, K_T) == pytest.approx(q / K_T, rel=1e-6)
    assert presliding_m(5.0, f, MU_S, 0.0) == 0.0              # rigid pads: Coulomb
    for k_t in (1e6, 1e9, 1e12):                                # delta <= 3 mu_s F / (2 k_t)
        assert 0.0 < presliding_m(5.0, f, MU_S, k_t) <= 1.5 * MU_S * f / k_t


def test_gross_slip_keeps_its_closed_forms_on_compliant_pads():
    m, a, f = 0.5, 1.0, 2.0
    hold = lifted(m, a)
    a_rel = G + a - 2.0 * MU_K * f / m
    t_loss = math.sqrt(2.0 * PAD_M / a_rel)
    assert hold.advance(f, 0.5 * t_loss) is None
    assert hold.state is HoldState.SLIDING
    assert hold.slip_m == pytest.approx(0.5 * a_rel * (0.5 * t_loss) ** 2, rel=1e-12)
    # sliding, each pad carries mu_k F and stays sheared by it
    assert hold.shear_n(f) == MU_K * f
    assert hold.presliding_m(f) == pytest.approx(closed_form_m(MU_K * f, f), rel=1e-12)
    assert hold.advance(f, t_loss) == pytest.approx(0.5 * t_loss, rel=1e-12)
    assert hold.state is HoldState.LOST and hold.presliding_m(f) == 0.0


def test_rigid_and_compliant_pads_slide_alike():
    runs = []
    for k_t in (0.0, K_T):
        hold = lifted(1.0, 10.0, k_t)
        trace = []
        for _ in range(40):
            hold.advance(15.0, 1e-3)
            trace.append((hold.state, hold.slip_m, hold.slip_speed_mps))
        runs.append(trace)
    assert runs[0] == runs[1]


def test_plant_reports_the_pad_shear_and_displacement_of_a_lifted_object():
    volts, m, a = 10.0, 1.0, 2.0
    plant = make_plant(CONFIG)
    plant.set_object(plant.configured_friction(GraspObject(0.05, mass_kg=m)),
                     lift=Lift(a, 0.0, 1.0))
    plant.touch_object()
    for _ in range(2000):
        plant.step(volts, 1e-4)
    plant.begin_hold(plant.t_ns)
    plant.step(volts, 1e-4)
    state = plant.object_state
    f = plant.sample().force_n
    assert state.state is HoldState.STUCK
    assert state.shear_n == pytest.approx(0.5 * m * (G + a), rel=1e-15)
    assert state.presliding_m == pytest.approx(closed_form_m(state.shear_n, f), rel=1e-12)
