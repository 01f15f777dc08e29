"""Text for one-line messages (errors, refusals) shared by nodes, apps and bag tools."""
from __future__ import annotations


def one_line(text: object) -> str:
    """Return ``text`` as one line, its whitespace runs (newlines too) as single spaces."""
    return ' '.join(str(text).split())
