"""A live arm drives the load through ``sim/load_acceleration`` while the gripper holds.

The graph (real DDS, fast mode) holds a 1 kg object at the friction law's grip for a resting
object (k m g / (2 mu_s)); an AccelStamped from another node at an upward acceleration beyond
what that grip carries, ``a > g (k - 1)``, makes the object slide at ``a_rel = g + a - 2 mu_k F
/ m`` and leave the pads after ``sqrt(2 L / a_rel)``; the supervisor then reports OBJECT_LOST.
Below that acceleration the object stays stuck.
"""
import math
import time

from geometry_msgs.msg import AccelStamped
from gripper_ros.core.config import load_config
from gripper_ros.core.physics.hold import HoldState
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.wire import Outcome, TOPIC_LOAD_ACCELERATION
import pytest

CONFIG = load_config()
G = CONFIG.plant.gravity_mps2
C = CONFIG.contact
K = CONFIG.supervisor.grip_safety_factor
WIDTH, MASS = 0.05, 1.0


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(action_server=False)) as g:
        g.arm = g.client_node.create_publisher(AccelStamped, TOPIC_LOAD_ACCELERATION,
                                               GRAPH_QOS)
        deadline = time.monotonic() + 10.0
        while g.arm.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert g.arm.get_subscription_count() > 0
        yield g


def hold(graph):
    assert graph.set_object(WIDTH, mass_kg=MASS, default_friction=True).success
    r = graph.grasp(WIDTH, MASS)
    assert r.success and r.outcome == Outcome.HOLDING, r.message
    graph.wait_still()
    return r.final_force_n


def drive(graph, accel_mps2):
    msg = AccelStamped()
    msg.accel.linear.z = accel_mps2
    t0 = graph.sim_time_ns
    graph.arm.publish(msg)
    deadline = time.monotonic() + 20.0
    while graph.sim_time_ns == t0 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert graph.wait_still(timeout_s=60.0)


def test_a_live_acceleration_beyond_the_grip_makes_the_object_slide_out(graph):
    f = hold(graph)
    assert f == pytest.approx(K * MASS * G / (2 * C.static_friction), rel=0.02)
    a = 3.0 * G * (K - 1.0)                      # well beyond what the grip carries
    drive(graph, a)
    plant = graph.plant.plant
    state = plant.object_state
    assert state.state is HoldState.NONE or state.state is HoldState.LOST
    assert state.lost_ns is not None or plant.hold_state is HoldState.NONE
    logic = graph.supervisor.logic
    assert logic.outcome == Outcome.OBJECT_LOST, logic.message
    a_rel = G + a - 2 * C.kinetic_friction * f / MASS
    assert a_rel > 0.0 and math.sqrt(2 * C.pad_length_m / a_rel) < C.after_lift_s


def test_a_live_acceleration_within_the_grip_leaves_it_stuck(graph):
    graph.release()
    hold(graph)
    drive(graph, 0.5 * G * (K - 1.0))
    state = graph.plant.plant.object_state
    assert state.state is HoldState.STUCK and state.slip_m == 0.0
    assert state.lift_acceleration_mps2 == 0.5 * G * (K - 1.0)
    assert graph.supervisor.logic.outcome == Outcome.HOLDING
