"""Silence as the watchdogs count it: wall time without progress while the executor ran."""
from __future__ import annotations

import time


MAX_COUNTED_GAP_S = 0.25
"""Silence is counted only while the executor runs: a longer gap between two watchdog checks
(the process starved, a slow callback) counts as this much, since messages may be queued behind."""


class ExecutorSilence:
    """Wall time without progress, for the watchdogs.

    The supervisor's is time without a tick, the controllers' time without a status. Only time
    in which the executor demonstrably ran counts: call :meth:`check` from a steady timer; a
    check more than ``MAX_COUNTED_GAP_S`` late adds only that much, so that after a stall of the
    whole process the messages queued behind the timer are not taken for silence.
    """

    def __init__(self):
        self.silent_s = 0.0
        self._last_check = time.monotonic()

    def reset(self) -> None:
        """Progress was made: silence starts afresh."""
        self.silent_s = 0.0
        self._last_check = time.monotonic()

    def check(self, counting: bool) -> float:
        """Check from the timer; the gap since the last check counts only when ``counting``."""
        now = time.monotonic()
        gap_s, self._last_check = now - self._last_check, now
        if counting:
            self.silent_s += min(gap_s, MAX_COUNTED_GAP_S)
        return self.silent_s
