"""One grasp's time series: every loop message of every tick, as the graph publishes them.

A headless grasp or move keeps it (:mod:`gripper_ros.core.runtime.headless`), and a bag reader
builds it from a recording (:mod:`gripper_ros.bags.series`): the same rows, so that the same
analysis reads both. No rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import functools
from pathlib import Path
from typing import Any

from gripper_ros.wire import COMMAND_LAYOUT, REFERENCE_LAYOUT
import numpy as np

STATUS_ROW = np.dtype(
    [('stamp_ns', 'i8'), ('phase', 'i4'), ('active_controller', 'i4'),
     ('switch_criterion', 'i4'), ('grasp_id', 'i8'), ('outcome', 'i4'),
     ('position_setpoint_m', 'f8'), ('force_setpoint_n', 'f8'), ('position_m', 'f8'),
     ('force_n', 'f8'), ('contact', 'b1'), ('stage_id', 'i8'), ('approach_setpoint_m', 'f8'),
     ('pending_request', 'i4'), ('seed_voltage_v', 'f8')],
    align=True)
"""The supervisor's state: as ``supervisor/status`` reports it on a tick it changed, and as each
reference carries its decision (:attr:`GraspSeries.decisions`). The seed voltage is the
supervisor's in a run without ROS, NaN from a bag (``supervisor/status`` does not carry it)."""
OBJECT_ROW = np.dtype(
    [('stamp_ns', 'i8'), ('state', 'i4'), ('slip_m', 'f8'), ('slip_speed_mps', 'f8'),
     ('load_n', 'f8'), ('capacity_n', 'f8')], align=True)
"""The held object's ground truth on a tick the plant node publishes ``sim/object_state``."""
TICK_STATE_ROW = np.dtype(
    [('phase', 'i1'), ('force_setpoint_n', 'f8'), ('approach_setpoint_m', 'f8'),
     ('load_n', 'f8'), ('slip_m', 'f8'), ('hold_state', 'i4'), ('mu_est', 'f8')], align=True)
"""What the loop knew on a tick beside its message, one row a tick: the supervisor's phase and
setpoints, the held object's truth (load m (g + a) while held, slide so far, HoldState) and the
load-tracking law's friction estimate. A run without ROS keeps it; a bag does not."""


def rows(dtype: np.dtype, values=()) -> np.ndarray:
    """Return ``values`` (tuples in ``dtype``'s field order) as a structured array."""
    return np.array(list(values), dtype=dtype)


@dataclass(eq=False)
class GraspSeries:
    """One grasp's messages as structured arrays, in tick order; stamps are simulated time.

    ``ticks``, ``references`` and ``commands`` have the wire layouts' fields
    (``TICK_LAYOUT.dtype`` ...); ``statuses`` (:data:`STATUS_ROW`) the supervisor's state on
    each tick it changed; ``objects`` (:data:`OBJECT_ROW`) the held object's ground truth when
    the plant published it; ``tick_states`` (:data:`TICK_STATE_ROW`, runs without ROS only)
    one row a tick. The rest says where the series comes from: a bag's path, namespace, format,
    custom_data, message counts, size and damage, or nothing for a run.
    """

    ticks: np.ndarray
    references: np.ndarray = field(default_factory=lambda: rows(REFERENCE_LAYOUT.dtype))
    commands: np.ndarray = field(default_factory=lambda: rows(COMMAND_LAYOUT.dtype))
    statuses: np.ndarray = field(default_factory=lambda: rows(STATUS_ROW))
    objects: np.ndarray = field(default_factory=lambda: rows(OBJECT_ROW))
    tick_states: np.ndarray | None = field(default=None, repr=False)
    path: Path = Path()
    namespace: str = ''
    bag_format: int = 2
    custom_data: dict[str, Any] = field(default_factory=dict, repr=False)
    counts: dict[str, int] = field(default_factory=dict, repr=False)
    start_ns: int = 0
    end_ns: int = 0
    size_bytes: int = 0
    truncated: bool = False
    damage: str = ''
    absent: frozenset = frozenset()
    """``kind.field`` (kind ``tick``, ``reference``, ``command``) of the message fields the
    bag's own (older) message types lack: read as 0, never recorded."""

    @property
    def t_s(self) -> np.ndarray:
        """Each tick's time in seconds."""
        return self.ticks['stamp_ns'] * 1e-9

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    @functools.cached_property
    def decisions(self) -> np.ndarray:
        """Return the supervisor's decision of each reference (:data:`STATUS_ROW`).

        Its switch criterion is the one the supervisor's state reported by then; when the
        supervisor ended the request after the last reference (a FAULT: no stage is named, so no
        reference carries it), its last state follows, with a NaN seed voltage.
        """
        ref, st = self.references, self.statuses
        out = np.zeros(ref.size, STATUS_ROW)
        for name in STATUS_ROW.names:
            if name in ref.dtype.names:
                out[name] = ref[name]
        out['active_controller'] = ref['controller']
        if st.size:
            at = np.searchsorted(st['stamp_ns'], ref['stamp_ns'], side='right') - 1
            known = at >= 0
            out['switch_criterion'][known] = st['switch_criterion'][at[known]]
            last = st[-1]
            if not (ref.size and (last['stamp_ns'] < ref['stamp_ns'][-1] or (
                    out['outcome'][-1] == last['outcome'] and out['phase'][-1] == last['phase']))):
                final = np.zeros(1, STATUS_ROW)
                final[0] = last
                final['seed_voltage_v'] = np.nan
                out = np.concatenate((out, final))
        return out


def seconds(stamped: np.ndarray) -> np.ndarray:
    """Return the ``stamp_ns`` of structured rows in seconds."""
    return stamped['stamp_ns'] * 1e-9


__all__ = ['GraspSeries', 'OBJECT_ROW', 'rows', 'seconds',
           'STATUS_ROW', 'TICK_STATE_ROW']
