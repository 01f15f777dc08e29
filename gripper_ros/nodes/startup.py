"""How a node or tool refuses to start: one exception, one exit status."""
from __future__ import annotations


EXIT_BAD_START = 2
"""Exit status of a node or tool that refused to start (one line on stderr says why)."""


class StartupError(RuntimeError):
    """A node cannot start (its names are taken, a bad parameter); the message is one line."""
