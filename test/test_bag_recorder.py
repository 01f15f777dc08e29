"""BagRecorder and bag_replay over real DDS (Fast DDS, localhost only, own domain id).

Nodes of this module live in their own rclpy Context, so bag_replay.main() can init the default
context in-process; an executor thread spins them.
"""
from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import textwrap
import threading

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', '79')

from gripper_ros.bags import info as bag_info  # noqa: E402
from gripper_ros.bags import replay as bag_replay  # noqa: E402
from gripper_ros.bags.reader import EXIT_TRUNCATED, EXIT_UNDELIVERED, read_bag  # noqa: E402
from gripper_ros.bags.recorder import BagRecorder, BagRecorderError  # noqa: E402
from gripper_ros.nodes.services import wait_until  # noqa: E402
from helpers import in_executor, run_main  # noqa: E402
import pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
import yaml  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PROCESS_BOUND_S = 120.0
"""A bound on a replay process and its consumer, never reached unless something hangs."""
BOUND_S = 60.0
"""A bound on an event (a match, a message taken): milliseconds on an idle machine, and reached
only when the event never comes, so that a loaded machine fails no test."""
JS, CLK = '/gripper/joint_states', '/clock'
STD_TOPICS = {JS: 'sensor_msgs/msg/JointState', CLK: 'rosgraph_msgs/msg/Clock'}
GRAPH_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

try:
    from gripper_interfaces.msg import SupervisorStatus
except ImportError:  # interface package not built/sourced
    SupervisorStatus = None


@pytest.fixture(scope='module')
def ros():
    """(context, executor) spinning in a thread; nodes are added by the tests."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield context, executor
    executor.shutdown()
    rclpy.try_shutdown(context=context)
    thread.join(timeout=2)


@pytest.fixture
def node_factory(ros):
    context, executor = ros
    nodes = []

    def make(name: str, **kwargs):
        node = rclpy.create_node(name, context=context, **kwargs)
        executor.add_node(node)
        nodes.append(node)
        return node
    yield make

    def destroy():
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()
    in_executor(executor, destroy)


def joint_state(k: int) -> JointState:
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * 10_000_000, 1_000_000_000)
    msg.name = ['finger_joint']
    msg.position, msg.velocity, msg.effort = [k * 1e-4], [0.01], [0.0]
    return msg


def clock(k: int) -> Clock:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(k * 10_000_000, 1_000_000_000)
    return msg


def record(node_factory, bag_dir: Path, n: int = 150, **kwargs) -> dict:
    """Publish n JointState + n Clock (+ n SupervisorStatus when built) through a recorder."""
    topics = dict(STD_TOPICS)
    if SupervisorStatus is not None:
        topics['/gripper/supervisor/status'] = 'gripper_interfaces/msg/SupervisorStatus'
    rec_node = node_factory('recorder')
    pub_node = node_factory('publisher')
    pubs = {JS: pub_node.create_publisher(JointState, JS, LATCHED_QOS),
            CLK: pub_node.create_publisher(Clock, CLK, GRAPH_QOS)}
    if SupervisorStatus is not None:
        pubs['/gripper/supervisor/status'] = pub_node.create_publisher(
            SupervisorStatus, '/gripper/supervisor/status', LATCHED_QOS)
    recorder = BagRecorder(rec_node, bag_dir, topics, custom_data={'grasp_request': {
        'width_m': 0.05, 'mass_kg': 0.2}}, **kwargs)
    assert wait_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()),
                      BOUND_S)
    sent = {t: [] for t in topics}
    for k in range(n):
        msgs = {JS: joint_state(k), CLK: clock(k)}
        if SupervisorStatus is not None:
            status = SupervisorStatus()
            status.header.stamp = msgs[JS].header.stamp
            status.phase, status.grasp_id = 1, 3
            msgs['/gripper/supervisor/status'] = status
        for topic, msg in msgs.items():
            pubs[topic].publish(msg)
            sent[topic].append(msg)
    assert wait_until(lambda: recorder.message_count == len(topics) * n, BOUND_S), \
        recorder.counts
    recorder.set_custom_data({'grasp_outcome': {'outcome': 'HOLDING'}})
    return {'recorder': recorder, 'sent': sent, 'topics': topics, 'n': n,
            'publishers': pubs, 'rec_node': rec_node}


@pytest.fixture
def recorded(node_factory, tmp_path):
    """450 messages in chunks of 100: a bag of several chunks, as a long recording makes."""
    result = record(node_factory, tmp_path / 'run1', flush_every_messages=100)
    result['recorder'].close()
    result['recorder'].close()               # idempotent
    return result


def test_counts_equal_published(recorded):
    n = recorded['n']
    assert recorded['recorder'].counts == {t: n for t in recorded['topics']}


def test_metadata_yaml_version_9(recorded, tmp_path):
    info = yaml.safe_load((tmp_path / 'run1' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['ros_distro'] == 'jazzy'
    assert info['relative_file_paths'] == ['run1_0.mcap']
    assert info['message_count'] == recorded['n'] * len(recorded['topics'])
    assert info['compression_format'] == '' and info['compression_mode'] == ''
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    js = topics[JS]['topic_metadata']
    assert isinstance(js['offered_qos_profiles'], list)
    assert js['offered_qos_profiles'][0]['durability'] == 'transient_local'
    assert js['offered_qos_profiles'][0]['reliability'] == 'reliable'
    assert js['type_description_hash'].startswith('RIHS01_')
    assert 'grasp_request' in info['custom_data'] and 'grasp_outcome' in info['custom_data']


def test_rosbags_anyreader_reads_it(recorded, tmp_path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([tmp_path / 'run1'],
                   default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {t: recorded['n'] for t in recorded['topics']}
        positions = [reader.deserialize(raw, c.msgtype).position[0]
                     for c, _, raw in reader.messages() if c.topic == JS]
    assert positions == pytest.approx([k * 1e-4 for k in range(recorded['n'])])


def test_mcap_reader_with_ros2_decoder(recorded, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(tmp_path / 'run1' / 'run1_0.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {s.name: s.encoding for s in summary.schemas.values()}[
            'sensor_msgs/msg/JointState'] == 'ros2msg'
        schema = next(s for s in summary.schemas.values()
                      if s.name == 'sensor_msgs/msg/JointState').data.decode()
        assert '=' * 80 + '\nMSG: std_msgs/Header\n' in schema
        assert 'MSG: builtin_interfaces/Time\n' in schema
        for channel in summary.channels.values():
            assert channel.message_encoding == 'cdr'
            assert set(channel.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert 'serialized_metadata' in metadata['rosbag2']
        assert yaml.safe_load(metadata['rosbag2']['serialized_metadata'])['version'] == 9
        decoded = [(c.topic, m) for _, c, _, m in reader.iter_decoded_messages()]
    assert len(decoded) == recorded['n'] * len(recorded['topics'])
    js = [m for t, m in decoded if t == JS]
    assert js[5].name == ['finger_joint'] and js[5].position[0] == pytest.approx(5e-4)


def test_recorded_messages_are_what_was_published(recorded, tmp_path):
    """Messages compare decoded: CDR padding bytes are not deterministic across serializations."""
    from rclpy.serialization import deserialize_message
    bag = read_bag(tmp_path / 'run1')
    for topic, sent in recorded['sent'].items():
        cls = type(sent[0])
        assert [deserialize_message(m.data, cls) for m in bag.messages if m.topic == topic] == sent


def _recorded_bytes(bag_dir: Path, topic: str) -> list[bytes]:
    return [m.data for m in read_bag(bag_dir).messages if m.topic == topic]


def test_refuses_existing_folder(node_factory, tmp_path):
    node = node_factory('refuser')
    (tmp_path / 'busy').mkdir()
    (tmp_path / 'busy' / 'busy_0.mcap').write_bytes(b'x')
    with pytest.raises(BagRecorderError, match='not empty'):
        BagRecorder(node, tmp_path / 'busy', STD_TOPICS)
    BagRecorder(node, tmp_path / 'busy', STD_TOPICS, overwrite=True).close()
    (tmp_path / 'busy' / 'thesis.tex').write_text('precious')
    with pytest.raises(BagRecorderError, match='refusing'):
        BagRecorder(node, tmp_path / 'busy', STD_TOPICS, overwrite=True)
    with pytest.raises(BagRecorderError, match='cannot record'):
        BagRecorder(node, tmp_path / 'new', {'/x': 'no_such_pkg/msg/Nope'})


def test_context_manager_keeps_bag_after_exception(node_factory, tmp_path):
    node = node_factory('cm')
    pub = node_factory('cm_pub').create_publisher(JointState, JS, GRAPH_QOS)
    with pytest.raises(RuntimeError, match='boom'):
        with BagRecorder(node, tmp_path / 'cm', {JS: STD_TOPICS[JS]}) as rec:
            assert wait_until(lambda: pub.get_subscription_count() >= 1, BOUND_S)
            for k in range(10):
                pub.publish(joint_state(k))
            assert wait_until(lambda: rec.message_count == 10, BOUND_S)
            raise RuntimeError('boom')
    assert rec.closed
    assert (tmp_path / 'cm' / 'metadata.yaml').is_file()
    bag = read_bag(tmp_path / 'cm')
    assert bag.message_count == 10 and not bag.truncated


def test_sim_time_log_time(node_factory, tmp_path):
    """Default time source = the node's clock: under use_sim_time, /clock time."""
    node = node_factory('simrec', parameter_overrides=[Parameter('use_sim_time', value=True)])
    pub_node = node_factory('simpub')
    clock_pub = pub_node.create_publisher(Clock, CLK, GRAPH_QOS)
    js_pub = pub_node.create_publisher(JointState, JS, GRAPH_QOS)
    rec = BagRecorder(node, tmp_path / 'sim', {JS: STD_TOPICS[JS]})
    assert wait_until(lambda: clock_pub.get_subscription_count() >= 1
                      and js_pub.get_subscription_count() >= 1, BOUND_S)
    msg = Clock()
    msg.clock.sec = 42

    def clock_is_42() -> bool:
        # again until seen: the time source's best-effort subscription (rclpy time_source.py)
        # drops a message sent before its side of the match
        clock_pub.publish(msg)
        return node.get_clock().now().nanoseconds == 42_000_000_000
    assert wait_until(clock_is_42, BOUND_S)
    js_pub.publish(joint_state(1))
    assert wait_until(lambda: rec.message_count == 1, BOUND_S)
    rec.close()
    bag = read_bag(tmp_path / 'sim')
    assert bag.messages[0].log_time_ns == 42_000_000_000


# --- kill -9: bounded loss --------------------------------------------------------------------

KILLED_RECORDER = textwrap.dedent("""
    import sys, threading, time, rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from gripper_ros.bags.recorder import BagRecorder
    rclpy.init()
    node, pub_node = rclpy.create_node('killed_rec'), rclpy.create_node('killed_pub')
    ex = SingleThreadedExecutor(); ex.add_node(node)
    threading.Thread(target=ex.spin, daemon=True).start()
    rec = BagRecorder(node, sys.argv[1], {'/gripper/joint_states': 'sensor_msgs/msg/JointState'},
                      flush_every_messages=int(sys.argv[3]), flush_every_s=60.0,
                      custom_data={'grasp_request': {'width_m': 0.04}})
    pub = pub_node.create_publisher(JointState, '/gripper/joint_states', 1000)
    while pub.get_subscription_count() < 1:
        time.sleep(0.01)
    n = int(sys.argv[2])
    for k in range(n):
        m = JointState(); m.position = [float(k)]; pub.publish(m)
    while rec.message_count < n:
        time.sleep(0.01)
    print('READY', flush=True)
    time.sleep(60)
""")


def test_sigkill_loses_at_most_the_flush_bound(tmp_path):
    n, every = 537, 100
    proc = subprocess.Popen([sys.executable, '-c', KILLED_RECORDER, str(tmp_path / 'killed'),
                             str(n), str(every)], stdout=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=os.pathsep.join(
                                [str(REPO), os.environ.get('PYTHONPATH', '')])))
    try:
        line = proc.stdout.readline()
        assert line.strip() == 'READY'
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert not (tmp_path / 'killed' / 'metadata.yaml').exists()
    bag = read_bag(tmp_path / 'killed')
    assert bag.truncated
    assert n - (every - 1) <= bag.message_count <= n
    assert bag.message_count == (n // every) * every        # exactly the flushed chunks
    positions = [float(bag.decode(m).position[0]) for m in bag.messages]
    assert positions == [float(k) for k in range(bag.message_count)]
    assert bag.custom_data_parsed()['grasp_request'] == {'width_m': 0.04}


# --- replay -----------------------------------------------------------------------------------

def _collector(node_factory, name: str, topics: dict[str, type], qos=GRAPH_QOS):
    node = node_factory(name)
    got = {t: [] for t in topics}
    subs = [node.create_subscription(cls, t, lambda data, t=t: got[t].append(bytes(data)), qos,
                                     raw=True) for t, cls in topics.items()]
    return node, got, subs


def test_player_republishes_exactly_in_order(recorded, node_factory, tmp_path):
    bag = read_bag(tmp_path / 'run1')
    topics = {JS: JointState, CLK: Clock}
    _, got, _ = _collector(node_factory, 'listener', {'/replayed/js': JointState, CLK: Clock})
    player_node = node_factory('player')
    player = bag_replay.BagPlayer(player_node, bag, bag_replay.ReplayOptions(
        rate=20.0, topics=list(topics), remap={JS: '/replayed/js'}, wait_for_subscribers=1))
    assert player.play() == 2 * recorded['n']
    assert wait_until(lambda: len(got['/replayed/js']) == recorded['n']
                      and len(got[CLK]) == recorded['n'], BOUND_S)
    assert got['/replayed/js'] == _recorded_bytes(tmp_path / 'run1', JS)     # byte-identical
    assert got[CLK] == _recorded_bytes(tmp_path / 'run1', CLK)


def _replay_env() -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO),
                                                        os.environ.get('PYTHONPATH', '')]))


def _clock_stamps(bag_dir: Path) -> list[int]:
    """Return the /clock a ``--clock`` replay of the joint states sends: each bag time, once."""
    return sorted({m.log_time_ns for m in read_bag(bag_dir).messages if m.topic == JS})


def _clock_ns(data: list[bytes]) -> list[int]:
    from rclpy.serialization import deserialize_message
    clocks = [deserialize_message(b, Clock).clock for b in data]
    return [c.sec * 1_000_000_000 + c.nanosec for c in clocks]


def test_replay_cli_in_subprocess_with_clock(recorded, node_factory, tmp_path):
    """bag_replay as a program; --clock replaces the recorded /clock with bag time.

    It exits once every reliable reader has acknowledged every message, so what it sent is in
    the listener's history (keep_last 1000, above the burst of 150) when it exits.
    """
    _, got, _ = _collector(node_factory, 'cli_listener', {JS: JointState, CLK: Clock},
                           qos=GRAPH_QOS)
    proc = subprocess.run(
        [sys.executable, '-m', 'gripper_ros.bags.replay', str(tmp_path / 'run1'), '--rate', '10',
         '--clock', '--wait-for-subscribers', '1', '--topics', JS],
        capture_output=True, text=True, timeout=PROCESS_BOUND_S, env=_replay_env())
    assert proc.returncode == 0, proc.stderr
    assert f"{recorded['n']}/{recorded['n']} msgs" in proc.stderr       # progress line
    stamps = _clock_stamps(tmp_path / 'run1')
    assert wait_until(lambda: len(got[JS]) == recorded['n'] and len(got[CLK]) == len(stamps),
                      BOUND_S), {t: len(v) for t, v in got.items()}
    assert got[JS] == _recorded_bytes(tmp_path / 'run1', JS)
    assert _clock_ns(got[CLK]) == stamps


def test_wait_for_subscribers_waits_for_the_clock_subscriber_too(recorded, node_factory,
                                                                 tmp_path):
    """A /clock subscriber that comes last still gets the first /clock: nothing is sent before."""
    bag = read_bag(tmp_path / 'run1')
    node, got, _ = _collector(node_factory, 'js_first', {JS: JointState})
    player = bag_replay.BagPlayer(node_factory('clock_player'), bag, bag_replay.ReplayOptions(
        rate=20.0, topics=[JS], clock=True, wait_for_subscribers=1))
    waiting = threading.Event()
    notes = []

    def note(line):
        notes.append(line)
        waiting.set()
    played = threading.Thread(target=player.play, kwargs={'progress': note})
    played.start()
    try:
        assert waiting.wait(PROCESS_BOUND_S), 'no word of what it waits on'
        assert notes[0] == f'waiting for 1 subscriber(s) on {CLK}' and player.published == 0
        clocks = []
        node.create_subscription(Clock, CLK, lambda data: clocks.append(bytes(data)),
                                 GRAPH_QOS, raw=True)
    finally:
        played.join(PROCESS_BOUND_S)
    assert not played.is_alive() and player.undelivered == {}
    stamps = _clock_stamps(tmp_path / 'run1')
    assert wait_until(lambda: len(got[JS]) == recorded['n'] and len(clocks) == len(stamps),
                      BOUND_S)
    assert _clock_ns(clocks) == stamps


STARVED_CONSUMER = textwrap.dedent("""
    import pickle, select, sys, rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node('starved_consumer')
    got = {'/gripper/joint_states': [], '/clock': []}
    keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    for topic, cls in (('/gripper/joint_states', JointState), ('/clock', Clock)):
        node.create_subscription(cls, topic, lambda data, t=topic: got[t].append(bytes(data)),
                                 keep_all, raw=True)
    print('READY', flush=True)
    while not select.select([sys.stdin], [], [], 0)[0]:  # until told the replay has ended
        rclpy.spin_once(node, timeout_sec=0.05)
    while True:                      # then take what its history holds, until it holds none
        before = sum(map(len, got.values()))
        rclpy.spin_once(node, timeout_sec=0.1)
        if sum(map(len, got.values())) == before:
            break
    with open(sys.argv[1], 'wb') as f:
        pickle.dump(got, f)
""")


def _starved_replay(bag_dir: Path, tmp_path: Path, argv: list[str], monkeypatch, capsys,
                    resume: bool):
    """Run bag_replay into a consumer process that is stopped (SIGSTOP) for the whole burst.

    It is stopped once the replay's publishers have matched it, before the first message;
    ``resume``: it runs again (SIGCONT) when the replay begins its wait for the
    acknowledgements, else once the replay has ended. Returns the replay's exit code and
    stderr, and what the consumer took, per topic.
    """
    import pickle
    out = tmp_path / 'consumer.pickle'
    consumer = subprocess.Popen([sys.executable, '-c', STARVED_CONSUMER, str(out)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                env=_replay_env())
    matched, confirm = bag_replay.BagPlayer.wait_for_subscribers, bag_replay.confirm

    def match_then_stop(player, *args, **kwargs):
        done = matched(player, *args, **kwargs)
        consumer.send_signal(signal.SIGSTOP)
        return done

    def resume_then_confirm(*args, **kwargs):
        consumer.send_signal(signal.SIGCONT)
        return confirm(*args, **kwargs)
    monkeypatch.setattr(bag_replay.BagPlayer, 'wait_for_subscribers', match_then_stop)
    if resume:
        monkeypatch.setattr(bag_replay, 'confirm', resume_then_confirm)
    try:
        assert consumer.stdout.readline().strip() == 'READY'
        code, captured = run_main(bag_replay.main, [
            str(bag_dir), '--topics', JS, '--clock', '--wait-for-subscribers', '1', '-q',
            *argv], capsys)
        consumer.send_signal(signal.SIGCONT)
        consumer.stdin.write('replay ended\n')
        consumer.stdin.flush()
        assert consumer.wait(PROCESS_BOUND_S) == 0
    finally:
        consumer.send_signal(signal.SIGCONT)
        consumer.kill()
        consumer.wait()
    with open(out, 'rb') as f:
        return code, captured.err, pickle.load(f)


def test_a_starved_consumer_still_gets_every_message(recorded, tmp_path, monkeypatch, capsys):
    """A keep_all consumer stopped for the whole burst gets every message once it runs again.

    As rosbag2's player with ``--wait-for-all-acked`` (rosbag2_transport player.cpp: after the
    last message, ``wait_for_all_acked`` on each publisher): the replay keeps every message a
    reliable reader has not acknowledged and exits only once all are (here within the default
    wait).
    """
    code, err, got = _starved_replay(tmp_path / 'run1', tmp_path, ['--rate', '5'],
                                     monkeypatch, capsys, resume=True)
    assert code == 0, err
    assert got[JS] == _recorded_bytes(tmp_path / 'run1', JS)
    assert _clock_ns(got[CLK]) == _clock_stamps(tmp_path / 'run1')


def test_a_consumer_starved_past_the_wait_is_counted_in_one_line(recorded, tmp_path,
                                                                 monkeypatch, capsys):
    """Stopped past ``--wait-for-all-acked``: exit 4 and one line counting what it lacks.

    The consumer acknowledged nothing, so every message sent is counted, per topic.
    """
    n = recorded['n']
    code, err, got = _starved_replay(tmp_path / 'run1', tmp_path,
                                     ['--rate', '5', '--wait-for-all-acked', '500'],
                                     monkeypatch, capsys, resume=False)
    assert code == EXIT_UNDELIVERED
    assert err.strip().splitlines() == [
        f'bag_replay: error: {2 * n} messages may not have been delivered ({n} on {CLK}, '
        f'{n} on {JS}): not acknowledged by every reliable subscriber within 500 ms']


def test_a_loop_waits_before_its_history_drops_what_a_reader_lacks(recorded, node_factory,
                                                                   tmp_path):
    """A keep_last writer drops its oldest sample when full, acknowledged or not.

    So a replay looping into a reader that acknowledges nothing stops once a topic's
    unacknowledged messages fill its history (1000: a pass is 150), waits for the
    acknowledgements up to ``wait_for_all_acked_ms`` and only then lets the writer drop: the
    1000 counted, per topic, /clock's too.
    """
    consumer = subprocess.Popen([sys.executable, '-c', STARVED_CONSUMER,
                                 str(tmp_path / 'unused.pickle')],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                env=_replay_env())
    stop = threading.Event()
    player = bag_replay.BagPlayer(node_factory('looping_player'), read_bag(tmp_path / 'run1'),
                                  bag_replay.ReplayOptions(rate=50.0, loop=True, topics=[JS],
                                                           clock=True,
                                                           wait_for_all_acked_ms=300))
    try:
        assert consumer.stdout.readline().strip() == 'READY'
        assert player.wait_for_subscribers(1, BOUND_S)
        consumer.send_signal(signal.SIGSTOP)
        player.play(stop, progress=lambda _line: player.undelivered and stop.set())
    finally:
        consumer.send_signal(signal.SIGCONT)
        consumer.kill()
        consumer.wait()
    assert player.undelivered == {JS: 1000, CLK: 1000}
    assert player.published > 1000


def test_truncated_recorder_file(recorded, node_factory, tmp_path, capsys):
    """A real recorder file cut in the middle: complete messages recovered; CLIs exit 3."""
    src = tmp_path / 'run1' / 'run1_0.mcap'
    data = src.read_bytes()
    cut_dir = tmp_path / 'cut'
    cut_dir.mkdir()
    (cut_dir / 'cut_0.mcap').write_bytes(data[:len(data) // 2])
    full, cut = read_bag(tmp_path / 'run1'), read_bag(cut_dir)
    assert cut.truncated and 0 < cut.message_count < full.message_count
    assert [m.data for m in cut.messages] == [m.data for m in full.messages[:cut.message_count]]
    with pytest.raises(SystemExit) as exc_info:
        bag_info.main([str(cut_dir)])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc_info.value.code == EXIT_TRUNCATED
    assert len(err) == 1 and f'truncated: {cut.message_count} complete messages' in err[0]
    # replay in-process (default context; this module's nodes use their own)
    n_js = sum(1 for m in cut.messages if m.topic == JS)
    _, got, _ = _collector(node_factory, 'cut_listener', {JS: JointState})
    with pytest.raises(SystemExit) as exc_info:
        bag_replay.main([str(cut_dir), '--topics', JS, '--rate', '50', '--quiet',
                         '--wait-for-subscribers', '1'])
    assert exc_info.value.code == EXIT_TRUNCATED
    assert wait_until(lambda: len(got[JS]) == n_js, BOUND_S)
    assert got[JS] == _recorded_bytes(tmp_path / 'run1', JS)[:n_js]


# --- the writer thread ------------------------------------------------------------------------

class _LoggedFile:
    """A bag file that notes which thread wrote how many bytes."""

    def __init__(self, f, log):
        self.f, self.log = f, log

    def write(self, data):
        self.log.append((threading.current_thread().name, len(data)))
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


def test_write_queues_and_the_file_is_written_a_chunk_at_a_time(node_factory, tmp_path,
                                                                monkeypatch):
    """A message costs the caller an append; the file sees one write per chunk and index.

    A topic's first message also writes its channel, once.
    """
    from gripper_ros.bags import recorder as recorder_module
    from rclpy.serialization import serialize_message
    log, real_open = [], open
    monkeypatch.setattr(recorder_module, 'open', lambda path, mode='r': _LoggedFile(
        real_open(path, mode), log), raising=False)
    every, n = 50, 200
    rec = BagRecorder(node_factory('queued'), tmp_path / 'queued', {JS: STD_TOPICS[JS]},
                      subscribe=False, flush_every_messages=every)
    data = serialize_message(joint_state(1))
    before = len(log)
    rec.write(JS, data, 0)
    assert len(log) == before + 1                              # the channel
    for k in range(1, every - 1):
        rec.write(JS, data, k)
    assert len(log) == before + 1 and rec.readable_count == 0  # in the chunk, nothing written
    for k in range(every - 1, n):
        rec.write(JS, data, k)
    assert rec.readable_count == n and rec.message_count == n
    assert len(log) - before == 1 + 2 * (n // every)      # the channel; a chunk, its index each
    rec.close()
    bag = read_bag(tmp_path / 'queued')
    assert bag.message_count == n and not bag.truncated
    assert [m.log_time_ns for m in bag.messages] == list(range(n))


def test_messages_left_waiting_are_written_by_the_timer(node_factory, tmp_path):
    """Fewer than a chunk, and nothing more comes: written within ``flush_every_s``."""
    from rclpy.serialization import serialize_message
    rec = BagRecorder(node_factory('waiting'), tmp_path / 'waiting', {JS: STD_TOPICS[JS]},
                      subscribe=False, flush_every_messages=100, flush_every_s=0.1)
    for k in range(7):
        rec.write(JS, serialize_message(joint_state(k)), k)
    assert wait_until(lambda: rec.readable_count == 7, BOUND_S)
    assert read_bag(tmp_path / 'waiting', allow_empty=True).message_count == 7
    rec.close()


def test_a_writer_failure_is_raised_by_the_next_write_and_nothing_is_lost_silently(
        node_factory, tmp_path, monkeypatch):
    """A full disk: write() raises it; messages taken but not readable are counted."""
    import errno
    from gripper_ros.bags import recorder as recorder_module
    from rclpy.serialization import serialize_message

    class Full:
        def __init__(self, f):
            self.f, self.n = f, 0

        def write(self, data):
            if self.n + len(data) > 3000:
                raise OSError(errno.ENOSPC, 'No space left on device')
            self.n += len(data)
            return self.f.write(data)

        def __getattr__(self, name):
            return getattr(self.f, name)

    real_open = open
    monkeypatch.setattr(recorder_module, 'open', lambda path, mode='r': Full(
        real_open(path, mode)), raising=False)
    rec = BagRecorder(node_factory('full'), tmp_path / 'full', {JS: STD_TOPICS[JS]},
                      subscribe=False, flush_every_messages=10)
    data = serialize_message(joint_state(1))
    with pytest.raises(OSError, match='No space left'):
        for k in range(100_000):
            rec.write(JS, data, k)
    assert isinstance(rec.failure, OSError)
    assert rec.accepted_count > rec.readable_count > 0
    with pytest.raises(BagRecorderError, match='No space left'):
        rec.close()
    # a chunk can be whole on disk while its index did not fit: a reader gets it back too
    readable = read_bag(tmp_path / 'full', allow_empty=True).message_count
    assert rec.readable_count <= readable <= rec.accepted_count
