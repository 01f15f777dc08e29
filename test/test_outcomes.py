"""Outcomes a robot program can rely on, over the real node graph (DDS, lockstep, services).

Faults are injected in the plant through ``/gripper/sim/set_object`` (``SetObject.FAULT_*``,
fired at an exact simulated instant after the start of the next grasp); every outcome must be in
the service response and on the status topic, the motor command must stay within +-24 V, and a
grasp after each of them must succeed. Known answers: the object removed while holding is lost
within ``lost_force_hold_s`` (+ one force sample); a slipping object (capacity F_0 e^(-t/tau))
within ``tau ln(1/lost_force_fraction) + lost_force_hold_s``; a sensor dropout is a FAULT at the
first sample after it; a release ends within 2 % of the open position.

Runs stay short: a 0.14 m object (0.01 m of travel) of 3 kg (F_sp = 14.7 N, approach cap 10.6 V)
settles in about 0.91 s of simulated time.
"""
import math
import threading
import time

from gripper_interfaces.msg import MotorCommand, SupervisorStatus
from gripper_interfaces.srv import SetObject
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (Controller, Outcome, Phase, TOPIC_MOTOR_COMMAND, TOPIC_OUTCOME,
                              TOPIC_STATUS)
import pytest

CONFIG = load_config()
S = CONFIG.supervisor
L_LS = CONFIG.plant.max_travel_m
V_LIMIT = CONFIG.plant.voltage_limit_v
WIDTH, MASS = 0.14, 1.0
F_SP = S.grip_safety_factor * MASS * CONFIG.plant.gravity_mps2 / (2 * S.friction_coefficient)
FORCE_SAMPLE_S = CONFIG.force.sample_time_s


class Tap:
    """What a robot program sees: the status topic and the motor commands."""

    def __init__(self, node):
        self._lock = threading.Lock()
        self.last_status: SupervisorStatus | None = None
        self.commands: list[tuple[int, float]] = []
        self.subscriptions = [
            node.create_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status, GRAPH_QOS),
            node.create_subscription(MotorCommand, TOPIC_MOTOR_COMMAND, self._on_command,
                                     GRAPH_QOS)]

    def matched(self) -> bool:
        """Tell whether every reader has matched the graph's writers (both controllers')."""
        status, commands = self.subscriptions
        return status.get_publisher_count() >= 1 and commands.get_publisher_count() >= 2

    def _on_status(self, msg):
        with self._lock:
            self.last_status = msg

    def _on_command(self, msg):
        with self._lock:
            self.commands.append((msg.stamp_ns, msg.voltage_v))

    def take_commands(self):
        with self._lock:
            out, self.commands = self.commands, []
        return out

    def final_status(self, grasp_id: int, timeout_s: float = 5.0) -> SupervisorStatus:
        """Return the latched last status of ``grasp_id`` (it may come just after the reply)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            s = self.last_status
            if s is not None and s.grasp_id == grasp_id and s.outcome != 0:
                return s
            time.sleep(0.005)
        raise AssertionError(f'no final status for grasp {grasp_id}: {self.last_status}')


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(action_server=False)) as g:
        g.tap = Tap(g.client_node)
        assert wait_until(g.tap.matched, 10.0)
        yield g


def grasp_ok(graph, open_fingers=True):
    assert graph.set_object(WIDTH, open_fingers=open_fingers).success
    r = graph.grasp(WIDTH, MASS)
    assert r.success and r.outcome == Outcome.HOLDING, r.message
    assert abs(r.final_force_n - F_SP) <= S.force_settle_band_fraction * F_SP
    return r


@pytest.fixture(scope='module')
def settle_s(graph):
    """Measure simulated time from the start of a grasp of the test object to a settled force."""
    graph.tap.take_commands()
    r = grasp_ok(graph)
    logic = graph.supervisor.logic
    status = graph.tap.final_status(r.grasp_id)
    assert status.phase == Phase.HOLDING and status.outcome == Outcome.HOLDING
    assert status.message == r.message and status.contact
    assert status.width_m == pytest.approx(WIDTH, abs=0.02 * (L_LS - WIDTH))
    # the force loop held and watched for hold_watch_s after settling before answering
    assert (logic.end_ns - logic.settled_ns) * 1e-9 == pytest.approx(S.hold_watch_s, abs=2e-4)
    return (logic.settled_ns - logic.start_ns) * 1e-9


def faulty_grasp(graph, fault, at_s, **kw):
    placed = graph.set_object(WIDTH, fault=fault, fault_at_s=at_s, **kw)
    assert placed.success and 'fault' in placed.message, placed.message
    graph.tap.take_commands()
    r = graph.grasp(WIDTH, MASS)
    logic = graph.supervisor.logic
    fault_ns = logic.start_ns + round(at_s * 1e9)
    assert graph.plant.plant.fired_faults[0] == (fault, fault_ns)
    commands = graph.tap.take_commands()
    assert commands and all(abs(v) <= V_LIMIT for _, v in commands)
    return r, (logic.end_ns - fault_ns) * 1e-9, commands


def test_object_removed_while_holding_is_object_lost_in_bounded_time(graph, settle_s):
    r, detect_s, _ = faulty_grasp(graph, SetObject.Request.FAULT_OBJECT_REMOVED, settle_s + 0.005)
    assert not r.success and r.outcome == Outcome.OBJECT_LOST, r.message
    assert 'object lost' in r.message and f'{F_SP:.3f} N' in r.message
    # the force drops to 0 at once: lost after lost_force_hold_s, within one force sample
    assert S.lost_force_hold_s <= detect_s <= S.lost_force_hold_s + FORCE_SAMPLE_S + 1e-9
    status = graph.tap.final_status(r.grasp_id)
    assert status.outcome == Outcome.OBJECT_LOST and status.phase == Phase.FAILED
    assert status.message == r.message
    assert status.active_controller == Controller.POSITION   # holds the finger where it is
    print(f'\nremoved: OBJECT_LOST {detect_s * 1e3:.2f} ms after the removal')
    # a program that subscribes only now still gets the outcome (latched topic)
    got = []
    sub = graph.client_node.create_subscription(SupervisorStatus, TOPIC_OUTCOME, got.append,
                                                LATCHED_QOS)
    deadline = time.monotonic() + 10
    while not got and time.monotonic() < deadline:
        time.sleep(0.01)
    graph.client_node.destroy_subscription(sub)
    assert got and got[-1].grasp_id == r.grasp_id and got[-1].outcome == Outcome.OBJECT_LOST
    assert got[-1].message == r.message
    grasp_ok(graph)


def test_slipping_object_is_object_lost_when_its_force_has_collapsed(graph, settle_s):
    tau = 0.01
    r, detect_s, _ = faulty_grasp(graph, SetObject.Request.FAULT_OBJECT_SLIPPING,
                                  settle_s + 0.005, fault_time_constant_s=tau)
    assert not r.success and r.outcome == Outcome.OBJECT_LOST, r.message
    # the measured force is F_0 exp(-t/tau), F_0 ~ F_sp: below 0.5 F_sp at tau ln 2, then the dwell
    expected = tau * math.log(1.0 / S.lost_force_fraction) + S.lost_force_hold_s
    assert abs(detect_s - expected) <= 4 * FORCE_SAMPLE_S, (detect_s, expected)
    assert graph.tap.final_status(r.grasp_id).outcome == Outcome.OBJECT_LOST
    print(f'\nslipping (tau {tau} s): OBJECT_LOST {detect_s * 1e3:.2f} ms after the slip began '
          f'(expected {expected * 1e3:.2f} ms)')
    grasp_ok(graph)


def test_sensor_dropout_is_a_fault_naming_the_sensor_and_the_motor_is_not_driven(
        graph, settle_s):
    r, detect_s, commands = faulty_grasp(graph, SetObject.Request.FAULT_SENSOR_DROPOUT,
                                         settle_s + 0.005)
    assert not r.success and r.outcome == Outcome.FAULT, r.message
    assert 'force sensor' in r.message and 'dropout' in r.message
    assert 0.0 < detect_s <= FORCE_SAMPLE_S + 1e-9       # the first sample after it
    end_ns = graph.supervisor.logic.end_ns
    assert all(stamp < end_ns for stamp, _ in commands)  # nothing answered the bad sample
    assert all(math.isfinite(v) for _, v in commands)
    frozen = graph.plant.ticks_published
    time.sleep(0.2)
    assert graph.plant.ticks_published == frozen         # nobody drives the plant
    status = graph.tap.final_status(r.grasp_id)
    assert status.outcome == Outcome.FAULT and 'force sensor' in status.message
    assert status.active_controller == Controller.NONE
    # the sensor stays out until the next set_object: a grasp is refused, saying why
    refused = graph.grasp(WIDTH, MASS)
    assert refused.outcome == Outcome.REFUSED and 'sensor dropout' in refused.message
    # ... but the fingers can still be opened: the release needs only the position
    released = graph.release(60)
    assert released.success, released.message
    assert abs(graph.plant.plant.sample().position_m) <= S.release_tolerance_m
    print(f'\ndropout: FAULT {detect_s * 1e3:.2f} ms after the dropout')
    grasp_ok(graph)


def test_a_fault_scheduled_after_the_grasp_ends_never_fires(graph, settle_s):
    assert graph.set_object(WIDTH, fault=SetObject.Request.FAULT_OBJECT_REMOVED,
                            fault_at_s=settle_s + 1.0).success
    r = graph.grasp(WIDTH, MASS)
    assert r.outcome == Outcome.HOLDING, r.message
    assert graph.plant.plant.fired_faults == [] and graph.plant.plant.scheduled_fault is None


def test_bad_fault_request_is_refused(graph):
    r = graph.set_object(WIDTH, fault=SetObject.Request.FAULT_OBJECT_SLIPPING, fault_at_s=0.1,
                         stiffness_n_per_m=1e4)
    assert not r.success and 'rigid objects only' in r.message
    r = graph.set_object(WIDTH, fault=SetObject.Request.FAULT_OBJECT_REMOVED, fault_at_s=-1.0)
    assert not r.success and 'fault_at_s' in r.message


def test_release_opens_the_fingers_and_the_next_grasp_succeeds(graph, settle_s):
    grasp_ok(graph)
    graph.tap.take_commands()
    r = graph.release(60)
    assert r.success and r.message.startswith('RELEASED'), r.message
    position = graph.plant.plant.sample().position_m
    assert abs(position - 0.0) <= 0.02 * L_LS                 # within 2 % of the open position
    assert abs(position) <= S.release_tolerance_m
    assert all(abs(v) <= V_LIMIT for _, v in graph.tap.take_commands())
    status = graph.tap.final_status(graph.supervisor.logic.grasp_id)
    assert status.outcome == Outcome.RELEASED and status.phase == Phase.DONE
    assert status.width_m == pytest.approx(L_LS, abs=S.release_tolerance_m)
    print(f'\nreleased: finger at {position * 1e3:.3f} mm from fully open')
    grasp_ok(graph, open_fingers=False)                       # from where the release left it


def test_release_is_refused_while_a_grasp_runs(graph):
    """The grasp is held in its position stage (paused, stepped) while the release is asked."""
    from helpers import step_into_phase
    assert graph.set_object(WIDTH).success
    assert graph.wait_still()
    assert graph.pause().success
    pending = graph.grasp_async(WIDTH, MASS)
    try:
        assert wait_until(lambda: graph.supervisor.logic.pending, 10.0)
        step_into_phase(graph, Phase.POSITION, ticks_into=5)
        assert graph.supervisor.logic.running
        r = graph.release(10)
    finally:
        assert graph.resume().success
    assert not r.success and 'grasp is running' in r.message and '/gripper/stop' in r.message
    assert wait_until(pending.done, 60.0)
    assert pending.result().outcome == Outcome.HOLDING


def test_object_removed_before_contact_is_no_object_not_object_lost(graph):
    """Loss needs a grip: an object gone before the fingers reach it is simply not there."""
    assert graph.set_object(WIDTH, fault=SetObject.Request.FAULT_OBJECT_REMOVED,
                            fault_at_s=0.3).success
    r = graph.grasp(WIDTH, MASS)
    assert r.outcome == Outcome.NO_OBJECT and 'without contact' in r.message, r.message
    assert graph.tap.final_status(r.grasp_id).outcome == Outcome.NO_OBJECT
    grasp_ok(graph)


def test_grasp_client_release_from_another_process(graph):
    import os
    import subprocess
    import sys

    def client(*args):
        return subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client', *args],
                              capture_output=True, text=True, timeout=60,
                              env=os.environ.copy())

    grasp_ok(graph)
    result = client('--release')
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'success: True' in result.stdout and 'RELEASED' in result.stdout
    assert abs(graph.plant.plant.sample().position_m) <= S.release_tolerance_m
    usage = client('--mass', '1.0')                       # a grasp needs --width
    assert usage.returncode == 2 and '--width and --mass are required' in usage.stderr
