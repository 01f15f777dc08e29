"""ROS time stamps to and from integer nanoseconds, the unit of the core and the bags."""
from __future__ import annotations

from builtin_interfaces.msg import Time


def ns_to_time(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def time_to_ns(stamp: Time) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec
