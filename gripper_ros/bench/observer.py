"""What the graph benchmarks watch: each grasp's phase changes, and the graph's loggers quieted."""
from __future__ import annotations

import time
from typing import Callable, Dict, Optional

from gripper_ros.wire import Phase, stamp_ns

GRAPH_LOGGERS = ('plant_simulator', 'position_controller', 'force_controller', 'supervisor',
                 'grasp_demo_client', 'grasp_action_server', 'bench_graph_observer')
"""The loggers a benchmark's graph speaks through; set to WARN while it measures."""


class PhaseObserver:
    """Marks each phase change of each grasp seen on ``supervisor/status``.

    A mark is ``(phase, wall s, ticks, simulated ns, CPU s)``. ``ticks`` is read from
    ``tick_count()`` (the plant's own counter, in one process) or left None (the ticks are then
    counted from simulated time and the stage's sampling time). ``stop()`` is called once for a
    grasp still running ``cap_s`` wall seconds after :meth:`arm`.
    """

    def __init__(self, node, namespace: str, tick_count: Optional[Callable[[], int]],
                 cpu_s: Callable[[], float], stop: Callable[[], None]) -> None:
        from gripper_interfaces.msg import SupervisorStatus
        from gripper_ros.nodes.loop_io import read_status
        from gripper_ros.nodes.qos import GRAPH_QOS
        from gripper_ros.wire import TOPIC_STATUS, qualified
        self._read_status = read_status
        self._tick_count, self._cpu_s, self._stop = tick_count, cpu_s, stop
        self.sub = node.create_subscription(SupervisorStatus, qualified(namespace, TOPIC_STATUS),
                                            self._on_status, GRAPH_QOS, raw=True)
        self.marks: Dict[int, list] = {}
        self.finished: set = set()
        self.capped: set = set()
        self._deadline: Optional[float] = None

    def arm(self, cap_s: float) -> None:
        self._deadline = time.perf_counter() + cap_s if cap_s > 0 else None

    def _on_status(self, data: bytes) -> None:
        now = time.perf_counter()
        msg = self._read_status(data)
        gid = msg.grasp_id
        if gid == 0 or gid in self.finished:
            return
        marks = self.marks.setdefault(gid, [])
        if not marks or marks[-1][0] != msg.phase:
            ticks = self._tick_count() if self._tick_count else None
            marks.append((msg.phase, now, ticks, stamp_ns(msg),
                          self._cpu_s()))
        if msg.phase not in (Phase.POSITION, Phase.FORCE):
            self.finished.add(gid)
        elif self._deadline is not None and now > self._deadline and gid not in self.capped:
            self.capped.add(gid)
            self._stop()


def quiet_loggers() -> None:
    """Set the graph's loggers to WARN, so that a benchmark's output is its figures."""
    from rclpy.logging import LoggingSeverity, set_logger_level
    for name in GRAPH_LOGGERS:
        set_logger_level(name, LoggingSeverity.WARN)
