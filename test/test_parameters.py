"""Node parameters and start-up configuration: bad values are refused with a reason.

1. Start-up (before any graph runs on this domain): a bad YAML file given through the nodes'
   ``config_file`` parameter (missing key, wrong type, negative resistance, out-of-range value)
   stops every node with a ConfigError naming the key; the installed executables exit with
   status 2 and that one-line message. An out-of-range parameter override stops start-up too.
   A standard ROS params file sets config keys at start-up.
2. The running graph: every numeric parameter of a node's own, declared with a range, found
   through the nodes' own ``describe_parameters`` services, refuses out-of-range, non-finite and
   wrongly typed values over a real ``rcl_interfaces/srv/SetParameters`` call, with a reason, and
   keeps its value; every read-only parameter refuses any change. Every config key is a
   parameter of the nodes that use it, described and ranged as the config schema declares it;
   a writable one is checked by the config reader (refused with its message) and
   takes effect: a gain from the position controller's next stage on, a threshold from the
   supervisor's next tick.
"""
import math
import os
from pathlib import Path
import re
import shutil
import subprocess
import time

from gripper_ros.core.config import ConfigError, flatten, SCHEMA
from gripper_ros.nodes.control_actions import FollowJointTrajectory
from gripper_ros.nodes.controller_node import DEFAULT_STATUS_TIMEOUT_S
from gripper_ros.nodes.description_node import DescriptionPublisher
from gripper_ros.nodes.excitation_node import ExcitationServer
from gripper_ros.nodes.force_controller_node import ForceControllerNode
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.grasp_action_node import GraspActionServer
from gripper_ros.nodes.move_action_node import MoveActionServer
from gripper_ros.nodes.parameters import refuse_unknown_overrides
from gripper_ros.nodes.plant_simulator_node import PlantSimulatorNode
from gripper_ros.nodes.position_controller_node import PositionControllerNode
from gripper_ros.nodes.supervisor_node import DEFAULT_TICK_TIMEOUT_S, SupervisorNode
from gripper_ros.nodes.trajectory_action_node import TrajectoryActionServer
from gripper_ros.wire import DEFAULT_NAMESPACE, Outcome, Phase, STATUS_HEARTBEAT_S
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters
import rclpy
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
import yaml

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / 'config' / 'gripper.yaml'
BIN = REPO / 'install' / 'gripper_ros' / 'lib' / 'gripper_ros'
SHIPPED_DATA = yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))

NODE_CLASSES = {'plant_simulator': PlantSimulatorNode,
                'position_controller': PositionControllerNode,
                'force_controller': ForceControllerNode,
                'supervisor': SupervisorNode,
                'grasp_action_server': GraspActionServer}

# every numeric parameter of the nodes' own (not a config key) they declare with a range (the
# graph test checks that the nodes declare no other, and that these are ranged)
RANGED = {('supervisor', 'tick_timeout_s'), ('supervisor', 'status_rate_hz'),
          ('force_controller', 'approach_force_margin'),
          ('grasp_action_server', 'feedback_period_s'),
          ('position_controller', 'status_timeout_s'), ('force_controller', 'status_timeout_s'),
          ('plant_simulator', 'real_time_factor'), ('plant_simulator', 'state_rate_hz'),
          ('plant_simulator', 'command_timeout_s')}
READ_ONLY = {('position_controller', 'controller'), ('force_controller', 'controller'),
             ('plant_simulator', 'frame_id'), ('plant_simulator', 'time_mode'),
             ('plant_simulator', 'publish_clock')} | {(n, 'config_file') for n in NODE_CLASSES}
# the config sections each node declares as parameters: (writable, read-only)
# (a section, or one key of a section)
CONFIG_SECTIONS = {'plant_simulator': ((), ('plant', 'contact', 'force_sensor',
                                            'sensor_noise', 'pad_sensor',
                                            'force_control.sample_time_s')),
                   'position_controller': (('position_control',), ('plant',)),
                   'force_controller': (('force_control',), ('plant',)),
                   'supervisor': (('supervisor',), ('plant', 'contact',
                                                    'force_control.sample_time_s',
                                                    'pad_sensor', 'load_grip')),
                   'grasp_action_server': ((), ())}
START_UP_ONLY = {'force_control.sample_time_s'}
"""Keys used by more than one node: read-only even in their owner's writable section."""


def _entry_keys(entry):
    section, _, leaf = entry.partition('.')
    return {entry} if leaf else set(flatten(SHIPPED_DATA[section], section + '.'))


def config_keys(node_name, which):
    """Return the dotted config keys a node declares: ``which`` 0 = writable, 1 = read-only."""
    writable, read_only = ({k for entry in CONFIG_SECTIONS[node_name][i]
                            for k in _entry_keys(entry)} for i in (0, 1))
    return writable - START_UP_ONLY if which == 0 else read_only | (writable & START_UP_ONLY)


def _bad_config(tmp_path, dotted, value):
    data = yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))
    *parents, leaf = dotted.split('.')
    section = data
    for p in parents:
        section = section[p]
    if value is None:
        del section[leaf]
    else:
        section[leaf] = value
    path = tmp_path / f'bad_{dotted.replace(".", "_")}.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


BAD_CONFIGS = [   # (key, value or None = missing, words in the message)
    ('plant.resistance_ohm', None, 'missing'),
    ('plant.gear_ratio', 'four', 'must be a number'),
    ('plant.resistance_ohm', -2.32, '> 0'),
    ('force_control.closed_loop_pole', 1.5, '[0, 1)'),
    ('supervisor.timeout_s', float('nan'), 'finite'),
]
BAD_IDS = ['missing', 'wrong_type', 'negative_resistance', 'out_of_range', 'nan']


# ====================================================================== start-up
@pytest.fixture
def own_context():
    """Yield a context on a domain of its own (101..200, beyond those scripts/test.sh hands out).

    A node whose constructor fails leaves its parameter services behind until shutdown, and they
    must never answer for the graph's nodes.
    """
    context = Context()
    domain_id = 100 + int(os.environ.get('ROS_DOMAIN_ID', '0')) % 100 + 1
    rclpy.init(context=context, domain_id=domain_id)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('node_name', list(NODE_CLASSES))
@pytest.mark.parametrize('key, value, words', BAD_CONFIGS, ids=BAD_IDS)
def test_bad_config_file_stops_every_node_naming_the_key(own_context, tmp_path, node_name,
                                                         key, value, words):
    path = _bad_config(tmp_path, key, value)
    with pytest.raises(ConfigError) as info:
        NODE_CLASSES[node_name](context=own_context, parameter_overrides=[
            Parameter('config_file', value=str(path))])
    assert key in str(info.value) and words in str(info.value)


def test_bad_config_file_stops_the_whole_graph(own_context, tmp_path):
    path = _bad_config(tmp_path, 'plant.resistance_ohm', -2.32)
    with pytest.raises(ConfigError, match=r'plant\.resistance_ohm.*> 0'):
        GripperGraph(GraphOptions(config_file=str(path)), context=own_context)


def test_missing_config_file_stops_a_node_naming_the_file(own_context, tmp_path):
    with pytest.raises(ConfigError, match='nope.yaml'):
        SupervisorNode(context=own_context, parameter_overrides=[
            Parameter('config_file', value=str(tmp_path / 'nope.yaml'))])


@pytest.mark.parametrize('node_name, parameter, value', [
    ('supervisor', 'tick_timeout_s', 0.0),
    ('supervisor', 'tick_timeout_s', 1e6),
    ('force_controller', 'approach_force_margin', -0.5),
    ('force_controller', 'approach_force_margin', 11.0),
    ('grasp_action_server', 'feedback_period_s', -1.0),
    ('position_controller', 'status_timeout_s', 0.0),
    ('force_controller', 'status_timeout_s', math.inf),
    ('force_controller', 'status_timeout_s', STATUS_HEARTBEAT_S),   # a live, idle supervisor
])
def test_out_of_range_override_stops_start_up_naming_the_parameter(own_context, node_name,
                                                                   parameter, value):
    with pytest.raises(InvalidParameterValueException) as info:
        NODE_CLASSES[node_name](context=own_context,
                                parameter_overrides=[Parameter(parameter, value=value)])
    assert parameter in str(info.value) and 'out of range' in str(info.value)


def _run(executable, *ros_args):
    env = dict(os.environ)
    return subprocess.run([str(BIN / executable), '--ros-args', '-r',      # its own namespace
                           f'__ns:=/params_{executable}', *ros_args], env=env,
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)


def test_executables_exit_2_with_a_one_line_error_on_a_bad_config(tmp_path):
    """The real start-up path: ``ros2 run gripper_ros <node> --ros-args -p config_file:=...``."""
    path = _bad_config(tmp_path, 'plant.resistance_ohm', -2.32)
    procs = {name: subprocess.Popen([str(BIN / name), '--ros-args', '-r', f'__ns:=/bad_{name}',
                                     '-p', f'config_file:={path}'], stdin=subprocess.DEVNULL,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name in NODE_CLASSES}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 2, (name, proc.returncode, err[-2000:])
        lines = err.strip().splitlines()
        assert lines[-1].startswith(f'{name}: ') and 'plant.resistance_ohm' in lines[-1]
        assert 'Traceback' not in err


@pytest.mark.parametrize('executable, parameter, value', [
    ('position_controller', 'status_timeout_s', '0.0'),
    ('force_controller', 'approach_force_margin', '20.0'),
])
def test_controller_executables_exit_2_on_an_out_of_range_parameter(executable, parameter, value):
    r = _run(executable, '-p', f'{parameter}:={value}')
    assert r.returncode == 2, r.stderr[-2000:]
    assert 'Traceback' not in r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(f'{executable}: ') and parameter in last and 'out of range' in last


# ====================================================================== the running graph
@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        client = rclpy.create_node('parameter_client', context=g.context)
        g.add_node(client)
        g.param_client = client
        g.param_clients = {}
        yield g


def _service(graph, node_name, srv_type, suffix):
    key = (node_name, suffix)
    if key not in graph.param_clients:
        name = f'/{graph.namespace}/{node_name}/{suffix}'
        client = graph.param_client.create_client(srv_type, name)
        assert client.wait_for_service(timeout_sec=10.0), name
        graph.param_clients[key] = client
    return graph.param_clients[key]


def _describe(graph, node_name):
    names = graph.call(_service(graph, node_name, ListParameters, 'list_parameters'),
                       ListParameters.Request(), 10.0).result.names
    descriptors = graph.call(_service(graph, node_name, DescribeParameters,
                                      'describe_parameters'),
                             DescribeParameters.Request(names=list(names)), 10.0).descriptors
    return {d.name: d for d in descriptors}


def _get(graph, node_name, name):
    values = graph.call(_service(graph, node_name, GetParameters, 'get_parameters'),
                        GetParameters.Request(names=[name]), 10.0).values
    return Parameter.from_parameter_msg(ParameterMsg(name=name, value=values[0])).value


def _set(graph, node_name, name, value_msg, timeout_s=10.0):
    result = graph.call(_service(graph, node_name, SetParameters, 'set_parameters'),
                        SetParameters.Request(parameters=[ParameterMsg(name=name,
                                                                       value=value_msg)]),
                        timeout_s).results[0]
    return result


def _double(v):
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(v))


def _bad_values(descriptor):
    """Out of range on both sides, non-finite, and of the wrong type."""
    r = descriptor.floating_point_range[0]
    lo, hi = min(r.from_value, r.to_value), max(r.from_value, r.to_value)
    below = lo - max(1e-3, abs(lo) * 0.01)
    above = hi + max(1e-3, abs(hi) * 0.01)
    return [('below', _double(below), 'out of range'), ('above', _double(above), 'out of range'),
            ('nan', _double(math.nan), 'out of range'),
            ('+inf', _double(math.inf), 'out of range'),
            ('-inf', _double(-math.inf), 'out of range'),
            ('string', ParameterValue(type=ParameterType.PARAMETER_STRING, string_value='1.0'),
             'Wrong parameter type'),
            ('integer', ParameterValue(type=ParameterType.PARAMETER_INTEGER,
                                       integer_value=math.floor(below)), 'out of range'),
            ('bool', ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=True),
             'Wrong parameter type')]


@pytest.fixture(scope='module')
def descriptors(graph):
    return {node: _describe(graph, node) for node in NODE_CLASSES}


def test_the_ranged_and_read_only_parameters_are_the_known_ones(descriptors):
    ranged = {(n, p) for n, ds in descriptors.items() for p, d in ds.items()
              if d.floating_point_range or d.integer_range}
    read_only = {(n, p) for n, ds in descriptors.items() for p, d in ds.items() if d.read_only}
    config = {(n, p) for n in descriptors for which in (0, 1) for p in config_keys(n, which)}
    numeric = {(n, p) for n, ds in descriptors.items() for p, d in ds.items()
               if d.type in (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER)}
    assert ranged - config == RANGED
    assert numeric - config == RANGED  # numbers: ranged, or config keys the reader checks
    assert READ_ONLY <= read_only


def test_every_config_parameter_is_described_and_ranged_as_its_key_is_declared(descriptors):
    """``ros2 param describe`` gives each config key's meaning and its bounds from the schema.

    A number's range is the key's [low, high] exactly (integer for a whole number, such as a
    DMC horizon), a choice has none; every key has a description of its own.
    """
    checked = set()
    for node_name in NODE_CLASSES:
        for dotted in config_keys(node_name, 0) | config_keys(node_name, 1):
            d, spec = descriptors[node_name][dotted], SCHEMA[dotted]
            assert d.description == spec.description and spec.doc, (node_name, dotted)
            if spec.choices is not None:
                assert not (d.floating_point_range or d.integer_range), dotted
                continue
            [r] = d.integer_range if spec.integer else d.floating_point_range
            assert (r.from_value, r.to_value, r.step) == (*spec.bounds, 0), (dotted, r)
            assert not (d.floating_point_range if spec.integer else d.integer_range), dotted
            checked.add(dotted)
    assert 'supervisor.hold_watch_s' in checked and 'position_control.mpc_pd.horizon' in checked


@pytest.mark.parametrize('node_name', list(NODE_CLASSES))
def test_every_config_key_is_a_parameter_of_the_nodes_that_use_it(descriptors, node_name):
    ds = descriptors[node_name]
    writable, read_only = config_keys(node_name, 0), config_keys(node_name, 1)
    assert writable | read_only <= set(ds), sorted((writable | read_only) - set(ds))[:5]
    assert all(not ds[k].read_only for k in writable)
    assert all(ds[k].read_only for k in read_only)
    other = {k for k in ds if '.' in k and k.split('.')[0] in SHIPPED_DATA}
    assert other == writable | read_only            # and no other section


def test_every_ranged_parameter_refuses_bad_values_and_keeps_its_value(graph, descriptors):
    checked = 0
    for node_name, ds in descriptors.items():
        for name, d in ds.items():
            if (node_name, name) not in RANGED:      # config keys: the hostile graph's cases
                continue
            assert d.floating_point_range, (node_name, name, 'integer ranges: add cases')
            before = _get(graph, node_name, name)
            for label, value, words in _bad_values(d):
                result = _set(graph, node_name, name, value)
                assert not result.successful, (node_name, name, label)
                assert words in result.reason, (node_name, name, label, result.reason)
                if words == 'out of range':
                    assert name in result.reason
                assert _get(graph, node_name, name) == before, (node_name, name, label)
                checked += 1
    assert checked == 8 * len(RANGED)


def test_every_ranged_parameter_accepts_its_range_limits(graph, descriptors):
    """The range edges are valid values (the refusals above are not a closed door)."""
    for node_name, name in sorted(RANGED):
        d = descriptors[node_name][name]
        before = _get(graph, node_name, name)
        r = d.floating_point_range[0]
        for edge in (r.from_value, r.to_value, before):
            result = _set(graph, node_name, name, _double(edge))
            assert result.successful, (node_name, name, edge, result.reason)
            assert _get(graph, node_name, name) == edge
        assert _get(graph, node_name, name) == before


def test_read_only_parameters_refuse_any_change(graph, descriptors):
    """Even setting the value it already has is refused."""
    checked = 0
    for node_name, ds in descriptors.items():
        for name, d in ds.items():
            if not d.read_only:
                continue
            before = _get(graph, node_name, name)
            if name in config_keys(node_name, 1):
                values = [_double(before + 1.0 if isinstance(before, float) else 1.0)] \
                    if d.type == ParameterType.PARAMETER_DOUBLE else \
                    [ParameterValue(type=d.type, integer_value=int(before) + 1)]
            elif d.type == ParameterType.PARAMETER_STRING:
                values = [ParameterValue(type=d.type, string_value=text)
                          for text in ('pd', 'pi', 'mpc_pi', 'nonsense', before)]
            elif d.type == ParameterType.PARAMETER_BOOL:    # rclpy's own, on every node
                values = [ParameterValue(type=d.type, bool_value=b) for b in (True, False)]
            else:
                raise AssertionError((node_name, name, d.type, 'add a case'))
            for value in values:
                result = _set(graph, node_name, name, value)
                assert not result.successful and 'read-only' in result.reason, (node_name, name)
                assert _get(graph, node_name, name) == before
                checked += 1
    assert checked >= len(READ_ONLY) + sum(len(config_keys(n, 1)) for n in NODE_CLASSES)


NEW_TIMEOUT_S = 2.0
"""A controller's watchdog timeout set at run time: below the 3 s default, above the 1 s of the
supervisor's heartbeat (a paused simulation's only status)."""
NEW_TICK_TIMEOUT_S = 0.6
"""The supervisor's tick timeout set at run time, well below its 2 s default."""
TICKS_INTO_STAGE = 20
"""The stage runs this many ticks before the kill: its controller is named and answering."""
STAGE_LEAD_S = {Phase.POSITION: 0.0, Phase.FORCE: 1.5}
"""Simulated seconds stepped at once before the stage is looked for tick by tick: a 0.1 m grasp
from open fingers runs its position stage from 0.01 s to 1.92 s of simulated time."""


def _counted_silence_s(message: str, words: str) -> float:
    """Return the silence a watchdog's message says it counted (``<words> 1.23 s``)."""
    found = re.search(re.escape(words) + r' (\d+\.\d+) s', message)
    assert found, message
    return float(found.group(1))


def _param_graph(g):
    client = rclpy.create_node('parameter_client', context=g.context)
    g.add_node(client)
    g.param_client, g.param_clients = client, {}
    return g


@pytest.mark.parametrize('phase', [Phase.POSITION, Phase.FORCE], ids=['position', 'force'])
def test_a_new_status_timeout_is_the_one_the_controller_watchdog_fires_at(phase):
    """A stage controller's status_timeout_s set to 2 s: the supervisor killed in that stage.

    The controller commands 0 V once after 2 s without a status (its log says so), not after
    the 3 s default; the other controller, not named, never does. The simulation is paused and
    stepped into the stage, so the kill comes at a known simulated moment on any machine; the
    paused graph's supervisor still sends its heartbeat, which keeps the watchdog quiet.
    """
    from gripper_ros.nodes.services import wait_until
    from gripper_ros.nodes.watchdog import MAX_COUNTED_GAP_S
    from gripper_ros.wire import COMMAND_LAYOUT
    from helpers import step_into_phase
    with _param_graph(GripperGraph.in_own_context(GraphOptions(namespace='new_timeouts'))) as g:
        controller, other = (g.position, g.force) if phase is Phase.POSITION else \
            (g.force, g.position)
        name = controller.get_name()
        assert STATUS_HEARTBEAT_S < NEW_TIMEOUT_S < DEFAULT_STATUS_TIMEOUT_S
        assert _set(g, name, 'status_timeout_s',
                    _double(NEW_TIMEOUT_S)).successful
        assert other.status_timeout_s == DEFAULT_STATUS_TIMEOUT_S
        assert g.set_object(0.10).success
        assert g.wait_still()
        assert g.pause().success
        pending = g.grasp_async(0.10, 0.75)
        try:
            assert wait_until(lambda: g.supervisor.logic.pending, 10.0)
            step_into_phase(g, phase, TICKS_INTO_STAGE, STAGE_LEAD_S[phase])
            assert controller.watchdog_trips == 0 and controller.commands_published > 0
            g.kill_node(g.supervisor)
            killed_at = time.monotonic()
            assert wait_until(lambda: controller.watchdog_trips >= 1, NEW_TIMEOUT_S + 30.0)
            acted_s = time.monotonic() - killed_at
            message = controller.watchdog_message
            last = dict(zip(COMMAND_LAYOUT.fields, COMMAND_LAYOUT.unpack(
                controller._last_command)))
        finally:
            g.forget(pending)
    print(f'\n{phase.name}: 0 V {acted_s:.2f} s of wall time after the kill: {message}')
    silent_s = _counted_silence_s(message, 'no status from the supervisor for')
    assert NEW_TIMEOUT_S <= silent_s <= NEW_TIMEOUT_S + MAX_COUNTED_GAP_S, message
    assert silent_s < DEFAULT_STATUS_TIMEOUT_S
    assert name in message and 'supervisor' in message
    assert last['voltage_v'] == 0.0 and last['source'] == controller.source
    assert controller.watchdog_trips == 1 and other.watchdog_trips == 0


def test_a_new_tick_timeout_is_the_one_the_supervisor_watchdog_fires_at():
    """tick_timeout_s set to 0.6 s: the plant falls silent mid-approach, FAULT after 0.6 s.

    Not after the 2 s default. The plant is silenced at a known tick of the position stage (its
    tick publisher swallows every tick from there on, as a hung process would) and then killed.
    """
    from gripper_ros.nodes.services import wait_until
    from gripper_ros.nodes.watchdog import MAX_COUNTED_GAP_S
    from helpers import in_phase, TickHook
    with _param_graph(GripperGraph.in_own_context(GraphOptions(namespace='new_timeouts'))) as g:
        assert _set(g, 'supervisor', 'tick_timeout_s', _double(NEW_TICK_TIMEOUT_S)).successful
        assert g.set_object(0.10).success
        assert g.wait_still()
        hook = TickHook(g, in_phase(g, Phase.POSITION, TICKS_INTO_STAGE), silence=True)
        pending = g.grasp_async(0.10, 0.75)
        assert hook.fired.wait(30.0)
        g.kill_node(g.plant)
        assert wait_until(pending.done, NEW_TICK_TIMEOUT_S + 30.0)
        answer = pending.result()
    print(f'\n{Outcome(answer.outcome).name}: {answer.message}')
    assert answer.outcome == Outcome.FAULT, answer.message
    assert 'plant_simulator' in answer.message
    silent_s = _counted_silence_s(answer.message, 'no progress for')
    assert NEW_TICK_TIMEOUT_S <= silent_s <= NEW_TICK_TIMEOUT_S + MAX_COUNTED_GAP_S
    assert silent_s < DEFAULT_TICK_TIMEOUT_S


def test_a_new_approach_margin_is_the_one_a_bag_records(graph):
    """approach_force_margin reaches the force stage and the settings every bag records."""
    assert _set(graph, 'force_controller', 'approach_force_margin', _double(2.0)).successful
    assert graph.controller_settings()['approach_force_margin'] == 2.0
    assert _set(graph, 'force_controller', 'approach_force_margin', _double(1.0)).successful
    assert graph.controller_settings()['approach_force_margin'] == 1.0


def test_config_file_cannot_be_changed_on_a_running_node(graph, descriptors):
    """The file is read once at start-up: a new path would be accepted and silently ignored."""
    other = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value='/tmp/other.yaml')
    for node_name in NODE_CLASSES:
        assert descriptors[node_name]['config_file'].read_only, node_name
        before = _get(graph, node_name, 'config_file')
        result = _set(graph, node_name, 'config_file', other)
        assert not result.successful and 'read-only' in result.reason, node_name
        assert _get(graph, node_name, 'config_file') == before


def test_graph_still_grasps_after_the_refused_changes(graph):
    assert graph.set_object(0.10).success
    r = graph.grasp(0.10, 0.75, wall_timeout_s=60.0)
    assert r.success, r.message


def test_plant_answers_an_accepted_parameter_change(graph):
    """Last in the file: when it fails, the plant's parameter service is left broken.

    An accepted change publishes a parameter event stamped with the node's clock; the plant's
    Clock message once shadowed rclpy's ``Node._clock`` and the call was never answered.
    frame_id is read-only (read once at start-up), so an accepted change is use_sim_time's.
    """
    from rclpy.clock import Clock
    assert isinstance(graph.plant.get_clock(), Clock)
    result = _set(graph, 'plant_simulator', 'frame_id', ParameterValue(
        type=ParameterType.PARAMETER_STRING, string_value='other_frame'), timeout_s=3.0)
    assert not result.successful and 'read-only' in result.reason
    result = _set(graph, 'plant_simulator', 'use_sim_time', ParameterValue(
        type=ParameterType.PARAMETER_BOOL, bool_value=False), timeout_s=3.0)
    assert result.successful, result.reason
    assert _get(graph, 'plant_simulator', 'use_sim_time') is False
    assert graph.set_object(0.10).success      # the plant still answers its own service


def test_a_whole_number_is_taken_for_a_double_parameter_at_run_time(graph):
    """``ros2 param set ... kc 900`` sends an INTEGER: it is 900.0, and the controller uses it."""
    key = 'position_control.mpc_pd.kc'
    before = _get(graph, 'position_controller', key)
    try:
        result = _set(graph, 'position_controller', key, ParameterValue(
            type=ParameterType.PARAMETER_INTEGER, integer_value=900))
        assert result.successful, result.reason
        value = _get(graph, 'position_controller', key)
        assert isinstance(value, float) and value == 900.0
        assert graph.position.config.position.mpc_pd.kc == 900.0
    finally:
        assert _set(graph, 'position_controller', key, _double(before)).successful


def test_a_whole_number_is_taken_for_a_double_parameter_at_start_up(own_context):
    """``-p kc:=900`` and ``-p status_timeout_s:=5`` start the node; a horizon stays whole."""
    node = PositionControllerNode(context=own_context, parameter_overrides=[
        Parameter('position_control.mpc_pd.kc', value=900),
        Parameter('status_timeout_s', value=5),
        Parameter('position_control.mpc_pd.horizon', value=600)])
    try:
        assert node.config.position.mpc_pd.kc == 900.0
        assert node.get_parameter('status_timeout_s').type_ is Parameter.Type.DOUBLE
        assert node.status_timeout_s == 5.0
        horizon = node.get_parameter('position_control.mpc_pd.horizon')
        assert horizon.type_ is Parameter.Type.INTEGER and horizon.value == 600
    finally:
        node.destroy_node()


# ---------------------------------------------------------------------- config keys at run time
def _value(v):
    if isinstance(v, bool):
        return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=v)
    if isinstance(v, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=v)
    if isinstance(v, str):
        return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=v)
    return _double(v)


@pytest.mark.parametrize('node_name', ['position_controller', 'force_controller', 'supervisor'])
def test_every_writable_config_number_refuses_bad_values_naming_the_key(graph, node_name):
    """NaN, infinity and a negative number go through the config reader and are refused.

    The refusal carries the reader's message, which names the key, and the value stays.
    """
    checked = 0
    for key in sorted(config_keys(node_name, 0)):
        before = _get(graph, node_name, key)
        if isinstance(before, bool) or not isinstance(before, (int, float)):
            continue
        bad = [-1] if isinstance(before, int) else [math.nan, math.inf, -1.0]
        for value in bad:
            result = _set(graph, node_name, key, _value(value))
            assert not result.successful, (key, value)
            assert key in result.reason, (key, value, result.reason)
            assert _get(graph, node_name, key) == before
            checked += 1
    assert checked > 10


def test_a_gain_set_over_the_parameter_services_takes_effect_at_the_next_stage(
        graph, tmp_path):
    """A gain set over the parameter services takes effect at the next stage.

    ``ros2 param set /gripper/position_controller position_control.mpc_pd.kc 900.0``: the next
    grasp's position stage runs with it, tick for tick as the headless loop with that gain.
    """
    import dataclasses
    from gripper_ros.bags.series import load_grasp_series
    from gripper_ros.core.config import load_config
    from gripper_ros.core.runtime.headless import simulate_grasp
    from gripper_ros.nodes.recording import recorded_grasp
    key = 'position_control.mpc_pd.kc'
    shipped = SHIPPED_DATA['position_control']['mpc_pd']['kc']
    assert _get(graph, 'position_controller', key) == shipped
    try:
        result = _set(graph, 'position_controller', key, _double(900.0))
        assert result.successful, result.reason
        assert _get(graph, 'position_controller', key) == 900.0
        run = recorded_grasp(graph, tmp_path / 'kc900', 0.10, 0.75)
        assert run.response.success, run.response.message
        assert run.recorded['/gripper/loop/tick'] > 100
        series = load_grasp_series(run.bag_dir)
        assert series.custom_data['config']['position_control']['mpc_pd']['kc'] == 900.0
        cfg = load_config()
        cfg = dataclasses.replace(cfg, position=dataclasses.replace(
            cfg.position, mpc_pd=dataclasses.replace(cfg.position.mpc_pd, kc=900.0)))
        start = int(series.decisions['stamp_ns'][0])
        h = simulate_grasp(cfg, 0.10, 0.75, start_ns=start - round(
            cfg.position.sample_time_s * 1e9))
        shipped_run = simulate_grasp(load_config(), 0.10, 0.75, start_ns=start)
        assert np.array_equal(h.series.ticks['position_m'][1:], series.ticks['position_m'])
        assert not np.array_equal(shipped_run.series.ticks['position_m'][:50],
                                  h.series.ticks['position_m'][1:51])
    finally:
        assert _set(graph, 'position_controller', key, _double(shipped)).successful


def test_a_supervisor_threshold_applies_from_the_next_tick(graph):
    """supervisor.timeout_s set to 0.5 s: the next grasp (which needs 2 s) times out."""
    key = 'supervisor.timeout_s'
    before = _get(graph, 'supervisor', key)
    try:
        assert _set(graph, 'supervisor', key, _double(0.5)).successful
        assert graph.supervisor.logic.params.timeout_s == 0.5
        assert graph.set_object(0.10).success
        r = graph.grasp(0.10, 0.75, wall_timeout_s=60.0)
        assert r.outcome == 4 and 'not settled within 0.5 s' in r.message, r.message  # TIMEOUT
    finally:
        assert _set(graph, 'supervisor', key, _double(before)).successful


def test_the_force_law_is_a_parameter(graph):
    key = 'supervisor.force_law'
    assert _get(graph, 'supervisor', key) == 'friction'
    refused = _set(graph, 'supervisor', key, _value('nonsense'))
    assert not refused.successful and 'friction' in refused.reason and 'paper' in refused.reason
    try:
        assert _set(graph, 'supervisor', key, _value('paper')).successful
        assert graph.set_object(0.10).success
        r = graph.grasp(0.10, 0.75, wall_timeout_s=60.0)
        mu, g = SHIPPED_DATA['supervisor']['friction_coefficient'], 9.81
        assert r.force_setpoint_n == pytest.approx(mu * 0.75 * g)         # eq. 23 as printed
    finally:
        assert _set(graph, 'supervisor', key, _value('friction')).successful


def test_a_params_file_sets_config_keys_at_start_up(tmp_path):
    """A standard ROS params file (nested or dotted keys), read by rcl at start-up."""
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {'position_control': {'mpc_pd': {'kc': 901.0}}}},
        f'/{DEFAULT_NAMESPACE}/supervisor': {'ros__parameters': {'supervisor.timeout_s': 7.5}}}),
        encoding='utf-8')
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)],
               domain_id=100 + int(os.environ.get('ROS_DOMAIN_ID', '0')) % 100 + 1)
    try:
        position = PositionControllerNode(context=context)
        supervisor = SupervisorNode(context=context)
        assert position.get_parameter('position_control.mpc_pd.kc').value == 901.0
        assert position.config.position.mpc_pd.kc == 901.0
        assert supervisor.config.supervisor.timeout_s == 7.5
        assert supervisor.logic.params.timeout_s == 7.5
        for node in (position, supervisor):
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_set_of_an_unknown_name_is_refused_naming_it_and_the_nearest(graph):
    """``ros2 param set`` of a typo: the name in the refusal, and what it was likely meant as.

    rclpy alone answers ``Invalid access to undeclared parameter(s): []`` (its
    ``_check_undeclared_parameters`` lists a generator its ``any()`` consumed).
    """
    refused = _set(graph, 'supervisor', 'supervisor.timeot_s', _double(5.0))
    assert not refused.successful
    assert refused.reason == ('Invalid access to undeclared parameter(s): '
                              "['supervisor.timeot_s']; did you mean \"supervisor.timeout_s\"?")
    refused = _set(graph, 'plant_simulator', 'bogus_key', _double(1.0))
    assert not refused.successful and "['bogus_key']; known here: " in refused.reason
    assert _get(graph, 'supervisor', 'supervisor.timeout_s') == \
        SHIPPED_DATA['supervisor']['timeout_s']


@pytest.mark.skipif(shutil.which('ros2') is None, reason='ros2cli is not installed')
def test_ros2_param_set_of_an_unknown_name_says_which(graph):
    """The real ``ros2 param set`` prints the refusal's reason: the name and the nearest one."""
    run = subprocess.run(['ros2', 'param', 'set', '--no-daemon', '--timeout', '60',
                          f'/{graph.namespace}/supervisor', 'supervisor.timeot_s', '5.0'],
                         capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert run.stderr.strip() == ('Setting parameter failed: Invalid access to undeclared '
                                  "parameter(s): ['supervisor.timeot_s']; did you mean "
                                  '"supervisor.timeout_s"?'), run.stdout + run.stderr


UNKNOWN_OVERRIDES = [   # (node class, a typo of one of its parameters, the name it meant)
    (PlantSimulatorNode, 'time_mod', 'time_mode'),
    (PositionControllerNode, 'position_control.mpc_pd.kcc', 'position_control.mpc_pd.kc'),
    (ForceControllerNode, 'status_timeout', 'status_timeout_s'),
    (SupervisorNode, 'supervisor.timeot_s', 'supervisor.timeout_s'),
    (GraspActionServer, 'feedback_period', 'feedback_period_s'),
    (MoveActionServer, 'allow_stalled', 'allow_stalling'),
    (ExcitationServer, 'excitation.amplitude', 'excitation.amplitude_v'),
    (DescriptionPublisher, 'publish_frequncy', 'publish_frequency'),
    (TrajectoryActionServer, 'constraints.goal_tme', 'constraints.goal_time')]
NEEDS_CONTROL_MSGS = pytest.mark.skipif(FollowJointTrajectory is None,
                                        reason='control_msgs is not installed')


@pytest.mark.parametrize('node_class, typo, meant', [
    pytest.param(*case, marks=NEEDS_CONTROL_MSGS if case[0] is TrajectoryActionServer else ())
    for case in UNKNOWN_OVERRIDES], ids=[c.__name__ for c, *_ in UNKNOWN_OVERRIDES])
def test_an_unknown_start_up_parameter_is_refused_naming_the_nearest(own_context, node_class,
                                                                     typo, meant):
    """A ``-p`` or params-file name the node does not declare ends its start (run_node).

    As a typo in config_file: the name, and the closest of the node's own in its group.
    """
    node = node_class(context=own_context, namespace=f'params_unknown_{node_class.__name__}',
                      parameter_overrides=[Parameter(typo, value=1.0)])
    try:
        with pytest.raises(ConfigError, match=f'^unknown parameter "{re.escape(typo)}"; '
                                              f'did you mean "{re.escape(meant)}"[?]$'):
            refuse_unknown_overrides([node])
    finally:
        node.destroy_node()


def test_every_node_executable_is_held_to_its_declared_parameters():
    """Every node class of the package is a case above: each runs through run_node's check."""
    from gripper_ros.nodes import NODE_MODULES
    import importlib
    classes = {cls for module in NODE_MODULES.values() for cls in vars(importlib.import_module(
        f'gripper_ros.nodes.{module}')).values()
        if isinstance(cls, type) and cls.__module__.endswith(module) and
        issubclass(cls, Node)}
    assert classes == {c for c, *_ in UNKNOWN_OVERRIDES}


def test_a_bad_params_file_value_stops_the_executable_in_one_line(tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'position_control.mpc_pd.kc': -5.0}}}), encoding='utf-8')
    r = _run('position_controller', '--params-file', str(path))
    assert r.returncode == 2, r.stderr[-2000:]
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith('position_controller: ') and 'position_control.mpc_pd.kc' in last
    assert 'Traceback' not in r.stderr


# ---------------------------------------------------------------------- every run-time change
GRAPH_NODES = (*NODE_CLASSES, 'move_action_server', 'excitation_server') + (
    ('trajectory_action_server',) if FollowJointTrajectory is not None else ())
RCLPY_OWN = {'use_sim_time'}
"""rclpy's own writable parameter on every node (test_plant_answers_... sets it)."""


def _new_value(before, descriptor):
    """Return a valid value other than ``before``: the other choice, one less, 0.8x or 1e-4."""
    if isinstance(before, bool):
        return not before
    if isinstance(before, str):
        return {'friction': 'paper', 'paper': 'friction'}[before]
    if isinstance(before, int):
        return before - 1 if before > 1 else before + 1
    new = 0.8 * before if before else 1e-4
    if descriptor.floating_point_range:
        r = descriptor.floating_point_range[0]
        assert r.from_value <= new <= r.to_value, (descriptor.name, new)
    return new


def _in_use(node, name):
    """Return what ``node`` runs with (or its next stage will) for parameter ``name``."""
    if name == 'approach_force_margin':
        return float((node._next_stage or node.stage).record[0]['approach_margin'])
    if name.startswith('excitation.'):
        return getattr(node.spec, name.split('.', 1)[1])
    if node.get_name() == 'trajectory_action_server':     # read as each goal is accepted
        return node.get_parameter(name).value
    if '.' not in name:
        return getattr(node, name)
    stage = getattr(node, '_next_stage', None) or getattr(node, 'stage', None)
    config = stage.config if stage is not None else node.config
    if name.startswith('supervisor.'):
        assert node.logic.params is config.supervisor
    return flatten(config.data)[name]


def _set_atomically(graph, node_name, values):
    from rcl_interfaces.srv import SetParametersAtomically
    service = _service(graph, node_name, SetParametersAtomically, 'set_parameters_atomically')
    return graph.call(service, SetParametersAtomically.Request(parameters=[
        ParameterMsg(name=k, value=_value(v)) for k, v in values.items()]), 30.0).result


def test_every_writable_parameter_set_at_run_time_reaches_every_node_that_uses_it(graph):
    """Each node's writable parameters, all set at once over SetParametersAtomically.

    Every node that declares a changed name then reports the new value and runs with it (its
    next stage's kernel, its supervisor thresholds, its timers' settings); no key is writable
    on one node and a start-up copy on another. A key several nodes use is read-only on each,
    with the reason in its description.
    """
    described = {n: _describe(graph, n) for n in GRAPH_NODES}
    nodes = {graph.plant.get_name(): graph.plant, graph.position.get_name(): graph.position,
             graph.force.get_name(): graph.force, graph.supervisor.get_name(): graph.supervisor,
             graph.action_server.get_name(): graph.action_server,
             graph.move_action_server.get_name(): graph.move_action_server,
             graph.excitation_server.get_name(): graph.excitation_server}
    if graph.trajectory_action_server is not None:
        nodes[graph.trajectory_action_server.get_name()] = graph.trajectory_action_server
    for key in START_UP_ONLY:
        holders = [n for n, ds in described.items() if key in ds]
        assert sorted(holders) == ['force_controller', 'plant_simulator', 'supervisor']
        for node_name in holders:
            d = described[node_name][key]
            assert d.read_only and 'plant_simulator' in d.description and \
                'supervisor' in d.description, (node_name, d.description)
            result = _set(graph, node_name, key, _double(2e-4))
            assert not result.successful and 'read-only' in result.reason
    checked = set()
    for owner, ds in described.items():
        writable = {k: d for k, d in ds.items() if not d.read_only and k not in RCLPY_OWN}
        before = {k: _get(graph, owner, k) for k in writable}
        new = {k: _new_value(before[k], d) for k, d in writable.items()}
        try:
            result = _set_atomically(graph, owner, new)
            assert result.successful, (owner, result.reason)
            for name, value in new.items():
                if name.split('.')[0] in SHIPPED_DATA:      # a config key: one fact
                    users = [n for n, other in described.items() if name in other]
                    assert users == [owner], (name, users)     # no stale copy elsewhere
                assert _get(graph, owner, name) == value
                assert _in_use(nodes[owner], name) == value, (owner, name)
                checked.add((owner, name))
        finally:
            assert _set_atomically(graph, owner, before).successful
        for name, value in before.items():
            assert _in_use(nodes[owner], name) == value, (owner, name)
    assert {n for n, _ in checked} == set(GRAPH_NODES)
    assert {(n, k) for n in NODE_CLASSES for k in config_keys(n, 0)} <= checked
