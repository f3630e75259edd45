"""Borrowed arrays: views that numba does not count references to, for the arrays a kernel's hot loops pass on.

numba counts the references to an array's memory with an atomic add and subtract (``NRT_incref``/``NRT_decref``)
wherever a variable, an argument or a tuple's field binds it, and its pruning pass removes a pair only where both lie
in one basic block or a simple fork of blocks. A kernel inlined into a loop binds each of its array arguments on
entry and releases them after its own loops, so every pass of the loop pays two atomic operations per array, and
a named tuple of arrays pays them per field: 128 a record window in the digitiser, a quarter of its time.

:func:`borrowed` gives the same arrays with no memory reference (numba's ``meminfo`` null, as ``numba.carray``'s
arrays have), whose bindings cost a call that tests for null. A borrowed array must not outlive its owner: borrow
only a kernel's own arguments, which the caller holds for the whole call, never an array the kernel allocates
(numba frees that after its last use as an owned array), and never return one.
"""

from __future__ import annotations

from numba.core import cgutils, types
from numba.extending import intrinsic


def _borrow(context, builder, ty, value):
    """``value`` of numba type ``ty`` with every array in it made reference-free (recursing into tuples)."""
    if isinstance(ty, types.Array):
        array = context.make_array(ty)(context, builder, value=value)
        array.meminfo = cgutils.get_null_value(array.meminfo.type)
        array.parent = cgutils.get_null_value(array.parent.type)
        return array._getvalue()
    if isinstance(ty, types.BaseTuple):
        out = value
        for i, member in enumerate(ty):
            out = builder.insert_value(out, _borrow(context, builder, member, builder.extract_value(value, i)), i)
        return out
    return value


def _is_borrowable(ty) -> bool:
    """Whether numba type ``ty`` is an array, a scalar, None, or a tuple of such (nested): what :func:`borrowed` takes."""
    return isinstance(ty, (types.Array, types.Number, types.Boolean, types.NoneType, types.Omitted)) or (
        isinstance(ty, types.BaseTuple) and all(_is_borrowable(member) for member in ty))


@intrinsic
def borrowed(typingctx, value):
    """``value`` (an array, a scalar, None, or a tuple or named tuple of them, nested) with each array a
    reference-free view of the same memory (module doc)."""
    if not _is_borrowable(value):
        return None

    def codegen(context, builder, signature, args):
        return _borrow(context, builder, signature.args[0], args[0])

    return value(value), codegen

