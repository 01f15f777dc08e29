"""The compiled kernels' numpy records: how a kernel takes one, how a Python face reads it.

The kernels own each face's state in a one-element structured array, ``self.record``; a face
reads and writes its fields through these descriptors rather than one hand-written property each.
"""

from __future__ import annotations

from numba import types
from numba.extending import overload
import numpy as np


class RecordField:
    """The field of ``self.record[0]`` of the attribute's own name, read through ``read``."""

    def __init__(self, read=float, writable: bool = True):
        self.read = read
        self.writable = writable
        self.name = ''

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, face, owner=None):
        if face is None:
            return self
        return self.read(face.record[0][self.name])

    def __set__(self, face, value) -> None:
        if not self.writable:
            raise AttributeError(f'{self.name} is read-only')
        face.record[0][self.name] = value


class RecordLimits:
    """An output clamp kept as fields ``low`` and ``high`` of ``self.record[0]``."""

    def __get__(self, face, owner=None):
        if face is None:
            return self
        s = face.record[0]
        return (float(s['low']), float(s['high']))

    def __set__(self, face, limits: tuple[float, float]) -> None:
        s = face.record[0]
        s['low'], s['high'] = limits


def as_record(x):
    """Return the record of a 1-element record array, or the record itself.

    Kernels take either: a Python façade passes its 1-element array (a record passed from
    Python would be a copy), compiled callers pass records (no reference counting).
    """
    return x[0] if isinstance(x, np.ndarray) else x


@overload(as_record)
def _as_record(x):
    if isinstance(x, types.Array):
        return lambda x: x[0]
    return lambda x: x
