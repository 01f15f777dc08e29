"""The QoS of the graph's topics and services, one profile per kind of traffic."""
from __future__ import annotations

from gripper_ros.wire import GRAPH_QOS_DEPTH
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

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
