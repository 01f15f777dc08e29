"""What every node of the package is: the default namespace, and one teardown of all it owns."""
from __future__ import annotations

from typing import Protocol, TypeVar

from gripper_ros.nodes.names import default_namespace
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
    """

    def __init__(self, node_name: str, **kwargs):
        self._owned: list = []
        super().__init__(node_name, **default_namespace(kwargs))

    def own(self, resource: OwnedT) -> OwnedT:
        """Destroy ``resource`` with this node; return it."""
        self._owned.append(resource)
        return resource

    def destroy_node(self):
        owned, self._owned = self._owned, []
        for resource in reversed(owned):
            resource.destroy()
        return super().destroy_node()
