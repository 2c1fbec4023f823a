"""
The named records of the compiled kernels: a record's declaration checks what it is built from.

A small record of its own (two arrays and a scalar) through :func:`make_record`: fields by name
on both sides, the same memory on both sides, a read-only field, the checks of every field, the
owner that refuses to rebind an array, and a record handed back from compiled code.
"""

from cbha_inverse.core._kernels import kernel_modules
from cbha_inverse.core._kernels.records import (compiled_entry, define_record, Field, make_record,
                                                Record, RecordOwner, RecordType)
import numba
from numba.experimental import structref
import numpy as np
import pytest


@structref.register
class PairRecordType(RecordType):
    """The numba type of :class:`PairRecord`."""


class PairRecord(Record):
    """Values, their read-only weights and a scale."""

    __slots__ = ()


PAIR_FIELDS = (
    Field('values', np.float64, 1, '(k,) values'),
    Field('weights', np.float64, 1, '(k,) weights', read_only=True),
    Field('scale', float, 0, 'factor of the values'),
)
define_record(PairRecord, PairRecordType, PAIR_FIELDS)


@numba.njit
def new_pair(*values):
    return PairRecord(*values)


@numba.njit
def scale_and_weigh(pair):
    """Scale ``pair.values`` in place; return the weighted sum of the scaled values."""
    total = 0.0
    for i in range(pair.values.shape[0]):
        pair.values[i] *= pair.scale
        total += pair.weights[i] * pair.values[i]
    return total


@numba.njit
def handed_back(pair):
    return pair


def _pair(values=None, weights=None, scale=2.0):
    values = np.array([1.0, 2.0, 3.0]) if values is None else values
    weights = np.array([0.5, -1.0, 4.0]) if weights is None else weights
    return make_record(PairRecord, new_pair, values=values, weights=weights, scale=scale)


def test_the_compiled_code_reads_and_writes_the_arrays_the_record_was_built_with():
    values = np.array([1.0, 2.0, 3.0])
    pair = _pair(values)
    assert scale_and_weigh(pair) == pytest.approx(0.5 * 2 - 1.0 * 4 + 4.0 * 6)
    np.testing.assert_array_equal(values, [2.0, 4.0, 6.0])
    assert pair.values is values and pair.scale == 2.0
    # the read-only field is a view of the given array that refuses writes
    assert not pair.weights.flags.writeable
    with pytest.raises(ValueError):
        pair.weights[0] = 1.0
    with pytest.raises(AttributeError, match='offsets'):
        pair.offsets


def test_a_record_handed_back_from_compiled_code_is_the_same_record():
    pair = _pair()
    back = handed_back(pair)
    entry = compiled_entry(scale_and_weigh, back)
    assert entry(back) == pytest.approx(21.0)
    np.testing.assert_array_equal(pair.values, [2.0, 4.0, 6.0])


@pytest.mark.parametrize('values, message', [
    ({'offsets': np.zeros(3)}, 'unknown fields'),
    ({'values': np.zeros(3, np.float32)}, 'float64 array'),
    ({'values': np.zeros((3, 1))}, '1-D'),
    ({'values': np.zeros(6)[::2]}, 'C-contiguous'),
    ({'values': [1.0, 2.0, 3.0]}, 'list'),
    ({'values': np.zeros(3)}, 'writable'),
])
def test_every_field_is_checked_against_its_declaration(values, message):
    given = {'values': np.zeros(3), 'weights': np.ones(3), 'scale': 1.0}
    given.update(values)
    if message == 'writable':
        given['values'].flags.writeable = False
    with pytest.raises(ValueError, match=message):
        make_record(PairRecord, new_pair, **given)
    del given['scale']
    with pytest.raises(ValueError, match=r"missing fields \['scale'\]"):
        make_record(PairRecord, new_pair, **given)


class _Owner(RecordOwner):

    def __init__(self):
        arrays = {'values': np.zeros(3), 'weights': np.ones(3)}
        self._hold(make_record(PairRecord, new_pair, scale=1.0, **arrays), arrays)


def test_the_owner_refuses_to_rebind_an_array_of_its_record():
    owner = _Owner()
    values = owner.values
    owner.values += 1.0                      # in place: the same array, allowed
    assert owner.values is values and (owner.record.values == 1.0).all()
    with pytest.raises(AttributeError, match=r'values\[:\] = \.\.\.'):
        owner.values = np.zeros(3)
    owner.label = 'not a field'              # other attributes are free
    assert owner.values is values


def test_every_record_of_the_kernels_is_declared_with_named_documented_fields():
    records = [value for module in kernel_modules() for value in vars(module).values()
               if isinstance(value, type) and issubclass(value, Record)
               and value is not Record]
    assert sorted(record.__name__ for record in records) == [
        'EquilibriumRecord', 'EstimatorRecord', 'NewtonRecord', 'ObstacleRowsRecord', 'TickRecord']
    for record in records:
        names = [field.name for field in record.fields]
        assert len(set(names)) == len(names) and all(name.isidentifier() for name in names)
        assert all(field.doc and field.ndim in (0, 1, 2, 3, 4) for field in record.fields)
