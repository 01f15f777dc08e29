"""grasp_demo --serve answers grasp_client from another process (real DDS between processes)."""
import os
import signal
import subprocess
import sys
import time

from helpers import ProgressWatch, wait_for_exit, wait_for_recording
import pytest

SERVICE_WAIT_S = 60.0
"""What a grasp_client waits for the services: a try of the start-up loop, which goes on while
the nodes' processes still use CPU (a loaded machine starts them slowly)."""
GRAPH_START_CPU_S = 120.0
"""CPU a node process may use before the graph answers a grasp: a start costs a few seconds, and
the plant runs at real time meanwhile."""


def _run_client(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client', *args],
                          capture_output=True, text=True, timeout=timeout, env=os.environ.copy())


@pytest.fixture(scope='module')
def server(tmp_path_factory):
    out = tmp_path_factory.mktemp('served_bags')     # never the repository's bags/
    proc = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve',
                             '--time-mode', 'fast', '--output', str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=os.environ.copy())
    deadline = time.monotonic() + 60
    for line in proc.stdout:
        if 'serving /gripper/grasp' in line or time.monotonic() > deadline:
            proc.banner = line
            break
    yield proc
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()


PARAMETER_SERVICES = ('describe_parameters', 'get_parameter_types', 'get_parameters',
                      'list_parameters', 'set_parameters', 'set_parameters_atomically',
                      'get_type_description')


def test_the_start_up_line_names_every_service_and_action_served(server):
    """What ``grasp_demo --serve`` announces is what another process finds on the graph."""
    import re

    import rclpy
    from rclpy.context import Context
    announced = set(re.search(r'serving (.*), publishing', server.banner).group(1).split(', '))
    context = Context()
    rclpy.init(context=context)
    try:
        probe = rclpy.create_node('served_names_probe', context=context)
        deadline = time.monotonic() + 20
        while True:
            names = [n for n, _ in probe.get_service_names_and_types()
                     if n.startswith('/gripper/') and n.rsplit('/', 1)[1] not in
                     PARAMETER_SERVICES]
            served = {n for n in names if '/_action/' not in n} | {
                n.split('/_action/')[0] for n in names if n.endswith('/_action/send_goal')}
            if served >= announced or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert served == announced, (sorted(served - announced), sorted(announced - served))


def test_client_grasp_from_another_process_is_held(server):
    result = _run_client('--width', '0.05', '--mass', '1.69')
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'outcome: HOLDING' in result.stdout
    assert 'final_width_m: 0.050000' in result.stdout


def test_client_bad_request_is_refused_and_server_keeps_serving(server):
    bad = _run_client('--width', 'nan', '--mass', '1.0', '--no-place')
    assert bad.returncode == 1
    assert 'outcome: REFUSED' in bad.stdout and 'width_m must be a finite number' in bad.stdout
    good = _run_client('--width', '0.1', '--mass', '0.75')
    assert good.returncode == 0 and 'outcome: HOLDING' in good.stdout


def test_client_action_prints_feedback_from_another_process(server):
    result = _run_client('--width', '0.1', '--mass', '0.75', '--action')
    assert result.returncode == 0, result.stdout + result.stderr
    feedback = [line for line in result.stdout.splitlines() if line.startswith('feedback:')]
    assert any('phase POSITION' in line for line in feedback)
    assert any('phase FORCE' in line for line in feedback)
    assert 'outcome: HOLDING' in result.stdout and 'final_width_m: 0.100000' in result.stdout


def test_server_stops_cleanly_on_sigint(server):
    server.send_signal(signal.SIGINT)
    assert server.wait(timeout=20) in (0, 130)


def test_client_without_server_says_so():
    env = dict(os.environ, ROS_DOMAIN_ID=str((int(os.environ.get('ROS_DOMAIN_ID', '0')) + 1)
                                             % 100 + 101))
    result = subprocess.run([sys.executable, '-m', 'gripper_ros.apps.grasp_client',
                             '--width', '0.05', '--mass', '1', '--wait', '1'],
                            capture_output=True, text=True, timeout=60, env=env)
    assert result.returncode == 2
    assert 'not available' in result.stderr


def test_serve_mode_records_one_complete_bag_per_grasp(tmp_path):
    from gripper_ros.bags.reader import read_bag
    from gripper_ros.bags.series import load_grasp_series
    proc = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve',
                             '--output', str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
    try:
        for line in proc.stdout:
            if 'serving /gripper/grasp' in line:
                break
        for width, mass in (('0.1', '0.75'), ('0.05', '1.69')):
            done = _run_client('--width', width, '--mass', mass, timeout=60)
            assert done.returncode == 0, done.stdout + done.stderr
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=20)
    assert proc.returncode in (0, 130), out
    bags = sorted(tmp_path.glob('grasp_*'))
    assert len(bags) == 2
    for bag_dir in bags:
        bag = read_bag(bag_dir)
        assert not bag.truncated and (bag_dir / 'metadata.yaml').is_file()
        series = load_grasp_series(bag)
        decisions = series.decisions
        assert decisions['outcome'][-1] == 1, (bag_dir.name, decisions['outcome'][-9:],
                                               decisions['phase'][-9:])      # HOLDING
        counts = bag.counts()
        loop = [(m.topic.rsplit('/', 1)[1], int.from_bytes(m.data[4:12], 'little'))
                for m in bag.messages if '/loop/' in m.topic]
        assert counts['/gripper/loop/tick'] == counts['/gripper/loop/motor_command'] > 100, \
            (bag_dir.name, loop[:4], loop[-4:])


def test_nodes_as_four_separate_processes_grasp_together():
    """Each node runnable alone: four processes, lockstep over DDS, a grasp from a fifth."""
    nodes = ['plant_simulator_node', 'position_controller_node', 'force_controller_node',
             'supervisor_node']
    procs = []
    try:
        for i, module in enumerate(nodes):
            extra = [] if i == 0 else ['--ros-args', '-p', 'use_sim_time:=true']
            procs.append(subprocess.Popen(
                [sys.executable, '-m', f'gripper_ros.nodes.{module}', *extra],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ.copy()))
        watch = ProgressWatch([p.pid for p in procs], GRAPH_START_CPU_S)
        while True:   # the supervisor refuses until it has discovered every peer and heard
            # the plant; each try waits for the services while the nodes start, however slowly
            result = _run_client('--width', '0.1', '--mass', '0.75',
                                 '--wait', f'{SERVICE_WAIT_S:g}', timeout=2 * SERVICE_WAIT_S)
            starting = 'graph not ready' in result.stdout or 'not available' in result.stderr
            hung = watch.hung([p.pid for p in procs if p.poll() is None])
            if not starting or hung or any(p.poll() is not None for p in procs):
                break
            time.sleep(0.5)
        assert result.returncode == 0, (result.stdout + result.stderr, hung,
                                        [p.poll() for p in procs])
        assert 'outcome: HOLDING' in result.stdout
    finally:
        for p in procs:
            p.send_signal(signal.SIGINT)
        assert [wait_for_exit(p) for p in procs] == [0] * len(procs)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_signal_during_a_recorded_grasp_leaves_a_complete_bag(tmp_path, sig):
    from gripper_ros.bags.reader import read_bag
    proc = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--width',
                             '0.01', '--mass', '1.27', '--time-mode', 'realtime', '--output',
                             str(tmp_path), '--no-plot'], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
    for line in proc.stdout:
        if 'grasping width' in line:
            break
    wait_for_recording(tmp_path)            # recording: the grasp takes 3.8 s, paced
    proc.send_signal(sig)
    out, _ = proc.communicate(timeout=120)   # beyond its own stop bound
    assert proc.returncode == 130, out
    bags = sorted(tmp_path.glob('grasp_*'))
    assert len(bags) == 1
    assert (bags[0] / 'metadata.yaml').is_file()
    bag = read_bag(bags[0])
    assert not bag.truncated and bag.message_count > 0


@pytest.mark.serial   # the cancel races the paced grasp
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_client_action_stopped_mid_grasp_prints_the_servers_stopped_answer(tmp_path, sig):
    """Ctrl-C on ``grasp_client --action`` cancels the goal and prints the server's answer."""
    namespace = 'stopped_by_signal'           # a gripper of its own beside the module's server
    server = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve',
                               '--namespace', namespace, '--time-mode', 'realtime',
                               '--output', str(tmp_path)],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env=os.environ.copy())
    client = None
    try:
        for line in server.stdout:
            if f'serving /{namespace}/grasp' in line:
                break
        client = subprocess.Popen([sys.executable, '-m', 'gripper_ros.apps.grasp_client',
                                   '--namespace', namespace, '--width', '0.01', '--mass', '1.27',
                                   '--action'],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env=os.environ.copy())
        first = client.stdout.readline()          # the grasp runs: 3.8 s of paced time
        assert first.startswith('feedback:'), first + client.stderr.read()
        client.send_signal(sig)
        out, err = client.communicate(timeout=30)
    finally:
        if client is not None and client.poll() is None:
            client.kill()
        server.send_signal(signal.SIGINT)
        server.communicate(timeout=30)
    assert client.returncode == 130, out + err
    assert 'outcome: STOPPED' in out, out + err
    assert 'cancelling the goal' in err and 'did not answer' not in err, err
    assert 'Traceback' not in err, err
