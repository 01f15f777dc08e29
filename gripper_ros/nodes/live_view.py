"""The graph shown live in Foxglove: its topics served over the Foxglove WebSocket protocol.

Foxglove's own SDK (``foxglove-sdk``) runs the server, on its own threads; its subprotocol,
``foxglove.sdk.v1``, is the one the Foxglove app speaks. Each channel is one topic of the graph
(``wire.LIVE_TOPICS``) with its ROS 2 schema, the text a bag's MCAP carries
(``bags.schema.message_definition``, encoding ``ros2msg``) and ``cdr`` messages, so a panel or a
layout works the same live and on a bag. Every message's log time is the simulated time, as in a
bag.

The messages come from the graph's own publishers, at their pace: a tap in each publisher of a
served topic (as a recorder's), put in when the first client subscribes to the topic and taken
out when the last one leaves, so a topic nobody watches costs the loop nothing; one watched
costs one call into the SDK per message. The SDK queues each client's messages and drops the
oldest for a client that reads too slowly (one whose control messages back up is
disconnected): the graph never waits for a client. A client can only subscribe: the server
advertises no capability (no publishing, services or parameters), so nothing it sends reaches
the graph. Latched topics (robot_description, /tf_static, gripper_status) go again to each new
subscriber, as a transient-local ROS subscription gets them.
"""
from __future__ import annotations

import sys
import threading

from gripper_ros.bags.schema import message_definition
from gripper_ros.text import one_line
from gripper_ros.wire import (LATCHED_LIVE_TOPICS, LIVE_TOPICS, qualified, TOPIC_TF,
                              TOPIC_TF_STATIC)
from rclpy.serialization import serialize_message

DEFAULT_PORT = 8765
"""The port of ``--foxglove`` and ``foxglove_port``: the Foxglove app's default."""
DEFAULT_ADDRESS = '127.0.0.1'
"""Where the server listens unless the user names an address: this machine only."""
SERVER_NAME = 'gripper_ros'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'


class LiveViewError(RuntimeError):
    """The server could not start (the port is taken, the address is not this machine's)."""


class _Topic:
    """One served topic: its channel, the graph's publishers of it and who watches it."""

    def __init__(self, channel, publishers: list, latched: bytes | None, now_ns):
        self.channel = channel
        self.publishers = publishers
        self.latched = latched          # the last message of a latched topic (None: others)
        self.watchers = 0
        # the SDK's channel below its Python wrapper: a call into Rust per message, not three
        base = getattr(channel, 'base', None)
        self._log = base.log if base is not None and hasattr(base, 'log') else \
            (lambda data, log_time: channel.log(data, log_time=log_time))
        self._now_ns = now_ns

    def tap(self, _topic: str, msg) -> None:
        """Send a message just published to the clients that subscribed to it."""
        data = msg if msg.__class__ is bytes else serialize_message(msg)
        if self.latched is not None:
            self.latched = data
        if self.watchers:
            self._log(data, self._now_ns())


class LiveView:
    """A Foxglove WebSocket server of one graph's topics; :meth:`close` stops it.

    ``graph``: a running :class:`~gripper_ros.nodes.graph.GripperGraph`. ``address`` and
    ``port`` (0: any free port) say where it listens; :attr:`url` is where to connect.
    """

    def __init__(self, graph, address: str = DEFAULT_ADDRESS, port: int = DEFAULT_PORT):
        import foxglove
        self._lock = threading.Lock()
        self._context = foxglove.Context()
        plant = graph.plant.plant
        self.topics: dict[int, _Topic] = {}          # by channel id
        publishers: dict[str, list] = {}
        latched: dict[str, bytes] = {}
        for node in graph.nodes:
            for publisher in getattr(node, 'graph_publishers', ()):
                publishers.setdefault(publisher.topic_name, []).append(publisher)
            for name, msg in getattr(node, 'latched', {}).items():
                latched[qualified(graph.namespace, name)] = serialize_message(msg)
        latched_names = {qualified(graph.namespace, t) for t in LATCHED_LIVE_TOPICS}
        for relative, msgtype in LIVE_TOPICS.items():
            name = qualified(graph.namespace, relative)
            if name not in publishers:
                continue                        # not in this graph (no description...)
            channel = foxglove.Channel(name, schema=foxglove.Schema(
                name=msgtype, encoding=SCHEMA_ENCODING,
                data=message_definition(msgtype).encode('utf-8')),
                message_encoding=MESSAGE_ENCODING, context=self._context)
            topic = _Topic(channel, publishers[name],
                           latched.get(name, b'') if name in latched_names else None,
                           lambda: plant.t_ns)
            if topic.latched is not None:       # kept current from the start
                for publisher in topic.publishers:
                    publisher.add_tap(topic.tap)
            self.topics[channel.id()] = topic
        try:
            self.server = foxglove.start_server(
                name=SERVER_NAME, host=address, port=port, capabilities=[],
                server_listener=self, context=self._context)
        except RuntimeError as exc:
            self._untap()
            raise LiveViewError(f'the Foxglove live view cannot listen on {address}:{port}: '
                                f'{one_line(exc).removeprefix("FoxgloveError: ")}') from None
        self.address = address
        self.port = self.server.port

    @property
    def url(self) -> str:
        """Where a Foxglove client connects: ``ws://ADDRESS:PORT``."""
        host = f'[{self.address}]' if ':' in self.address else self.address
        return f'ws://{host}:{self.port}'

    # ---------------------------------------------------------------- the SDK's listener
    def on_subscribe(self, _client, channel) -> None:
        """Count a client in: tap the topic's publishers for the first; send a latched one."""
        try:
            topic = self.topics.get(channel.id)
            if topic is None:
                return
            with self._lock:
                topic.watchers += 1
                first = topic.watchers == 1 and topic.latched is None
            if first:
                for publisher in topic.publishers:
                    publisher.add_tap(topic.tap)
            if topic.latched:
                topic.channel.log(topic.latched, log_time=topic._now_ns())
        except Exception as exc:  # noqa: BLE001 - a client's request never ends the graph
            print(f'live view: subscription of channel {channel.id} failed: {one_line(exc)}',
                  file=sys.stderr)

    def on_unsubscribe(self, _client, channel) -> None:
        """Count a client out (it left or disconnected): untap a topic nobody watches."""
        try:
            topic = self.topics.get(channel.id)
            if topic is None:
                return
            with self._lock:
                topic.watchers = max(0, topic.watchers - 1)
                last = topic.watchers == 0 and topic.latched is None
            if last:
                for publisher in topic.publishers:
                    publisher.remove_tap(topic.tap)
        except Exception as exc:  # noqa: BLE001 - as above
            print(f'live view: unsubscription of channel {channel.id} failed: {one_line(exc)}',
                  file=sys.stderr)

    # ---------------------------------------------------------------- lifecycle
    def _untap(self) -> None:
        for topic in self.topics.values():
            topic.watchers = 0
            for publisher in topic.publishers:
                publisher.remove_tap(topic.tap)

    def close(self) -> None:
        """Stop the server and take every tap out of the graph's publishers; safe to call twice."""
        server, self.server = getattr(self, 'server', None), None
        if server is not None:
            server.stop()
        self._untap()


def layout_topics(layout) -> list[str]:
    """Return the topics a Foxglove layout (its JSON, as a dict) subscribes to.

    Those its panels name (a 3D panel's topics, a plot's message paths, a raw message's topic
    path), and ``/tf`` and ``/tf_static``, which a 3D panel takes for its frames.
    """
    found: set[str] = set()

    def walk(node) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                if key == 'topics' and isinstance(value, dict):
                    found.update(value)
                elif key in ('value', 'topicPath') and isinstance(value, str):
                    found.add(value.split('.')[0])
                else:
                    walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)
    walk(layout)
    return sorted(found | {TOPIC_TF, TOPIC_TF_STATIC})


def serve_live(prog: str, graph, address: str, port: int) -> LiveView:
    """Start a :class:`LiveView` of ``graph``, closed with it; say, as ``prog``, where it is.

    ValueError for a port out of range; :class:`LiveViewError` when it cannot listen.
    """
    if not (isinstance(port, int) and 0 <= port <= 65535):
        raise ValueError(f'foxglove port: 0-65535, got {port!r}')
    view = LiveView(graph, address, port)
    graph.close_hooks.append(view.close)
    print(f'{prog}: Foxglove live view at {view.url} (in Foxglove: Open connection, Foxglove '
          'WebSocket)', flush=True)
    return view
