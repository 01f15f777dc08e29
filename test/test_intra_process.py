"""The graph's topics handed over inside one process, and the same topics for everybody else.

Known answers: the bus delivers in publish order, a callback's own publications after what was
queued before them, and goes on past a callback that raises; an executor timer runs between two
drain slices; a subscriber in another process gets each publisher's loop messages of a grasp in
publish order, byte for byte what the bag recorded, and the newest of each topic, while the
graph's own nodes never see one twice. (The loop itself, tick for tick against the headless loop
and run against run, is test_graph's.)
"""
from __future__ import annotations

import struct
import threading
import time

from gripper_ros.bags.reader import read_bag
from gripper_ros.bags.schema import import_message_class
from gripper_ros.nodes import intra_process
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.intra_process import IntraProcessBus
from gripper_ros.nodes.process import ExecutorKind, make_executor
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (COMMAND_LAYOUT, GRAPH_QOS_DEPTH, LOOP_TOPICS, Outcome, qualified,
                              TOPIC_MOTOR_COMMAND)
import pytest
import rclpy
from rclpy.context import Context

WIDTH, MASS = 0.05, 1.69


class _Log:
    def __init__(self):
        self.errors: list[str] = []

    def error(self, text: str) -> None:
        self.errors.append(text)


@pytest.fixture
def spun():
    """Give a node and the EventsExecutor that spins it (the graph's executor)."""
    context = Context()
    rclpy.init(context=context)
    executor = make_executor(ExecutorKind.EVENTS, context)
    node = rclpy.create_node('bus_test', context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _spin_until(ex, predicate, timeout_s: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.01)
    return predicate()


def test_the_bus_delivers_in_publish_order_and_a_reply_after_what_was_queued(spun):
    node, executor = spun
    bus, seen = IntraProcessBus(_Log()), []

    def on_a(msg):
        seen.append(('a', msg))
        if msg == b'1':
            bus.post('/b', b'reply to 1')        # queued behind '/b' 'x' posted before

    bus.subscribe('owner', '/a', on_a, None, True)
    bus.subscribe('owner', '/b', lambda msg: seen.append(('b', msg)), None, True)
    bus.post('/a', b'1')
    bus.post('/b', b'x')
    bus.post('/a', b'2')
    bus.post('/nobody', b'dropped')              # no subscriber: nothing queued
    bus.bind(executor)
    assert _spin_until(executor, lambda: len(seen) == 4)
    assert seen == [('a', b'1'), ('b', b'x'), ('a', b'2'), ('b', b'reply to 1')]


def test_a_callback_that_raises_is_reported_and_the_rest_is_delivered(spun):
    node, executor = spun
    log = _Log()
    bus, seen = IntraProcessBus(log), []

    def broken(_msg):
        raise ValueError('a bug in a callback')

    bus.subscribe('owner', '/a', broken, None, True)
    bus.subscribe('owner', '/a', seen.append, None, True)
    bus.bind(executor)
    bus.post('/a', b'1')
    bus.post('/a', b'2')
    assert _spin_until(executor, lambda: len(seen) == 2)
    assert seen == [b'1', b'2']
    assert len(log.errors) == 2 and 'ValueError: a bug in a callback' in log.errors[0]


def test_a_detached_node_gets_nothing_more(spun):
    node, executor = spun
    bus, seen = IntraProcessBus(_Log()), []
    bus.subscribe('killed', '/a', seen.append, None, True)
    bus.subscribe('alive', '/a', lambda msg: seen.append(b'alive ' + msg), None, True)
    bus.bind(executor)
    bus.detach('killed')
    bus.post('/a', b'1')
    assert _spin_until(executor, lambda: len(seen) == 1)
    assert seen == [b'alive 1'] and bus.subscriber_count('/a') == 1


def test_a_timer_runs_between_two_slices_of_an_endless_exchange(spun, monkeypatch):
    """A ping-pong that never ends by itself still leaves the executor its timers."""
    node, executor = spun
    monkeypatch.setattr(intra_process, 'DRAIN_SLICE_S', 0.001)
    monkeypatch.setattr(intra_process, 'CHECK_EVERY', 1)
    bus, exchanged, fired = IntraProcessBus(_Log()), [0], threading.Event()
    stop = [False]

    def ping(msg):
        exchanged[0] += 1
        if exchanged[0] == 10:          # the exchange runs: the timer starts now, not before
            node.create_timer(0.01, fired.set)
        if not stop[0]:
            reply = b'pong' if msg == b'ping' else b'ping'
            bus.post('/' + reply.decode(), reply)

    bus.subscribe('owner', '/ping', ping, None, True)
    bus.subscribe('owner', '/pong', ping, None, True)
    bus.bind(executor)
    bus.post('/ping', b'ping')
    assert _spin_until(executor, fired.is_set), 'the timer never ran'
    stop[0] = True
    assert exchanged[0] >= 10


def test_the_bus_converts_between_bytes_and_messages(spun):
    node, executor = spun
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64
    bus, raw, typed = IntraProcessBus(_Log()), [], []
    bus.subscribe('owner', '/x', raw.append, Float64, True)
    bus.subscribe('owner', '/x', typed.append, Float64, False)
    bus.bind(executor)
    bus.post('/x', Float64(data=2.5))
    bus.post('/x', serialize_message(Float64(data=-1.0)))
    assert _spin_until(executor, lambda: len(raw) == len(typed) == 2)
    assert raw == [serialize_message(Float64(data=2.5)), serialize_message(Float64(data=-1.0))]
    assert [m.data for m in typed] == [2.5, -1.0]


def _stamp_ns(data: bytes) -> int:
    """Return a loop message's stamp (its first field, after the encapsulation header)."""
    return struct.unpack_from('<q', data, 4)[0]


def _by_publisher(topic: str, messages: list[bytes]) -> dict[int, list[bytes]]:
    """Split a topic's messages by publisher: the motor commands by their source controller."""
    if not topic.endswith(TOPIC_MOTOR_COMMAND):
        return {0: messages}
    source = COMMAND_LAYOUT.fields.index('source')
    split: dict[int, list[bytes]] = {}
    for m in messages:
        split.setdefault(COMMAND_LAYOUT.unpack(m)[source], []).append(m)
    return split


def _subsequence_length(got: list[bytes], recorded: list[bytes]) -> int:
    """Match ``got`` in order against ``recorded``; return how many matched (all: in order)."""
    it = iter(recorded)
    return sum(1 for message in got if any(message == r for r in it))


def test_another_participant_gets_loop_messages_in_order_and_the_newest_thousand(tmp_path):
    """What a subscriber in another process is promised on the loop topics (ARCHITECTURE, QoS).

    With the graph's QoS (reliable, keep_last 1000) it gets each publisher's messages, byte for
    byte as the bag recorded them, in that publisher's order and each once (the two controllers'
    motor commands are two publishers); it may miss older ones while it lags more than 1000
    behind (a fast-mode grasp outruns a Python subscriber); once the graph stands still it has
    the newest message of each topic, and the newest 1000 of a topic with one publisher. The bag
    is the complete record. The listener is a DDS participant of its own (a context of its own),
    as another process is.
    """
    with GripperGraph.in_own_context(GraphOptions(namespace='ipc_outside')) as graph:
        listener_context = Context()
        rclpy.init(context=listener_context)
        try:
            node = rclpy.create_node('outside_listener', context=listener_context)
            ex = make_executor(ExecutorKind.EVENTS, listener_context)
            ex.add_node(node)
            topics = {qualified(graph.namespace, t): m for t, m in LOOP_TOPICS.items()}
            got: dict[str, list[bytes]] = {topic: [] for topic in topics}
            for topic, msgtype in topics.items():
                node.create_subscription(import_message_class(msgtype), topic,
                                         got[topic].append, GRAPH_QOS, raw=True)
            publishers = [p for n in (graph.plant, graph.supervisor, graph.position, graph.force)
                          for p in n.graph_publishers if p.topic_name in topics]
            assert _spin_until(ex, lambda: all(p.get_subscription_count() >= 2
                                               for p in publishers))
            done = threading.Event()
            listening = threading.Thread(target=lambda: _spin_until(ex, done.is_set, 600.0))
            listening.start()                            # the listener keeps up as it can
            try:
                run = recorded_grasp(graph, tmp_path / 'bag', WIDTH, MASS)
                assert run.response.outcome == Outcome.HOLDING, run.response.message
                assert graph.wait_still()
                bag = read_bag(tmp_path / 'bag')
                recorded = {topic: [m.data for m in bag.messages if m.topic == topic]
                            for topic in topics}
                assert all(recorded.values())
                # the graph stands still: the newest message reaches the listener, however late
                assert wait_until(lambda: all(recorded[t][-1] in got[t][-3:] for t in topics),
                                  120.0), {t: (len(got[t]), len(recorded[t])) for t in topics}
            finally:
                done.set()
                listening.join()
            ex.shutdown()
            node.destroy_node()
        finally:
            rclpy.try_shutdown(context=listener_context)
        assert graph.plant.commands_ignored == 0, 'a command reached the plant twice'
    for topic in topics:
        first_ns = _stamp_ns(recorded[topic][0])
        during = [m for m in got[topic] if _stamp_ns(m) >= first_ns]   # not the earlier ones
        assert during[-1] == recorded[topic][-1], topic
        mine, theirs = _by_publisher(topic, during), _by_publisher(topic, recorded[topic])
        assert set(mine) <= set(theirs), topic
        for source, messages in mine.items():     # each publisher's in its order, each once
            assert _subsequence_length(messages, theirs[source]) == len(messages), topic
        if len(theirs) == 1:
            newest = min(GRAPH_QOS_DEPTH, len(recorded[topic]))
            assert during[-newest:] == recorded[topic][-newest:], topic
        print(f'{topic}: {len(during)} of {len(recorded[topic])} recorded messages')


def test_a_service_callback_sees_what_was_published_before_it(spun):
    """deliver_queued hands over what waits now; what that publishes in turn waits its turn."""
    node, executor = spun
    bus, seen = IntraProcessBus(_Log()), []

    def on_status(msg):
        seen.append(msg)
        bus.post('/status', msg + b' again')    # published while being delivered: later

    bus.subscribe('owner', '/status', on_status, None, True)
    bus.bind(executor)
    bus.post('/status', b'done')
    bus.post('/status', b'idle')
    bus.deliver_queued()                        # as a service callback would, before judging
    assert seen == [b'done', b'idle']
    assert bus.subscriber_count('/status') == 1
