"""A node's process: executors, spinning, signals, and the one ``main()`` every node shares."""
from __future__ import annotations

import atexit
import enum
import gc
import os
import signal
import sys
import threading
from typing import Callable

from gripper_ros.core.config import ConfigError
from gripper_ros.nodes.names import destroy_probes, NameClaim
from gripper_ros.nodes.parameters import refuse_unknown_overrides
from gripper_ros.nodes.startup import EXIT_BAD_START, StartupError
from gripper_ros.text import one_line
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node


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
    neither cut the closing short nor abort the interpreter. With ``hard_bound_s`` the first
    signal also starts the process's stop bound (:func:`arm_hard_bound`), which the closing code
    may re-arm step by step. Install it in the main thread
    (``with StopSignals():``) and initialise rclpy with ``SignalHandlerOptions.NO``.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, on_first: Callable[[int], None] | None = None,
                 hard_bound_s: float | None = None):
        self.received: int | None = None      # the first signal's number
        self.on_first = on_first              # set None once closing has begun
        self.hard_bound_s = hard_bound_s      # the first signal arms arm_hard_bound with it
        self._previous: dict = {}

    def _handle(self, signum, _frame) -> None:
        if self.received is not None:
            return
        self.received = signum
        if self.hard_bound_s is not None:
            arm_hard_bound(self.hard_bound_s)
        if self.on_first is not None:
            self.on_first(signum)

    def __enter__(self) -> StopSignals:
        self._previous = {sig: signal.signal(sig, self._handle) for sig in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        """Restore the handlers; once a stop signal came, ignore these signals from now on.

        The process is ending: a second Ctrl-C, or launch's own SIGINT after the terminal's
        (launch sends one when it runs non-interactive), must not raise KeyboardInterrupt in
        its last lines and end it killed by SIGINT instead of with its exit code. What is left
        (the interpreter's exit) is bounded instead, by :func:`arm_hard_bound`.
        """
        for sig, handler in self._previous.items():
            signal.signal(sig, handler if self.received is None else signal.SIG_IGN)
        if self.received is not None:
            arm_hard_bound(CLEAN_UP_LIMIT_S + GIL_HELD_MARGIN_S)


APP_BAGS_LIMIT_S = 30.0
"""Longest a console app's open bags may take to close once it stops (the last ticks written,
the MCAP summary and index): past it the process ends (:func:`arm_hard_bound`)."""


def close_app_graph(graph, signals: StopSignals) -> None:
    """End a console app's graph: no signal may cut the closing short, then rclpy shuts down.

    Bounded in two steps, neither needing the GIL: the bags get :data:`APP_BAGS_LIMIT_S` to
    close (from the stop signal when ``signals`` armed it, else from here), then the nodes and
    the context :data:`CLEAN_UP_LIMIT_S` + :data:`GIL_HELD_MARGIN_S`; past either, every
    thread's stack goes to stderr and the process exits 1.
    """
    import rclpy
    signals.on_first = None
    if signals.received is None or signals.hard_bound_s is None:   # not armed by the signal
        arm_hard_bound(APP_BAGS_LIMIT_S)
    try:
        if graph is not None:
            graph.close_recordings()
        arm_hard_bound(CLEAN_UP_LIMIT_S + GIL_HELD_MARGIN_S)
        if graph is not None:
            graph.close()
        rclpy.try_shutdown()
    finally:                   # the bound is for a stop that hangs, not for one that raises
        disarm_hard_bound()
    signals.__exit__()


def raise_keyboard_interrupt(signum: int) -> None:
    """Interrupt the main thread's work: a one-shot command's first Ctrl-C or SIGTERM."""
    raise KeyboardInterrupt


def exit_without_a_last_collection() -> None:
    """Skip the interpreter's last garbage collection when this process ends.

    It walks every object numba and the compiled core made, 0.5-1 s on a loaded 2-core machine,
    after the node, its bags and its context were closed explicitly: a stopped node would
    outlive the 2 s a launch file or a process manager allows. ``gc.freeze`` at exit leaves
    those objects to the operating system; it changes nothing while the process runs.
    """
    atexit.register(gc.freeze)


CLEAN_UP_LIMIT_S = 3.0
"""Longest a node executable's clean-up may take once it has its exit code (executor, node,
context), on free cores (times :func:`machine_load` on a loaded machine): past it the process
ends with that code, saying so in one line. Deleting a DDS entity
can block for good in the middle of discovery traffic (seen once in some hundreds of stops, in
the action server's ``rcl_action_server_fini``); a stopped node must still stop."""

CLEAN_UP_STEP_S = CLEAN_UP_LIMIT_S / 3
"""Longest a clean-up waits for a spinning thread to end, and again for its executor to shut
down: a third of :data:`CLEAN_UP_LIMIT_S` each, the last third for destroying the nodes."""

GIL_HELD_MARGIN_S = 1.0
"""How much later than its limit a bound ends the process when no Python thread can run.

A destruction can spin in C holding the GIL (rclpy's ``destroy_when_not_in_use`` waiting for a
handle still in use): a Python timer then never runs. :func:`arm_hard_bound`'s watchdog is
C (``faulthandler``): at its limit it writes every thread's stack to stderr and calls
``_exit(1)`` without taking the GIL."""


def machine_load() -> float:
    """Return how many runnable processes share each core, at least 1 (the 1-minute load average).

    A process gets about one over this of a core: what it does in a second on free cores takes
    this many seconds here.
    """
    try:
        return max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))
    except OSError:               # no load average on this system
        return 1.0


def load_bound_s(limit_s: float) -> float:
    """Return the wall time a bound of ``limit_s`` (on free cores) allows on this machine now.

    A bound on a wait or a clean-up is there for one that never ends; one that a loaded machine
    only slows down must still end as it would on free cores, not be cut short as hung.
    """
    return limit_s * machine_load()


def arm_hard_bound(limit_s: float) -> None:
    """End this process :func:`load_bound_s` of ``limit_s`` from now, whatever its threads do.

    ``faulthandler.dump_traceback_later(exit=True)``: a C thread that needs no GIL writes
    ``Timeout (H:MM:SS)!`` and every thread's stack to stderr, then ``_exit(1)`` (CPython's
    Modules/faulthandler.c: the code is fixed, so the process's own is lost). Re-arming
    replaces it.
    """
    import faulthandler
    faulthandler.dump_traceback_later(load_bound_s(limit_s), exit=True, file=sys.__stderr__)


def disarm_hard_bound() -> None:
    """Cancel :func:`arm_hard_bound`."""
    import faulthandler
    faulthandler.cancel_dump_traceback_later()


class BoundedCleanUp:
    """Within ``with``: if the block outlasts ``limit_s`` (:func:`load_bound_s`), say so and exit.

    A Python timer ends the process with ``code`` and one line; when the GIL is held for good,
    :func:`arm_hard_bound` ends it :data:`GIL_HELD_MARGIN_S` later with 1 and the stacks.
    Only for a process that is ending anyway and holds nothing that needs a clean close (a node
    executable: its name claims are file locks the system releases, DDS peers drop its
    participant at its lease's end). An app that records bags closes them first
    (:func:`close_app_graph`).
    """

    def __init__(self, name: str, code: int, limit_s: float = CLEAN_UP_LIMIT_S):
        self._limit_s = limit_s
        self._name, self._code = name, code
        self._timer = None

    def __enter__(self) -> BoundedCleanUp:
        bound_s = load_bound_s(self._limit_s)
        self._timer = threading.Timer(bound_s, self._give_up, (self._name, self._code, bound_s))
        self._timer.daemon = True
        arm_hard_bound(self._limit_s + GIL_HELD_MARGIN_S)
        self._timer.start()
        return self

    def __exit__(self, *exc) -> None:
        self._timer.cancel()
        disarm_hard_bound()

    @staticmethod
    def _give_up(name: str, code: int, limit_s: float) -> None:
        sys.stderr.write(f'{name}: clean-up did not finish within {limit_s:.0f} s (a DDS entity '
                         f'that never finished deleting); exiting with {code}\n')
        sys.stderr.flush()
        os._exit(code)


def release_nodes(executor, nodes) -> None:
    """Take ``nodes`` out of a stopped ``executor``, then shut it down: nothing uses them after.

    A node destroyed while an executor still holds its handles waits in C, GIL held, for them to
    be let go (rclpy ``destroy_when_not_in_use``); call this once spinning has ended.
    """
    for node in nodes:
        try:
            executor.remove_node(node)
        except Exception:  # noqa: BLE001 - a node the executor no longer has
            pass
    executor.shutdown(timeout_sec=CLEAN_UP_STEP_S)


def build_node(make_node: Callable[..., Node], *args, **kwargs) -> Node:
    """Construct a node; when its constructor raises, destroy what it had made, then re-raise.

    A node refused half-way (a bad start-up parameter) already holds publishers, timers and a
    DDS participant; left to the interpreter's exit, they are torn down after the context,
    beside Fast DDS's own threads, which can hang or crash the process instead of exiting 2.
    """
    if not isinstance(make_node, type):
        return make_node(*args, **kwargs)
    node = make_node.__new__(make_node)
    try:
        node.__init__(*args, **kwargs)
    except BaseException:
        try:
            node.destroy_node()
        except Exception:  # noqa: BLE001 - Node.__init__ itself failed: nothing to destroy
            pass
        raise
    return node


def user_arguments(name: str, argv: list[str] | None) -> list[str] | None:
    """Return the arguments of ``argv`` (``sys.argv`` if None) outside ``--ros-args``.

    None after one line on stderr when the ROS arguments are bad (e.g. a ``--params-file`` that
    is missing or not YAML).
    """
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.utilities import remove_ros_args
    try:
        return remove_ros_args(sys.argv if argv is None else argv)[1:]
    except RCLError as exc:
        print(f'{name}: bad --ros-args: {one_line(exc)}', file=sys.stderr)
        return None


def init_without_signal_handlers(name: str, argv: list[str] | None) -> bool:
    """Initialise rclpy without its own signal handlers (:class:`StopSignals` takes the signals).

    False after one line on stderr when rcl refuses the ROS arguments.
    """
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.signals import SignalHandlerOptions
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        print(f'{name}: bad --ros-args: {one_line(exc)}', file=sys.stderr)
        return False
    return True


def run_node(make_node: Callable[[], Node], name: str, args=None,
             services: tuple[str, ...] = ()) -> int:
    """Run a node: the one ``main()`` of every node (init, spin, clean shutdown, exit codes).

    0 on Ctrl-C or SIGTERM, after the node is destroyed and the context shut down, with
    nothing on stderr (:class:`StopSignals`); ``EXIT_BAD_START`` with one line on stderr, no
    traceback, for a bad config file, a refused or unknown start-up parameter or names already
    taken (a node ``name``, or a server of one of ``services``, in its namespace). Any other
    exception is a bug and keeps its traceback. The executor is the node's ``executor`` parameter
    (``events``, the default, or ``single``).
    """
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.task import Future

    exit_without_a_last_collection()
    user_args = user_arguments(name, args)
    if user_args is None:
        return EXIT_BAD_START
    if {'-h', '--help'} & set(user_args):
        print(node_usage(name, make_node))
        return 0
    node = executor = claim = None
    exit_code = 0
    with StopSignals(hard_bound_s=CLEAN_UP_LIMIT_S + GIL_HELD_MARGIN_S) as signals:
        if not init_without_signal_handlers(name, args):
            return EXIT_BAD_START
        try:
            claim = NameClaim.take((name,), services)
            node = build_node(make_node)
            destroy_probes(node.context)     # beside the node: the participant stays
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
            refuse_unknown_overrides([node])
            executor.add_node(node)
            if not signals.received:         # a signal during start-up: stop at once
                spin_until_stopped(executor, Future(), signals)
        except (ConfigError, ParameterException, StartupError, RCLError) as exc:
            print(f'{name}: {one_line(exc)}', file=sys.stderr)
            exit_code = EXIT_BAD_START
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            with BoundedCleanUp(name, exit_code):
                if executor is not None:
                    release_nodes(executor, [] if node is None else [node])
                if node is not None:
                    node.destroy_node()
                if claim is not None:
                    claim.release()
                rclpy.try_shutdown()
    return exit_code


def node_usage(name: str, make_node) -> str:
    """Return what ``NODE --help`` prints: the node's docstring and how ROS arguments reach it."""
    import inspect
    doc = inspect.getdoc(sys.modules.get(getattr(make_node, '__module__', ''), None)) or ''
    return (f'usage: {name} [--ros-args -r __ns:=/NAMESPACE -p NAME:=VALUE '
            f'--params-file FILE ...]\n\n{doc}\n\nParameters: ros2 param list / describe '
            f'on the running node; defaults in config/gripper.yaml.')
