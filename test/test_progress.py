"""Progress on long jobs: a bar with the count, the rate and the time left, only on a terminal.

The bar every long job uses (``progress_bar``), updated as the engine updates it, with
standard error a terminal, not one, and a terminal with ``quiet``.
"""
from __future__ import annotations

import io
import re
import sys

from gripper_ros.progress import progress_bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _run_bar(monkeypatch, capsys, terminal: bool, quiet: bool = False) -> str:
    """Count 30 grasps in chunks of 10, as the engine reports them; return what was printed."""
    if terminal:
        monkeypatch.setattr(sys, 'stderr', _Terminal())
    with progress_bar(30, 'contact_sweep', quiet=quiet) as bar:
        for _ in range(3):
            bar.update(10)
    return sys.stderr.getvalue() if terminal else capsys.readouterr().err


def test_on_a_terminal_the_bar_shows_count_rate_and_time_left(monkeypatch, capsys):
    err = _run_bar(monkeypatch, capsys, True)
    last = err.replace('\r', '\n').strip().splitlines()[-1]
    assert last.startswith('contact_sweep: 100%') and '30/30' in last, last
    assert re.search(r'\[\d\d:\d\d<\d\d:\d\d, +[\d.]+(grasp/s|s/grasp)\]', last), last


def test_off_a_terminal_and_with_quiet_nothing_is_printed(monkeypatch, capsys):
    assert _run_bar(monkeypatch, capsys, False) == ''
    assert _run_bar(monkeypatch, capsys, True, quiet=True) == ''
