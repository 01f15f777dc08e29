"""Recording a running graph: one bag per grasp, from inside the graph's process.

A :class:`GraphTap` subscribes (raw) to every topic of one gripper's graph only while it
records, and starts recording only once every publisher has matched it, so that no message
of the grasp is missed. :func:`recorded_grasp` places the object, records the grasp and what
follows it until simulated time stands still (fast mode: the hold scenario, a lift, played
out) or ``linger_s`` of simulated time after the answer (realtime). :class:`ServeRecorder`
records one bag per request made by other processes (``grasp_demo --serve``).

A recorder that fails (a full disk) never stops the graph: recording ends with one line that
names the bag and how many messages it holds, the bag stays readable up to there, and the
grasp goes on.
"""
from __future__ import annotations

import functools
import os
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from gripper_ros.bags.recorder import BagRecorder, BagRecorderError
from gripper_ros.bags.schema import import_message_class
from gripper_ros.nodes.common import GRAPH_QOS, wait_until
from gripper_ros.wire import GRAPH_TOPICS, TOPIC_STATUS, Outcome, qualified

BAG_FORMAT = 2
"""custom_data gripper_ros.format: 2 = the lockstep loop topics (loop/tick, references,
loop/motor_command); 1 (absent) = bags with a tick message per topic (joint_states...)."""
MATCH_TIMEOUT_S = 10.0


class RecordingError(RuntimeError):
    """Recording could not start or stopped early; the message is one line."""


@dataclass
class RecordedGrasp:
    """A grasp's answer, its bag, and how many messages the graph published per topic."""

    response: object
    bag_dir: Path | None
    published: dict
    recorded: dict
    wall_s: float
    final_outcome: Outcome = Outcome.UNKNOWN    # after the hold scenario (a lift) played out
    final_message: str = ''
    recording_error: str = ''
    notes: list = field(default_factory=list)


class GraphTap:
    """Raw subscriptions on every topic of ``graph`` that forward to a sink while recording."""

    def __init__(self, graph, topics: dict[str, str] | None = None):
        self.graph = graph
        self.node = graph.client_node
        self.topics = {qualified(graph.namespace, t): msgtype
                       for t, msgtype in (topics or GRAPH_TOPICS).items()}
        self.sink: BagRecorder | None = None
        self.error = ''                          # why the last sink stopped early
        self.on_status = None                    # called with the raw bytes of each status
        self.received = {t: 0 for t in self.topics}
        self._lock = threading.Lock()
        self._subs = []

    def open(self) -> GraphTap:
        """Subscribe, and wait until every publisher of the graph has matched this tap."""
        baseline = {t: [p.get_subscription_count() for p in self._publishers(t)]
                    for t in self.topics}
        for topic, msgtype in self.topics.items():
            self._subs.append(self.node.create_subscription(
                import_message_class(msgtype), topic,
                functools.partial(self._on_message, topic), GRAPH_QOS, raw=True))
        matched = wait_until(lambda: all(
            p.get_subscription_count() > n for t in self.topics
            for p, n in zip(self._publishers(t), baseline[t])), MATCH_TIMEOUT_S)
        if not matched:
            self.close()
            raise RecordingError(f'the recorder was not matched by every publisher within '
                                 f'{MATCH_TIMEOUT_S:g} s')
        return self

    def _publishers(self, topic: str) -> list:
        return [p for node in self.graph.nodes if node is not self.node
                for p in node.publishers if p.topic_name == topic]

    def _on_message(self, topic: str, data: bytes) -> None:
        self.received[topic] += 1
        sink = self.sink
        if sink is not None:
            try:
                sink.write(topic, data)
            except Exception as exc:  # noqa: BLE001 - a recorder error never stops the graph
                self._fail(sink, exc)
        if self.on_status is not None and topic.endswith('/' + TOPIC_STATUS):
            self.on_status(data)

    def _fail(self, sink: BagRecorder, exc: BaseException) -> None:
        with self._lock:
            if self.sink is not sink:
                return
            self.sink = None
        count = sink.message_count
        try:
            sink.close()
        except Exception:  # noqa: BLE001 - the first error is the one to report
            pass
        reason = getattr(exc, 'strerror', None) or str(exc)
        self.error = (f'recording stopped: {sink.bag_dir}: {reason}; the bag holds {count} '
                      'messages, readable up to there')
        self.node.get_logger().error(self.error)

    def close(self) -> None:
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        self._subs = []

    def __enter__(self) -> GraphTap:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()


def bag_metadata(graph, request: dict, placed: dict) -> dict:
    """custom_data of a grasp bag: all a closed-loop re-run needs, and the format."""
    return {'gripper_ros': {'format': BAG_FORMAT, 'namespace': graph.namespace,
                            'time_mode': graph.options.time_mode},
            'request': request, 'object': placed,
            'controllers': graph.controller_settings(),
            'config': graph.plant.config.data}


def unique_bag_dir(parent: Path, stem: str) -> Path:
    """A new folder under ``parent`` named after ``stem``, never one that exists: the name
    carries the process id and a counter, and the folder is created atomically."""
    parent.mkdir(parents=True, exist_ok=True)
    for n in range(1000):
        candidate = parent / f'{stem}_{os.getpid()}' if n == 0 else \
            parent / f'{stem}_{os.getpid()}_{n}'
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        return candidate
    raise RecordingError(f'no free bag folder name for {stem} under {parent}')


def recorded_grasp(graph, bag_dir, width_m: float, mass_kg: float,
                   friction_coefficient: float = 0.0, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, overwrite: bool = False,
                   wall_timeout_s: float = 600.0, width_tolerance_m: float = 0.0,
                   object_width_m: float | None = None, acceleration_mps2: float = 0.0,
                   linger_s: float = 0.5, **hold) -> RecordedGrasp:
    """Place the object, record every topic of the graph into ``bag_dir`` and grasp it.

    ``hold`` sets the object's hold and lift fields (SetObject). The bag is closed (summary,
    metadata.yaml) whatever happens, Ctrl-C included.
    """
    placed_width = graph.simulated_width_m(width_m, object_width_m)
    placed = graph.set_object(placed_width, stiffness_n_per_m, damping_n_s_per_m, **hold)
    if not placed.success:
        raise RecordingError(f'set_object: {placed.message}')
    graph.wait_still()
    request = {'width_m': width_m, 'mass_kg': mass_kg,
               'friction_coefficient': friction_coefficient,
               'acceleration_mps2': acceleration_mps2, 'width_tolerance_m': width_tolerance_m}
    obj = {'width_m': placed_width, 'stiffness_n_per_m': stiffness_n_per_m,
           'damping_n_s_per_m': damping_n_s_per_m, **{k: float(v) for k, v in hold.items()}}
    with GraphTap(graph) as tap:
        try:
            recorder = BagRecorder(graph.client_node, bag_dir, tap.topics, overwrite=overwrite,
                                   subscribe=False, time_source=lambda: graph.sim_time_ns,
                                   custom_data=bag_metadata(graph, request, obj))
        except BagRecorderError as exc:
            raise RecordingError(str(exc)) from None
        response = None
        before = graph.published_counts()
        tap.sink = recorder
        t0 = time.perf_counter()
        try:
            response = graph.grasp(width_m, mass_kg, friction_coefficient, acceleration_mps2,
                                   wall_timeout_s=wall_timeout_s,
                                   width_tolerance_m=width_tolerance_m)
            _play_out(graph, linger_s)
        finally:
            published = {qualified(graph.namespace, t): n - before.get(t, 0)
                         for t, n in graph.published_counts().items()
                         if qualified(graph.namespace, t) in tap.topics}
            _drain(tap, recorder, published)
            tap.sink = None
            logic = graph.supervisor.logic
            final, message = logic.outcome, logic.message
            if not recorder.closed:
                if response is not None:
                    recorder.set_custom_data({
                        'outcome': Outcome(response.outcome).name, 'success': response.success,
                        'message': response.message, 'final_outcome': final.name,
                        'final_message': message,
                        'position_setpoint_m': response.position_setpoint_m,
                        'force_setpoint_n': response.force_setpoint_n})
                recorder.close()
            recorded = dict(recorder.counts)
    return RecordedGrasp(response, Path(bag_dir), published, recorded,
                         time.perf_counter() - t0, final, message, tap.error)


def _play_out(graph, linger_s: float) -> None:
    """After the answer: until simulated time stands still (fast), or ``linger_s`` of it."""
    if graph.options.time_mode == 'fast':
        graph.wait_still()
        return
    until = graph.sim_time_ns + round(linger_s * 1e9)
    wait_until(lambda: graph.sim_time_ns >= until, timeout_s=max(10.0, 10 * linger_s))


def _drain(tap: GraphTap, recorder: BagRecorder, published: dict, timeout_s: float = 10.0):
    """Wait until the recorder holds every message published during the grasp."""
    wait_until(lambda: recorder.closed or all(
        recorder.counts.get(t, 0) >= n for t, n in published.items()), timeout_s)


class ServeRecorder:
    """Serve mode: one bag per request, whoever made it, under ``output_dir``.

    A bag opens when the supervisor accepts a request (its status says ``pending``, before the
    request's first tick) and closes ``linger_s`` of simulated time after the answer, when
    simulated time stands still, or when the next request is accepted.
    """

    def __init__(self, graph, output_dir, linger_s: float = 0.5):
        from gripper_interfaces.msg import SupervisorStatus
        from rclpy.clock import Clock, ClockType
        self._status_cls = SupervisorStatus
        self.graph = graph
        self.output_dir = Path(output_dir)
        self.linger_s = linger_s
        self.bags: list[Path] = []
        self.errors: list[str] = []
        self._answered_ns: int | None = None
        self._last_count = 0
        self._still_since = time.monotonic()
        self.tap = GraphTap(graph).open()
        self.tap.on_status = self._on_status
        graph.close_hooks.append(self.close)
        self._timer = graph.client_node.create_timer(
            0.05, self._check, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def recording(self) -> bool:
        return self.tap.sink is not None

    def _on_status(self, data: bytes) -> None:
        from rclpy.serialization import deserialize_message
        status = deserialize_message(data, self._status_cls)
        if status.pending:
            self._open(status)
        elif self.tap.sink is not None and status.outcome != 0 and self._answered_ns is None:
            self._answered_ns = status.header.stamp.sec * 1_000_000_000 + \
                status.header.stamp.nanosec

    def _open(self, status) -> None:
        self._close_bag()
        stamp = datetime.now().strftime('%Y%m%d_%H%M%S')
        try:
            bag_dir = unique_bag_dir(self.output_dir, f'grasp_{stamp}_id{status.grasp_id + 1}')
            self.tap.sink = BagRecorder(
                self.graph.client_node, bag_dir, self.tap.topics, subscribe=False,
                time_source=lambda: self.graph.sim_time_ns, overwrite=True,
                custom_data={'gripper_ros': {'format': BAG_FORMAT,
                                             'namespace': self.graph.namespace,
                                             'time_mode': self.graph.options.time_mode},
                             'controllers': self.graph.controller_settings(),
                             'config': self.graph.plant.config.data})
        except (OSError, BagRecorderError, RecordingError) as exc:
            self._report(f'recording not started under {self.output_dir}: '
                         f'{getattr(exc, "strerror", None) or exc}')
            return
        self._answered_ns = None
        self.bags.append(bag_dir)

    def _check(self) -> None:
        sink = self.tap.sink
        if self.tap.error:
            self._report(self.tap.error)
            self.tap.error = ''
        if sink is None:
            return
        count = sink.message_count
        if count != self._last_count:
            self._last_count, self._still_since = count, time.monotonic()
        if self._answered_ns is None:
            return
        if self.graph.sim_time_ns >= self._answered_ns + round(self.linger_s * 1e9) or \
                time.monotonic() - self._still_since > 0.2:
            self._close_bag()

    def _report(self, message: str) -> None:
        self.errors.append(message)
        self.graph.client_node.get_logger().error(message)
        self.graph.supervisor.response_notes.append(message)

    def _close_bag(self) -> None:
        sink, self.tap.sink = self.tap.sink, None
        if sink is not None and not sink.closed:
            try:
                sink.close()
            except Exception as exc:  # noqa: BLE001 - reported, never raised into the graph
                self._report(f'closing {sink.bag_dir} failed: {exc}')

    def close(self) -> None:
        self._close_bag()
        self.tap.close()
