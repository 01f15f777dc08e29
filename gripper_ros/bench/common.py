"""What the benchmarks share: service calls from a measuring thread, CPU time of a process."""
from __future__ import annotations

import os

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
