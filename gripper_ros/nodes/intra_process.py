"""The graph's topics between nodes of one process, handed over without DDS.

As rclcpp's intra-process communication does, a message published by a node of the graph's
process goes straight to the subscribers of its topic in the same process, as the very object
that was published (the loop messages: their bytes): no serialisation, no DDS delivery, no
executor event per message. The topic keeps its name, type and QoS for everybody else: while a
subscriber of another process (or a node of this one that is not on the bus: a test's,
``ros2 topic echo``) is matched, the message is also published over DDS; a recorder's tap sees
every message either way.

The nodes of one process share one :class:`IntraProcessBus` (``GripperGraph`` makes it and
hands it to the nodes it builds, like rclcpp's ``use_intra_process_comms``). It carries the
volatile topics that only the graph publishes (the loop, ``supervisor/status``,
``joint_states``, ``sim/status``); their subscriptions on the bus have no DDS reader, so a
publisher in another process cannot drive a graph that runs in one. Inputs from other
programs (``joint_commands``, ``sim/load_acceleration``) and latched topics stay on DDS. A node
started alone has no bus and uses DDS for all of it.
"""
from __future__ import annotations

from collections import deque
import time
from typing import Callable

from gripper_ros.text import one_line

DRAIN_SLICE_S = 0.002
"""Longest a drain hands messages over before it yields to the executor (services, timers,
parameter requests and outside subscriptions are served between two slices)."""
CHECK_EVERY = 32
"""Messages handed over between two looks at the clock."""
OUTSIDE_POLL_S = 0.001
"""Longest a publisher with no matched outside subscriber goes without asking DDS for one: a
subscriber matched in between is served from the next publish, not from when the executor
handles its matched event."""


class IntraProcessBus:
    """The loop subscribers of one process and a queue of the messages to hand them, in order.

    Delivery is first in, first out, by executor tasks: a publish appends and, unless a drain
    is running or due, asks the executor for one. So the callback that published finishes
    first (a tick's state topics follow their tick, as over DDS), a tick's three messages
    follow each other as DDS would deliver them, and the stack never deepens. A drain yields
    to the executor after ``DRAIN_SLICE_S``; where it does changes no order of delivery.
    """

    def __init__(self, logger) -> None:
        self._subscribers: dict[str, list[tuple[object, Callable, bool, type]]] = {}
        self._queue: deque = deque()
        self._draining = False
        self._scheduled = False
        self._executor = None
        self._logger = logger
        self.delivered = 0

    def bind(self, executor) -> None:
        """Drain in ``executor``'s tasks from now; what waits is handed over at once."""
        self._executor = executor
        self._schedule()

    def subscribe(self, owner, topic: str, callback: Callable, msg_type, raw: bool) -> None:
        """Hand every message on ``topic`` (fully qualified) to ``callback`` of node ``owner``.

        ``raw``: as serialised bytes, else as a ``msg_type`` object (converted where it was
        published in the other form).
        """
        self._subscribers.setdefault(topic, []).append((owner, callback, raw, msg_type))

    def detach(self, owner) -> None:
        """Forget every subscription of ``owner`` (a node destroyed or taken out of the graph)."""
        for topic, subscribers in list(self._subscribers.items()):
            kept = [s for s in subscribers if s[0] is not owner]
            if kept:
                self._subscribers[topic] = kept
            else:
                del self._subscribers[topic]

    def subscriber_count(self, topic: str) -> int:
        return len(self._subscribers.get(topic, ()))

    @property
    def idle(self) -> bool:
        """True when nothing waits to be handed over (asked between two executor callbacks)."""
        return not self._queue and not self._draining

    def post(self, topic: str, msg) -> None:
        """Queue ``msg`` (bytes or a message) for each subscriber of ``topic``."""
        subscribers = self._subscribers.get(topic)
        if not subscribers:
            return
        append = self._queue.append
        published_raw = msg.__class__ is bytes
        converted = None                  # the other form, made once for every subscriber
        for _owner, callback, raw, msg_type in subscribers:
            if raw == published_raw:
                append((callback, msg))
            else:
                if converted is None:
                    converted = _convert(msg, raw, msg_type)
                append((callback, converted))
        if not self._draining:
            self._schedule()

    def deliver_queued(self) -> None:
        """Hand over now what is queued (not what that publishes in turn): for a service callback.

        A request judged on the graph's state must see every message published before it came:
        a client that got an answer and asks again has a right to the state that answer left.
        """
        if self._draining or self._executor is None:
            return
        if self._queue:
            self._drain(limit=len(self._queue))

    def _schedule(self) -> None:
        if self._executor is not None and not self._scheduled and self._queue:
            self._scheduled = True
            self._executor.create_task(self._drain)

    def _drain(self, limit: int | None = None) -> None:
        """Hand over what is queued, for at most ``DRAIN_SLICE_S``; then yield to the executor.

        ``limit``: at most this many messages, whatever the time. A callback that raises is
        reported in one line and the rest goes on, as the executor does with a failing callback.
        """
        if limit is None:
            self._scheduled = False
        queue = self._queue
        popleft = queue.popleft
        self._draining = True
        deadline = time.perf_counter() + DRAIN_SLICE_S
        handed = 0
        check_at = CHECK_EVERY if limit is None else limit     # the next look: clock or count
        try:
            while queue:
                callback, data = popleft()
                try:
                    callback(data)
                except Exception as exc:  # noqa: BLE001 - reported; the loop goes on
                    self._logger.error(f'a callback failed and was skipped: '
                                       f'{type(exc).__name__}: {one_line(exc)}')
                handed += 1
                if handed == check_at:
                    if limit is not None or time.perf_counter() > deadline:
                        break
                    check_at += CHECK_EVERY
        finally:
            self._draining = False
            self.delivered += handed
        self._schedule()


def _convert(msg, raw: bool, msg_type):
    """``msg`` in the form a subscriber takes: serialised (``raw``) or a ``msg_type`` object."""
    from rclpy.serialization import deserialize_message, serialize_message
    return serialize_message(msg) if raw else deserialize_message(msg, msg_type)


class GraphPublisher:
    """A graph topic's publisher: to the bus's subscribers, and over DDS while others listen.

    Each of ``taps`` is called with (topic, message) before the message is handed over (a
    recorder, a live view: what was published is what each sees, in publish order). A tap is
    added or removed from any thread: the tuple is replaced, never changed in place.
    """

    def __init__(self, node, msg_type, topic: str, qos, bus: IntraProcessBus | None) -> None:
        from rclpy.event_handler import PublisherEventCallbacks
        self._bus = bus
        self._outside = 0 if bus is not None else 1      # matched DDS subscriptions
        self._next_poll_s = 0.0
        events = PublisherEventCallbacks(matched=self._on_matched) if bus is not None else None
        self.dds = node.create_publisher(msg_type, topic, qos, event_callbacks=events)
        self.topic_name = self.dds.topic_name
        self.taps: tuple[Callable[[str, object], None], ...] = ()

    def add_tap(self, tap: Callable[[str, object], None]) -> None:
        """Call ``tap(topic, message)`` with every message published from now on."""
        self.taps = (*self.taps, tap)

    def remove_tap(self, tap: Callable[[str, object], None]) -> None:
        """Stop calling ``tap`` (one that was not added is ignored)."""
        self.taps = tuple(t for t in self.taps if t != tap)

    def _on_matched(self, info) -> None:
        self._outside = info.current_count

    def publish(self, msg) -> None:
        """Publish ``msg``: serialised bytes or a message object.

        Over DDS while a subscription is matched there, asking DDS for one at most every
        ``OUTSIDE_POLL_S`` (the loop's topics publish ten thousand a second: one call here).
        """
        for tap in self.taps:
            tap(self.topic_name, msg)
        if not self._outside:
            now_s = time.monotonic()
            if now_s >= self._next_poll_s:
                self._next_poll_s = now_s + OUTSIDE_POLL_S
                self._outside = self.dds.get_subscription_count()
        if self._outside:
            self.dds.publish(msg)
        if self._bus is not None:
            self._bus.post(self.topic_name, msg)

    def get_subscription_count(self) -> int:
        """Subscriptions on the topic: the bus's and those matched over DDS."""
        local = self._bus.subscriber_count(self.topic_name) if self._bus is not None else 0
        return local + self.dds.get_subscription_count()
