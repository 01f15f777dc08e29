"""Integer nanoseconds, the unit of the core and the bags, as a ROS time stamp.

The way back is :func:`gripper_ros.wire.stamp_ns`.
"""
from __future__ import annotations

from builtin_interfaces.msg import Duration, Time


def ns_to_time(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def duration_ns(duration) -> int:
    """Return a ``builtin_interfaces/Duration`` in integer nanoseconds."""
    return int(duration.sec) * 1_000_000_000 + int(duration.nanosec)


def ns_to_duration(t_ns: int) -> Duration:
    return Duration(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
