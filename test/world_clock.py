"""A world simulator's /clock for tests, and what a robot stack's node receives of the gripper.

The clock is :class:`gripper_ros.bench.world_clock.WorldClock`: as Gazebo publishes it through
ros_gz_bridge (its docstring names the upstream sources it follows), here at half the wall
clock's pace.
"""
from __future__ import annotations

import bisect
import threading

from gripper_interfaces.msg import SimStatus
from gripper_ros.bench.world_clock import START_NS, WorldClock
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.wire import (DEFAULT_NAMESPACE, qualified, TimeMode, TOPIC_JOINT_STATES,
                              TOPIC_SIM_STATUS)
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState

PACE = 0.5
"""The world's simulated seconds per wall second."""
WORLD_START_NS = START_NS
"""The world has run for a while before the gripper starts."""
SETTLING_NS = 100_000_000
"""A gripper's first 0.1 s of simulated time: it starts on its state grid, up to a period behind
the world's first time, while its process still warms up."""


def following(namespace: str = DEFAULT_NAMESPACE) -> GripperGraph:
    """Start a graph on the world's clock, given ``use_sim_time`` as launch gives gripper_graph.

    The launch file's parameters reach every node of the process (``/**``), the deferred
    services' private server nodes too.
    """
    return GripperGraph.in_own_context(GraphOptions(
        namespace=namespace, time_mode=TimeMode.REALTIME.parameter, use_sim_time=True),
        args=['--ros-args', '-p', 'use_sim_time:=true'])


class World:
    """A world's /clock at ``pace``, and the joint_states and sim/status of ``namespaces``.

    Each joint_states sample is (DDS source timestamp, stamp ns, position m).
    """

    def __init__(self, namespaces: tuple[str, ...], pace: float = PACE):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('world', context=self.context)
        self.clock = WorldClock(self.node, pace, keep_history=True)
        self.lock = threading.Lock()
        self.samples: dict[str, list] = {ns: [] for ns in namespaces}
        self.statuses: list[SimStatus] = []
        for ns in namespaces:
            self.node.create_subscription(
                JointState, qualified(ns, TOPIC_JOINT_STATES),
                lambda msg, info, ns=ns: self._on_joint(ns, msg, info), GRAPH_QOS)
        self.node.create_subscription(SimStatus, qualified(namespaces[0], TOPIC_SIM_STATUS),
                                      self.statuses.append, GRAPH_QOS)
        self._stop = threading.Event()
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._spinner = threading.Thread(target=self._spin, daemon=True)
        self._spinner.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_joint(self, ns: str, msg: JointState, info: dict) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            self.samples[ns].append((info['source_timestamp'], stamp_ns, msg.position[0]))

    def at(self, system_ns: int) -> int:
        """Return the world's newest time published before ``system_ns`` (-1: none yet)."""
        with self.clock.lock:
            history = self.clock.history
            k = bisect.bisect_right(history, (system_ns, 1 << 62))
            return history[k - 1][1] if k else -1

    def now_ns(self) -> int:
        return self.clock.now_ns()

    def pause(self) -> int:
        return self.clock.pause()

    def resume(self) -> None:
        self.clock.resume()

    def step(self, duration_ns: int) -> int:
        return self.clock.step(duration_ns)

    def since(self, ns: str, stamp_ns: int) -> list:
        with self.lock:
            return [s for s in self.samples[ns] if s[1] >= stamp_ns]

    def close(self) -> None:
        self.clock.stop()
        self._stop.set()
        self._spinner.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def lags_ns(world: World, samples: list) -> list[int]:
    """Return the world's time when each sample was sent, minus its stamp.

    Samples of the gripper's first :data:`SETTLING_NS` are left out.
    """
    start_ns = samples[0][1] if samples else 0
    return [world.at(sent) - stamp for sent, stamp, _ in samples
            if stamp >= start_ns + SETTLING_NS]
