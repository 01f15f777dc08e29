"""Lockstep ping-pong benchmark: rclpy EventsExecutor vs SingleThreadedExecutor.

Thin wrapper: the measurement lives in :mod:`gripper_ros.bench_graph` (installed with the
package, so the ``bench_graph`` console script does not depend on this folder), which uses it as
the baseline of the node-graph benchmark.

Two nodes in one process share one executor.  Node A publishes a std_msgs/Float64 ping, node B
echoes it back, and A publishes the next ping only after the echo of the previous one arrived, so
exactly one message in flight and each round trip is two publish/take/callback cycles.

Usage::

    python bench/bench_pingpong.py --executor both --seconds 3

Other code can import :func:`measure_pingpong` from here or from ``gripper_ros.bench_graph``.
"""
from __future__ import annotations

import sys
from pathlib import Path

try:
    from gripper_ros.bench_graph import (EXECUTOR_KINDS, BenchError, _BenchError,  # noqa: F401
                                         build_pingpong_parser as build_parser,
                                         format_pingpong as _format, measure_pingpong,
                                         pingpong_main as main)
except ImportError:  # not sourced scripts/env.sh: fall back to the source tree next to us
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from gripper_ros.bench_graph import (EXECUTOR_KINDS, BenchError, _BenchError,  # noqa: F401
                                         build_pingpong_parser as build_parser,
                                         format_pingpong as _format, measure_pingpong,
                                         pingpong_main as main)

__all__ = ['EXECUTOR_KINDS', 'BenchError', 'build_parser', 'main', 'measure_pingpong']

if __name__ == '__main__':
    sys.exit(main())
