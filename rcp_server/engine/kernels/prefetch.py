"""``prefetch(array, k)``: a hint, from a compiled kernel, that the CPU bring the cache line of ``array``'s k-th
element (flat, C order) in now; it changes no result.

A kernel that first works out where its scattered reads go (a texture's texels, a face's corners) and then
reads them in a later loop asks for the lines in the first: then many reads wait on memory at once, where the
later loop alone overlaps the waits of two or three samples.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_I8_PTR = ir.IntType(8).as_pointer()
_I32 = ir.IntType(32)


@intrinsic
def prefetch(typingctx, array, k):
    """LLVM's prefetch of ``array``'s k-th element: a read, kept in every cache level, of data."""
    if not isinstance(array, types.Array) or not isinstance(k, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        index = context.cast(builder, args[1], signature.args[1], types.intp)
        address = builder.bitcast(builder.gep(data, [index]), _I8_PTR)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [_I8_PTR, _I32, _I32, _I32]), "llvm.prefetch.p0"
        )
        builder.call(function, [address, ir.Constant(_I32, 0), ir.Constant(_I32, 3), ir.Constant(_I32, 1)])
        return context.get_dummy_value()

    return types.void(array, k), codegen
