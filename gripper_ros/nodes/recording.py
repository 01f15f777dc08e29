"""Recording a running graph: one bag per grasp, from inside the graph's process.

A :class:`GraphTap` sees every message the graph's nodes publish on its topics, in the
publish call itself, so that no message of a grasp is missed and the tick pays for no
subscription of its own; a :class:`BagRecorder` queues them and writes a chunk at a time.
:func:`recorded_grasp` places the object, records the grasp and what
follows it until simulated time stands still (fast mode: the hold scenario, a lift, played
out) or ``linger_s`` of simulated time after the answer (realtime). :class:`ServeRecorder`
records one bag per request made by other processes (``grasp_demo --serve``).

A recorder that fails (a full disk) never stops the graph: recording ends with one line that
names the bag and how many messages it holds, the bag stays readable up to there, and the
grasp goes on.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
import struct
import threading
import time

from gripper_ros.bags.recorder import (BAG_FORMAT, BagRecorder, BagRecorderError, failure_message,
                                       RecordingError, unique_bag_dir)
from gripper_ros.nodes.process import load_bound_s
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (BAG_TOPICS, GRAPH_TOPICS, LOOP_TOPICS, Outcome, Phase, qualified,
                              REFERENCE_LAYOUT, TimeMode, TOPIC_FORCE_REFERENCE,
                              TOPIC_MOTOR_COMMAND, TOPIC_POSITION_REFERENCE, TOPIC_TICK)
from rclpy.serialization import serialize_message


@dataclass
class RecordedGrasp:
    """A grasp the graph ran: the request, the answer, its bag and what was published.

    ``bag_dir`` None: not recorded. ``published``: messages per topic (fast mode; in realtime
    simulated time runs on and it is empty).
    """

    response: object
    bag_dir: Path | None
    published: dict
    recorded: dict
    wall_s: float
    final_outcome: Outcome = Outcome.UNKNOWN    # after the hold scenario (a lift) played out
    final_message: str = ''
    recording_error: str = ''
    notes: list = field(default_factory=list)
    width_m: float = 0.0                        # the request's
    mass_kg: float = 0.0


_STAMP = struct.Struct('<q')
"""Every lockstep message begins, after its 4-byte CDR header, with its tick's stamp_ns."""
_REFERENCE_KEY = REFERENCE_LAYOUT.reader('stamp_ns', 'grasp_id', 'phase', 'outcome')
"""What serve-mode recording reads of each reference: which request, and how it stands."""


class GraphTap:
    """Every message the graph's nodes publish on its topics, forwarded to a sink while recording.

    The tap sits in the publishers themselves (:meth:`open`), not in DDS subscriptions: a
    subscription of its own would add a DDS delivery and an executor callback to every loop
    message, about 8 us each, the largest part of what recording cost the tick. What a
    publisher hands to DDS is handed here too, in the same call, so the counts recorded equal
    the counts published by construction. The sink queues it and writes a chunk at a time.

    A sink records a window of whole ticks: from a start tick, whose measurement, decision and
    command it holds, up to an end tick it holds nothing of. The window is kept by the stamps
    the lockstep messages carry, and a sink closes only once the command of its last tick is in.
    """

    def __init__(self, graph, topics: dict[str, str] | None = None):
        self.graph = graph
        self.node = graph.client_node
        default = BAG_TOPICS if getattr(graph, 'description', None) is not None else GRAPH_TOPICS
        self.topics = {qualified(graph.namespace, t): msgtype
                       for t, msgtype in (topics or default).items()}
        self.sink: BagRecorder | None = None
        self.error = ''                          # why the last sink stopped early
        self.on_reference = None                 # called with each reference (its bytes)
        self.on_tick = None                      # called with each tick's stamp
        self.on_closed = None                    # called with a sink the tap finished
        self.on_error = None                     # called with the message of a failed sink
        self.received = dict.fromkeys(self.topics, 0)
        self._tick_topic = qualified(graph.namespace, TOPIC_TICK)
        self._command_topic = qualified(graph.namespace, TOPIC_MOTOR_COMMAND)
        self._loop_topics = {qualified(graph.namespace, t) for t in LOOP_TOPICS}
        self._reference_topics = {qualified(graph.namespace, t) for t in
                                  (TOPIC_POSITION_REFERENCE, TOPIC_FORCE_REFERENCE)}
        self._last_tick: tuple[int, bytes] | None = None
        self._this_tick: list[tuple[str, bytes, int]] = []   # loop messages of the newest tick
        self._state_of_tick: list[tuple[str, bytes]] = []    # its state topics, unrecorded
        self._held: tuple[int, bytes] | None = None   # the newest tick, written with its decision
        self._decided_ns: int | None = None     # newest stamp of a reference or command seen
        self._last_command_ns: int | None = None
        self._start_ns: int | None = None       # the window: ticks start_ns <= t < end_ns
        self._end_ns: int | None = None
        self._last_written_tick_ns: int | None = None
        self._start_at_next_tick = False
        self._closing_since: float | None = None
        self._lock = threading.Lock()
        self._tapped = []                        # graph publishers that call the tap

    def open(self) -> GraphTap:  # noqa: A003 - a tap is opened and closed like a file
        """Tap every publisher of the graph's topics: what each publishes is seen here at once.

        Each is a :class:`~gripper_ros.nodes.intra_process.GraphPublisher`, which calls the tap
        itself, whether the message goes over the process's bus, DDS or both. A node that
        publishes a recorded topic past one is refused here, before any bag misses its messages.
        """
        for node in self.graph.nodes:
            if node is self.node:
                continue
            wrapped = getattr(node, 'graph_publishers', ())
            for publisher in wrapped:
                if publisher.topic_name in self.topics:
                    publisher.add_tap(self._on_message)
                    self._tapped.append(publisher)
            inner = {id(p.dds) for p in wrapped}
            untapped = sorted(p.topic_name for p in node.publishers
                              if p.topic_name in self.topics and id(p) not in inner)
            if untapped:
                self.close()
                raise RuntimeError(f'{node.get_name()} publishes {", ".join(untapped)} with a '
                                   'plain rclpy publisher: a recorder cannot see it '
                                   '(use GripperNode.graph_publisher or tapped_publisher)')
        return self

    # ------------------------------------------------------------------ the window
    def start(self, sink: BagRecorder, at: str = 'now') -> None:
        """Record into ``sink`` from ``at``.

        ``now`` (time stands still: nothing is in flight), ``next_tick``, or ``last_tick`` (the
        newest tick, whose decision is being handled).
        """
        if self.sink is not None:
            self._finish()                      # a sink still closing ends here
        self.error = ''
        self._end_ns = self._last_written_tick_ns = self._closing_since = None
        self._last_command_ns = None
        self._start_at_next_tick = at == 'next_tick'
        self._start_ns = None
        if at == 'last_tick' and self._last_tick is not None:
            self._start_ns = self._last_tick[0]
            self.sink = sink
            self._held = None
            self._write_latched(sink)
            for topic, data, stamp in self._this_tick:     # the tick, and what came of it
                if stamp == self._start_ns:
                    self._write(sink, topic, data, stamp)
            for topic, data in self._state_of_tick:         # and the state it published
                self._write(sink, topic, data)
            return
        self.sink = None if self._start_at_next_tick else sink
        self._pending_sink = sink
        if self.sink is not None:
            self._write_latched(sink)

    def _write_latched(self, sink: BagRecorder) -> None:
        """Begin with each latched message a node holds (robot_description, /tf_static).

        They were published once, before the window; a late subscriber gets them, so a bag
        does too, as ``ros2 bag record`` gets them when it subscribes.
        """
        for node in self.graph.nodes:
            for topic, msg in getattr(node, 'latched', {}).items():
                name = qualified(self.graph.namespace, topic)
                if name in self.topics:
                    self._write(sink, name, serialize_message(msg))

    def flush(self) -> None:
        """Write a tick still held for its decision (time stands still: none is coming)."""
        held, self._held = self._held, None
        if held is not None:
            self._keep(self._tick_topic, held[1], held[0])

    def stop_at(self, end_ns: int | None = None) -> None:
        """End the window before tick ``end_ns`` (default: the next tick to come).

        The sink closes once the command of its last tick is in (:attr:`on_closed`).
        """
        if self.sink is None:
            return
        self._end_ns = end_ns if end_ns is not None else -1
        self._closing_since = time.monotonic()
        if self._held is not None and end_ns is not None and self._held[0] >= end_ns:
            self._held = None                   # that tick belongs after the window
        if end_ns is not None and self._last_written_tick_ns is not None and \
                self._last_command_ns == self._last_written_tick_ns:
            self._finish()                      # nothing of the last tick is in flight

    def stop(self, timeout_s: float = 2.0) -> BagRecorder | None:
        """End the window at the next tick and wait until the sink is whole.

        When no tick comes within ``timeout_s`` on free cores (:func:`load_bound_s`; simulated
        time stands still) it ends now; if the command of its last tick has not come by then
        (the graph's executor stalled, a stage gone), :attr:`error` says the sink is incomplete.
        """
        sink = self.sink
        if sink is None:
            return None
        self.stop_at()
        bound_s = load_bound_s(timeout_s)
        if not wait_until(lambda: self.sink is None, bound_s):
            self._end_incomplete(sink, bound_s)
        return sink

    def _end_incomplete(self, sink: BagRecorder | None, waited_s: float) -> None:
        """Finish ``sink`` now, saying so in :attr:`error` if its last tick has no command."""
        tick_ns = self._last_written_tick_ns
        if sink is not None and self.sink is sink and tick_ns is not None and \
                self._last_command_ns != tick_ns and not self.error:
            self.error = (f'recording incomplete: {sink.bag_dir}: the motor command of its last '
                          f'tick ({tick_ns} ns) did not come within {waited_s:.1f} s')
        self._finish()

    def _finish(self) -> None:
        with self._lock:
            sink, self.sink = self.sink, None
            self._end_ns = self._closing_since = None
        if sink is not None and self.on_closed is not None:
            self.on_closed(sink)

    def check_closing(self, grace_s: float = 0.5) -> None:
        """Finish a sink whose last command has not come for ``grace_s`` (a node gone).

        ``grace_s`` is for free cores (:func:`load_bound_s`); :attr:`error` says it is incomplete.
        """
        since = self._closing_since
        if since is None:
            return
        waited_s = time.monotonic() - since
        if waited_s > load_bound_s(grace_s):
            self._end_incomplete(self.sink, waited_s)

    def _on_message(self, topic: str, msg) -> None:
        """See one published message (bytes, or a message object); never raises."""
        try:
            self._see(topic, msg if msg.__class__ is bytes else serialize_message(msg))
        except Exception as exc:  # noqa: BLE001 - a recorder error never stops the graph
            sink = self.sink
            if sink is not None:
                self._fail(sink, exc)

    def _see(self, topic: str, data: bytes) -> None:
        self.received[topic] += 1
        if topic not in self._loop_topics:
            sink = self.sink
            if sink is not None and self._end_ns is None:
                self._write(sink, topic, data)
            else:
                self._state_of_tick.append((topic, data))
            return
        stamp = _STAMP.unpack_from(data, 4)[0]
        if topic == self._tick_topic:
            held, self._held = self._held, (stamp, data)
            if held is not None:
                self._keep(self._tick_topic, held[1], held[0])   # a tick nobody answered
            if self._decided_ns is not None and stamp <= self._decided_ns:
                self._held = None               # its decision came first: write it now
                self._keep(topic, data, stamp)
            self._last_tick = (stamp, data)
            self._this_tick = []
            self._state_of_tick = []
            if self._start_at_next_tick:
                self._start_at_next_tick = False
                self._start_ns, self.sink = stamp, self._pending_sink
                self._write_latched(self.sink)
            if self._end_ns == -1 and self.sink is not None:
                self._end_ns = stamp
            if self.on_tick is not None:
                self.on_tick(stamp)
        else:
            if self.on_reference is not None and topic in self._reference_topics:
                self.on_reference(data)
            held = self._held
            if held is not None and held[0] == stamp:
                self._held = None
                self._keep(self._tick_topic, held[1], stamp)
            self._decided_ns = stamp if self._decided_ns is None else max(stamp, self._decided_ns)
            self._keep(topic, data, stamp)
        self._this_tick.append((topic, data, stamp))

    def _keep(self, topic: str, data: bytes, stamp: int) -> None:
        """Write a lockstep message if its tick is inside the window."""
        sink = self.sink
        if sink is None or (self._start_ns is not None and stamp < self._start_ns) or \
                (self._end_ns is not None and self._end_ns != -1 and stamp >= self._end_ns):
            return
        self._write(sink, topic, data, stamp)
        if topic == self._command_topic:
            self._last_command_ns = stamp
            if self._end_ns is not None and stamp == self._last_written_tick_ns:
                self._finish()                  # the last tick is whole

    def _write(self, sink: BagRecorder, topic: str, data: bytes, stamp: int | None = None):
        try:
            sink.write(topic, data, stamp)      # a loop message: logged at its tick's time
        except Exception as exc:  # noqa: BLE001 - a recorder error never stops the graph
            self._fail(sink, exc)
            return
        if topic == self._tick_topic:
            self._last_written_tick_ns = stamp

    def _fail(self, sink: BagRecorder, exc: BaseException) -> None:
        with self._lock:
            if self.sink is not sink:
                return
            self.sink = None
        self.error = failure_message(sink, exc)
        if self.on_error is not None:           # not inside the publish of a node's callback
            self.graph.executor.create_task(self.on_error, self.error)

    def close(self) -> None:
        for publisher in self._tapped:
            publisher.remove_tap(self._on_message)
        self._tapped = []

    def __enter__(self) -> GraphTap:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()


def graph_tap(graph) -> GraphTap:
    """Give the graph's one tap, opened at its first recording, kept while the graph lives.

    A graph that never records has none and pays nothing for it; while no bag is open the tap
    costs a counter and a few comparisons a message.
    """
    tap = getattr(graph, 'recording_tap', None)
    if tap is None:
        tap = GraphTap(graph).open()
        graph.recording_tap = tap
        graph.close_hooks.append(tap.close)
    return tap


def bag_metadata(graph, request: dict | None, placed: dict | None) -> dict:
    """custom_data of a grasp bag: all a closed-loop re-run needs, and the format.

    ``request`` and ``placed`` None: left out (a move's bag).
    """
    rerun = {'request': request, 'object': placed} if request is not None else {}
    return {'gripper_ros': {'format': BAG_FORMAT, 'namespace': graph.namespace,
                            'time_mode': graph.plant.time_mode.parameter,
                            'state_rate_hz': float(graph.plant.state_rate_hz)},
            **rerun,
            'controllers': graph.controller_settings(),
            'config': graph.config_data()}


def recorded_grasp(graph, bag_dir, width_m: float, mass_kg: float,
                   friction_coefficient: float = 0.0, stiffness_n_per_m: float = 0.0,
                   damping_n_s_per_m: float = 0.0, overwrite: bool = False,
                   wall_timeout_s: float = 600.0, width_tolerance_m: float = 0.0,
                   object_width_m: float | None = None, acceleration_mps2: float = 0.0,
                   linger_s: float = 0.5, stop_on_error: bool = False,
                   object_mass_kg: float = 0.0, **hold) -> RecordedGrasp:
    """Place the object, record every topic of the graph into ``bag_dir`` and grasp it.

    ``hold`` sets the object's hold and lift fields and a fault for the grasp (SetObject:
    ``fault``, ``fault_at_s``, ``fault_time_constant_s``), all recorded with the object. The
    bag is closed (summary, metadata.yaml) whatever happens, Ctrl-C included.
    ``stop_on_error``: a recording that fails stops the grasp at once (STOPPED: the position
    stage holds the finger where it is); else the grasp goes on unrecorded. Either way
    :attr:`RecordedGrasp.recording_error` says what failed. ``object_mass_kg`` > 0: the object's
    real mass (SetObject ``mass_kg``), not the request's.
    """
    if object_mass_kg:
        hold = {**hold, 'mass_kg': object_mass_kg}
    placed_width = graph.simulated_width_m(width_m, object_width_m)
    placed = graph.set_object(placed_width, stiffness_n_per_m, damping_n_s_per_m, **hold)
    if not placed.success:
        raise RecordingError(f'set_object: {placed.message}')
    if graph.options.time_mode == TimeMode.FAST.parameter:
        graph.wait_still()              # the placement's tick is answered before recording
    request = {'width_m': width_m, 'mass_kg': mass_kg,
               'friction_coefficient': friction_coefficient,
               'acceleration_mps2': acceleration_mps2, 'width_tolerance_m': width_tolerance_m}
    obj = {'width_m': placed_width, 'stiffness_n_per_m': stiffness_n_per_m,
           'damping_n_s_per_m': damping_n_s_per_m, 'default_friction': 0.0,
           **{k: int(v) if k == 'fault' else float(v) for k, v in hold.items()}}
    tap = graph_tap(graph)
    try:
        recorder = BagRecorder(graph.client_node, bag_dir, tap.topics, overwrite=overwrite,
                               subscribe=False, time_source=lambda: graph.sim_time_ns,
                               custom_data=bag_metadata(graph, request, obj))
    except BagRecorderError as exc:
        raise RecordingError(str(exc)) from None
    response = None
    before = graph.published_counts()
    received_before = dict(tap.received)
    fast = graph.options.time_mode == TimeMode.FAST.parameter
    if stop_on_error:
        tap.on_error = lambda message: graph.supervisor.stop_grasp(message)
    tap.start(recorder, 'now' if fast else 'next_tick')     # fast: nothing is in flight
    t0 = time.perf_counter()
    try:
        response = graph.grasp(width_m, mass_kg, friction_coefficient, acceleration_mps2,
                               wall_timeout_s=wall_timeout_s,
                               width_tolerance_m=width_tolerance_m)
        _play_out(graph, linger_s)
    finally:
        tap.on_error = None
        if fast:
            published = drain_published(graph, tap, recorder, before, received_before)
            tap.sink = None             # time stands still: the last tick is whole
        else:
            tap.stop()                  # realtime: at a tick, once the last one is whole
            published = {}              # (time runs on: no count to compare with)
        logic = graph.supervisor.logic
        final, message = logic.outcome, logic.message
        if not recorder.closed:
            try:
                if response is not None:
                    recorder.set_custom_data({
                        'outcome': Outcome(response.outcome).name,
                        'success': response.success, 'message': response.message,
                        'final_outcome': final.name, 'final_message': message,
                        'position_setpoint_m': response.position_setpoint_m,
                        'force_setpoint_n': response.force_setpoint_n})
                recorder.close()
            except Exception as exc:  # noqa: BLE001 - a writer that failed after the last tick
                tap.error = failure_message(recorder, recorder.failure or exc)
        recorded = dict(recorder.counts)
    return RecordedGrasp(response, Path(bag_dir), published, recorded,
                         time.perf_counter() - t0, final, message, tap.error, width_m=width_m,
                         mass_kg=mass_kg)


def _play_out(graph, linger_s: float) -> None:
    """After the answer: until simulated time stands still (fast), or ``linger_s`` of it."""
    if graph.options.time_mode == TimeMode.FAST.parameter:
        graph.wait_still()
        return
    until = graph.sim_time_ns + round(linger_s * 1e9)
    wait_until(lambda: graph.sim_time_ns >= until,
               timeout_s=load_bound_s(max(10.0, 10 * linger_s)))


def _published_since(graph, tap: GraphTap, before: dict) -> dict:
    return {qualified(graph.namespace, t): n - before.get(t, 0)
            for t, n in graph.published_counts().items()
            if qualified(graph.namespace, t) in tap.topics}


def drain_published(graph, tap: GraphTap, recorder: BagRecorder, before: dict,
                    received_before: dict, timeout_s: float = 60.0) -> dict:
    """Wait until the tap has seen all published since ``before``; return the counts per topic.

    Time stands still then; a tick the tap still holds for its decision is written. /tf
    follows joint_states through description_publisher: the last joint state is waited for first.
    ``timeout_s`` is for free cores (:func:`~gripper_ros.nodes.process.load_bound_s`): past it
    the recording is incomplete, and the tap's :attr:`~GraphTap.error` names what it never saw.
    """
    timeout_s = load_bound_s(timeout_s)
    description = getattr(graph, 'description', None)
    if description is not None:
        wait_until(lambda: recorder.closed or
                   description.last_state_ns == graph.plant.last_state_ns, timeout_s)
    published = _published_since(graph, tap, before)
    wait_until(lambda: recorder.closed or all(
        tap.received[t] - received_before[t] >= n for t, n in published.items()), timeout_s)
    tap.flush()
    unseen = {t: n - (tap.received[t] - received_before[t])
              for t, n in published.items() if tap.received[t] - received_before[t] < n}
    if unseen and not tap.error:
        tap.error = (f'recording incomplete: {recorder.bag_dir}: published but never seen by the '
                     f'recorder: {unseen}')
    return published


class ServeRecorder:
    """Serve mode: one bag per grasp or move, whoever requested it, under ``output_dir``.

    The tap watches the stage references: the first reference of a new grasp opens a bag
    (with the tick it decides), the tick ``linger_s`` of simulated time after the grasp's
    answer closes it, as does the first reference of another request, or simulated time
    standing still after the answer (fast mode, or paused). Each bag holds whole ticks.
    """

    def __init__(self, graph, output_dir, linger_s: float = 0.5):
        from rclpy.clock import Clock, ClockType
        self.graph = graph
        self.output_dir = Path(output_dir)
        self.linger_s = linger_s
        self.bags: list[Path] = []
        self.errors: list[str] = []
        self._grasp_id: int | None = None       # the grasp being recorded
        self._close_at_ns: int | None = None
        self._answered = False                  # the recorded request's answer was seen
        self._placements_used = 0               # the plant's SetObjects a request began after
        self.tap = graph_tap(graph)
        self.tap.on_reference = self._on_reference
        self.tap.on_tick = self._on_tick
        self.tap.on_closed = self._close_sink
        graph.close_hooks.append(self.close)
        self._timer = graph.client_node.create_timer(
            0.05, self._check, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def recording(self) -> bool:
        return self.tap.sink is not None

    def _on_reference(self, data: bytes) -> None:
        stamp_ns, grasp_id, phase, outcome = _REFERENCE_KEY.unpack_from(data)
        if grasp_id != self._grasp_id:
            self._close_bag(stamp_ns)
            self._grasp_id = grasp_id
            placements, placed = self.graph.plant.placed
            fresh = placements != self._placements_used
            self._placements_used = placements
            if phase in (Phase.POSITION, Phase.MOVING) and outcome == Outcome.UNKNOWN:
                self._open(grasp_id, 'grasp' if phase == Phase.POSITION else 'move',
                           placed if fresh else None)
        elif self.tap.sink is not None and outcome != Outcome.UNKNOWN and \
                self._close_at_ns is None:
            self._close_at_ns = stamp_ns + round(self.linger_s * 1e9)
            self._answered = True

    def _rerun_data(self, grasp_id: int, placed: dict | None) -> dict:
        """custom_data a closed-loop re-run reads: the request and the object, or why not."""
        accepted = self.graph.supervisor.accepted_grasp
        if accepted is None or accepted[0] != grasp_id:
            return {'not_rerun': f'the request of grasp {grasp_id} was not seen when its bag '
                                 'opened'}
        if placed is None:
            what = 'no object was placed (SetObject)' if not self._placements_used else \
                'it began on an object placed before an earlier request (no SetObject between)'
            return {'not_rerun': f'grasp {grasp_id}: {what}; a re-run starts from a placement'}
        return {'request': accepted[1], 'object': placed}

    def _on_tick(self, stamp_ns: int) -> None:
        if self._close_at_ns is not None and self.tap.sink is not None and \
                stamp_ns >= self._close_at_ns:
            self._close_at_ns = None
            self.tap.stop_at(stamp_ns)          # before this tick: whole ticks only

    def _open(self, grasp_id: int, kind: str, placed: dict | None) -> None:
        stamp = datetime.now().strftime('%Y%m%d_%H%M%S')
        try:
            bag_dir = unique_bag_dir(self.output_dir, f'{kind}_{stamp}_id{grasp_id}')
            custom = bag_metadata(self.graph, None, None)
            if kind == 'grasp':
                custom.update(self._rerun_data(grasp_id, placed))
            sink = BagRecorder(
                self.graph.client_node, bag_dir, self.tap.topics, subscribe=False,
                time_source=lambda: self.graph.sim_time_ns, overwrite=True,
                custom_data=custom)
        except (OSError, BagRecorderError, RecordingError) as exc:
            self._report(f'recording not started under {self.output_dir}: '
                         f'{getattr(exc, "strerror", None) or exc}')
            return
        self._close_at_ns, self._answered = None, False
        self.bags.append(bag_dir)
        self.tap.start(sink, 'last_tick')          # the tick this first decision is for

    def _check(self) -> None:
        self.tap.check_closing()
        self._report_tap_error()
        if self._answered and self.tap.sink is not None and self.graph.stands_still():
            self._close_bag()                   # no linger tick is coming

    def _report_tap_error(self) -> None:
        """Report why the tap's last bag stopped early, once."""
        if self.tap.error:
            self._report(self.tap.error)
            self.tap.error = ''

    def _report(self, message: str) -> None:
        self.errors.append(message)
        self.graph.client_node.get_logger().error(message)
        self.graph.supervisor.response_notes.append(message)

    def _close_bag(self, before_ns: int | None = None) -> None:
        """Close the bag now, or (``before_ns``) before that tick, once the last one is whole."""
        self._close_at_ns, self._answered = None, False
        if before_ns is not None and self.tap.sink is not None:
            sink = self.tap.sink
            self.tap.stop_at(before_ns)
            if self.tap.sink is sink:           # its last command may still be in flight
                return
        sink, self.tap.sink = self.tap.sink, None
        self._close_sink(sink)

    def _close_sink(self, sink) -> None:
        if sink is not None and not sink.closed:
            if sink.failure is not None:        # the writer failed after the last message
                self._report(failure_message(sink, sink.failure))
                return
            try:
                sink.close()
            except Exception as exc:  # noqa: BLE001 - reported, never raised into the graph
                self._report(failure_message(sink, sink.failure or exc))

    def close(self) -> None:
        """End recording (the graph is shutting down): a bag open now ends with whole ticks."""
        self._timer.cancel()
        self.tap.on_closed = None
        sink = self.tap.stop()                  # the executor still runs the tap here
        self._report_tap_error()
        self._close_sink(sink)
        self._close_bag()
