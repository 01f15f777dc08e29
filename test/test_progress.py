"""Progress on long jobs: a bar with the count, the rate and the time left, only on a terminal.

contact_sweep --quick (30 grasps, in this process) with standard error a terminal, not one,
and a terminal with --quiet.
"""
from __future__ import annotations

import io
import re
import sys

from gripper_ros.apps import contact_sweep


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _sweep_stderr(monkeypatch, capsys, terminal: bool, *extra) -> str:
    if terminal:
        monkeypatch.setattr(sys, 'stderr', _Terminal())
    assert contact_sweep.main(['--quick', '--jobs', '1', '--hold-s', '0', *extra]) == 0
    return sys.stderr.getvalue() if terminal else capsys.readouterr().err


def test_on_a_terminal_the_bar_shows_count_rate_and_time_left(monkeypatch, capsys):
    err = _sweep_stderr(monkeypatch, capsys, True)
    last = err.replace('\r', '\n').strip().splitlines()[-1]
    assert last.startswith('contact_sweep: 100%') and '30/30' in last, last
    assert re.search(r'\[\d\d:\d\d<\d\d:\d\d, +[\d.]+(grasp/s|s/grasp)\]', last), last


def test_off_a_terminal_and_with_quiet_nothing_is_printed(monkeypatch, capsys):
    assert _sweep_stderr(monkeypatch, capsys, False) == ''
    assert _sweep_stderr(monkeypatch, capsys, True, '--quiet') == ''
