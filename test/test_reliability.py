"""Bad input and load on the live graph: fuzzed requests, many clients at once.

Real DDS, real service calls, one EventsExecutor (as in grasp_demo).
"""
import math
import threading

from gripper_ros.core.config import load_config
from gripper_ros.core.supervision.requests import GraspRequest, RequestError, validate_request
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.wire import Outcome
from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
import pytest

CONFIG = load_config()


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        g.set_object(0.05)
        yield g


any_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e308, -1e308,
                     0.15, 0.15000000000000002, 1e-12]),
    st.floats(min_value=-1.0, max_value=1.0))


def _is_valid(fields):
    try:
        validate_request(GraspRequest(**fields), CONFIG.plant, CONFIG.supervisor)
        return True
    except RequestError:
        return False


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(width=any_float, mass=any_float, friction=any_float, accel=any_float, timeout=any_float,
       tolerance=any_float)
def test_fuzzed_requests_get_a_well_formed_refusal(graph, width, mass, friction, accel, timeout,
                                                   tolerance):
    fields = {'width_m': width, 'mass_kg': mass, 'friction_coefficient': friction,
              'acceleration_mps2': accel, 'timeout_s': timeout, 'width_tolerance_m': tolerance}
    if _is_valid(fields):
        return    # a valid request would run a whole grasp; valid grasps are tested elsewhere
    ticks = graph.plant.ticks_published
    r = graph.grasp(width, mass, friction, accel, timeout, wall_timeout_s=30,
                    width_tolerance_m=tolerance)
    assert r.success is False and r.outcome == Outcome.REFUSED
    assert r.message.startswith('refused: ') and len(r.message) > 12
    for value in (r.final_position_m, r.final_force_n, r.position_setpoint_m,
                  r.force_setpoint_n, r.switch_time_s):
        assert math.isfinite(value)
    assert graph.plant.ticks_published == ticks       # nothing moved


def test_valid_request_after_fuzzing_succeeds(graph):
    graph.set_object(0.05)
    assert graph.grasp(0.05, 1.69).success


def test_twenty_clients_at_once_exactly_one_grasp_runs(graph):
    graph.set_object(0.10)
    results = [None] * 20
    barrier = threading.Barrier(len(results))

    def client(i):
        barrier.wait()
        results[i] = graph.grasp(0.10, 0.75, wall_timeout_s=120)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(len(results))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=180)
    assert all(r is not None for r in results)
    held = [r for r in results if r.outcome == Outcome.HOLDING]
    busy = [r for r in results if r.outcome == Outcome.REFUSED]
    assert len(held) == 1 and len(busy) == len(results) - 1
    # refused while the first one waited for its tick, or while it ran
    assert all('grasp is running' in r.message or 'request is waiting' in r.message
               for r in busy), [r.message for r in busy]
    assert graph.supervisor.logic.grasp_id == held[0].grasp_id


def test_dead_force_controller_mid_grasp_ends_in_fault_naming_it(graph):
    """Its own graph: a controller is destroyed at the switch; the lockstep must not hang.

    The graph is paused and stepped to the first tick of the force stage, so the kill comes
    there on any machine; time then runs again.
    """
    import time

    from gripper_ros.nodes.services import wait_until
    from gripper_ros.wire import Phase
    from helpers import step_into_phase
    graph.close()   # one graph at a time on this domain
    with GripperGraph.in_own_context() as g:
        g.set_object(0.10)
        assert g.wait_still()
        assert g.pause().success
        pending = g.grasp_async(0.10, 0.75)
        assert wait_until(lambda: g.supervisor.logic.pending, 10.0)
        step_into_phase(g, Phase.FORCE, 0, lead_s=1.5)
        g.kill_node(g.force)
        killed_at = time.monotonic()
        assert g.resume().success
        assert wait_until(pending.done, 60.0)
        detected_s = time.monotonic() - killed_at
        r = pending.result()
        print(f'\ndead force controller detected after {detected_s:.3f} s wall: {r.message}')
        assert r.outcome == Outcome.FAULT and not r.success
        assert 'force_controller' in r.message
        # the other controller never stepped in, and neither controller's status watchdog fired
        assert g.position.watchdog_trips == 0
        assert detected_s < g.supervisor.tick_timeout_s + 2.0
