"""``bag_replay BAG``: publish a recorded bag again (what ``ros2 bag play`` does; no rosbag2 here).

Messages go out as recorded bytes (``Publisher.publish(bytes)``), paced by their recorded
``log_time`` (simulated time in our bags) divided by ``--rate``. ``--clock`` publishes /clock
from the bag's time so nodes with ``use_sim_time`` follow the replay.

It delivers or says so: every publisher (/clock too) waits for its subscribers
(``--wait-for-subscribers``), keeps every message no reliable reader has acknowledged yet, and
at the end waits until every reliable reader has acknowledged everything
(``--wait-for-all-acked``, rosbag2's option); what was not acknowledged is counted in one line
(exit :data:`~gripper_ros.bags.reader.EXIT_UNDELIVERED`).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import math
import sys
import threading
import time
from typing import Callable, Sequence

from gripper_ros.bags.reader import (
    Bag,
    BagError,
    EXIT_ERROR,
    EXIT_TRUNCATED,
    EXIT_UNDELIVERED,
    MissingTopicsError,
    quiet_on_closed_pipe,
    RawMessage,
    read_bag,
)
from gripper_ros.bags.schema import import_message_class
from gripper_ros.wire import (DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_POSITION_CONTROLLER,
                              ForceControllerKind, GRAPH_QOS_DEPTH, PositionControllerKind,
                              TOPIC_CLOCK)

PROG = 'bag_replay'
_PROGRESS_PERIOD_S = 0.1
ACK_TIMEOUT_MS = 30_000
"""``--wait-for-all-acked`` when not given: a reliable reader acknowledges at the writer's next
heartbeat (Fast DDS: every 3 s) once its process runs; a starved one gets ten of them."""
_ACK_PROBE_PERIOD_S = 0.1
"""How often a replay asks its publishers whether everything so far is acknowledged."""
_ACK_SLICE_S = 0.1
"""A wait for acknowledgements is cut into slices this long, so that a stop is seen between."""
_WAIT_NOTE_S = 1.0
"""--wait-for-subscribers: after this long unmatched it says which topics it waits on."""


@dataclass
class ReplayOptions:
    """What to replay and how (mirrors ``ros2 bag play`` options)."""

    rate: float = 1.0
    loop: bool = False
    start_offset_s: float = 0.0
    topics: list[str] | None = None               # None = all topics of the bag
    remap: dict[str, str] = field(default_factory=dict)
    clock: bool = False
    clock_hz: float = 0.0                          # 0: publish /clock at each new bag time only
    delay_s: float = 0.0
    wait_for_subscribers: int = 0
    wait_timeout_s: float | None = None            # None: until matched (or stopped)
    wait_for_all_acked_ms: int = ACK_TIMEOUT_MS    # as rosbag2's: 0 forever, negative no wait
    progress: bool = True


RATE_RANGE = (1e-3, 1e3)
"""--rate: slower than a thousandth or faster than a thousand times is no replay."""
MAX_OFFSET_S = 2 ** 63 * 1e-9
"""--start-offset: a bag's stamps are int64 nanoseconds, so no bag is longer."""
MAX_DELAY_S = 86400.0
"""--delay: at most a day."""
MAX_ACK_TIMEOUT_MS = 86_400_000
"""--wait-for-all-acked: at most a day (0 waits for ever)."""


def parse_remap(items: Sequence[str]) -> dict[str, str]:
    """['old:=new', ...] -> {old: new}; ValueError with a one-line reason."""
    out = {}
    for item in items:
        old, sep, new = item.partition(':=')
        if not sep or not old or not new:
            raise ValueError(f'bad --remap {item!r} (expected old:=new)')
        from rclpy.exceptions import InvalidTopicNameException
        from rclpy.expand_topic_name import expand_topic_name
        from rclpy.validate_full_topic_name import validate_full_topic_name
        from rclpy.validate_topic_name import validate_topic_name
        try:                                 # as the publisher will: expanded under '/'
            validate_topic_name(new)
            validate_full_topic_name(expand_topic_name(new, PROG, '/'))
        except InvalidTopicNameException as exc:
            reason = str(exc).splitlines()[0]
            raise ValueError(f'bad --remap {item!r}: {new!r} is not a topic name '
                             f'({reason})') from None
        out[old] = new
    return out


def select_messages(bag: Bag, options: ReplayOptions) -> list[RawMessage]:
    """Select the messages to replay, in recorded order; BagError for unknown topics."""
    if options.topics:
        missing = [t for t in options.topics if t not in bag.topics]
        if missing:
            raise MissingTopicsError(f'{bag.path}: topics not in bag: {", ".join(missing)} '
                                     f'(has: {", ".join(sorted(bag.topics))})')
        wanted = set(options.topics)
    else:
        wanted = set(bag.topics)
    if options.clock:
        wanted.discard(TOPIC_CLOCK)                # one time source: ours
    unknown = [old for old in options.remap if old not in bag.topics]
    if unknown:
        raise MissingTopicsError(f'{bag.path}: --remap of topics not in bag: {", ".join(unknown)}')
    start_ns = bag.start_ns + int(round(options.start_offset_s * 1e9))
    selected = [m for m in bag.messages if m.topic in wanted and m.log_time_ns >= start_ns]
    if not selected:
        raise BagError(f'{bag.path}: nothing to replay (check --topics and --start-offset)')
    return selected


def _qos_for(bag: Bag, topic: str, count: int = 0):
    """Offer the recorded publishers' reliability/durability, keeping at least ``count``.

    The depth is the recorded one, at least :data:`GRAPH_QOS_DEPTH` and ``count`` (the
    topic's messages in one pass): a reliable keep_last writer drops its oldest sample when
    its history is full, acknowledged or not, so the history holds a whole pass.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    profiles = bag.topics[topic].offered_qos_profiles or [{}]
    first = profiles[0] if isinstance(profiles[0], dict) else {}
    reliability = (ReliabilityPolicy.BEST_EFFORT if first.get('reliability') == 'best_effort'
                   else ReliabilityPolicy.RELIABLE)
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if first.get('durability') == 'transient_local'
                  else DurabilityPolicy.VOLATILE)
    depth = int(first.get('depth') or 0) or GRAPH_QOS_DEPTH
    return QoSProfile(history=HistoryPolicy.KEEP_LAST,
                      depth=max(depth, GRAPH_QOS_DEPTH, count),
                      reliability=reliability, durability=durability)


def clock_qos(count: int = 0):
    """/clock as the graph's plant publishes it (reliable, volatile), keeping ``count``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(GRAPH_QOS_DEPTH, count),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


class Delivery:
    """One publisher of a replay: what it sent that no reliable reader has confirmed yet.

    ``unconfirmed`` counts the messages published since the publisher last reported every one
    acknowledged by every reliable reader (``Publisher.wait_for_all_acked``): an upper bound on
    those a reader may still lack. ``undelivered`` counts those given up on.
    """

    def __init__(self, topic: str, publisher, depth: int):
        self.topic, self.publisher, self.depth = topic, publisher, depth
        self.unconfirmed = 0
        self.undelivered = 0

    def publish(self, data) -> None:
        self.publisher.publish(data)
        self.unconfirmed += 1

    def confirmed(self, timeout_s: float = 0.0) -> bool:
        """Whether every reliable reader acknowledged all, waiting up to ``timeout_s``."""
        if self.unconfirmed == 0:
            return True
        from rclpy.duration import Duration
        try:
            done = self.publisher.wait_for_all_acked(Duration(nanoseconds=int(timeout_s * 1e9)))
        except Exception:  # noqa: BLE001 - a context already shut down confirms nothing
            return False
        if done:
            self.unconfirmed = 0
        return done

    def give_up(self) -> None:
        self.undelivered += self.unconfirmed
        self.unconfirmed = 0


def confirm(deliveries: Sequence[Delivery], timeout_ms: int,
            stop: threading.Event | None = None) -> list[Delivery]:
    """Wait until every reliable reader has acknowledged everything; return those unconfirmed.

    ``timeout_ms`` as rosbag2's ``--wait-for-all-acked``: 0 waits for ever, a negative value not
    at all. The wait is shared by all publishers and ends early when ``stop`` is set.
    """
    pending = [d for d in deliveries if not d.confirmed()]
    if timeout_ms < 0:
        return pending
    deadline = math.inf if timeout_ms == 0 else time.monotonic() + timeout_ms * 1e-3
    while pending and not (stop is not None and stop.is_set()):
        left = deadline - time.monotonic()
        if left <= 0:
            break
        pending = [d for d in pending if not d.confirmed(min(_ACK_SLICE_S, left))]
    return pending


def undelivered_line(counts: dict[str, int], timeout_ms: int) -> str:
    """Say in one line how many messages on which topics may not have been delivered."""
    within = f'within {timeout_ms} ms' if timeout_ms > 0 else \
        'before the stop' if timeout_ms == 0 else 'at the end (no wait asked)'
    topics = ', '.join(f'{n} on {t}' for t, n in sorted(counts.items()))
    return (f'{sum(counts.values())} messages may not have been delivered ({topics}): not '
            f'acknowledged by every reliable subscriber {within}')


class BagPlayer:
    """Publishes a bag's messages on a caller's node with recorded timing, and delivers them.

    Every publisher keeps what its reliable readers have not acknowledged: a pass of the bag in
    its history, and before it would drop an unacknowledged message (a second pass, a reader
    far behind) it waits for the acknowledgements (``wait_for_all_acked_ms``), as a keep_all
    writer does. :attr:`undelivered` counts, per topic, what was not acknowledged in time.
    """

    def __init__(self, node, bag: Bag, options: ReplayOptions | None = None):
        self._node = node
        self._bag = bag
        self._options = options or ReplayOptions()
        if not (self._options.rate > 0 and math.isfinite(self._options.rate)):
            raise ValueError('rate must be a positive number')
        self._messages = select_messages(bag, self._options)
        classes = resolve_classes(bag, {m.topic for m in self._messages})
        per_topic = dict.fromkeys(classes, 0)
        for m in self._messages:
            per_topic[m.topic] += 1
        self._deliveries: dict[str, Delivery] = {}
        for topic, cls in classes.items():
            qos = _qos_for(bag, topic, per_topic[topic])
            name = self._options.remap.get(topic, topic)
            self._deliveries[topic] = Delivery(name, node.create_publisher(cls, name, qos),
                                               qos.depth)
        self._clock: Delivery | None = None
        if self._options.clock:
            from rosgraph_msgs.msg import Clock
            qos = clock_qos(self._clock_count())
            self._clock = Delivery(TOPIC_CLOCK, node.create_publisher(Clock, TOPIC_CLOCK, qos),
                                   qos.depth)
        self.published = 0

    @property
    def messages(self) -> list[RawMessage]:
        return list(self._messages)

    @property
    def deliveries(self) -> list[Delivery]:
        """Every publisher the replay uses, /clock included."""
        return list(self._deliveries.values()) + ([self._clock] if self._clock else [])

    @property
    def undelivered(self) -> dict[str, int]:
        """Messages per topic (as published) not acknowledged in time: none when delivered."""
        return {d.topic: d.undelivered for d in self.deliveries if d.undelivered}

    def _clock_count(self) -> int:
        """/clock messages in one pass: one per bag time, and those ``clock_hz`` adds."""
        opts = self._options
        stamps = len({m.log_time_ns for m in self._messages})
        span_s = (self._messages[-1].log_time_ns - self._messages[0].log_time_ns) * 1e-9
        return stamps + (math.ceil(span_s / opts.rate * opts.clock_hz) if opts.clock_hz else 0)

    def unmatched(self, count: int) -> list[str]:
        """Return the topics (/clock included) with fewer than ``count`` matched subscriptions."""
        return [d.topic for d in self.deliveries
                if d.publisher.get_subscription_count() < count]

    def wait_for_subscribers(self, count: int, timeout_s: float | None = None,
                             stop: threading.Event | None = None,
                             note: Callable[[str], None] | None = None) -> bool:
        """Until every publisher, /clock's too, has ``count`` matched subscriptions.

        A volatile subscription gets only what is published after it matched: waiting here
        loses no first message. ``timeout_s`` None waits until then (or ``stop``); ``note``
        hears once which topics it still waits on.
        """
        start = time.monotonic()
        noted = False
        while not (stop is not None and stop.is_set()):
            missing = self.unmatched(count)
            if not missing:
                return True
            waited = time.monotonic() - start
            if timeout_s is not None and waited >= timeout_s:
                return False
            if note is not None and not noted and waited >= _WAIT_NOTE_S:
                noted = True
                note(f'waiting for {count} subscriber(s) on {", ".join(missing)}')
            time.sleep(0.01)
        return False

    def _publish_clock(self, t_ns: int, stop: threading.Event) -> None:
        from rosgraph_msgs.msg import Clock
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self._send(self._clock, msg, stop)

    def _send(self, delivery: Delivery, data, stop: threading.Event) -> None:
        """Publish, first waiting for acknowledgements where the history would drop one."""
        if delivery.unconfirmed >= delivery.depth and \
                confirm([delivery], self._options.wait_for_all_acked_ms, stop):
            delivery.give_up()                  # the oldest is dropped now: counted
        delivery.publish(data)

    def play(self, stop: threading.Event | None = None,
             progress: Callable[[str], None] | None = None) -> int:
        """Publish (looping if asked) until done or ``stop`` is set; the count published.

        At the end (not after a stop) it waits for every reliable reader's acknowledgements
        (``wait_for_all_acked_ms``); what is still unacknowledged then is in :attr:`undelivered`.
        """
        opts = self._options
        stop = stop or threading.Event()
        if opts.wait_for_subscribers > 0:
            if not self.wait_for_subscribers(opts.wait_for_subscribers, opts.wait_timeout_s,
                                             stop, progress):
                if stop.is_set():
                    return self.published
                print(f'{PROG}: warning: {", ".join(self.unmatched(opts.wait_for_subscribers))}'
                      f' still without {opts.wait_for_subscribers} subscriber(s) after '
                      f'{opts.wait_timeout_s} s; playing anyway', file=sys.stderr)
        if opts.delay_s > 0 and stop.wait(opts.delay_s):
            return self.published
        first_ns, last_ns = self._messages[0].log_time_ns, self._messages[-1].log_time_ns
        span_s = (last_ns - first_ns) * 1e-9
        loop_index = 0
        last_probe = time.monotonic()
        while not stop.is_set():
            wall0 = time.monotonic()
            last_clock_ns, last_progress = None, 0.0
            for i, msg in enumerate(self._messages):
                target = wall0 + (msg.log_time_ns - first_ns) * 1e-9 / opts.rate
                while True:
                    now = time.monotonic()
                    if target <= now or stop.is_set():
                        break
                    step = target - now
                    if self._clock is not None and opts.clock_hz > 0:
                        step = min(step, 1.0 / opts.clock_hz)
                        bag_ns = first_ns + int((now - wall0) * opts.rate * 1e9)
                        self._publish_clock(bag_ns, stop)
                    stop.wait(step)
                if stop.is_set():
                    break
                if self._clock is not None and msg.log_time_ns != last_clock_ns:
                    self._publish_clock(msg.log_time_ns, stop)
                    last_clock_ns = msg.log_time_ns
                self._send(self._deliveries[msg.topic], msg.data, stop)
                self.published += 1
                now = time.monotonic()
                if now - last_probe >= _ACK_PROBE_PERIOD_S:
                    last_probe = now
                    for delivery in self.deliveries:
                        delivery.confirmed()
                if progress is not None and (now - last_progress >= _PROGRESS_PERIOD_S
                                             or i + 1 == len(self._messages)):
                    last_progress = now
                    progress(f'{(msg.log_time_ns - first_ns) * 1e-9:8.3f} / {span_s:.3f} s  '
                             f'{i + 1}/{len(self._messages)} msgs'
                             + (f'  loop {loop_index + 1}' if opts.loop else ''))
            loop_index += 1
            if not opts.loop:
                break
        if not stop.is_set():
            for delivery in confirm(self.deliveries, opts.wait_for_all_acked_ms, stop):
                delivery.give_up()
        return self.published


def resolve_classes(bag: Bag, topics: set[str]) -> dict[str, type]:
    """Message class per topic (importlib); LookupError names the missing package."""
    return {topic: import_message_class(bag.topics[topic].msgtype) for topic in sorted(topics)}


def resimulate(bag: Bag | str, config_path: str | None = None, **kwargs):
    """Re-simulate the bag open loop (``--resimulate [CONFIG.yaml]``).

    Feed the bag's recorded measurements through the controllers built from CONFIG (None/'' =
    the installed default), tick by tick as the controller nodes answer them, and compare with
    the recorded commands (open loop: the plant is not re-run). Returns a
    :class:`gripper_ros.bags.resimulate.ResimulationReport`.

    Raises BagError (one line) for an unusable bag, ConfigError (one line) for an unusable
    configuration. ``kwargs``: ``position_controller``, ``force_controller``,
    ``approach_force_margin``, ``keep_ticks`` (see
    :func:`gripper_ros.bags.resimulate.resimulate_bag`).
    """
    from gripper_ros.bags.resimulate import resimulate_bag
    return resimulate_bag(bag, config_path, **kwargs)


# --- CLI --------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description='Replay a rosbag2 MCAP bag: raw '
                                     'messages with recorded timing (like ros2 bag play).')
    parser.add_argument('bag', metavar='BAG', help='bag folder or .mcap file')
    parser.add_argument('-r', '--rate', type=float, default=1.0,
                        help='playback rate factor (default 1.0)')
    parser.add_argument('-l', '--loop', action='store_true', help='play again and again')
    parser.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                        help='start this many seconds after the bag start')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC', help='only these topics')
    parser.add_argument('--remap', nargs='+', default=[], metavar='OLD:=NEW',
                        help='publish topic OLD as NEW')
    parser.add_argument('--clock', nargs='?', type=float, const=0.0, default=None, metavar='HZ',
                        help='publish /clock from bag time (at each new time; or also at HZ)')
    parser.add_argument('-d', '--delay', type=float, default=0.0, metavar='S',
                        help='wait this long after creating publishers')
    parser.add_argument('--wait-for-subscribers', type=int, default=0, metavar='N',
                        help='first wait until every topic (/clock too) has N subscribers')
    parser.add_argument('--wait-for-all-acked', type=int, default=ACK_TIMEOUT_MS,
                        metavar='TIMEOUT',
                        help='at the end, wait up to TIMEOUT ms until every reliable subscriber '
                             'has acknowledged every message (0 = for ever; default '
                             f'{ACK_TIMEOUT_MS}); what is not: one line, exit '
                             f'{EXIT_UNDELIVERED}')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress line')
    resim = parser.add_argument_group(
        're-simulation (open loop; nothing is published)',
        'Feed the recorded measurements through the controllers of CONFIG.yaml tick by tick and '
        'compare their commands with the recorded ones (the plant is not re-run).')
    resim.add_argument('--resimulate', nargs='?', const='', default=None, metavar='CONFIG.yaml',
                       help='re-simulate with this config (no value: the installed default)')
    resim.add_argument('--position-controller', default=None,
                       choices=[k.value for k in PositionControllerKind],
                       help='position controller kind (default: as recorded in the bag, '
                            'else the node default mpc_pd)')
    resim.add_argument('--force-controller', default=None,
                       choices=[k.value for k in ForceControllerKind],
                       help='force controller kind (default: as recorded, else pi: bags '
                            'from before the kind was recorded used pi)')
    resim.add_argument('--approach-force-margin', type=float, default=None, metavar='M',
                       help='force controller cap before contact (default: as recorded, '
                            'else 1.0; 0 = off)')
    resim.add_argument('--json', action='store_true', help='print the comparison as JSON')
    loop = parser.add_argument_group(
        'closed-loop re-run (what-if; with --resimulate --closed-loop; nothing is published)',
        "Grasp again without ROS (the graph's plant, supervisor and stages, tick for tick) with "
        'the recorded request, object, controllers and configuration, changed as asked, and '
        'show the figures recorded, re-run and their difference. Bad input: one line, exit 2.')
    loop.add_argument('--closed-loop', action='store_true',
                      help='re-run the grasp in closed loop (the plant answers new commands)')
    loop.add_argument('--config', metavar='FILE', default=None,
                      help='start from this config file instead of the recorded configuration')
    loop.add_argument('--set', action='append', default=[], metavar='SECTION.KEY=VALUE',
                      help='change one config value (repeatable), e.g. '
                           'position_control.mpc_pd.kc=900')
    loop.add_argument('--sweep', default=None, metavar='SECTION.KEY=V1,V2,...',
                      help='re-run once per value and print one row per value')
    loop.add_argument('--jobs', type=int, default=None, metavar='N',
                      help="a sweep's local worker processes (default 1: starting the Dask "
                           'workers costs seconds, more than a few re-runs)')
    loop.add_argument('--scheduler', default=None, metavar='tcp://HOST:8786',
                      help="run a sweep's re-runs on the Dask cluster of this scheduler")
    loop.add_argument('--plot', default=None, metavar='FILE.png',
                      help='draw recorded and re-run position, force, motor and FSR voltage')
    return parser


def _fail(message: str, code: int = EXIT_ERROR) -> None:
    print(f'{PROG}: error: {message}', file=sys.stderr)
    sys.exit(code)


def options_from_args(args: argparse.Namespace) -> ReplayOptions:
    """Validate the replay options; ValueError with a one-line reason."""
    for name, value in (('--rate', args.rate), ('--start-offset', args.start_offset),
                        ('--delay', args.delay)):
        if not math.isfinite(value):
            raise ValueError(f'{name} must be finite')
    if not RATE_RANGE[0] <= args.rate <= RATE_RANGE[1]:
        raise ValueError(f'--rate must be in [{RATE_RANGE[0]:g}, {RATE_RANGE[1]:g}], '
                         f'got {args.rate:g}')
    if args.start_offset < 0 or args.delay < 0:
        raise ValueError('--start-offset and --delay must be >= 0')
    if args.start_offset > MAX_OFFSET_S:
        raise ValueError(f'--start-offset must be <= {MAX_OFFSET_S:g} s (the span of a '
                         f"bag's int64 nanosecond stamps), got {args.start_offset:g}")
    if args.delay > MAX_DELAY_S:
        raise ValueError(f'--delay must be <= {MAX_DELAY_S:g} s, got {args.delay:g}')
    if args.clock is not None and not (math.isfinite(args.clock) and args.clock >= 0):
        raise ValueError('--clock HZ must be >= 0')
    if args.wait_for_subscribers < 0:
        raise ValueError('--wait-for-subscribers must be >= 0')
    if not 0 <= args.wait_for_all_acked <= MAX_ACK_TIMEOUT_MS:
        raise ValueError(f'--wait-for-all-acked must be in [0, {MAX_ACK_TIMEOUT_MS}] ms '
                         f'(0 = for ever), got {args.wait_for_all_acked}')
    return ReplayOptions(rate=args.rate, loop=args.loop, start_offset_s=args.start_offset,
                         topics=args.topics, remap=parse_remap(args.remap),
                         clock=args.clock is not None, clock_hz=args.clock or 0.0,
                         delay_s=args.delay, wait_for_subscribers=args.wait_for_subscribers,
                         wait_for_all_acked_ms=args.wait_for_all_acked, progress=not args.quiet)


def _run_resimulation(args: argparse.Namespace) -> int:
    """Exit 0 when it ran (identical or not); 1 bad bag/options, 2 bad config, 3 truncated bag."""
    from gripper_ros.bags.resimulate import load_resim_config, to_json, to_table
    from gripper_ros.core.config import ConfigError
    try:
        config = load_resim_config(args.resimulate)
        bag = read_bag(args.bag)
        # The recorder stores the graph's controller settings; explicit options override them.
        recorded = bag.custom_data_parsed().get('controllers') or {}
        if not isinstance(recorded, dict):
            recorded = {}
        position = args.position_controller or recorded.get(
            'position_controller', DEFAULT_POSITION_CONTROLLER.value)
        # bags from before the kind was recorded ran the PI
        force = args.force_controller or recorded.get('force_controller',
                                                      ForceControllerKind.PI.value)
        margin = args.approach_force_margin
        if margin is None:
            margin = float(recorded.get('approach_force_margin', DEFAULT_APPROACH_FORCE_MARGIN))
        if not (math.isfinite(margin) and margin >= 0.0):
            _fail('--approach-force-margin must be finite and >= 0')
        report = resimulate(bag, config, position_controller=position, force_controller=force,
                            approach_force_margin=margin)
    except ConfigError as exc:
        _fail(str(exc), code=2)
    except BagError as exc:
        _fail(str(exc))
    print(to_json(report) if args.json else to_table(report))
    if bag.truncated:
        print(f'{PROG}: warning: {bag.truncation_note()}', file=sys.stderr)
        sys.exit(EXIT_TRUNCATED)
    return 0


def _run_closed_loop(args: argparse.Namespace) -> int:
    """Re-run the bag's grasp in closed loop and print the comparison.

    Exit 0 when it ran; 2 on bad input (the bag, an option, a key or value; one line on
    stderr); 3 when the bag was truncated (the recorded figures cover the part recovered).
    """
    from gripper_ros.bags import rerun, rerun_report
    from gripper_ros.core.config import ConfigError
    from gripper_ros.core.runtime.engine import EngineError, options_problem
    from gripper_ros.progress import progress_bar
    if args.resimulate and args.config and args.resimulate != args.config:
        _fail('give the configuration once: --resimulate CONFIG.yaml or --config FILE', code=2)
    if args.plot and not args.plot.lower().endswith('.png'):
        _fail(f'--plot needs a .png file name, got {args.plot!r}', code=2)
    margin = args.approach_force_margin
    if margin is not None and not (math.isfinite(margin) and margin >= 0.0):
        _fail('--approach-force-margin must be finite and >= 0', code=2)
    try:
        settings = [rerun.parse_assignment(item) for item in args.set]
        sweep = rerun.parse_sweep(args.sweep) if args.sweep else None
        changes = rerun.Changes(args.config or args.resimulate or None, settings,
                                args.position_controller, args.force_controller, margin)
        if options_problem(args.jobs, args.scheduler):
            _fail(options_problem(args.jobs, args.scheduler), code=2)
        with progress_bar(len(sweep[1]) if sweep else 1, PROG, 're-run',
                          quiet=args.quiet or sweep is None) as bar:
            result = rerun.whatif(args.bag, changes, sweep, args.jobs or 1,
                                  scheduler=args.scheduler, progress=bar.update)
    except (ConfigError, BagError, EngineError, ValueError) as exc:
        _fail(str(exc), code=2)
    if sweep is None:
        print(rerun_report.to_json(result) if args.json else rerun_report.to_table(result))
    else:
        print(rerun_report.sweep_json(result) if args.json else rerun_report.sweep_table(result))
    if args.plot:
        try:
            rerun_report.plot(result, args.plot)
        except OSError as exc:
            _fail(f'cannot write {args.plot}: {exc.strerror or exc}', code=2)
        print(f'figure: {args.plot}', file=sys.stderr if args.json else sys.stdout)
    if result.record.truncated:
        series = result.record.series
        print(f'{PROG}: warning: {series.path}: truncated ({series.damage}); the recorded '
              f'figures cover the part recovered', file=sys.stderr)
        sys.exit(EXIT_TRUNCATED)
    return 0


CLOSED_LOOP_OPTIONS = ('config', 'sweep', 'plot', 'jobs', 'scheduler')


@quiet_on_closed_pipe
def main(argv: Sequence[str] | None = None) -> int:
    """Replay a bag, or re-simulate it (open or closed loop).

    Exit 0; 1 on bad input (one line on stderr); 3 when the bag was truncated (what was
    recovered is replayed); 4 when some messages were not acknowledged by every reliable
    subscriber in time (one line: how many on which topics; before 3). ``--resimulate``: see
    :func:`_run_resimulation`;
    ``--resimulate --closed-loop``: see :func:`_run_closed_loop`.
    """
    args = build_parser().parse_args(argv)
    if args.closed_loop:
        return _run_closed_loop(args)
    given = [f'--{name}' for name in CLOSED_LOOP_OPTIONS if getattr(args, name) is not None]
    if args.set:
        given.append('--set')
    if given:
        _fail(f'{", ".join(given)} only apply to --resimulate --closed-loop')
    if args.resimulate is not None:
        return _run_resimulation(args)
    if args.json:
        _fail('--json only applies to --resimulate')
    try:
        options = options_from_args(args)
        bag = read_bag(args.bag)
        messages = select_messages(bag, options)
        resolve_classes(bag, {m.topic for m in messages})
    except (BagError, ValueError, LookupError) as exc:
        _fail(str(exc))

    import rclpy
    from rclpy.executors import ExternalShutdownException

    def show(line: str) -> None:
        sys.stderr.write(f'\r[{PROG}] {line}\033[K')
        sys.stderr.flush()

    rclpy.init()
    node = player = None
    try:
        node = rclpy.create_node('bag_replay')
        player = BagPlayer(node, bag, options)
        player.play(progress=show if options.progress else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if options.progress:
            sys.stderr.write('\n')
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    code = 0
    if bag.truncated:
        print(f'{PROG}: warning: {bag.truncation_note()}', file=sys.stderr)
        code = EXIT_TRUNCATED
    if player is not None and player.undelivered:
        line = undelivered_line(player.undelivered, options.wait_for_all_acked_ms)
        print(f'{PROG}: error: {line}', file=sys.stderr)
        code = EXIT_UNDELIVERED
    if code:
        sys.exit(code)
    return 0


if __name__ == '__main__':
    sys.exit(main())
