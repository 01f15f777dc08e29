"""What the benchmarks share: a node of their own, service calls, CPU time of a process."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from typing import Callable

from gripper_ros.bench.pingpong import BenchError


def call(client, request, timeout_s: float):
    """Return the response of a real service call, or raise BenchError when none came in time."""
    from gripper_ros.nodes.services import call_and_wait
    response = call_and_wait(client, request, timeout_s)
    if response is None:
        raise BenchError(f'{client.srv_name} did not answer within {timeout_s:g} s')
    return response


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc; NaN elsewhere)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            fields = f.read().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, IndexError, ValueError):
        return float('nan')


class SpunNode:
    """A node in a context of its own, spun by an EventsExecutor on a thread of its own.

    What a benchmark watches the graph and calls its services from, as another process would.
    Make its subscriptions and clients on :attr:`node`, then :meth:`start` it.
    """

    def __init__(self, name: str, namespace: str | None = None) -> None:
        import rclpy
        from rclpy.experimental import EventsExecutor
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(name, context=self.context,
                                      **({'namespace': namespace} if namespace else {}))
        self.executor = EventsExecutor(context=self.context)
        self._stop = rclpy.task.Future()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        from gripper_ros.nodes.process import spin_until_stopped
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=spin_until_stopped,
                                        args=(self.executor, self._stop), daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set_result(True)
        if self._thread is not None:
            self._thread.join(5.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()


def run_bench(prog: str, run: Callable[[], int]) -> int:
    """Return ``run()``'s exit status; a BenchError is one line and 1, Ctrl-C is 130."""
    try:
        return run()
    except BenchError as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def reap(proc: subprocess.Popen, timeout_s: float, group: bool = False) -> None:
    """Wait ``timeout_s`` for a child told to stop, then kill it (``group``: its whole group)."""
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        if group:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.kill()
        proc.wait()


def group_pids(pgid: int) -> list[int]:
    """Return the processes of process group ``pgid`` still alive (Linux /proc; zombies not)."""
    pids = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open(f'/proc/{entry}/stat') as f:
                fields = f.read().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != 'Z':
            pids.append(int(entry))
    return pids


def ros2_launch_command(namespace: str, per_node: bool = False) -> list[str]:
    """Return ``ros2 launch gripper_ros gripper.launch.py`` in ``namespace`` (BenchError: none)."""
    import shutil
    ros2 = shutil.which('ros2')
    if ros2 is None:
        raise BenchError('the ros2 command is not on PATH (source a ROS 2 with ros2launch)')
    return [ros2, 'launch', 'gripper_ros', 'gripper.launch.py', f'namespace:={namespace}',
            f'per_node:={"true" if per_node else "false"}']
