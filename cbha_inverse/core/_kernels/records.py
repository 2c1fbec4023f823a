"""
Named records of arrays for the compiled kernels: one declaration per record, fields by name.

numba unboxes every argument of a compiled call at every call (a few tenths of a microsecond per
array), so an entry over a few dozen arrays would pay more for its arguments than for its
arithmetic. A record is a numba StructRef (a reference-counted struct of arrays and scalars,
built once): an entry takes it as one argument and its kernels read the fields by name
(``system.stiffness``, ``tick.actuation``). A StructRef, rather than a jitclass, because numba
caches the machine code of functions that take a StructRef (a jitclass argument is not
cacheable) and because its fields are plain attributes on both sides.

Each record is declared once, by a tuple of :class:`Field` (name, element type, dimensions,
meaning) beside the kernels that read it; :func:`define_record` derives the compiled type's
constructor and its boxing from that tuple, and :func:`make_record` builds an instance from
arrays given by name, checking each against its field. Adding an array to a record is one line
of its declaration (and its allocation by the record's owner).

With numba's JIT off (``NUMBA_DISABLE_JIT=1``, the kernels' coverage run) the kernels run as
Python and a record is a plain namespace of the same fields.
"""

from dataclasses import dataclass
from types import SimpleNamespace

from llvmlite import ir
import numba
from numba.core import cgutils, types
from numba.core.extending import box, NativeValue, unbox
from numba.experimental import structref
import numpy as np


@dataclass(frozen=True)
class Field:
    """
    One field of a record.

    Attributes
    ----------
    name : str
        Attribute name on both sides (Python and compiled).
    dtype : type or str
        Element type of an array field (``np.float64``, ``np.int64``, ``np.bool_``,
        ``np.int8``), or ``'record'`` for a nested record, ``int`` / ``float`` for a scalar.
    ndim : int
        Dimensions of an array field (0 for a scalar or a record).
    doc : str
        What it holds: shape and unit.
    read_only : bool
        The compiled code only reads it: it is stored as a read-only view (one compiled type
        whatever the owner passes, a writable array or a read-only view).

    """

    name: str
    dtype: object
    ndim: int
    doc: str
    read_only: bool = False


class RecordType(types.StructRef):
    """Base of the numba types of the records (fields keep their array layout and flags)."""

    def preprocess_fields(self, fields):
        """Keep the field types as given (no literal types)."""
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Record(structref.StructRefProxy):
    """
    Base of the Python proxies of the records (build them with :func:`make_record`).

    Python reads the fields by name too (``system.record.rhs``): the arrays the record was built
    from, the same memory the compiled code reads and writes.
    """

    __slots__ = ('_values',)

    def __getattr__(self, name):
        """Return the field ``name`` as the record was built with it."""
        if name == '_values':
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f'{type(self).__name__} has no field {name!r}') from None


def define_record(proxy_class, type_class, fields):
    """
    Define the compiled constructor and the boxing of a record from its declaration.

    Parameters
    ----------
    proxy_class : type
        The record's :class:`Record` subclass (module level: numba's cache finds it by name).
    type_class : type
        The record's :class:`RecordType` subclass, registered with ``structref.register``.
    fields : tuple of Field
        The declaration (constructor order).

    """
    proxy_class.fields = tuple(fields)
    structref.define_constructor(proxy_class, type_class, [f.name for f in fields])
    _define_boxing(type_class, proxy_class)


def _define_boxing(type_class, proxy_class):
    """
    Box a record as numba's StructRef does; unbox it by an interned name.

    numba's own unboxing looks ``_meminfo`` up by a new string object at every call, and
    CPython's type attribute cache keeps a reference to each such string (by address) until
    the entry is reused: a call would now and then leave a few bytes behind, and a tick must
    allocate nothing. ``PyUnicode_InternFromString`` returns the one interned string instead.
    """
    constructor = proxy_class._numba_box_

    @box(type_class)
    def _box(typ, val, c):
        meminfo = cgutils.create_struct_proxy(typ)(c.context, c.builder, value=val).meminfo
        boxed_meminfo = c.box(types.MemInfoPointer(types.voidptr), meminfo)
        make = c.pyapi.unserialize(c.pyapi.serialize_object(constructor))
        type_object = c.pyapi.unserialize(c.pyapi.serialize_object(typ))
        boxed = c.pyapi.call_function_objargs(make, [type_object, boxed_meminfo])
        for reference in (make, type_object, boxed_meminfo):
            c.pyapi.decref(reference)
        return boxed

    @unbox(type_class)
    def _unbox(typ, obj, c):
        intern = cgutils.get_or_insert_function(
            c.builder.module, ir.FunctionType(c.pyapi.pyobj, [c.pyapi.cstring]),
            'PyUnicode_InternFromString')
        name = c.builder.call(intern, [c.context.insert_const_string(c.builder.module,
                                                                     '_meminfo')])
        meminfo_object = c.pyapi.object_getattr(obj, name)
        c.pyapi.decref(name)
        meminfo = c.unbox(types.MemInfoPointer(types.voidptr), meminfo_object).value
        value = cgutils.create_struct_proxy(typ)(c.context, c.builder)
        value.meminfo = meminfo
        c.pyapi.decref(meminfo_object)
        return NativeValue(value._getvalue())


def make_record(proxy_class, constructor, **values):
    """
    Return a record of the given fields (arrays are not copied).

    Parameters
    ----------
    proxy_class : type
        The record's proxy class (its ``fields``, :func:`define_record`).
    constructor : numba dispatcher
        The record's compiled constructor, ``constructor(*values)`` in field order (a
        module-level ``njit(cache=True)`` function returning ``proxy_class(*values)``).
    **values
        Every field by name: arrays of the declared element type and dimensions, C-contiguous,
        records, scalars.

    Returns
    -------
    Record or types.SimpleNamespace
        The compiled record (a namespace of the same fields with the JIT off).

    Raises
    ------
    ValueError
        If a field is missing or unknown, or an array does not match its declaration.

    """
    names = [f.name for f in proxy_class.fields]
    missing, unknown = set(names) - set(values), set(values) - set(names)
    if missing or unknown:
        raise ValueError(f'{proxy_class.__name__}: missing fields {sorted(missing)}, unknown '
                         f'fields {sorted(unknown)}')
    ordered = [_checked(proxy_class.__name__, field, values[field.name])
               for field in proxy_class.fields]
    if numba.config.DISABLE_JIT:
        return SimpleNamespace(**dict(zip(names, ordered)))
    record = constructor(*ordered)
    record._values = dict(zip(names, ordered))
    return record


def _checked(record, field, value):
    """Return a field's value as the record stores it, or raise."""
    if field.dtype == 'record':
        return value
    if field.ndim == 0:
        return field.dtype(value)
    if not isinstance(value, np.ndarray) or value.dtype != field.dtype or (
            value.ndim != field.ndim) or not value.flags.c_contiguous:
        raise ValueError(f'{record}.{field.name}: expected a C-contiguous {field.ndim}-D '
                         f'{np.dtype(field.dtype).name} array, got '
                         f'{getattr(value, "dtype", type(value))} of shape '
                         f'{getattr(value, "shape", None)}')
    if field.read_only:
        value = value.view()
        value.flags.writeable = False
    elif not value.flags.writeable:
        raise ValueError(f'{record}.{field.name}: the array must be writable')
    return value


class RecordOwner:
    """
    Base of the Python objects that own a record: its arrays are their attributes, not rebound.

    The compiled code reads the arrays the record was built with; assigning a new array to one
    of those attributes would leave the record on the old one, so it is refused (write into the
    array instead, ``owner.field[:] = value``). Rebinding to the same array, as an in-place
    operator does (``owner.mask |= dropped``), is allowed.
    """

    _fields = frozenset()

    def _hold(self, record, arrays):
        """Keep the record and make its arrays attributes of this object."""
        self.record = record
        for name, array in arrays.items():
            object.__setattr__(self, name, array)
        self._fields = frozenset(arrays)

    def __setattr__(self, name, value):
        """Refuse to rebind an attribute that is one of the record's arrays to another object."""
        if name in self._fields and value is not getattr(self, name):
            raise AttributeError(f'{name} is an array of the compiled record: write into it '
                                 f'({name}[:] = ...) instead of replacing it')
        object.__setattr__(self, name, value)


def compiled_entry(dispatcher, *arguments):
    """
    Return the compiled wrapper of an entry for the types of the given arguments.

    Compiles the entry for them, or loads it from numba's on-disk cache. Calling the wrapper
    skips numba's type dispatch, which types a record on its slow path at every call (a few
    tenths of a microsecond); the caller passes arguments of exactly these types (the wrapper
    does not check them).

    Parameters
    ----------
    dispatcher : numba dispatcher
        A compiled entry.
    *arguments
        Example arguments (their numba types are the signature).

    Returns
    -------
    callable
        The entry itself with numba's JIT off.

    """
    if numba.config.DISABLE_JIT:
        return dispatcher
    signature = tuple(numba.typeof(argument) for argument in arguments)
    dispatcher.compile(signature)
    return dispatcher.get_overload(signature)
