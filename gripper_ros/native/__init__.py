"""Native code the package preloads into its own processes: the condition-wait fix.

``cond_wait_fix.c`` (built by setup.py when a C compiler is present) makes a wrapped "wait
for ever" deadline wait for ever instead of failing, which is what keeps a process of Fast DDS
2.14 (the ros-jazzy wheels) from spinning for ever when its last node is destroyed while a
discovery callback is in flight (docs/ARCHITECTURE.md, "A stop that always stops"). It acts
only when loaded before the C library (``LD_PRELOAD``), so each executable of the package
starts again once with it (:func:`preload_into_this_process`).
"""
from __future__ import annotations

import importlib.machinery
import os
from pathlib import Path
import sys

LIBRARY_STEM = 'cond_wait_fix'


def cond_wait_fix_path() -> Path | None:
    """Return the built fix's path, or None when it was not built (no C compiler)."""
    here = Path(__file__).resolve().parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = here / (LIBRARY_STEM + suffix)
        if path.is_file():
            return path
    return None


def preloaded() -> bool:
    """Say whether this process's LD_PRELOAD names the built fix (of this or any checkout)."""
    names = os.environ.get('LD_PRELOAD', '').replace(':', ' ').split()
    return any(Path(name).name.startswith(LIBRARY_STEM + '.') for name in names)


def preload_into_this_process() -> None:
    """Start this process again, the same program with the same arguments, with the fix.

    Does nothing when the fix is already preloaded, was not built, or the interpreter's
    command line is unknown; the process then goes on without it. The process id, its
    standard streams and its signals stay the same (exec), so a launcher sees one process.
    """
    path = cond_wait_fix_path()
    argv = getattr(sys, 'orig_argv', None)
    if path is None or preloaded() or not argv or not sys.executable:
        return
    preload = ' '.join(filter(None, (os.environ.get('LD_PRELOAD', ''), str(path))))
    environ = dict(os.environ, LD_PRELOAD=preload)
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execve(sys.executable, argv, environ)
    except OSError:
        return
