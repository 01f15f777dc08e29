"""``bag_replay BAG``: publish a recorded bag again (what ``ros2 bag play`` does; no rosbag2 here).

Messages go out as recorded bytes (``Publisher.publish(bytes)``), paced by their recorded
``log_time`` (simulated time in our bags) divided by ``--rate``. ``--clock`` publishes /clock
from the bag's time so nodes with ``use_sim_time`` follow the replay.
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
    MissingTopicsError,
    quiet_on_closed_pipe,
    RawMessage,
    read_bag,
)
from gripper_ros.bags.schema import import_message_class
from gripper_ros.core.control.factories import ForceControllerKind, PositionControllerKind
from gripper_ros.core.control.stages import (DEFAULT_APPROACH_FORCE_MARGIN,
                                             DEFAULT_POSITION_CONTROLLER)
from gripper_ros.wire import GRAPH_QOS_DEPTH, TOPIC_CLOCK

PROG = 'bag_replay'
_PROGRESS_PERIOD_S = 0.1


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
    wait_timeout_s: float = 5.0
    progress: bool = True


RATE_RANGE = (1e-3, 1e3)
"""--rate: slower than a thousandth or faster than a thousand times is no replay."""
MAX_OFFSET_S = 2 ** 63 * 1e-9
"""--start-offset: a bag's stamps are int64 nanoseconds, so no bag is longer."""
MAX_DELAY_S = 86400.0
"""--delay: at most a day."""


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


def _qos_for(bag: Bag, topic: str):
    """Offer the recorded publishers' reliability/durability (depth from the bag, or 1000)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    profiles = bag.topics[topic].offered_qos_profiles or [{}]
    first = profiles[0] if isinstance(profiles[0], dict) else {}
    reliability = (ReliabilityPolicy.BEST_EFFORT if first.get('reliability') == 'best_effort'
                   else ReliabilityPolicy.RELIABLE)
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if first.get('durability') == 'transient_local'
                  else DurabilityPolicy.VOLATILE)
    depth = int(first.get('depth') or 0) or GRAPH_QOS_DEPTH
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(depth, GRAPH_QOS_DEPTH),
                      reliability=reliability, durability=durability)


class BagPlayer:
    """Publishes a bag's messages on a caller's node with recorded timing."""

    def __init__(self, node, bag: Bag, options: ReplayOptions | None = None):
        self._node = node
        self._bag = bag
        self._options = options or ReplayOptions()
        if not (self._options.rate > 0 and math.isfinite(self._options.rate)):
            raise ValueError('rate must be a positive number')
        self._messages = select_messages(bag, self._options)
        classes = resolve_classes(bag, {m.topic for m in self._messages})
        self._publishers = {
            topic: node.create_publisher(cls, self._options.remap.get(topic, topic),
                                         _qos_for(bag, topic))
            for topic, cls in classes.items()}
        self._clock_pub = None
        if self._options.clock:
            from rosgraph_msgs.msg import Clock
            self._clock_pub = node.create_publisher(Clock, TOPIC_CLOCK, 10)
        self.published = 0

    @property
    def messages(self) -> list[RawMessage]:
        return list(self._messages)

    def wait_for_subscribers(self, count: int, timeout_s: float) -> bool:
        """Until every publisher has ``count`` matched subscriptions (no lost first messages)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() >= count for p in self._publishers.values()):
                return True
            time.sleep(0.01)
        return False

    def _publish_clock(self, t_ns: int) -> None:
        from rosgraph_msgs.msg import Clock
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self._clock_pub.publish(msg)

    def play(self, stop: threading.Event | None = None,
             progress: Callable[[str], None] | None = None) -> int:
        """Publish (looping if asked) until done or ``stop`` is set; the count published."""
        opts = self._options
        stop = stop or threading.Event()
        if opts.wait_for_subscribers > 0:
            if not self.wait_for_subscribers(opts.wait_for_subscribers, opts.wait_timeout_s):
                print(f'{PROG}: warning: not all topics have {opts.wait_for_subscribers} '
                      f'subscriber(s) after {opts.wait_timeout_s} s; playing anyway',
                      file=sys.stderr)
        if opts.delay_s > 0 and stop.wait(opts.delay_s):
            return self.published
        first_ns, last_ns = self._messages[0].log_time_ns, self._messages[-1].log_time_ns
        span_s = (last_ns - first_ns) * 1e-9
        loop_index = 0
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
                    if self._clock_pub is not None and opts.clock_hz > 0:
                        step = min(step, 1.0 / opts.clock_hz)
                        bag_ns = first_ns + int((now - wall0) * opts.rate * 1e9)
                        self._publish_clock(bag_ns)
                    stop.wait(step)
                if stop.is_set():
                    break
                if self._clock_pub is not None and msg.log_time_ns != last_clock_ns:
                    self._publish_clock(msg.log_time_ns)
                    last_clock_ns = msg.log_time_ns
                self._publishers[msg.topic].publish(msg.data)
                self.published += 1
                now = time.monotonic()
                if progress is not None and (now - last_progress >= _PROGRESS_PERIOD_S
                                             or i + 1 == len(self._messages)):
                    last_progress = now
                    progress(f'{(msg.log_time_ns - first_ns) * 1e-9:8.3f} / {span_s:.3f} s  '
                             f'{i + 1}/{len(self._messages)} msgs'
                             + (f'  loop {loop_index + 1}' if opts.loop else ''))
            loop_index += 1
            if not opts.loop:
                break
        self.wait_for_acks(2.0)
        return self.published

    def wait_for_acks(self, timeout_s: float) -> bool:
        """Reliable readers acknowledged everything (so exiting right after loses nothing)."""
        from rclpy.duration import Duration
        ok = True
        for pub in list(self._publishers.values()) + [p for p in [self._clock_pub] if p]:
            try:
                ok = pub.wait_for_all_acked(Duration(seconds=timeout_s)) and ok
            except Exception:  # noqa: BLE001 - best effort publishers / shutdown
                ok = False
        return ok


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
                        help='first wait until every topic has N subscribers (max 5 s)')
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
    return ReplayOptions(rate=args.rate, loop=args.loop, start_offset_s=args.start_offset,
                         topics=args.topics, remap=parse_remap(args.remap),
                         clock=args.clock is not None, clock_hz=args.clock or 0.0,
                         delay_s=args.delay, wait_for_subscribers=args.wait_for_subscribers,
                         progress=not args.quiet)


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
    recovered is replayed). ``--resimulate``: see :func:`_run_resimulation`;
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
    node = None
    try:
        node = rclpy.create_node('bag_replay')
        player = BagPlayer(node, bag, options)
        player.play(progress=show if options.progress else None)
        if options.progress:
            sys.stderr.write('\n')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if bag.truncated:
        print(f'{PROG}: warning: {bag.truncation_note()}', file=sys.stderr)
        sys.exit(EXIT_TRUNCATED)
    return 0


if __name__ == '__main__':
    sys.exit(main())
