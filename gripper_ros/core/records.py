"""The compiled kernels' numpy records: how a kernel takes one, how a Python face reads it.

The kernels own each face's state in a one-element structured array, ``self.record``; a face
reads and writes its fields through these descriptors rather than one hand-written property each.
"""

from __future__ import annotations

from numba import literal_unroll, types
from numba.extending import overload
import numpy as np


class RecordField:
    """A field of the face's record, read through ``read``.

    ``field`` is the record's field (default: the attribute's own name); ``at`` the face's
    attribute that holds the record or its one-element array (default ``record``).
    """

    def __init__(self, read=float, writable: bool = True, *, field: str = '',
                 at: str = 'record', doc: str | None = None):
        self.read = read
        self.writable = writable
        self.field = field
        self.at = at
        self.name = ''
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.name = name
        self.field = self.field or name

    def __get__(self, face, owner=None):
        if face is None:
            return self
        return self.read(as_record(getattr(face, self.at))[self.field])

    def __set__(self, face, value) -> None:
        if not self.writable:
            raise AttributeError(f'{self.name} is read-only')
        as_record(getattr(face, self.at))[self.field] = value


class RecordPair:
    """Two fields of the face's record as one (first, second) tuple, such as output limits.

    With ``flag``, a third field says whether the pair is set: the attribute reads None while
    it is 0, and setting None clears it.
    """

    def __init__(self, first: str, second: str, read=float, *, flag: str = '',
                 at: str = 'record'):
        self.first, self.second, self.read, self.flag, self.at = first, second, read, flag, at

    def __get__(self, face, owner=None):
        if face is None:
            return self
        s = as_record(getattr(face, self.at))
        if self.flag and not s[self.flag]:
            return None
        return (self.read(s[self.first]), self.read(s[self.second]))

    def __set__(self, face, pair) -> None:
        s = as_record(getattr(face, self.at))
        if self.flag:
            s[self.flag] = pair is not None
        if pair is not None:
            s[self.first], s[self.second] = pair


class RecordParams:
    """A settings object (a frozen dataclass) the face keeps, its ``fields`` copied to the record.

    The kernels read the fields from the record; the face gives back the object it was given.
    """

    def __init__(self, fields, *, at: str = 'record', doc: str | None = None):
        self.fields = tuple(fields)
        self.at = at
        self.name = ''
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, face, owner=None):
        if face is None:
            return self
        try:
            return face.__dict__[self.name]
        except KeyError:
            raise AttributeError(f'{self.name} is not set yet') from None

    def __set__(self, face, value) -> None:
        face.__dict__[self.name] = value
        copy_fields(as_record(getattr(face, self.at)), value, self.fields)


def copy_fields(record, source, names) -> None:
    """Set fields of ``record`` from ``source``, an object (its attributes) or a record.

    ``names``: the fields, named alike in both, or a dict {record's field: source's name}.
    Compiled, ``source`` is a record and ``names`` a constant tuple.
    """
    for field, name in names.items() if isinstance(names, dict) else zip(names, names):
        record[field] = source[name] if isinstance(source, np.void) else getattr(source, name)


@overload(copy_fields)
def _copy_fields(record, source, names):
    def copy(record, source, names):
        for name in literal_unroll(names):
            record[name] = source[name]
    return copy


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
