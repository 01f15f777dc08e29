"""sim/object_marker: the object between the fingers as the plant knows it, drawn for a viewer.

A visualization_msgs/Marker, a CUBE in the gripper's base frame, published with each
``sim/object_state`` (at ``state_rate_hz``, stamped alike): as wide as the object placed
(``sim/set_object``), or as the opening while the pads squeeze a compliant one; against the fixed
finger's pad face, as the plant has it; as tall as the pad length it may slide along, from the
fingertips down by what it slid (``slip_m``); coloured by how it is held (:data:`COLORS`). With no
object the marker is deleted. Foxglove's 3D panel and RViz's Marker display draw it beside the
URDF, live and from a bag; it is packed by template, as the plant's other state topics are.
"""
from __future__ import annotations

import math

from gripper_ros.core.description import finger_frames
from gripper_ros.nodes.loop_io import MessageTemplate
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.wire import HoldState, TOPIC_OBJECT_MARKER

NAMESPACE = 'object'
"""The marker's ``ns`` (its ``id`` is 0): one object per gripper."""
COLORS = {
    HoldState.RESTING: (0.25, 0.45, 0.95, 0.8),    # blue: on its support, the grip carries none
    HoldState.STUCK: (0.15, 0.75, 0.3, 0.9),       # green: lifted, held by static friction
    HoldState.SLIDING: (1.0, 0.55, 0.0, 0.9),      # orange: lifted and slipping along the pads
    HoldState.LOST: (0.9, 0.1, 0.1, 0.35),         # faint red: slid the pad length, out
}
"""Colour (r, g, b, a) of each state of ``sim/object_state``."""
FIELDS = ('header.stamp.sec', 'header.stamp.nanosec', 'action', 'pose.position.x',
          'pose.position.z', 'scale.x', 'scale.z', 'color.r', 'color.g', 'color.b', 'color.a')


class ObjectMarker:
    """The marker of one gripper's object, packed from the plant's state.

    ``config``: the gripper's (finger frames, finger size, default pad length); ``frame_id``:
    the base link's frame (with the gripper's prefix).
    """

    def __init__(self, config, frame_id: str):
        from visualization_msgs.msg import Marker
        frames = finger_frames(config)
        self.travel_m = frames.travel_m
        self.fixed_face_x_m = frames.fixed_finger_xyz[0]
        geometry = config.geometry
        self.fingertip_z_m = frames.fixed_finger_xyz[2] + geometry.finger_length_m
        self.default_pad_length_m = config.contact.pad_length_m
        template = Marker(ns=NAMESPACE, id=0, type=Marker.CUBE, action=Marker.ADD)
        template.header.frame_id = frame_id
        template.pose.orientation.w = 1.0
        template.scale.y = geometry.finger_width_m
        self._add, self._delete = Marker.ADD, Marker.DELETE
        self.layout = MessageTemplate(template, FIELDS)

    def pack(self, sec: int, nanosec: int, state: int, slip_m: float, position_m: float,
             width_m: float, pad_length_m: float) -> bytes:
        """Return the serialised marker at stamp (sec, nanosec).

        ``state`` and ``slip_m`` as ``sim/object_state`` has them, ``position_m`` the finger's
        travel, ``width_m`` and ``pad_length_m`` the object as placed (0: the configured pad).
        """
        opening_m = self.travel_m - position_m
        drawn_m = min(width_m, opening_m) if math.isfinite(opening_m) else width_m
        color = COLORS.get(state)
        if color is None or not drawn_m > 0.0:
            return self.layout.pack(sec, nanosec, self._delete, 0.0, 0.0, 0.0, 0.0,
                                    0.0, 0.0, 0.0, 0.0)
        pad_m = pad_length_m if pad_length_m > 0.0 else self.default_pad_length_m
        return self.layout.pack(sec, nanosec, self._add, self.fixed_face_x_m - drawn_m / 2.0,
                                self.fingertip_z_m - pad_m / 2.0 - slip_m, drawn_m, pad_m,
                                *color)


class ObjectMarkerPublisher:
    """Publish ``sim/object_marker`` for a plant node, with each of its ``sim/object_state``.

    ``node``: the plant_simulator node; its ``placed`` (the last SetObject accepted) gives the
    object's width and pad length, its ``published`` counts the markers.
    """

    def __init__(self, node):
        from visualization_msgs.msg import Marker
        self.node = node
        self.marker = ObjectMarker(node.config, node.frame_id)
        self.publisher = node.tapped_publisher(Marker, TOPIC_OBJECT_MARKER, GRAPH_QOS)

    def publish(self, sec: int, nanosec: int, state: int, slip_m: float,
                position_m: float) -> None:
        """Publish the marker of the object in ``state`` at stamp (sec, nanosec)."""
        placed = self.node.placed[1] or {}
        self.publisher.publish(self.marker.pack(
            sec, nanosec, int(state), slip_m, position_m, placed.get('width_m', 0.0),
            placed.get('pad_length_m', 0.0)))
        self.node.published[TOPIC_OBJECT_MARKER] += 1
