"""Every node executable's exit code, as a user or a launch file sees it.

``python -m gripper_ros.nodes.<module>``, each case in a namespace of its own: stopped with
Ctrl-C (SIGINT) or SIGTERM once it runs (it answers a parameter request), it exits 0, quietly
(a clean-up that outlasts the node's own stop bound ends it with 1 and its stacks); given a
bad start-up parameter (out of range, of the wrong type, not one of the allowed words) it
exits 2 with one line on stderr naming the parameter, and no traceback; a second one started
beside a running one exits 2 with one line naming the taken name. The cases run side by side
in two module fixtures, the stops and the refusals (a node start costs about a second); each
test reads its own case's result. Nothing is timed: a process is waited for while it uses CPU
(:class:`helpers.ProgressWatch`), however loaded the machine.
"""
from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from gripper_ros.nodes import NODE_MODULES
from gripper_ros.nodes.process import load_bound_s
from gripper_ros.wire import (NODE_DESCRIPTION, NODE_EXCITATION, NODE_FORCE_CONTROLLER,
                              NODE_GRASP_ACTION, NODE_MOVE_ACTION, NODE_PLANT,
                              NODE_POSITION_CONTROLLER, NODE_SUPERVISOR,
                              NODE_TRAJECTORY_ACTION)
from helpers import native_stacks, ProgressWatch
import pytest
from rcl_interfaces.srv import GetParameters
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
import yaml

MODULES = NODE_MODULES
SIGNALS = {'sigint': signal.SIGINT, 'sigterm': signal.SIGTERM}
WRONG_TYPE = "expecting type 'DOUBLE'"
BAD_PARAMETERS = [   # (node, parameter, value as typed after -p name:=, words in the line)
    (NODE_PLANT, 'time_mode', 'sideways', 'must be realtime or fast'),
    (NODE_PLANT, 'real_time_factor', '0.0', 'out of range'),
    (NODE_POSITION_CONTROLLER, 'status_timeout_s', 'soon', WRONG_TYPE),
    (NODE_POSITION_CONTROLLER, 'controller', 'bangbang', 'must be one of'),
    (NODE_FORCE_CONTROLLER, 'controller', 'bangbang', 'must be one of'),
    (NODE_FORCE_CONTROLLER, 'status_timeout_s', '0', 'out of range'),      # an integer: 0.0
    (NODE_SUPERVISOR, 'tick_timeout_s', '0.0', 'out of range'),
    (NODE_SUPERVISOR, 'tick_timeout_s', 'true', WRONG_TYPE),
    (NODE_GRASP_ACTION, 'feedback_period_s', '-1.0', 'out of range'),
    (NODE_GRASP_ACTION, 'feedback_period_s', '-1', 'out of range'),
    (NODE_MOVE_ACTION, 'feedback_period_s', '-1.0', 'out of range'),
    (NODE_TRAJECTORY_ACTION, 'action_monitor_rate', '0.0', 'out of range'),
    (NODE_EXCITATION, 'excitation.amplitude_v', '99.0', 'amplitude_v must be in'),
    (NODE_GRASP_ACTION, 'executor', 'threads', 'must be one of'),          # run_node's own
    (NODE_DESCRIPTION, 'frame_prefix', 'left-', 'may hold only ASCII letters'),
    # a name the node does not declare (every node, test_parameters): the nearest one it does
    (NODE_PLANT, 'time_mod', 'fast', 'unknown parameter "time_mod"; did you mean "time_mode"'),
    (NODE_SUPERVISOR, 'supervisor.bogus_key', '1.0', 'unknown parameter "supervisor.bogus_key"'),
]
STEP_CPU_S = 60.0
"""CPU a node process may use for one step (to answer, to refuse, to stop): a start costs a few
seconds (imports, the compiled core, DDS), so one that needs much more spins. Some thirty start
at once: on a loaded machine the last answers come minutes after the first, each using CPU."""
ALARMING = ('Traceback', 'FATAL', 'ERROR', 'Fatal Python error')
ASK_AGAIN_S = 2.0
STRAGGLER_S = 120.0
"""A bound (on free cores, :func:`load_bound_s`) on the wait for the last nodes to answer once
none answered or exited for it: a node whose DDS threads tick uses some CPU however stuck its
executor is, so :class:`ProgressWatch` alone would wait for it until the suite's own timeout."""
ABORT_BOUND_S = 60.0
"""A bound on an aborted process writing its stacks, never reached unless SIGABRT is lost."""
ABORT_TEXT_CHARS = 4000
NATIVE_TEXT_CHARS = 30000
"""What an aborted case's text keeps: the end of its Python stacks, the start of its native
ones."""
NODES_DIR = Path(__file__).resolve().parents[1] / 'gripper_ros' / 'nodes'


@dataclass
class Case:
    node: str
    namespace: str
    args: list[str]
    stop: signal.Signals | None = None       # None: the node must refuse to start
    twin: Case | None = None                 # a second one started beside it once it runs
    proc: subprocess.Popen | None = None
    answered: bool = False                   # it answered a parameter request before the signal
    returncode: int | None = None
    exit_s: float = float('inf')             # from the signal to the exit
    stderr: str = ''


def _start(case: Case, domain_id: int | None = None) -> None:
    domain = {} if domain_id is None else {'ROS_DOMAIN_ID': str(domain_id)}
    case.proc = subprocess.Popen(
        [sys.executable, '-m', f'gripper_ros.nodes.{MODULES[case.node]}', '--ros-args', '-r',
         f'__ns:=/{case.namespace}', *case.args], stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env={**os.environ, 'PYTHONFAULTHANDLER': '1', **domain})


def _wait_until_running(cases: list[Case], domain_id: int | None = None) -> str:
    """Mark each case whose node answers ``get_parameters`` (its executor spins).

    It waits until every node answered or exited, or each that did neither is hung (used no CPU
    for a minute, or :data:`STEP_CPU_S` of it), however long the whole start takes here.
    Returns why those it gave up on are hung ('' if none).
    """
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        probe = rclpy.create_node('exit_code_probe', context=context,
                                  start_parameter_services=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(probe)
        clients = {id(c): probe.create_client(
            GetParameters, f'/{c.namespace}/{c.node}/get_parameters') for c in cases}
        futures = {}
        watch = ProgressWatch([c.proc.pid for c in cases], STEP_CPU_S)
        hung = ''
        waited_before, moved = len(cases) + 1, time.monotonic()
        while True:
            waited = [c.proc.pid for c in cases if not c.answered and c.proc.poll() is None]
            if len(waited) < waited_before:
                waited_before, moved = len(waited), time.monotonic()
            hung = watch.hung(waited) if waited else ''
            if waited and not hung and time.monotonic() - moved > load_bound_s(STRAGGLER_S):
                hung = (f'{len(waited)} of {len(cases)} never answered, none answered or exited '
                        f'for {time.monotonic() - moved:.0f} s')
            if not waited or hung:
                break
            for c in cases:
                if c.answered or c.proc.poll() is not None:
                    continue
                future, asked = futures.get(id(c), (None, 0.0))
                if future is not None and future.done():
                    c.answered = future.result() is not None
                elif clients[id(c)].service_is_ready() and (
                        future is None or time.monotonic() - asked > ASK_AGAIN_S):
                    # asked again: a node still starting may drop an answer to a client it has
                    # not yet discovered (rmw: "failed to send response (timeout)")
                    futures[id(c)] = (clients[id(c)].call_async(
                        GetParameters.Request(names=['use_sim_time'])), time.monotonic())
            executor.spin_once(timeout_sec=0.02)
        executor.shutdown()
        probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return hung


@pytest.fixture(scope='module')
def refusals():
    """Every bad start-up parameter at once: started side by side, each waited for."""
    cases = {f'{node}-{parameter}:={value}': Case(node, f'exit_{node}_bad_{k}',
                                                  ['-p', f'{parameter}:={value}'])
             for k, (node, parameter, value, _words) in enumerate(BAD_PARAMETERS)}
    try:
        for case in cases.values():
            _start(case)
        for case in cases.values():
            _finish(case)
    finally:
        for case in cases.values():
            if case.proc is not None and case.proc.poll() is None:
                case.proc.kill()
                case.proc.wait()
    return cases


@pytest.fixture(scope='module')
def results(spare_domain_id):
    """Every node stopped by each signal at once: started, signalled once running, waited for.

    In a domain of their own: some thirty participants, and Fast DDS's localhost discovery
    reaches only the first 32 of a domain (rmw_fastrtps: maxInitialPeersRange 32).
    """
    cases = {f'{node}-{label}': Case(node, f'exit_{node}_{label}', [], stop=sig)
             for node in MODULES for label, sig in SIGNALS.items()}
    try:
        for case in cases.values():
            _start(case, spare_domain_id)
        hung = _wait_until_running(list(cases.values()), spare_domain_id)
        for case in cases.values():
            if case.stop is signal.SIGINT and case.answered:
                case.twin = Case(case.node, case.namespace, [])
                _start(case.twin, spare_domain_id)
        for case in cases.values():             # each twin ends before its first one is stopped
            if case.twin is not None:
                _finish(case.twin)
        signalled = [c for c in cases.values() if c.answered and c.proc.poll() is None]
        sent = time.monotonic()
        for case in signalled:
            case.proc.send_signal(case.stop)
        watch = ProgressWatch([c.proc.pid for c in signalled], STEP_CPU_S)
        while any(c.exit_s == float('inf') for c in signalled):
            for case in signalled:
                if case.exit_s == float('inf') and case.proc.poll() is not None:
                    case.exit_s = time.monotonic() - sent
            if watch.hung([c.proc.pid for c in signalled if c.exit_s == float('inf')]):
                break
            time.sleep(0.01)
        for case in cases.values():
            if not case.answered and case.proc.poll() is None:
                _abort(case, f'never answered ({hung})')   # its test shows where it was
            else:
                _finish(case)
    finally:
        for case in cases.values():
            for proc in (case.proc, case.twin.proc if case.twin else None):
                if proc is not None and proc.poll() is None:
                    proc.kill()
                    proc.wait()
    return cases


def _finish(case: Case) -> None:
    """Wait for the case's process; one that hangs is aborted and its test shows every stack.

    Hung: it used no CPU for a minute, or :data:`STEP_CPU_S` of it (a start, a refusal, a stop).
    """
    watch = ProgressWatch([case.proc.pid], STEP_CPU_S)
    while True:
        try:
            case.stderr = case.proc.communicate(timeout=1.0)[1]
            break
        except subprocess.TimeoutExpired:
            hung = watch.hung()
            if hung:
                _abort(case, f'hung ({hung})')
                break
    case.returncode = case.proc.returncode


def _abort(case: Case, why: str) -> None:
    """Abort the case's process; its threads' stacks go into its test's text.

    faulthandler's Python ones first, then the native ones (gdb: where DDS spins or waits).
    """
    native = native_stacks(case.proc.pid)
    case.proc.send_signal(signal.SIGABRT)
    try:
        stacks = case.proc.communicate(timeout=ABORT_BOUND_S)[1]
    except subprocess.TimeoutExpired:
        case.proc.kill()
        stacks = case.proc.communicate()[1]
    case.stderr = f'{why}, aborted:\n{stacks[-ABORT_TEXT_CHARS:]}' + (
        f'\nnative stacks (gdb):\n{native[:NATIVE_TEXT_CHARS]}' if native else '')
    case.returncode = case.proc.returncode


@pytest.mark.parametrize('node', list(MODULES))
@pytest.mark.parametrize('label', list(SIGNALS))
def test_a_running_node_stopped_by_a_signal_exits_0_at_once_and_quietly(results, node, label):
    """Exit 0, no traceback, nothing at FATAL or ERROR.

    "At once" is the node's own stop bound (gripper_ros.nodes.process): a clean-up that
    outlasts it ends the process with 1 and every thread's stack, "Timeout" on stderr.
    """
    case = results[f'{node}-{label}']
    assert case.answered, f'{node} never answered a parameter request: {case.stderr}'
    assert case.returncode == 0, f'exit {case.returncode} {case.exit_s:.1f} s after the ' \
        f'signal: {case.stderr[-6000:]}'
    assert not [w for w in ALARMING if w in case.stderr], case.stderr[-2000:]


@pytest.mark.parametrize('node, parameter, value, words', BAD_PARAMETERS)
def test_a_bad_start_up_parameter_exits_2_in_one_line(refusals, node, parameter, value, words):
    case = refusals[f'{node}-{parameter}:={value}']
    assert case.returncode == 2, f'exit {case.returncode}: {case.stderr[-6000:]}'
    assert 'Traceback' not in case.stderr
    lines = case.stderr.strip().splitlines()
    assert len(lines) == 1, case.stderr
    assert lines[0].startswith(f'{node}: ') and parameter in lines[0] and words in lines[0], \
        lines[0]


@pytest.mark.parametrize('node', list(MODULES))
def test_a_second_node_beside_a_running_one_exits_2_in_one_line(results, node):
    first = results[f'{node}-sigint']
    assert first.twin is not None, f'{node} never ran: {first.stderr}'
    twin = first.twin
    assert twin.returncode == 2, f'exit {twin.returncode}: {twin.stderr[-6000:]}'
    assert 'Traceback' not in twin.stderr
    lines = twin.stderr.strip().splitlines()
    assert len(lines) == 1, twin.stderr
    assert lines[0].startswith(f'{node}: namespace /{first.namespace} is taken'), lines[0]
    assert f'/{first.namespace}/{node}' in lines[0], lines[0]


def test_every_node_executable_is_here_with_a_bad_start_up_parameter():
    """A node module with a ``main()`` is an executable: each one is in MODULES.

    ``graph_process`` (gripper_graph, every node in one process) has its own cases below.
    """
    executables = {p.stem for p in NODES_DIR.glob('*.py')
                   if '\ndef main(' in p.read_text(encoding='utf-8')}
    assert executables == set(MODULES.values()) | {'graph_process'}
    assert {node for node, *_ in BAD_PARAMETERS} == set(MODULES)


GRAPH_BAD_SETTINGS = [('time_mode', 'sideways', 'must be realtime or fast'),
                      ('real_time_factor', '0.0', 'out of range'),
                      ('real_time_factor', 'fast', WRONG_TYPE),
                      ('config_file', '/nonexistent/gripper.yaml', 'cannot read config file'),
                      ('supervisor.bogus_key', '1.0',
                       'unknown parameter "supervisor.bogus_key"; known here: '),
                      ('executor', 'single', 'unknown parameter "executor"'),
                      # the process's own settings, read by no node, are known: the typo is named
                      ('supervisor.timeot_s', '5.0 -p foxglove_port:=0 -p foxglove_address:=::1',
                       'unknown parameter "supervisor.timeot_s"; did you mean'),
                      ('time_mode', 'fast -p use_sim_time:=true', 'time_mode must be realtime')]


@pytest.mark.parametrize('name,value,words', GRAPH_BAD_SETTINGS)
def test_gripper_graph_refuses_a_bad_setting_in_one_line(name, value, words):
    """The launch file's settings reach gripper_graph as parameters; a bad one: exit 2, a line."""
    value, *more = value.split(' ')
    run = subprocess.run([sys.executable, '-m', 'gripper_ros.nodes.graph_process', '--ros-args',
                          '-r', f'__ns:=/graph_bad_{os.getpid()}', '-p', f'{name}:={value}',
                          *more], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                         timeout=120)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2, run.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith('gripper_graph: ') and words in lines[0], \
        run.stderr[-2000:]


@pytest.mark.parametrize('section', [{'supervisor': {'timeot_s': 5.0}},
                                     {'supervisor.timeot_s': 5.0}])
def test_gripper_graph_refuses_a_params_file_typo_naming_the_nearest_key(tmp_path, section):
    """A ``--params-file`` for ``/**`` (nested or dotted) with a typo: exit 2, one line."""
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': section}}), encoding='utf-8')
    run = subprocess.run([sys.executable, '-m', 'gripper_ros.nodes.graph_process', '--ros-args',
                          '-r', f'__ns:=/graph_typo_{os.getpid()}', '--params-file', str(path)],
                         stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr[-2000:]
    assert run.stderr.strip() == ('gripper_graph: unknown parameter "supervisor.timeot_s"; '
                                  'did you mean "supervisor.timeout_s"?'), run.stderr[-2000:]


@pytest.mark.parametrize('remap, namespace, prefix', [
    ((), 'gripper', ''), (('-r', '__ns:=/arm2/left'), 'arm2/left', 'arm2_left_')])
def test_gripper_graph_reads_its_namespace_with_its_settings(remap, namespace, prefix):
    """The namespace is the default one as ``-r __ns:=`` remaps it; the prefix follows it."""
    import rclpy
    from rclpy.context import Context
    from gripper_ros.nodes.graph_process import read_settings
    context = Context()
    rclpy.init(args=['--ros-args', *remap, '-p', 'time_mode:=fast'], context=context)
    try:
        settings = read_settings(context)
    finally:
        rclpy.try_shutdown(context=context)
    assert (settings['namespace'], settings['prefix'], settings['time_mode']) == \
        (namespace, prefix, 'fast')


def test_a_bug_in_a_node_constructor_keeps_its_traceback():
    """A ValueError raised by a node's own code is a bug, not a refused start: exit 1, traced."""
    code = ('from gripper_ros.nodes.process import run_node\n'
            'def broken():\n'
            '    raise ValueError("a bug in the constructor")\n'
            'raise SystemExit(run_node(broken, "broken_node", ["--ros-args", "-r", '
            '"__ns:=/exit_broken_constructor"]))\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=60, stdin=subprocess.DEVNULL)
    assert result.returncode == 1, (result.returncode, result.stderr[-2000:])
    assert 'Traceback' in result.stderr and 'ValueError: a bug in the constructor' in \
        result.stderr, result.stderr[-2000:]


def test_a_node_refused_half_way_leaves_nothing_in_the_graph():
    """A bad start-up parameter found after the node made its services: all of it is destroyed.

    The supervisor declares ``tick_timeout_s`` after its deferred services made their private
    server nodes; a refusal must take those down too (left to the interpreter's exit, they can
    keep its process from exiting).
    """
    from gripper_ros.nodes.process import build_node
    from gripper_ros.nodes.supervisor_node import SupervisorNode
    from rclpy.exceptions import ParameterException
    from rclpy.parameter import Parameter

    namespace = '/exit_refused_half_way'
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ParameterException, match='tick_timeout_s'):
            build_node(SupervisorNode, namespace=namespace, context=context,
                       parameter_overrides=[Parameter('tick_timeout_s', value=0.0)])
        probe = rclpy.create_node('refusal_probe', context=context)
        left = {name for name, ns in probe.get_node_names_and_namespaces() if ns == namespace}
        probe.destroy_node()
        assert left == set(), left
    finally:
        rclpy.try_shutdown(context=context)


def test_a_clean_up_that_never_ends_still_exits_with_the_nodes_code():
    """A node whose destruction blocks (as a DDS entity's deletion can) still ends, saying so."""
    import re

    from gripper_ros.nodes.process import CLEAN_UP_LIMIT_S
    code = ('import time\n'
            'from rclpy.node import Node\n'
            'from gripper_ros.nodes.process import run_node\n'
            'class Stuck(Node):\n'
            '    def __init__(self):\n'
            '        super().__init__("stuck_node", namespace="/exit_stuck_clean_up")\n'
            '    def destroy_node(self):\n'
            '        time.sleep(600)\n'
            'raise SystemExit(run_node(Stuck, "stuck_node", ["x", "--ros-args", "-p", '
            '"executor:=threads"]))\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120, stdin=subprocess.DEVNULL)      # it sleeps 600 s
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 2 and 'Traceback' not in result.stderr, result.stderr
    assert lines[0].startswith('stuck_node: parameter "executor" must be one of'), lines[0]
    said = re.fullmatch(r'stuck_node: clean-up did not finish within (\d+) s \(a DDS entity '
                        r'that never finished deleting\); exiting with 2', lines[1])
    assert said and int(said[1]) >= CLEAN_UP_LIMIT_S, lines[1]     # more on a loaded machine
