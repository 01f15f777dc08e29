"""What every node shares: QoS, executors, time stamps, the config, ``main()``, service tools."""
from __future__ import annotations

import atexit
import enum
import gc
import signal
import sys
import time
from typing import Callable

from builtin_interfaces.msg import Time
from gripper_ros.core.config import ConfigError, GripperConfig, load_config
from gripper_ros.wire import DEFAULT_NAMESPACE
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Lockstep keeps at most a few messages in flight; the depth is there so that a slow recorder
# callback never loses one (a reliable keep_last writer drops what its history cannot hold).
GRAPH_QOS_DEPTH = 1000
GRAPH_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=GRAPH_QOS_DEPTH,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
"""Every lockstep and state topic: reliable, so that neither the loop nor a recorder loses one."""

LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

# Services: rclpy's default keeps only 10 requests (and 10 responses at a client); a burst of
# grasp requests from many clients must be answered (refused as busy), not dropped.
SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=GRAPH_QOS_DEPTH,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)

EXIT_BAD_START = 2
"""Exit status of a node or tool that refused to start (one line on stderr says why)."""


class StartupError(RuntimeError):
    """A node cannot start (its names are taken, a bad parameter); the message is one line."""


class ExecutorKind(enum.Enum):
    EVENTS = 'events'      # rclpy.experimental.EventsExecutor: ~10x faster here
    SINGLE = 'single'      # rclpy.executors.SingleThreadedExecutor


def make_executor(kind: ExecutorKind, context=None):
    if kind is ExecutorKind.EVENTS:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor(context=context)


SPIN_SLICE_S = 0.1
"""Longest a spinning main thread stays inside the executor before it looks at its stop flag."""


def spin_until_stopped(executor, stop, stop_signals: StopSignals | None = None) -> None:
    """Spin ``executor`` until the ``stop`` future completes (set it from any thread).

    rclpy 7.1.6's EventsExecutor busy-loops and never fires timers in ``spin()`` without a
    timeout; ``spin_until_future_complete`` with a finite timeout works on both executors.
    With ``stop_signals`` (the main thread) it spins in slices of ``SPIN_SLICE_S``, so that a
    signal's Python handler runs and is seen within one. It returns when the context is shut
    down, whoever did it. A callback that raises is reported in one line and spinning goes on:
    one failing callback must not leave a graph that serves nothing.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.logging import get_logger
    slice_s = 3600.0 if stop_signals is None else SPIN_SLICE_S
    while not stop.done() and rclpy.ok(context=executor.context):
        if stop_signals is not None and stop_signals.received:
            return
        try:
            executor.spin_until_future_complete(stop, timeout_sec=slice_s)
        except (ExternalShutdownException, KeyboardInterrupt):
            return
        except Exception as exc:  # noqa: BLE001 - reported, and the graph keeps running
            if not rclpy.ok(context=executor.context):
                return
            get_logger('gripper_ros').error(
                f'a callback failed and was skipped: {type(exc).__name__}: {one_line(exc)}')


class StopSignals:
    """SIGINT and SIGTERM as a request to stop, seen by the code that owns the shutdown.

    rclpy's own handler shuts the context down from a signal thread while callbacks still run
    (their publishers then raise, and the executor logs each as FATAL), and a process whose
    SIGINT is ignored (a script's background job) is left alive with a dead context. Here a
    signal only sets :attr:`received`; the owner stops spinning, destroys its nodes, closes its
    bags and only then shuts the context down. A second signal during that adds nothing: it can
    neither cut the closing short nor abort the interpreter. Install it in the main thread
    (``with StopSignals():``) and initialise rclpy with ``SignalHandlerOptions.NO``.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, on_first: Callable[[int], None] | None = None):
        self.received: int | None = None      # the first signal's number
        self.on_first = on_first              # set None once closing has begun
        self._previous: dict = {}

    def _handle(self, signum, _frame) -> None:
        if self.received is not None:
            return
        self.received = signum
        if self.on_first is not None:
            self.on_first(signum)

    def __enter__(self) -> StopSignals:
        self._previous = {sig: signal.signal(sig, self._handle) for sig in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def exit_without_a_last_collection() -> None:
    """Skip the interpreter's last garbage collection when this process ends.

    It walks every object numba and the compiled core made, 0.5-1 s on a loaded 2-core machine,
    after the node, its bags and its context were closed explicitly: a stopped node would
    outlive the 2 s a launch file or a process manager allows. ``gc.freeze`` at exit leaves
    those objects to the operating system; it changes nothing while the process runs.
    """
    atexit.register(gc.freeze)


def run_node(make_node: Callable[[], Node], name: str, args=None,
             services: tuple[str, ...] = ()) -> int:
    """Run a node: the one ``main()`` of every node (init, spin, clean shutdown, exit codes).

    0 on Ctrl-C or SIGTERM, after the node is destroyed and the context shut down, with
    nothing on stderr (:class:`StopSignals`); ``EXIT_BAD_START`` with one line on stderr, no
    traceback, for a bad config file, a refused start-up parameter or names already taken (a
    node ``name``, or a server of one of ``services``, in its namespace). Any other exception
    is a bug and keeps its traceback. The executor is the node's ``executor`` parameter
    (``events``, the default, or ``single``).
    """
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions
    from rclpy.task import Future
    from rclpy.utilities import remove_ros_args

    from gripper_ros.nodes.names import NameClaim
    exit_without_a_last_collection()
    try:
        user_args = remove_ros_args(sys.argv if args is None else args)[1:]
    except RCLError as exc:              # e.g. a --params-file that is missing or not YAML
        print(f'{name}: bad --ros-args: {one_line(exc)}', file=sys.stderr)
        return EXIT_BAD_START
    if {'-h', '--help'} & set(user_args):
        print(node_usage(name, make_node))
        return 0
    node = executor = claim = None
    with StopSignals() as signals:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError as exc:
            print(f'{name}: bad --ros-args: {one_line(exc)}', file=sys.stderr)
            return EXIT_BAD_START
        try:
            claim = NameClaim.take((name,), services)
            node = make_node()
            kind = node.declare_parameter('executor', ExecutorKind.EVENTS.value,
                                          ParameterDescriptor(
                                              description='events (rclpy EventsExecutor) | '
                                                          'single (SingleThreadedExecutor)',
                                              read_only=True)).value
            try:
                executor = make_executor(ExecutorKind(kind))
            except ValueError:
                raise StartupError(f'parameter "executor" must be one of '
                                   f'{[k.value for k in ExecutorKind]}, got {kind!r}') from None
            executor.add_node(node)
            if not signals.received:         # a signal during start-up: stop at once
                spin_until_stopped(executor, Future(), signals)
        except (ConfigError, ParameterException, StartupError, RCLError) as exc:
            print(f'{name}: {one_line(exc)}', file=sys.stderr)
            return EXIT_BAD_START
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            if node is not None:
                node.destroy_node()
            if claim is not None:
                claim.release()
            rclpy.try_shutdown()
    return 0


def node_usage(name: str, make_node) -> str:
    """Return what ``NODE --help`` prints: the node's docstring and how ROS arguments reach it."""
    import inspect
    doc = inspect.getdoc(sys.modules.get(getattr(make_node, '__module__', ''), None)) or ''
    return (f'usage: {name} [--ros-args -r __ns:=/NAMESPACE -p NAME:=VALUE '
            f'--params-file FILE ...]\n\n{doc}\n\nParameters: ros2 param list / describe '
            f'on the running node; defaults in config/gripper.yaml.')


def one_line(text: object) -> str:
    return ' '.join(str(text).split())


def default_namespace(kwargs: dict) -> dict:
    """Return Node keyword arguments with the package's namespace unless one is given.

    A remap ``-r __ns:=/left`` still wins, as for every ROS node.
    """
    kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
    return kwargs


MAX_COUNTED_GAP_S = 0.25
"""Silence is counted only while the executor runs: a longer gap between two watchdog checks
(the process starved, a slow callback) counts as this much, since messages may be queued behind."""


class ExecutorSilence:
    """Wall time without progress, for the watchdogs.

    The supervisor's is time without a tick, the controllers' time without a status. Only time
    in which the executor demonstrably ran counts: call :meth:`check` from a steady timer; a
    check more than ``MAX_COUNTED_GAP_S`` late adds only that much, so that after a stall of the
    whole process the messages queued behind the timer are not taken for silence.
    """

    def __init__(self):
        self.silent_s = 0.0
        self._last_check = time.monotonic()

    def reset(self) -> None:
        """Progress was made: silence starts afresh."""
        self.silent_s = 0.0
        self._last_check = time.monotonic()

    def check(self, counting: bool) -> float:
        """Check from the timer; the gap since the last check counts only when ``counting``."""
        now = time.monotonic()
        gap_s, self._last_check = now - self._last_check, now
        if counting:
            self.silent_s += min(gap_s, MAX_COUNTED_GAP_S)
        return self.silent_s


def accept_goal(_goal_request):
    """Accept every action goal: the supervisor decides (a refusal is a REFUSED result)."""
    from rclpy.action import GoalResponse
    return GoalResponse.ACCEPT


def cancel_by_stop(goal_handle, running_goal, stop_client):
    """Cancel the running goal by calling the supervisor's stop (its service answers STOPPED)."""
    from rclpy.action import CancelResponse
    from std_srvs.srv import Trigger
    if goal_handle is running_goal and stop_client.service_is_ready():
        stop_client.call_async(Trigger.Request())
        return CancelResponse.ACCEPT
    return CancelResponse.REJECT


def call_and_wait(client, request, timeout_s: float):
    """Call a service from a thread that is not the executor's; return the response.

    None when none came within ``timeout_s`` (the pending request is dropped).
    """
    import threading
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout_s):
        client.remove_pending_request(future)
        return None
    return future.result()


def wait_until(predicate, timeout_s: float = 5.0, step_s: float = 0.005) -> bool:
    """Poll ``predicate`` until it holds or ``timeout_s`` of wall time has passed.

    Returns its last value (for callers that wait on another thread's spinning executor).
    """
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return predicate()


def ns_to_time(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def time_to_ns(stamp: Time) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def declare_config(node: Node) -> GripperConfig:
    """Declare ``config_file`` (empty = the installed config/gripper.yaml) and load it.

    A bad file raises ConfigError naming the key; the node does not start. A whole number is
    taken for every double parameter of the node (:func:`parameters.accept_whole_numbers`).
    """
    from gripper_ros.nodes.parameters import accept_whole_numbers
    accept_whole_numbers(node)
    path = node.declare_parameter('config_file', '', ParameterDescriptor(
        description='YAML file, read once at start-up', read_only=True)).value
    return load_config(path or None)


def keep_name_args(node_name: str) -> list[str]:
    """Node arguments that keep ``node_name`` under a global ``-r __node:=OTHER`` remap.

    ``launch_ros`` names a node with a global remap, which renames every node of the process;
    a node's own arguments are looked up first, so a helper node keeps its name with these.
    """
    return ['--ros-args', '-r', f'__node:={node_name}']


def server_node_name(node_name: str, service_name: str) -> str:
    """Name the private server node of a :class:`DeferredService`: ``<node>_<last>_server``."""
    base = service_name.rstrip('/').rsplit('/', 1)[-1]
    base = ''.join(c if c.isalnum() or c == '_' else '_' for c in base) or 'service'
    return f'{node_name}_{base}_server'


class DeferredService:
    """A service server whose reply may be sent later, from another callback.

    rclpy (Jazzy) sends a service callback's return value at once, and its EventsExecutor cannot
    await an ``async`` callback. A grasp takes many lockstep ticks, so the request is taken from
    the service handle by a 10 ms steady-clock timer on ``node`` (the server itself lives on a
    private, never-spun node) and answered with :meth:`reply` when the grasp ends. Requests queue
    in DDS meanwhile; each is handled in arrival order.
    """

    def __init__(self, node: Node, srv_type, name: str, on_request, poll_period_s: float = 0.01):
        from rclpy.clock import Clock, ClockType
        # one private node per service, named after it (node 'supervisor', '/gripper/grasp' ->
        # 'supervisor_grasp_server'): a node with two deferred services must not register one
        # name twice (rcl warns 'Publisher already registered for node name')
        server_name = server_node_name(node.get_name(), name)
        self._server_node = Node(server_name, namespace=node.get_namespace(),
                                 context=node.context, start_parameter_services=False,
                                 cli_args=keep_name_args(server_name))
        self._service = self._server_node.create_service(srv_type, name, self._not_spun,
                                                         qos_profile=SERVICE_QOS)
        self._on_request = on_request
        self._timer = node.create_timer(poll_period_s, self._poll,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    @staticmethod
    def _not_spun(request, response):  # pragma: no cover - the server node is never spun
        raise RuntimeError('DeferredService server node must not be added to an executor')

    def _poll(self) -> None:
        srv = self._service
        while True:
            with srv.handle:
                request, header = srv.handle.service_take_request(srv.srv_type.Request)
            if request is None:
                return
            self._on_request(request, header)

    def reply(self, header, response) -> None:
        self._service.send_response(response, header)

    def destroy(self) -> None:
        """Safe to call twice."""
        if self._server_node is None:
            return
        self._timer.destroy()
        self._server_node.destroy_node()
        self._server_node = None
