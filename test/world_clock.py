"""A world simulator's /clock for tests, as Gazebo publishes it through ros_gz_bridge.

One message every physics step (1 ms of simulated time), and while paused the same time again
every millisecond of wall time (gz-sim ``src/SimulationRunner.cc``: ``PublishStats`` sends a
clock message every iteration, "not throttled", paused iterations included); on a reliable,
volatile keep_last(10) publisher (ros_gz_bridge ``src/factory.hpp``, ``create_ros_publisher``:
``rclcpp::QoS(rclcpp::KeepLast(queue_size))``, ``kDefaultPublisherQueue`` 10). Its steps are
scheduled at ``PACE`` of the wall clock's, and a step that comes late moves the schedule rather
than bursting to catch up (``SimulationRunner::Run``: ``if (nextUpdateTime < now)
nextUpdateTime = now + updatePeriod``), so a starved world runs slower, never jumps.
"""
from __future__ import annotations

import bisect
import threading
import time

from gripper_interfaces.msg import SimStatus
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.wire import qualified, TOPIC_CLOCK, TOPIC_JOINT_STATES, TOPIC_SIM_STATUS
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

PACE = 0.5
"""The world's simulated seconds per wall second."""
STEP_NS = 1_000_000
"""Gazebo's default physics step (max_step_size 0.001): one /clock a step."""
WORLD_START_NS = 7_300_000_000
"""The world has run for a while before the gripper starts."""


class World:
    """A world simulator's /clock, and what a robot stack's node receives of the gripper.

    ``history`` holds (system time ns, world time ns) of every /clock, noted just before it is
    published: the world's time at any instant, as DDS stamps a message's sending (its
    ``source_timestamp``, system clock).
    """

    def __init__(self, namespaces: tuple[str, ...]):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('world', context=self.context)
        self._clock_pub = self.node.create_publisher(Clock, TOPIC_CLOCK, QoSProfile(depth=10))
        self.lock = threading.Lock()
        self.history: list[tuple[int, int]] = []
        self.samples: dict[str, list] = {ns: [] for ns in namespaces}
        self.statuses: list[SimStatus] = []
        for ns in namespaces:
            self.node.create_subscription(
                JointState, qualified(ns, TOPIC_JOINT_STATES),
                lambda msg, info, ns=ns: self._on_joint(ns, msg, info), GRAPH_QOS)
        self.node.create_subscription(SimStatus, qualified(namespaces[0], TOPIC_SIM_STATUS),
                                      self.statuses.append, GRAPH_QOS)
        self._world_now_ns = WORLD_START_NS
        self.paused = False
        self._stop = threading.Event()
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._threads = [threading.Thread(target=self._publish, daemon=True),
                         threading.Thread(target=self._spin, daemon=True)]
        for thread in self._threads:
            thread.start()

    def _publish(self) -> None:
        """One /clock an iteration: a step of STEP_NS at PACE, or the same time while paused."""
        period_s = STEP_NS * 1e-9 / PACE
        next_update = time.monotonic() + period_s
        while not self._stop.is_set():
            with self.lock:
                if not self.paused:
                    self._world_now_ns += STEP_NS
                t_ns = self._world_now_ns
                self.history.append((time.time_ns(), t_ns))
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 1_000_000_000)
            self._clock_pub.publish(msg)
            if self.paused:
                time.sleep(0.001)
                next_update = time.monotonic() + period_s
                continue
            now = time.monotonic()
            if next_update > now:
                time.sleep(next_update - now)
            next_update += period_s
            if next_update < time.monotonic():
                next_update = time.monotonic() + period_s

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_joint(self, ns: str, msg: JointState, info: dict) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            self.samples[ns].append((info['source_timestamp'], stamp_ns, msg.position[0]))

    def at(self, system_ns: int) -> int:
        """Return the world's newest time published before ``system_ns`` (-1: none yet)."""
        with self.lock:
            k = bisect.bisect_right(self.history, (system_ns, 1 << 62))
            return self.history[k - 1][1] if k else -1

    def now_ns(self) -> int:
        with self.lock:
            return self.history[-1][1] if self.history else -1

    def pause(self) -> int:
        """Stand still (and go on publishing that time, as Gazebo paused); return the time."""
        with self.lock:
            self.paused = True
            return self._world_now_ns

    def resume(self) -> None:
        with self.lock:
            self.paused = False

    def since(self, ns: str, stamp_ns: int) -> list:
        with self.lock:
            return [s for s in self.samples[ns] if s[1] >= stamp_ns]

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


SETTLING_NS = 100_000_000
"""A gripper's first 0.1 s of simulated time: it starts on its state grid, up to a period behind
the world's first time, while its process still warms up."""


def lags_ns(world: World, samples: list) -> list[int]:
    """Return the world's time when each sample was sent, minus its stamp.

    Samples of the gripper's first :data:`SETTLING_NS` are left out.
    """
    start_ns = samples[0][1] if samples else 0
    return [world.at(sent) - stamp for sent, stamp, _ in samples
            if stamp >= start_ns + SETTLING_NS]
