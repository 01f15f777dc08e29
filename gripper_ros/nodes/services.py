"""Service tools: a server that answers later, blocking calls, and waiting on another thread."""
from __future__ import annotations

import time
from typing import TYPE_CHECKING
import weakref

from gripper_ros.nodes.names import keep_name_args
from gripper_ros.nodes.qos import SERVICE_QOS
from rclpy.node import Node
from rclpy.parameter import Parameter

if TYPE_CHECKING:
    from gripper_ros.nodes.gripper_node import GripperNode


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


SPIN_SLICE_S = 0.1
"""Wall seconds of one spin: how soon a stop signal is seen while waiting for an answer."""


def spin_until_done(node, future, timeout_s: float, signals=None) -> bool:
    """Spin ``node`` until ``future`` is done, ``timeout_s`` has passed or a stop signal came."""
    import rclpy
    deadline = time.monotonic() + timeout_s
    while not future.done() and (signals is None or signals.received is None):
        left = deadline - time.monotonic()
        if left <= 0:
            break
        rclpy.spin_once(node, timeout_sec=min(SPIN_SLICE_S, left))
    return future.done()


def call_spinning(node, client, request, timeout_s: float, signals=None):
    """Call a service, spinning ``node`` in this thread; the response, or None after the timeout.

    A stop signal (``signals``, a :class:`~gripper_ros.nodes.process.StopSignals`) while
    waiting drops the request and raises KeyboardInterrupt.
    """
    future = client.call_async(request)
    if not spin_until_done(node, future, timeout_s, signals):
        client.remove_pending_request(future)
        if signals is not None and signals.received is not None:
            raise KeyboardInterrupt
        return None
    return future.result()


ASK_AGAIN_S = 5.0
"""Wall seconds an idempotent call waits for its answer before it asks again."""


def call_until_answered(node, client, request, timeout_s: float, signals=None,
                        ask_again_s: float = ASK_AGAIN_S):
    """Call an idempotent service, asking again while no answer comes; None after ``timeout_s``.

    A server drops its answer to a client whose response reader it has not matched within its
    writer's max_blocking_time, 100 ms (rmw_fastrtps rmw_response.cpp): a request sent as soon
    as the client sees the server can go unanswered on a loaded machine. Asked again, it is
    answered; an answer to an earlier request is dropped. A stop signal raises KeyboardInterrupt.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        response = call_spinning(node, client, request, min(ask_again_s, left), signals)
        if response is not None:
            return response


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


def server_node_name(node_name: str, service_name: str) -> str:
    """Name the private server node of a :class:`DeferredService`: ``<node>_<last>_server``."""
    base = service_name.rstrip('/').rsplit('/', 1)[-1]
    base = ''.join(c if c.isalnum() or c == '_' else '_' for c in base) or 'service'
    return f'{node_name}_{base}_server'


DEFERRED_POLL_S = 0.01
"""How often a node takes the requests that wait for its deferred services."""


class DeferredService:
    """A service server whose reply may be sent later, from another callback.

    rclpy (Jazzy) sends a service callback's return value at once, and its EventsExecutor cannot
    await an ``async`` callback. A grasp takes many lockstep ticks, so the request is taken from
    the service handle every 10 ms by a steady-clock timer on ``node``, one for all the
    deferred services of the node (:class:`DeferredPolls`; the server itself lives on a
    private, never-spun node) and answered with :meth:`reply` when the grasp ends. Requests
    queue in DDS meanwhile; each is handled in arrival order. ``node`` owns it: its teardown
    destroys the private node too.
    """

    def __init__(self, node: GripperNode, srv_type, name: str, on_request):
        # one private node per service, named after it (node 'supervisor', '/gripper/grasp' ->
        # 'supervisor_grasp_server'): a node with two deferred services must not register one
        # name twice (rcl warns 'Publisher already registered for node name')
        server_name = server_node_name(node.get_name(), name)
        # never spun, so no clock: no /clock subscription under a global use_sim_time:=true
        self._server_node = Node(server_name, namespace=node.get_namespace(),
                                 context=node.context, start_parameter_services=False,
                                 cli_args=keep_name_args(server_name),
                                 parameter_overrides=[Parameter('use_sim_time', value=False)])
        self._service = self._server_node.create_service(srv_type, name, self._not_spun,
                                                         qos_profile=SERVICE_QOS)
        self._on_request = on_request
        self._polls = DeferredPolls.of(node)
        self._polls.services.append(self)
        node.own(self)

    @staticmethod
    def _not_spun(request, response):  # pragma: no cover - the server node is never spun
        raise RuntimeError('DeferredService server node must not be added to an executor')

    def poll(self) -> None:
        """Handle each request that waits, in arrival order."""
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
        self._polls.forget(self)
        self._server_node.destroy_node()
        self._server_node = None


class DeferredPolls:
    """The one steady timer of a node that polls all its deferred services.

    Each timer costs the executor its firing (five deferred services, each on a timer of its
    own, took 0.026 of a core of a holding graph here): a node with three polls them from one.
    It stops with the node's last deferred service.
    """

    _of_node: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    @classmethod
    def of(cls, node: GripperNode) -> DeferredPolls:
        """Return the polls of ``node`` (made with its first deferred service)."""
        polls = cls._of_node.get(node)
        if polls is None or polls.timer is None:
            polls = cls._of_node[node] = cls(node)
        return polls

    def __init__(self, node: GripperNode) -> None:
        from rclpy.clock import Clock, ClockType
        self.services: list[DeferredService] = []
        self.timer = node.create_timer(DEFERRED_POLL_S, self._poll,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _poll(self) -> None:
        for service in tuple(self.services):
            service.poll()

    def forget(self, service: DeferredService) -> None:
        """Poll ``service`` no more; destroy the timer with the last one."""
        if service in self.services:
            self.services.remove(service)
        if not self.services and self.timer is not None:
            self.timer.destroy()
            self.timer = None
