"""The lockstep messages as bytes on rclpy publishers and subscriptions.

The loop messages are taken raw and published pre-serialised with the byte layouts of
:mod:`gripper_ros.wire`; a message in another encapsulation falls back to rclpy's own
deserialisation, so any DDS peer is understood.
"""
from __future__ import annotations

from rclpy.serialization import deserialize_message

from gripper_ros.wire import LoopLayout


def decode(layout: LoopLayout, data: bytes, msg_cls) -> tuple:
    """The field values of one serialised loop message, in layout order."""
    values = layout.unpack(data)
    if values is None:                       # not little-endian plain CDR: the general way
        msg = deserialize_message(data, msg_cls)
        values = tuple(getattr(msg, name) for name in layout.fields)
    return values
