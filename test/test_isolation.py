"""Two gripper graphs on one machine with different domain ids never meet.

Both graphs run in this process, each in its own rclpy Context bound to its own ROS_DOMAIN_ID
(the same DDS isolation two `grasp_demo` processes get), localhost discovery. Known answers: a
probe in domain A hears nothing while B grasps; each domain sees exactly one plant; two grasps
run at the same time on both give each graph its own object's result, as if it were alone.
"""
import os
import threading
import time

from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import DEFAULT_NAMESPACE, qualified, TOPIC_JOINT_STATES
import pytest
import rclpy
from sensor_msgs.msg import JointState

JOINT_STATES = qualified(DEFAULT_NAMESPACE, TOPIC_JOINT_STATES)
BOUND_S = 60.0
"""A bound on discovery and delivery: reached only when they never come."""

DOMAIN_A = int(os.environ.get('ROS_DOMAIN_ID', '0'))


def _graph(domain_id):
    return GripperGraph.in_own_context(GraphOptions(action_server=False), domain_id=domain_id)


@pytest.fixture(scope='module')
def graphs(spare_domain_id):
    assert DOMAIN_A != spare_domain_id           # B: a second id, locked for this run
    a = _graph(DOMAIN_A)
    b = _graph(spare_domain_id)
    yield a, b
    for g in (a, b):
        g.close()


def test_each_domain_sees_only_its_own_plant(graphs):
    for g in graphs:
        assert wait_until(lambda: g.client_node.count_publishers(JOINT_STATES) >= 1, BOUND_S)
        assert g.client_node.count_publishers(JOINT_STATES) == 1


def test_a_probe_in_one_domain_hears_nothing_of_the_other(graphs):
    a, b = graphs
    heard = []
    probe = rclpy.create_node('isolation_probe', context=a.context)
    probe.create_subscription(JointState, JOINT_STATES, heard.append, GRAPH_QOS)
    a.add_node(probe)
    b.set_object(0.10)
    ticks_before = b.plant.ticks_published
    assert b.grasp(0.10, 0.75).success
    assert b.plant.ticks_published - ticks_before > 1000      # B published a whole grasp
    time.sleep(0.2)
    assert heard == []                                    # ... and A heard none of it
    # the probe does work: it hears its own domain's grasp
    a.set_object(0.10)
    assert a.grasp(0.10, 0.75).success
    assert wait_until(lambda: len(heard) >= 200, BOUND_S)     # 100 Hz of a 2.2 s grasp


def test_simultaneous_grasps_on_both_domains_each_get_their_own_answer(graphs):
    a, b = graphs
    a.set_object(0.05)
    b.set_object(0.10)
    results = {}

    def run(name, g, width, mass):
        results[name] = g.grasp(width, mass, wall_timeout_s=120)

    threads = [threading.Thread(target=run, args=('a', a, 0.05, 1.69)),
               threading.Thread(target=run, args=('b', b, 0.10, 0.75))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=180)
    for name, width in (('a', 0.05), ('b', 0.10)):
        r = results[name]
        assert r.success, r.message
        assert r.final_width_m == pytest.approx(width, rel=0.02)
