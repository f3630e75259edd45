"""Borrowed arrays (muls.infra.borrowed): the same memory, no memory reference, tuples borrowed member by member."""

from typing import NamedTuple

import numba
import numpy as np
import pytest
from numba.core import cgutils, types
from numba.extending import intrinsic

from muls.infra.borrowed import borrowed


@intrinsic
def _meminfo_is_null(typingctx, array):
    """Whether numba holds no memory reference for ``array`` (its meminfo null), read off the array's own struct."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context, builder, signature, args):
        struct = context.make_array(signature.args[0])(context, builder, value=args[0])
        return cgutils.is_null(builder, struct.meminfo)

    return types.boolean(array), codegen


class _Pair(NamedTuple):
    values: np.ndarray
    scale: float


@numba.njit
def _references(a):
    return _meminfo_is_null(a), _meminfo_is_null(borrowed(a))


@numba.njit
def _write_through(a, pair):
    b, (p, q) = borrowed((a, (pair, 2)))
    b[1] = p.values[0] * p.scale + q
    return _meminfo_is_null(p.values), q


def test_a_borrowed_array_has_no_memory_reference_and_its_owner_keeps_one():
    assert _references(np.arange(4.0)) == (False, True)


def test_borrowing_goes_into_named_tuples_and_leaves_scalars_and_the_memory_as_they_are():
    a = np.zeros(3)
    pair = _Pair(np.array([5.0]), 3.0)
    null, q = _write_through(a, pair)
    assert null and q == 2
    np.testing.assert_array_equal(a, [0.0, 17.0, 0.0])  # written through the borrowed view into the caller's array


def test_a_value_holding_something_but_arrays_and_scalars_is_refused_at_compile_time():
    @numba.njit
    def borrow_a_string(s):
        return borrowed(s)

    with pytest.raises(numba.core.errors.TypingError):
        borrow_a_string("not an array")
