"""A world simulator's /clock, as Gazebo publishes it through ros_gz_bridge.

    python3 -m gripper_ros.bench.world_clock --pace 0.5      # until Ctrl-C

One message every physics step (1 ms of simulated time), and while paused the same time again
every millisecond of wall time (gz-sim ``src/SimulationRunner.cc``: ``PublishStats`` sends a
clock message every iteration, "not throttled", paused iterations included); on a reliable,
volatile keep_last(10) publisher (ros_gz_bridge ``src/factory.hpp``, ``create_ros_publisher``:
``rclcpp::QoS(rclcpp::KeepLast(queue_size))``, ``kDefaultPublisherQueue`` 10). Its steps are
scheduled at ``pace`` of the wall clock's, and a step that comes late moves the schedule rather
than bursting to catch up (``SimulationRunner::Run``: ``if (nextUpdateTime < now)
nextUpdateTime = now + updatePeriod``): a starved world runs slower, it never jumps. For
``bench_realtime --use-sim-time`` and the tests of a gripper on a world's clock.
"""
from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Optional, Sequence

STEP_NS = 1_000_000
"""Gazebo's default physics step (max_step_size 0.001): one /clock a step."""
START_NS = 7_300_000_000
"""The world has run for a while before a gripper starts."""


class WorldClock:
    """Publish /clock from ``node`` in a thread of its own, at ``pace`` x the wall clock's.

    ``history`` holds (system time ns, world time ns) of every message, noted just before it is
    published: the world's time at any instant, as DDS stamps a message's sending
    (``source_timestamp``, system clock).
    """

    def __init__(self, node, pace: float = 1.0, start_ns: int = START_NS,
                 keep_history: bool = False):
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        self._msg = Clock()
        self._pub = node.create_publisher(Clock, '/clock', QoSProfile(depth=10))
        self.pace = pace
        self.lock = threading.Lock()
        self.history: list[tuple[int, int]] = []
        self._keep_history = keep_history
        self._now_ns = start_ns
        self.paused = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='world_clock', daemon=True)
        self._thread.start()

    def _run(self) -> None:
        period_s = STEP_NS * 1e-9 / self.pace
        next_update = time.monotonic() + period_s
        msg = self._msg
        while not self._stop.is_set():
            with self.lock:
                t_ns = self._advance(0 if self.paused else STEP_NS)
            self._send(msg, t_ns)
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

    def now_ns(self) -> int:
        """Return the world's newest time."""
        with self.lock:
            return self._now_ns

    def pause(self) -> int:
        """Stand still (and go on publishing that time, as Gazebo paused); return the time."""
        with self.lock:
            self.paused = True
            return self._now_ns

    def resume(self) -> None:
        with self.lock:
            self.paused = False

    def step(self, duration_ns: int) -> int:
        """Paused: move the time on by ``duration_ns`` and publish it now; return it.

        As gz-sim's ``multi_step`` while paused: the world's time then stands again (and goes
        out every millisecond).
        """
        with self.lock:
            if not self.paused:
                raise RuntimeError('world_clock: step() needs a paused world (pause() first)')
            t_ns = self._advance(duration_ns)
        self._send(type(self._msg)(), t_ns)
        return t_ns

    def _advance(self, duration_ns: int) -> int:
        """Move the time on by ``duration_ns`` (the lock held) and note it; return it."""
        self._now_ns += duration_ns
        if self._keep_history:
            self.history.append((time.time_ns(), self._now_ns))
        return self._now_ns

    def _send(self, msg, t_ns: int) -> None:
        msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 1_000_000_000)
        self._pub.publish(msg)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)


def main(args: Optional[Sequence[str]] = None) -> int:
    """Publish /clock at ``--pace`` until SIGINT or SIGTERM."""
    import signal
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    p = argparse.ArgumentParser(prog='world_clock', description=__doc__.splitlines()[0])
    p.add_argument('--pace', type=float, default=1.0,
                   help="the world's simulated seconds per wall second (default 1)")
    opts = p.parse_args(list(sys.argv[1:] if args is None else args))
    if not 0.01 <= opts.pace <= 10.0:
        print('world_clock: error: --pace must be in [0.01, 10]', file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('world_clock')
    world = WorldClock(node, opts.pace)
    try:
        while not stop.wait(0.1):
            pass
    finally:
        world.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
