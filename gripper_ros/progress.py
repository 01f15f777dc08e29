"""A progress bar for long jobs (sweeps, studies, soaks): count, rate and time left.

tqdm, on standard error, only when it is a terminal and not ``--quiet``: a log or a pipe gets
nothing from it.
"""
from __future__ import annotations

import sys


def progress_bar(total: int, desc: str, unit: str = 'grasp', quiet: bool = False):
    """Return a tqdm bar of ``total`` ``unit``; disabled off a terminal or when ``quiet``.

    Use it as a context manager; its ``update(n)`` is what the engine's ``progress`` takes.
    """
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True,
                disable=quiet or not sys.stderr.isatty(), smoothing=0.1)
