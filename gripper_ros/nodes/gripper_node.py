"""What every node of the package is: the default namespace, loop endpoints, one teardown."""
from __future__ import annotations

from typing import Callable, Protocol, TypeVar

from gripper_ros.nodes.intra_process import GraphPublisher, IntraProcessBus
from gripper_ros.nodes.names import default_namespace
from gripper_ros.nodes.parameters import strict_parameters
from gripper_ros.nodes.qos import GRAPH_QOS
from rclpy.node import Node


class Destroyable(Protocol):
    """What a node can own: an action server, a deferred service."""

    def destroy(self) -> None:
        """Free its handles."""


OwnedT = TypeVar('OwnedT', bound=Destroyable)


class GripperNode(Node):
    """A node in the package's namespace (unless one is given) that destroys what it owns.

    rclpy's ``destroy_node`` frees the node's publishers, subscriptions, timers and services,
    not an action server or a deferred service's private server node; :meth:`own` adds those,
    and :meth:`destroy_node` frees them first, the last made first. A constructor that raises
    half-way leaves what it made so far to the same teardown (:func:`nodes.process.build_node`).

    ``intra_process``: the bus of the nodes of one process
    (:mod:`gripper_ros.nodes.intra_process`); the topics of :meth:`graph_publisher` and
    :meth:`graph_subscription` go over it. A set of a parameter it does not declare is refused
    with the name (:func:`~gripper_ros.nodes.parameters.strict_parameters`).
    """

    def __init__(self, node_name: str, *, intra_process: IntraProcessBus | None = None,
                 **kwargs):
        self._owned: list = []
        self.intra_process = intra_process
        self.graph_publishers: list[GraphPublisher] = []
        super().__init__(node_name, **default_namespace(kwargs))
        strict_parameters(self)

    def own(self, resource: OwnedT) -> OwnedT:
        """Destroy ``resource`` with this node; return it."""
        self._owned.append(resource)
        return resource

    def graph_publisher(self, msg_type, topic: str) -> GraphPublisher:
        """Publish ``msg_type`` (objects or serialised) on ``topic``, a volatile graph topic."""
        publisher = GraphPublisher(self, msg_type, topic, GRAPH_QOS, self.intra_process)
        self.graph_publishers.append(publisher)
        return publisher

    def tapped_publisher(self, msg_type, topic: str, qos) -> GraphPublisher:
        """Publish ``msg_type`` on ``topic`` over DDS only, where a recorder can tap it."""
        publisher = GraphPublisher(self, msg_type, topic, qos, None)
        self.graph_publishers.append(publisher)
        return publisher

    def graph_subscription(self, msg_type, topic: str, callback: Callable, raw: bool = True):
        """Take the messages of ``topic``, which only the graph publishes: the bus's, or DDS's.

        ``raw``: serialised bytes, else ``msg_type`` objects.
        """
        if self.intra_process is not None:
            self.intra_process.subscribe(self, self.resolve_topic_name(topic), callback,
                                         msg_type, raw)
            return None
        return self.create_subscription(msg_type, topic, callback, GRAPH_QOS, raw=raw)

    def deliver_queued(self) -> None:
        """Let this process's graph messages published so far arrive (before judging a request)."""
        if self.intra_process is not None:
            self.intra_process.deliver_queued()

    def destroy_node(self):
        if self.intra_process is not None:
            self.intra_process.detach(self)
        owned, self._owned = self._owned, []
        for resource in reversed(owned):
            resource.destroy()
        return super().destroy_node()
