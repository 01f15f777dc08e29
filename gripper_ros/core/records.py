"""The compiled kernels' numpy records: how a kernel takes one, how a Python face reads it.

The kernels own each face's state in a one-element structured array, ``self.record``; a face
reads and writes its fields through these descriptors rather than one hand-written property each.
Every kernel called from Python (a face's, a node's, the compiled loop itself) is declared with
:func:`face_kernel` and the types it is called with, so that :func:`compile_face_kernels`
compiles every one of them ahead of the first call: the one compile path of the core.
"""

from __future__ import annotations

import dataclasses
import sys

import numba
from numba import types
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


class RecordChoice:
    """A two-valued setting (such as an enum) kept as a 0/1 field: ``when_set`` while it is 1."""

    def __init__(self, field: str, when_set, when_clear, *, at: str = 'record'):
        self.field, self.when_set, self.when_clear, self.at = field, when_set, when_clear, at

    def __get__(self, face, owner=None):
        if face is None:
            return self
        set_ = as_record(getattr(face, self.at))[self.field]
        return self.when_set if set_ else self.when_clear

    def __set__(self, face, value) -> None:
        as_record(getattr(face, self.at))[self.field] = value is self.when_set


def record_view(name: str, dtype: np.dtype, fields, doc: str = '', **defaults) -> type:
    """Return a frozen dataclass of some of ``dtype``'s fields, read by ``view.of(record)``.

    ``fields`` names the record's fields, or maps each attribute to its field; an attribute
    reads as ``bool`` from a 1-byte field, as ``int`` from another integer one, else as
    ``float``; ``defaults`` overrides the zero an attribute has when built by hand.
    """
    fields = dict(fields) if isinstance(fields, dict) else {f: f for f in fields}
    reads = {attr: _reader(dtype.fields[field][0]) for attr, field in fields.items()}
    view = dataclasses.make_dataclass(
        name, [(attr, read, dataclasses.field(default=defaults.get(attr, read())))
               for attr, read in reads.items()], frozen=True)
    view.__doc__ = doc
    view.__module__ = sys._getframe(1).f_globals.get('__name__', __name__)

    def of(record) -> view:
        s = as_record(record)
        return view(*(read(s[field]) for read, field in zip(reads.values(), fields.values())))

    view.of = staticmethod(of)
    return view


def _reader(dtype: np.dtype):
    if dtype.kind == 'b' or (dtype.kind == 'u' and dtype.itemsize == 1):
        return bool
    return int if dtype.kind in 'iu' else float


def copy_fields(record, source, names=None, prefix: str = '', source_prefix: str = '') -> None:
    """Set each ``prefix + name`` of ``record`` to ``source_prefix + name`` of ``source``.

    ``source`` is an object (its attributes), a record, or (from Python) a dict of values;
    ``names`` the fields, named alike in both, or (from Python) a dict {record's field:
    source's name}; None (a dict source): every key of it. In compiled code ``names`` and the
    prefixes are constants and the copy compiles to one assignment per field.
    """
    read = source.__getitem__ if isinstance(source, (np.void, np.ndarray, dict)) else \
        (lambda field: getattr(source, field))
    names = tuple(source) if names is None else names
    for field, name in names.items() if isinstance(names, dict) else zip(names, names):
        record[prefix + field] = read(source_prefix + name)


def fields_into(out, record, names) -> None:
    """Set ``out[i]`` to field ``names[i]`` of ``record`` (compiled: one assignment each)."""
    for i, name in enumerate(names):
        out[i] = record[name]


def set_fields(record, names, value) -> None:
    """Set each of ``names`` in ``record`` to ``value`` (compiled: one assignment each)."""
    for name in names:
        record[name] = value


def _literal(value, what: str):
    """Return the constant a compiled call passed (a literal, or an omitted default)."""
    if isinstance(value, types.Omitted):
        return value.value
    if isinstance(value, str):               # a default the call left out
        return value
    if isinstance(value, types.BaseTuple):
        return tuple(_literal(v, what) for v in value)
    if isinstance(value, types.Literal):
        return value.literal_value
    raise numba.errors.TypingError(f'{what} must be a constant in compiled code, got {value}')


def _compiled(lines: list[str], name: str):
    """Return the function ``name`` that ``lines`` (Python source) define."""
    namespace = {}
    exec('\n'.join(lines), namespace)      # noqa: S102 - source built from a record's names
    return namespace[name]


@overload(copy_fields, prefer_literal=True)
def _copy_fields(record, source, names, prefix='', source_prefix=''):
    names = _literal(names, 'names')
    prefix, source_prefix = _literal(prefix, 'prefix'), _literal(source_prefix, 'source_prefix')
    return _compiled(['def copy(record, source, names, prefix="", source_prefix=""):']
                     + [f'    record.{prefix}{n} = source.{source_prefix}{n}' for n in names]
                     + ['    return None'], 'copy')


@overload(fields_into, prefer_literal=True)
def _fields_into(out, record, names):
    names = _literal(names, 'names')
    return _compiled(['def into(out, record, names):']
                     + [f'    out[{i}] = record.{n}' for i, n in enumerate(names)]
                     + ['    return None'], 'into')


@overload(set_fields, prefer_literal=True)
def _set_fields(record, names, value):
    names = _literal(names, 'names')
    return _compiled(['def set_(record, names, value):']
                     + [f'    record.{n} = value' for n in names] + ['    return None'], 'set_')


FACE_KERNELS = []
"""Every (kernel, argument types) a face calls from Python, as :func:`face_kernel` declares."""


def face_kernel(*args):
    """Declare the types a Python face calls this compiled kernel with (stack for several).

    Each of ``args`` is a record dtype (a 1-element array of it), ``float``, ``int``,
    ``bool``, a numba type, or a tuple of these (a tuple argument).
    """
    signature = tuple(_numba_type(a) for a in args)

    def declare(kernel):
        if not isinstance(kernel, numba.core.dispatcher.Dispatcher):
            if numba.config.DISABLE_JIT:          # the interpreted core: nothing to compile
                return kernel
            raise TypeError(f'{kernel!r} is not compiled: put face_kernel above numba.njit')
        FACE_KERNELS.append((kernel, signature))
        return kernel
    return declare


FLOATS = types.float64[::1]
"""A float array argument of :func:`face_kernel`."""
FLOATS_2D = types.float64[:, ::1]
"""A 2-D float array argument of :func:`face_kernel`."""
INTS = types.int64[::1]
"""An int64 array argument of :func:`face_kernel`."""
UINT8S = types.uint8[::1]
"""A byte array argument (a record's bytes) of :func:`face_kernel`."""
BYTES = numba.typeof(b'')
"""A ``bytes`` argument (a serialised message) of :func:`face_kernel`."""


def _numba_type(arg):
    if isinstance(arg, np.dtype):
        return types.Array(numba.from_dtype(arg), 1, 'C')
    if isinstance(arg, tuple):
        return types.Tuple(tuple(_numba_type(a) for a in arg))
    if arg in (float, int, bool):
        return numba.typeof(arg())
    return arg


def compile_face_kernels(package: str = 'gripper_ros') -> int:
    """Compile (or load from numba's cache) the declared kernels of ``package``; return how many.

    The one way the core is compiled ahead: set-up compiles them all, a node's face loads its
    package's before its first tick.
    """
    count = 0
    for kernel, signature in FACE_KERNELS:
        module = kernel.py_func.__module__
        if module == package or module.startswith(package + '.'):
            kernel.compile(signature)
            count += 1
    return count


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
